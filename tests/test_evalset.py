"""The shipped labeled evaluation set, and the offline backends (bev DRA, rules SG) run on one clip of each
bank scenario: every clip described and converted, every generated script safe, compiled and run, and the
figures on that subset at least those measured on it (less MARGIN).

The whole set's targets (SCS >= 0.90 and HR <= 0.10; E2E-SC >= 0.90 overall and >= 0.80 per use case but for
the known misses) are checked by ``python -m bench.bench_evalset --set in-house``."""

import json
from collections import Counter

import pytest

from dv2s_gym.pipeline.evaluate import EVALSET_DIR, collect_items, evaluate
from scenario_bank.bank import Bank

from evalset_helpers import one_clip_per_use_case

# measured on 2026-11-27 on the subset (the first clip of each of the 30 bank scenarios), bev DRA and rules
# SG: (SCS, HR) and E2E-SC. The first clips of the 21 older scenarios give SCS 0.942 and HR 0.097; those of
# the 9 pre-crash typology scenarios 0.712 and 0.103 (the analyzer has no bicycle, reversing or pull-out yet);
# E2E-SC 0.944 on the 21 and 0.785 on the 9. With the first clips of the 2 scenarios added for types 23 and 36
# (32 clips), measured on 2026-11-27: SCS 0.870, HR 0.104, E2E-SC 0.889 (the obstacle after the turn 1.0, 0.0 and
# 1.0; the car passing behind the slow truck 0.538, 0.125 and 0.538: the analyzer reads a cut-in that brakes, not
# the truck ahead or the pass from behind). The bounds below stay those of the 30.
SUBSET_DRA = (0.873, 0.099)
SUBSET_E2E = 0.897
MARGIN = 0.03


def test_every_bank_scenario_has_several_labeled_clips():
    items = collect_items(EVALSET_DIR)
    per_scenario = Counter(item.stem.rsplit("_seed", 1)[0] for item in items)
    assert set(per_scenario) == {entry.name for entry in Bank().list()}
    assert min(per_scenario.values()) >= 3
    for item in items:
        assert item.video and item.video.endswith(".webm")
        label = json.loads((EVALSET_DIR / f"{item.stem}.label.json").read_text())
        assert item.elements.to_dict() == label["elements"]  # stored in canonical form
        assert label["scenario"] == item.stem.rsplit("_seed", 1)[0] and label["ego_policy"] in ("agent", "scenic")
    # the folder holds videos, their labels and the README: nothing the analyzer could read instead of pixels
    assert {p.suffix for p in EVALSET_DIR.iterdir() if p.is_file()} == {".webm", ".json", ".md"}
    # the labelled descriptions live in a subfolder, which collect_items (top level only) does not read
    assert {p.name for p in EVALSET_DIR.iterdir() if p.is_dir()} <= {"descriptions", "__pycache__"}


@pytest.fixture(scope="module")
def subset(tmp_path_factory):
    return one_clip_per_use_case(EVALSET_DIR, tmp_path_factory.mktemp("evalset"))


@pytest.fixture(scope="module")
def dra_report(subset):
    return evaluate("dra", subset, jobs=2, progress=False)


@pytest.fixture(scope="module")
def e2e_report(subset):
    return evaluate("e2e", subset, jobs=2, progress=False)


@pytest.mark.slow
def test_bev_dra_on_one_clip_per_scenario(dra_report):
    overall = dra_report["summary"]["overall"]
    assert overall["ok_rate"] == 1.0
    assert overall["SCS"]["mean"] >= SUBSET_DRA[0] - MARGIN, overall
    assert overall["HR"]["mean"] <= SUBSET_DRA[1] + MARGIN, overall


@pytest.mark.slow
def test_end_to_end_on_one_clip_per_scenario(e2e_report):
    summary = e2e_report["summary"]
    assert summary["overall"]["ok_rate"] == 1.0, [i for i in e2e_report["items"] if not i["ok"]]
    assert summary["overall"]["E2E-SC"]["mean"] >= SUBSET_E2E - MARGIN, summary["overall"]
    for item in e2e_report["items"]:
        assert not item["detail"]["failures"], item["stem"]
