"""The public CARLA-model Scenic corpus (tests/data/carla_corpus): each script runs in DV2S-v0 or fails clearly,
as ``python -m bench.bench_carla_corpus`` classifies them (:func:`bench.bench_carla_corpus.failure_construct`).

"Clearly" means a :class:`envs.errors.DV2SError` whose message names the construct in
backticks (e.g. "unsupported construct `Debris`"), a :class:`SceneSamplingError` naming the
requirement that rejects, or the safety check's :class:`UnsafeScenarioError` (line and construct
of each finding). Any other exception (an AttributeError, a bare traceback from Scenic or
highway-env) fails the test with its traceback.
The counts against Scenic's own Newtonian simulator are in ``python -m bench.bench_carla_corpus``.
"""

from __future__ import annotations

import re
from pathlib import Path

import gymnasium as gym
import pytest

import dv2s_gym  # noqa: F401  (registers DV2S-v0)
from bench.bench_carla_corpus import CORPUS, corpus_scripts, failure_construct, summarize
from envs.errors import DV2SError, SceneSamplingError, UnsupportedConstructError
from scenario_bank.safety import SafetyFinding, UnsafeScenarioError

pytestmark = pytest.mark.usefixtures("in_process_simulator")

SCRIPTS = corpus_scripts()
STEPS = 10


def test_corpus_has_at_least_30_scenic3_scripts_each_with_its_source_recorded():
    scenic3 = [p for p in SCRIPTS if p.parent.name == "scenic3"]
    assert len(scenic3) >= 30
    sources = (CORPUS / "SOURCES.md").read_text()
    for path in SCRIPTS:
        assert f"`{path.parent.name}/{path.name}`" in sources, f"{path.name} is not listed in SOURCES.md"
    assert (CORPUS / "LICENSE-Scenic.txt").read_text().startswith("BSD 3-Clause License")


@pytest.mark.parametrize("path", SCRIPTS, ids=lambda p: f"{p.parent.name}/{p.stem}")
def test_corpus_map_lines_name_a_shipped_carla_town(path: Path):
    text = path.read_text()
    maps = re.findall(r"^param map = localPath\('([^']+)'\)", text, re.M)
    assert maps, f"{path.name} has no map line"
    for relative in maps:
        assert re.fullmatch(r"maps/Town0[1247]\.xodr", relative)
        assert (path.parent / relative).resolve().is_file()


def test_failure_construct_names_the_cause_or_nothing():
    assert failure_construct(UnsupportedConstructError("line 3: unsupported construct `Debris`.")) == "Debris"
    assert failure_construct(SceneSamplingError("... 'User requirement violation: requirement on line 78' (9x)")) == "requirement on line 78"
    assert failure_construct(UnsafeScenarioError([SafetyFinding(3, "import os", "no imports")])) == "import os"
    assert failure_construct(DV2SError("Scenic could not compile the scenario: KeyError: 'road69'")) is None
    assert failure_construct(AttributeError("'Car' object has no attribute `x`")) is None


def test_summarize_counts_runs_and_clear_failures():
    ok = {"runs": True}
    clear = {"runs": False, "error": "UnsupportedConstructError", "dv2s_error": True, "construct": "Debris"}
    unclear = {"runs": False, "error": "AttributeError", "dv2s_error": False, "construct": None, "message": "x"}
    rows = [
        {"script": "a", "syntax": "scenic3", "dv2s": ok, "newtonian": unclear},
        {"script": "b", "syntax": "scenic3", "dv2s": clear, "newtonian": ok},
        {"script": "c", "syntax": "scenic3", "dv2s": unclear, "newtonian": ok},
        {"script": "d", "syntax": "scenic2", "dv2s": ok, "newtonian": ok},
    ]
    s = summarize(rows)["scenic3"]
    assert (s["scripts"], s["dv2s_runs"], s["newtonian_runs"]) == (3, 1, 2)
    assert (s["dv2s_fail_clear"], s["dv2s_fail_unclear"]) == (1, 1)
    assert s["dv2s_failures_by_construct"] == {"Debris": 1, "<AttributeError>": 1}


@pytest.mark.slow
@pytest.mark.parametrize("path", SCRIPTS, ids=lambda p: f"{p.parent.name}/{p.stem}")
def test_corpus_script_runs_in_dv2s_or_names_the_construct(path: Path):
    env = None
    try:
        config = {"upgrade_scenic2": True} if path.parent.name == "scenic2" else None
        env = gym.make("dv2s_gym:DV2S-v0", scenario=str(path), config=config)
        env.reset(seed=0)
        for _ in range(STEPS):
            _, _, terminated, truncated, _ = env.step(1)
            if terminated or truncated:
                break
    except (DV2SError, UnsafeScenarioError) as error:
        assert failure_construct(error), f"{path.name}: {type(error).__name__} does not name the construct: {error}"
    finally:
        if env is not None:
            env.close()
