"""Checks of every scenario in the shipped bank (scenario_bank/scenarios).

Fast tests: the sidecars follow the schema (fields, canonical elements, content
hash, shipped map), every script has the house layout (docstring, the four
section comments, map/weather/model lines) and passes the safety check, every
script compiles once and samples scenes quickly, and a short DV2S-v0 episode of
each runs to the end with an agent-driven ego.

Story tests: the adversarial story of each scenario (its sidecar's ``story`` block:
every step of every named story actor, checked actor by actor on the episode trace,
see dv2s_gym/story_check.py) plays in at least 9 of 10 fixed seeds with each of four
egos (the script's own, the rule-based driver, a constant-speed keep-lane ego and an
IDM ego); see dv2s_gym/story.py. The scenarios whose actors time or place their manoeuvre on
the ego also play it with the probe egos (hang back, rush, surge, weave) in at least 90% of a shorter
seed range, but for an exact list of known misses. tests/test_bank_events.py reads the point
of some scenarios straight off the tracks.

Slow test (``-m slow``): the short episode with the script's own ego behaviour
(``ego_policy="scenic"``).
"""

from __future__ import annotations

import hashlib
import json
import math
import re
import sys
import warnings
from pathlib import Path
from typing import Dict

import pytest

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # allow plain `pytest` from any folder
    sys.path.insert(0, str(ROOT))

from scenario_bank import BANK_DIR, list_scenarios  # noqa: E402
from scenario_bank.elements import PARTICIPANTS, Elements  # noqa: E402
from scenario_bank.maps import list_maps, resolve_map  # noqa: E402

pytestmark = pytest.mark.usefixtures("in_process_simulator")

import scenic  # noqa: F401  (a core dependency: a broken install fails here)

NAMES = list_scenarios()
SECTIONS = (
    "# 1. Map and global parameters",
    "# 2. Adversarial behaviours",
    "# 3. Road geometry",
    "# 4. Spawn positions",
)
SIDECAR_FIELDS = {"schema_version", "name", "description", "elements", "tags", "map", "use_case", "source",
                  "content_hash"}
SOURCE_FIELDS = {"kind", "video", "parent", "seed", "generator", "model", "context_hash", "date"}
USE_CASES = {
    "collision_risk_avoidance_highway",
    "insertion_highway",
    "left_turn_intersection_oncoming",
    "pedestrian_crossing_urban",
    "pull_back_in_urban_highway",
}
IDLE = 1  # DiscreteMetaAction


def script_path(name: str) -> Path:
    return BANK_DIR / name / "scenario.scenic"


def sidecar(name: str) -> dict:
    return json.loads((BANK_DIR / name / "meta.json").read_text(encoding="utf-8"))


_COMPILED: Dict[str, object] = {}


def compiled(name: str):
    """Each scenario compiled once per test session (compile_scenario also caches per process)."""
    if name not in _COMPILED:
        from envs.scenarios import compile_scenario

        path = script_path(name)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            _COMPILED[name] = compile_scenario(path.read_text(encoding="utf-8"), name=name, path=str(path))
    return _COMPILED[name]


# --------------------------------------------------------------------- the bank


def test_bank_holds_at_least_20_scenarios():
    assert len(NAMES) >= 20, NAMES


def test_every_script_has_a_sidecar_and_vice_versa():
    scripts = {p.parent.name for p in BANK_DIR.glob("*/scenario.scenic")}
    sidecars = {p.parent.name for p in BANK_DIR.glob("*/meta.json")}
    assert scripts == sidecars


def test_paper_use_cases_and_descriptions_are_covered():
    metas = [sidecar(n) for n in NAMES]
    assert {m["use_case"] for m in metas if m["use_case"]} == USE_CASES
    assert sum("paper_description" in m["tags"] for m in metas) >= 3


# ------------------------------------------------------------------- sidecars


