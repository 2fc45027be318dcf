"""The external evaluation set (bench/evalsets/highway_env): stock highway-env clips, scripted and labelled by hand.

The offline backends, run on one clip of each use case, describe and convert every clip with the figures
measured on that subset (floors a little below). The whole set's figures, which
bench/evalsets/highway_env/README.md states, are checked by ``python -m bench.bench_evalset --set external``;
the set's builder and its labels by test_external_evalset_builder.py.
"""

import pytest

from bench.evalsets.make_external_evalset import EXTERNAL_EVALSET_DIR
from dv2s_gym.pipeline.evaluate import collect_items, evaluate

from evalset_helpers import one_clip_per_use_case

pytestmark = pytest.mark.usefixtures("in_process_simulator")

# measured on 2026-11-26 on the subset (the first clip of each of the 12 use cases), bev DRA and rules SG:
# (SCS, HR) and E2E-SC; the whole set's figures are checked by `python -m bench.bench_evalset --set external`
SUBSET_DRA = (0.948, 0.012)
SUBSET_E2E = 0.934
MARGIN = 0.03


@pytest.fixture(scope="module")
def subset(tmp_path_factory):
    return one_clip_per_use_case(EXTERNAL_EVALSET_DIR, tmp_path_factory.mktemp("external"))


@pytest.fixture(scope="module")
def dra_report(subset):
    return evaluate("dra", subset, jobs=2, progress=False)


@pytest.fixture(scope="module")
def e2e_report(subset):
    return evaluate("e2e", subset, jobs=2, progress=False)


@pytest.mark.slow
def test_bev_dra_on_one_clip_per_use_case(dra_report):
    overall = dra_report["summary"]["overall"]
    assert set(dra_report["summary"]["per_use_case"]) == {item.use_case for item in collect_items(EXTERNAL_EVALSET_DIR)}
    assert overall["ok_rate"] == 1.0
    assert overall["SCS"]["mean"] >= SUBSET_DRA[0] - MARGIN, overall
    assert overall["HR"]["mean"] <= SUBSET_DRA[1] + MARGIN, overall


@pytest.mark.slow
def test_end_to_end_on_one_clip_per_use_case(e2e_report):
    summary = e2e_report["summary"]
    assert summary["overall"]["ok_rate"] == 1.0, [i for i in e2e_report["items"] if not i["ok"]]
    assert summary["overall"]["E2E-SC"]["mean"] >= SUBSET_E2E - MARGIN, summary["overall"]
    for item in e2e_report["items"]:
        assert not item["detail"]["failures"], item["stem"]