@pytest.mark.parametrize("name", NAMES)
def test_sidecar_is_valid(name):
    meta = sidecar(name)
    # the actor-bound story block is optional
    assert set(meta) - {"story"} == SIDECAR_FIELDS, f"{name}.json fields: {sorted(meta)}"
    assert meta["schema_version"] == 1
    assert meta["name"] == name
    assert isinstance(meta["description"], str) and 20 <= len(meta["description"]) <= 400
    # elements follow the vocabulary, are stored in canonical form and have an ego
    assert Elements.from_dict(meta["elements"]).to_dict() == meta["elements"]
    # the story names actors the script names, of kinds the elements list
    from scenario_bank.story import normalize_story

    story = normalize_story(meta["story"]) if "story" in meta else {"actors": {}}
    script_text = script_path(name).read_text(encoding="utf-8")
    for actor, kind in story["actors"].items():
        assert f'with name "{actor}"' in script_text, f"{name}: story actor {actor} is not named in the script"
        assert kind in meta["elements"]["participants"]
    assert meta["elements"]["road"] is not None
    assert "ego" in meta["elements"]["participants"]
    assert set(meta["elements"]["participants"]) <= set(PARTICIPANTS)
    # tags
    tags = meta["tags"]
    assert isinstance(tags, list) and all(isinstance(t, str) and t for t in tags)
    assert len(set(tags)) == len(tags)
    assert "highway" in tags or "urban" in tags
    if "pedestrian" in meta["elements"]["participants"]:
        assert "pedestrian" in tags
    # map: shipped, and the one the script uses
    assert meta["map"] in list_maps()
    script = script_path(name).read_text(encoding="utf-8")
    match = re.search(r"^param map = '([^']+)'", script, re.M)
    assert match and match.group(1) == meta["map"]
    # use case and provenance
    assert meta["use_case"] is None or meta["use_case"] in USE_CASES
    if meta["use_case"] is not None:
        assert "paper_use_case" in tags
    assert set(meta["source"]) == SOURCE_FIELDS
    assert meta["source"]["kind"] == "hand-written"
    assert re.fullmatch(r"\d{4}-\d{2}-\d{2}", meta["source"]["date"])
    # the hash pins the script's exact bytes
    assert meta["content_hash"] == hashlib.sha256(script_path(name).read_bytes()).hexdigest()


# -------------------------------------------------------------------- scripts


@pytest.mark.parametrize("name", NAMES)
def test_script_follows_the_house_layout(name):
    script = script_path(name).read_text(encoding="utf-8")
    assert script.startswith('"""'), "module docstring first"
    positions = [script.find(section) for section in SECTIONS]
    assert all(p >= 0 for p in positions), f"missing sections: {[s for s, p in zip(SECTIONS, positions) if p < 0]}"
    assert positions == sorted(positions), "sections out of order"
    assert re.search(r"^param map = '\w+'$", script, re.M)
    assert re.search(r"^param weather = Uniform\(", script, re.M)
    assert re.search(r"^model scenic\.domains\.driving\.model$", script, re.M)
    assert len(re.findall(r"^param \w+ = (Range|Uniform)\(", script, re.M)) >= 3, "randomized parameters"


@pytest.mark.parametrize("name", NAMES)
def test_script_passes_the_safety_check(name):
    from scenario_bank import safety
    assert safety.check_script(script_path(name).read_text(encoding="utf-8")) == []


@pytest.mark.parametrize("name", NAMES)
def test_script_compiles_and_samples(name):
    scenario = compiled(name)
    resolve_map(sidecar(name)["map"])
    for seed in range(5):  # sampling speed is measured in bench/bench_bank.py
        scene = scenario.sample(seed)
        assert scene.egoObject is not None
        assert len(scene.objects) >= 2


# ---------------------------------------------------------------- DV2S-v0 runs


# The agent-driven run is in the fast suite; the run with the script's own ego behaviour is
# marked slow to keep the fast suite of this module under a minute.
@pytest.mark.parametrize("policy", ["agent", pytest.param("scenic", marks=pytest.mark.slow)])
@pytest.mark.parametrize("name", NAMES)
def test_short_episode_runs(name, policy):
    from envs.dv2s_env import DV2SEnv

    compiled(name)  # shares the compiled scenario with the env
    env = DV2SEnv(scenario=name, config={"duration": 6, "ego_policy": policy})
    try:
        obs, info = env.reset(seed=3)
        assert info["scenario"] == name
        steps, done = 0, False
        while not done:
            obs, reward, terminated, truncated, info = env.step(IDLE)
            steps += 1
            done = terminated or truncated
            assert steps <= 31
        assert math.isfinite(reward)
        assert info["scenic_status"] in ("running", "finished")
    finally:
        env.close()


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_every_declared_parameter_value_can_be_sampled(name):
    """Each random global parameter pinned at either end of its declared range still gives a scene: a miner or a
    replay entry that narrows the range around a failure never meets values the script cannot place."""
    scenario = compiled(name)
    unsampleable = []
    for param, declared in scenario.parameter_ranges().items():
        if declared.kind == "choice":
            continue
        for value in (declared.low, declared.high):
            try:
                scenario.sample(0, max_iterations=500, params={param: value})
            except Exception as error:  # noqa: BLE001 - every failure is reported with its value
                unsampleable.append((param, value, type(error).__name__))
    assert not unsampleable, f"{name}: parameter values the script declares but cannot sample: {unsampleable}"


# ----------------------------------------------------------- the story plays

STORY_SEEDS = range(10)
STORY_THRESHOLD = 0.9  # at least 9 of 10 seeds, with every ego

KNOWN_STORY_MISSES: dict = {}
"""Scenario and ego pairs under the threshold, with their rate on STORY_SEEDS: the test asserts exactly these
miss, so it fails when one more falls under or when one of them is fixed (then remove it here)."""


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_story_rate(name):
    """The scenario's adversarial story (its sidecar's story block, see dv2s_gym/story_check.py) plays in
    at least 90% of a fixed range of seeds with each of the four egos."""
    from dv2s_gym.story import EGOS, story_rate

    compiled(name)  # shares the compiled scenario with the env
    report, rates = {}, {}
    for ego in EGOS:
        rate, failures = story_rate(name, ego, STORY_SEEDS)
        rates[ego] = rate
        if rate < STORY_THRESHOLD and (name, ego) not in KNOWN_STORY_MISSES:
            report[ego] = (rate, failures)
    assert not report, f"{name}: story rate under {STORY_THRESHOLD}: {report}"
    for (scenario, ego), measured in KNOWN_STORY_MISSES.items():
        if scenario == name:
            assert rates[ego] == pytest.approx(measured), f"{name} with {ego}: story rate {rates[ego]} (was {measured})"


# ------------------------------------------------- the story plays for probe egos

PROBE_SEEDS = range(10)
PROBED_SCENARIOS = ("highway_lead_vehicle_brakes", "highway_lead_vehicle_decelerates", "urban_left_turn_oncoming",
                    "highway_truck_cut_in", "highway_fast_car_passes_behind_slow_truck", "urban_lead_vehicle_turns",
                    "urban_lead_vehicle_accelerates_then_stops")
"""Scenarios whose actors time or place their manoeuvre on the ego (its lane, its distance to a crossing point),
run with the probe egos that hang back, rush, surge and weave (dv2s_gym/story.py: PROBE_EGOS)."""

KNOWN_PROBE_MISSES: dict = {
    # the weaving ego changes lanes into the car driving beside it, which ends the episode before the lead's
    # story (seeds 1 and 8)
    ("highway_lead_vehicle_decelerates", "weave"): 0.8,
    # the oncoming car clears the ego's turn just before an ego that hangs back reaches it, but that ego takes
    # its turn so slowly that it passes the two paths' crossing point 4.1-4.2 s after the car (seeds 2 and 6)
    ("urban_left_turn_oncoming", "hangback"): 0.8,
    # the ego that hangs back keeps a 3 s gap to anything entering its lane, so the truck ends its move 3.6-3.8 s
    # ahead of it (seeds 2, 8, 9)
    ("highway_truck_cut_in", "hangback"): 0.7,
    # the weaving ego pulls out at 1 s into the car coming up beside it: the very collision the scenario warns of,
    # before the passing car's story (every seed)
    ("highway_fast_car_passes_behind_slow_truck", "weave"): 0.0,
    # the rushing ego ignores what is ahead and runs into the lead as it brakes for the junction, before it turns
    ("urban_lead_vehicle_turns", "rush"): 0.0,
    # an ego that rushes (or surges) at the lead as it drives off reaches it before it has outrun the ego, so the
    # lead never gets to brake in front of it: the rear-end comes first (rush every seed, surge 9 of 10)
    ("urban_lead_vehicle_accelerates_then_stops", "rush"): 0.0,
    ("urban_lead_vehicle_accelerates_then_stops", "surge"): 0.1,
}
"""Probed scenario and probe ego pairs under the threshold, with their rate on PROBE_SEEDS; exact, as
KNOWN_STORY_MISSES."""


@pytest.mark.slow
@pytest.mark.parametrize("name", PROBED_SCENARIOS)
def test_story_rate_with_probe_egos(name):
    """The story plays in at least 90% of a fixed range of seeds with egos that drive unlike traffic: the actors
    adapt to an ego that hangs back, rushes, speeds up mid-episode or weaves between lanes."""
    from dv2s_gym.story import PROBE_EGOS, story_rate

    compiled(name)
    report, rates = {}, {}
    for ego in PROBE_EGOS:
        rate, failures = story_rate(name, ego, PROBE_SEEDS)
        rates[ego] = rate
        if rate < STORY_THRESHOLD and (name, ego) not in KNOWN_PROBE_MISSES:
            report[ego] = (rate, failures)
    assert not report, f"{name}: story rate under {STORY_THRESHOLD} with probe egos: {report}"
    for (scenario, ego), measured in KNOWN_PROBE_MISSES.items():
        if scenario == name:
            assert rates[ego] == pytest.approx(measured), f"{name} with {ego}: story rate {rates[ego]} (was {measured})"
