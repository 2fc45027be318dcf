"""Failure mining core: parameter conditioning, the scene space, monitors, samplers, and the miner's
resume, crash handling, run lock and settings check."""

from __future__ import annotations

import json
import math
import os
import random
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from scenario_bank.records import EpisodeRecord
from scenario_bank.run_identity import RunIdentityError
from dv2s_gym.mining.errors import MiningError
from dv2s_gym.mining.failure_state import NOVELTY_RADIUS, STATE_SIZE
from dv2s_gym.mining.miner import episode_seed, read_records
from mining_helpers import mine
from dv2s_gym.mining.monitors import (
    COLLISION_TYPES,
    DEFAULT_STALL_SECONDS,
    FREE_PATH,
    Failure,
    MonitorSettings,
    collision_type,
    detect_failure,
    robustness,
)
from dv2s_gym.mining.sampling.samplers import SAMPLERS, SceneSampler, default_feedback, is_adaptive, make_sampler
from dv2s_gym.mining.sampling.space import SceneSpace
from envs.errors import DV2SError, SceneSamplingError
from envs.trace import EpisodeTrace
from policies.evaluation import EpisodeResult
from mining_helpers import global_draws, seed_globals_and_peek

ROOT = Path(__file__).resolve().parents[1]
BANK_DIR = ROOT / "scenario_bank" / "scenarios"
BRAKES = "highway_lead_vehicle_brakes"
LEFT_TURN = "urban_left_turn_oncoming"
SHORT = {"duration": 3}


# --- parameter conditioning -------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def brakes_env():
    from envs.dv2s_env import DV2SEnv

    env = DV2SEnv(scenario=BRAKES, config={"duration": 2})
    yield env
    env.close()


def test_reset_with_params_fixes_them_and_replays_the_same_trajectory(brakes_env):
    from policies.evaluation import run_episode
    from policies.registry import load_policy

    params = {"ego_speed": 21.5, "lead_gap": 30.0, "brake_after": 1.6, "brake_strength": 0.95}
    _, info = brakes_env.reset(seed=3, options={"scenario": BRAKES, "params": params})
    for key, value in params.items():
        assert info["params"][key] == pytest.approx(value)
    assert info["params"]["weather"] in ("ClearNoon", "CloudyNoon", "WetNoon")  # the rest still comes from the seed

    policy = load_policy("rule")
    policy.bind([brakes_env])
    first, trace = run_episode(brakes_env, policy, BRAKES, 3, params=params)
    second, _ = run_episode(brakes_env, policy, BRAKES, 3, params=params)
    assert first.trajectory_hash == second.trajectory_hash
    assert trace.params["ego_speed"] == pytest.approx(21.5)
    other, _ = run_episode(brakes_env, policy, BRAKES, 3, params={**params, "ego_speed": 27.0})
    assert other.trajectory_hash != first.trajectory_hash  # the parameter really reaches the scene


def test_out_of_range_and_unknown_params_are_refused_with_a_clear_message(brakes_env):
    with pytest.raises(SceneSamplingError) as error:
        brakes_env.reset(seed=0, options={"scenario": BRAKES, "params": {"ego_speed": 50.0}})
    message = str(error.value)
    assert "'ego_speed'" in message and "outside its range" in message and "20..28" in message
    assert isinstance(error.value, DV2SError) and "\n" not in message

    with pytest.raises(SceneSamplingError) as error:
        brakes_env.reset(seed=0, options={"scenario": BRAKES, "params": {"no_such_param": 1.0}})
    message = str(error.value)
    assert "'no_such_param'" in message and "ego_speed" in message and "lead_gap" in message

    # a refused reset leaves the parameters unconditioned: the next scene draws them from the seed again
    _, info = brakes_env.reset(seed=11, options={"scenario": BRAKES})
    _, again = brakes_env.reset(seed=12, options={"scenario": BRAKES})
    assert info["params"]["ego_speed"] != again["params"]["ego_speed"]


# --- the scene space --------------------------------------------------------------------------------------------

_EXTRA_PARAMS = "param lanes_over = DiscreteRange(1, 3)\nparam style = Uniform('calm', 'harsh', 'erratic')\n"


@pytest.fixture(scope="module")
def mixed_bank(tmp_path_factory):
    """A bank with the brakes scenario and a copy that also has a DiscreteRange and a Uniform parameter."""
    folder = tmp_path_factory.mktemp("mixed-bank")
    shutil.copytree(BANK_DIR / BRAKES, folder / BRAKES)
    shutil.copytree(BANK_DIR / BRAKES, folder / "brakes_mixed")
    script = folder / "brakes_mixed" / "scenario.scenic"
    text = script.read_text()
    line = "param ego_speed = Range(20, 28)\n"
    script.write_text(text.replace(line, line + _EXTRA_PARAMS))
    meta = json.loads((folder / "brakes_mixed" / "meta.json").read_text())
    meta["name"] = "brakes_mixed"
    (folder / "brakes_mixed" / "meta.json").write_text(json.dumps(meta))
    return folder


def _brakes_params() -> list:
    """The randomized parameters the shipped brakes script declares (weather excluded), read from its text."""
    text = (BANK_DIR / BRAKES / "scenario.scenic").read_text()
    names = re.findall(r"^param (\w+) = (?:Range|DiscreteRange|Uniform)\(", text, flags=re.M)
    return sorted(n for n in names if n != "weather")


@pytest.mark.slow
def test_scene_space_decodes_unit_points_into_each_parameter_range(mixed_bank):
    space = SceneSpace(["brakes_mixed", BRAKES], str(mixed_bank))
    assert space.scenarios == ["brakes_mixed", BRAKES]
    ranges = space.param_ranges("brakes_mixed")
    assert "weather" not in ranges and "weather" not in space.param_ranges(BRAKES)
    base = _brakes_params()
    assert {"brake_after", "ego_speed", "lead_gap"} <= set(base)
    assert list(ranges) == sorted(ranges) == sorted(base + ["lanes_over", "style"])
    assert {k: r.kind for k, r in ranges.items()}["lanes_over"] == "integer"
    assert ranges["style"].kind == "choice"
    dim = len(ranges)
    assert space.dimension == dim

    rng = np.random.default_rng(0)
    seen_lanes, seen_styles = set(), set()
    for u in [np.zeros(dim), np.ones(dim), *rng.random((40, dim))]:
        spec = space.decode(SimpleNamespace(scenario=(0,), u=tuple(u)))
        assert spec.scenario == "brakes_mixed" and set(spec.params) == set(ranges)
        assert 1.5 <= spec.params["brake_after"] <= 4.0 and 20 <= spec.params["ego_speed"] <= 28
        assert spec.params["lanes_over"] in (1, 2, 3) and isinstance(spec.params["lanes_over"], int)
        assert spec.params["style"] in ("calm", "harsh", "erratic")
        assert spec.point == [round(float(x), 6) for x in u]
        seen_lanes.add(spec.params["lanes_over"])
        seen_styles.add(spec.params["style"])
    assert seen_lanes == {1, 2, 3} and seen_styles == {"calm", "harsh", "erratic"}
    low = space.decode(SimpleNamespace(scenario=(0,), u=(0.0,) * dim)).params
    assert (low["ego_speed"], low["lanes_over"], low["style"]) == (20, 1, "calm")

    # the brakes scenario has two parameters fewer: the extra coordinates are ignored
    spec = space.decode(SimpleNamespace(scenario=(1,), u=(0.5,) * dim))
    assert spec.scenario == BRAKES and len(spec.point) == len(base) and spec.params["ego_speed"] == pytest.approx(24.0)


@pytest.mark.slow
def test_decoded_params_are_accepted_by_the_env(mixed_bank):
    from envs.dv2s_env import DV2SEnv

    space = SceneSpace(["brakes_mixed"], str(mixed_bank))
    env = DV2SEnv(scenario=None, config={"duration": 1}, bank_dir=str(mixed_bank))
    try:
        spec = space.decode(SimpleNamespace(scenario=(0,), u=(0.9,) * space.dimension))
        _, info = env.reset(seed=1, options={"scenario": spec.scenario, "params": spec.params})
        assert {k: info["params"][k] for k in spec.params} == spec.params
    finally:
        env.close()


# --- monitors on hand-built traces ------------------------------------------------------------------------------


def _result(**overrides) -> EpisodeResult:
    data = dict(scenario="s", seed=0, scene_seed=0, params={}, collided=False, collisions=[], off_road=False,
                success=True, min_ttc=math.inf, mean_speed=10.0, distance=100.0, episode_return=0.0, steps=0,
                trajectory_hash="h", error=None)
    data.update(overrides)
    return EpisodeResult(**data)


def _trace(states, events=(), kinds=None) -> EpisodeTrace:
    return EpisodeTrace(scenario="s", source="test", seed=0, scene_seed=0, params={}, config={"policy_frequency": 5},
                        states=list(states), events=list(events), kinds={"ego": "ego", **(kinds or {})})


EGO = [0.0, 0.0, 0.0, 10.0]
CASES = {  # other actor's state at impact (ego at the origin heading +x) and kind -> collision type
    "rear_end": ([5.0, 0.3, 0.05, 5.0], "car"),
    "struck_from_behind": ([-5.0, -0.2, 0.0, 15.0], "car"),
    "side": ([1.0, 2.5, math.pi / 2, 8.0], "car"),
    "head_on": ([5.0, 0.5, math.pi - 0.1, 10.0], "truck"),
    "pedestrian": ([3.0, 1.0, math.pi / 2, 1.5], "pedestrian"),
    "obstacle": ([4.0, 0.0, 0.0, 0.0], "obstacle"),
}


def test_collision_types_follow_the_states_at_impact():
    assert set(CASES) == set(COLLISION_TYPES)
    for expected, (other, kind) in CASES.items():
        assert collision_type(EGO, other, kind) == expected, expected
    # same heading but mostly beside the ego: a side swipe, not a rear-end
    assert collision_type(EGO, [1.0, 2.0, 0.0, 10.0], "car") == "side"
    # heading does not matter for the ego heading the other way round: ego heading pi, car ahead of it at -x
    assert collision_type([0.0, 0.0, math.pi, 10.0], [-5.0, 0.0, math.pi, 5.0], "car") == "rear_end"


@pytest.mark.parametrize("expected", COLLISION_TYPES)
def test_detect_failure_reports_the_collision_from_the_trace(expected):
    other, kind = CASES[expected]
    states = [{"ego": [x, 0.0, 0.0, 10.0], "other": [x + 40.0, 0.0, 0.0, 5.0]} for x in (0.0, 2.0, 4.0)]
    states.append({"ego": EGO, "other": other})
    trace = _trace(states, [{"time": 0.6, "kind": "collision", "actors": ["ego", "other"]}], {"other": kind})
    failure = detect_failure(_result(collided=True, collisions=["other"], min_ttc=0.2), trace)
    assert failure is not None
    assert (failure.type, failure.collision_type, failure.with_, failure.with_kind) == ("collision", expected,
                                                                                       "other", kind)
    assert failure.step == 3 and failure.time == pytest.approx(0.6) and failure.speed == pytest.approx(10.0)
    assert failure.kind == f"collision:{expected}"
    assert Failure.from_json(failure.to_json()) == failure
    assert robustness(_result(collided=True), failure) < 0


STALL_STEPS = int(math.ceil(DEFAULT_STALL_SECONDS * 5))  # at the traces' 5 Hz


def _standing(steps: int, others=None):
    return [{"ego": [0.0, 0.0, 0.0, 0.0], **(others or {})} for _ in range(steps)]


def test_stall_needs_a_free_path_ahead():
    # stall_seconds at 5 Hz standing with an empty road ahead: a stall from the first standing step
    failure = detect_failure(_result(), _trace([{"ego": [0.0, 0.0, 0.0, 8.0]}] * 2 + _standing(STALL_STEPS)))
    assert failure is not None and failure.type == "stall" and failure.step == 2
    long = STALL_STEPS + 5
    # a car stopped 10 m ahead in the lane: waiting behind it is not a stall
    assert detect_failure(_result(), _trace(_standing(long, {"car": [10.0, 0.5, 0.0, 0.0]}))) is None
    # the same car in the next lane, or beyond the free-path distance, or behind: the path is free
    for where in ([10.0, 3.5, 0.0, 0.0], [FREE_PATH + 5.0, 0.0, 0.0, 0.0], [-8.0, 0.0, 0.0, 0.0]):
        assert detect_failure(_result(), _trace(_standing(long, {"car": where}))).type == "stall"
    # standing for less than stall_seconds, or moving slowly but above the stall speed: no stall
    assert detect_failure(_result(), _trace(_standing(STALL_STEPS - 1))) is None
    assert detect_failure(_result(), _trace(_standing(long)), MonitorSettings(stall_seconds=DEFAULT_STALL_SECONDS + 2)) is None
    assert detect_failure(_result(), _trace(_standing(long)), MonitorSettings(stall_seconds=1.0)).type == "stall"
    assert detect_failure(_result(), _trace([{"ego": [0.0, 0.0, 0.0, 1.0]}] * (2 * long))) is None
    # standing split in two short stops does not add up to a stall
    half = STALL_STEPS // 2 + 1
    split = _standing(half) + [{"ego": [0.0, 0.0, 0.0, 5.0]}] + _standing(half)
    assert detect_failure(_result(), _trace(split)) is None


def test_the_min_ttc_time_and_actor_are_fields_written_in_the_results_extra_object():
    close = _result(min_ttc=0.6, min_ttc_time=1.2, min_ttc_with="car1")
    data = close.to_json()
    assert data["extra"] == {"min_ttc_time": 1.2, "min_ttc_with": "car1"} and list(data)[-2:] == ["extra", "failed"]
    assert "min_ttc_time" not in data and EpisodeResult.from_json(data) == close
    assert _result().to_json()["extra"] == {"min_ttc_time": None, "min_ttc_with": None}


def test_low_ttc_off_road_and_severity_order():
    moving = [{"ego": [2.0 * k, 0.0, 0.0, 10.0]} for k in range(10)]
    close = _result(min_ttc=0.6, min_ttc_time=1.2, min_ttc_with="car1")
    failure = detect_failure(close, _trace(moving, kinds={"car1": "car"}))
    assert (failure.type, failure.with_, failure.with_kind, failure.step) == ("low_ttc", "car1", "car", 6)
    assert failure.min_ttc == pytest.approx(0.6)
    assert detect_failure(close, _trace(moving), MonitorSettings(ttc_threshold=0.5)) is None
    assert detect_failure(_result(min_ttc=1.5), _trace(moving)) is None

    off = detect_failure(_result(off_road=True, min_ttc=0.3),
                         _trace(moving, [{"time": 1.0, "kind": "off_road", "actors": ["ego"]}]))
    assert (off.type, off.step) == ("off_road", 5)  # leaving the road outranks the low TTC
    # an error episode is no failure of the policy
    assert detect_failure(_result(error="RuntimeError: boom", collided=True), _trace(moving)) is None


def test_robustness_is_negative_exactly_for_failures():
    moving = [{"ego": [2.0 * k, 0.0, 0.0, 10.0]} for k in range(10)]
    outcomes = [
        (_result(collided=True, collisions=["c"]),
         _trace(moving, [{"time": 0.4, "kind": "collision", "actors": ["ego", "c"]}], {"c": "car"})),
        (_result(off_road=True), _trace(moving)),
        (_result(min_ttc=0.2, min_ttc_time=0.4, min_ttc_with="c"), _trace(moving)),
        (_result(min_ttc=0.999), _trace(moving)),
        (_result(), _trace(_standing(STALL_STEPS))),
        (_result(min_ttc=1.0), _trace(moving)),
        (_result(min_ttc=1.001), _trace(moving)),
        (_result(min_ttc=25.0), _trace(moving)),
        (_result(), _trace(moving)),
        (_result(), _trace(_standing(STALL_STEPS, {"car": [10.0, 0.0, 0.0, 0.0]}))),
        (_result(error="boom"), _trace(moving)),
    ]
    kinds = []
    for result, trace in outcomes:
        failure = detect_failure(result, trace)
        rho = robustness(result, failure)
        assert math.isfinite(rho)
        assert (rho < 0) == (failure is not None), (failure, rho)
        kinds.append(failure.type if failure else None)
    assert kinds == ["collision", "off_road", "low_ttc", "low_ttc", "stall", None, None, None, None, None, None]
    # near misses rank before easy scenes, a faster crash before a slower one
    assert robustness(_result(min_ttc=1.2), None) < robustness(_result(min_ttc=6.0), None)
    slow, fast = Failure("collision", 0.0, 0, speed=3.0), Failure("collision", 0.0, 0, speed=20.0)
    assert robustness(_result(collided=True), fast) < robustness(_result(collided=True), slow)


# --- samplers -----------------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def small_space():
    return SceneSpace([BRAKES, LEFT_TURN])


def _points(drawn, space):
    return [(space.decode(point).scenario, space.decode(point).point) for point, _ in drawn]


def _drive(sampler: SceneSampler, space, rounds: int = 3, batch: int = 5):
    """Draw and feed a few chunks; a failure wherever the first unit coordinate is below 0.4."""
    seen = []
    for _ in range(rounds):
        drawn = sampler.draw(batch)
        seen += _points(drawn, space)
        for point, info in drawn:
            sampler.feed(point, info, -1.0 if space.decode(point).point[0] < 0.4 else 1.0)
    return seen


@pytest.mark.parametrize("name", SAMPLERS)
def test_samplers_are_deterministic_for_a_seed_and_keep_the_global_rngs(name, small_space):
    before = seed_globals_and_peek(123)
    first = _drive(make_sampler(name, small_space.feature_space, 7), small_space)
    assert global_draws() == before  # the sampler never touched the global generators
    random.seed(999)  # whatever else ran in the process, the same seed draws the same scenes
    second = _drive(make_sampler(name, small_space.feature_space, 7), small_space)
    assert first == second
    other = _drive(make_sampler(name, small_space.feature_space, 8), small_space)
    assert other != first
    assert {scenario for scenario, _ in first} <= {BRAKES, LEFT_TURN}


@pytest.mark.parametrize("name", SAMPLERS)
def test_sampler_state_round_trips_through_dumps_and_loads(name, small_space):
    sampler = make_sampler(name, small_space.feature_space, 3)
    _drive(sampler, small_space, rounds=2)
    copy = SceneSampler.loads(sampler.dumps())
    assert copy.fed == sampler.fed == 10 and copy.name == name
    assert _drive(copy, small_space) == _drive(sampler, small_space)


def test_a_corrupt_sampler_checkpoint_is_refused():
    import dill

    from dv2s_gym.mining.sampling.checkpoint_mac import seal

    with pytest.raises(MiningError, match="holds no sampler.*delete sampler.pkl"):
        SceneSampler.loads(seal(dill.dumps({"not": "a sampler"})))


def test_adaptive_samplers_take_verifai_options(small_space):
    from dv2s_gym.mining.sampling.samplers import is_adaptive, sampler_params

    params = sampler_params("cross-entropy", {"alpha": 0.5, "buckets": 1})
    assert (params.alpha, params.cont.buckets, params.thres) == (0.5, 1, 0.0)
    assert sampler_params("bandit", None).alpha == 0.9 and sampler_params("random") is None
    assert [name for name in SAMPLERS if is_adaptive(name)] == ["cross-entropy", "bandit", "split", "novelty-bandit"]
    # one bucket per parameter: the parameters stay uniform, only the scenario distribution moves
    sampler = make_sampler("cross-entropy", small_space.feature_space, 1, {"alpha": 0.5, "buckets": 1})
    for _ in range(6):
        for point, info in sampler.draw(4):
            sampler.feed(point, info, -1.0 if small_space.decode(point).scenario == LEFT_TURN else 1.0)
    drawn = [small_space.decode(point).scenario for point, _ in sampler.draw(40)]
    assert drawn.count(LEFT_TURN) >= 36
    for bad, match in (({"alpha": 1.5}, "alpha must be between 0 and 1"), ({"buckets": 0}, "buckets must be"),
                       ({"gamma": 1}, "no option 'gamma'; it takes alpha, buckets, thres")):
        with pytest.raises(MiningError, match=match):
            make_sampler("cross-entropy", small_space.feature_space, 0, bad)
    with pytest.raises(MiningError, match="sampler 'random' has no option 'alpha'; it takes none"):
        make_sampler("random", small_space.feature_space, 0, {"alpha": 0.5})


def test_an_unknown_sampler_is_refused(small_space):
    with pytest.raises(MiningError, match="unknown sampler 'nope'.*cross-entropy"):
        make_sampler("nope", small_space.feature_space, 0)


# --- the miner: resume, crashes, the run lock, settings -------------------------------------------------------------

MINE = dict(budget=10, sampler="cross-entropy", scenarios=[BRAKES, LEFT_TURN], workers=1, batch=4, seed=5,
            reference="rule", env_config=SHORT, progress=False, reports=False)
POLICY = "rule?action_noise=0.4"  # a degraded driver: some failures, and the rule driver avoids some of them


def _stable(records):
    return [json.dumps(r.to_dict(), sort_keys=True) for r in records]  # episode records, as their file lines


RUNS = {
    "cross-entropy": {"sampler": "cross-entropy"},
    "random": {"sampler": "random"},  # non-adaptive: whole chunks go to the workers at once
    "bandit-novelty": {"sampler": "bandit", "feedback": "novelty", "sampler_options": {"alpha": 0.8, "buckets": 2}},
    "split": {"sampler": "split"},  # its default feedback: novelty
    "novelty-bandit": {"sampler": "novelty-bandit"},  # its default feedback: state-novelty
}


@pytest.fixture(scope="module", params=list(RUNS))
def whole_run(request, tmp_path_factory):
    """An uninterrupted run of each kind of sampler and feedback."""
    out = tmp_path_factory.mktemp("mine-whole")
    settings = {**MINE, **RUNS[request.param]}
    run = mine(POLICY, out=out, **settings)
    return out, run, settings


@pytest.mark.slow
def test_a_run_records_every_episode_with_its_scene(whole_run):
    out, run, settings = whole_run
    records = read_records(out / "episodes.jsonl")
    rows = [r.to_dict() for r in records]  # each line's JSON object
    assert [r["index"] for r in rows] == list(range(10)) and not any(r["error"] for r in rows)
    assert [r["seed"] for r in rows] == [episode_seed(5, i) for i in range(10)]
    for record in rows:
        assert record["scenario"] in (BRAKES, LEFT_TURN) and record["sampler"] == settings["sampler"]
        assert record["family"] == record["scenario"]  # shipped scenarios are their own family
        assert (record["rho"] < 0) == (record["failure"] is not None)
        if record["failure"]:
            assert (out / record["trace"]).is_file() and record["reference"]["policy"] == "rule"
            assert isinstance(record["avoidable"], bool)
            assert set(record["behaviour"]) == {"actor", "actor_manoeuvre", "ego_manoeuvre"}
            assert len(record["failure_state"]) == STATE_SIZE
            assert "unknown" not in record["behaviour"].values()
        else:
            assert "behaviour" not in record and "failure_state" not in record
            assert record["trace"] is None and record["avoidable"] is None
        proposal = record["proposal"]  # the density the scene was drawn with (the failure-rate estimate's weights)
        if settings["sampler"] == "random":
            assert proposal == {"scenario": 0.5, "params": 1.0, "floor": 1.0}
        elif settings["sampler"] == "cross-entropy":
            assert 0.0 < proposal["scenario"] < 1.0 and proposal["params"] > 0.0
        elif settings["sampler"] == "novelty-bandit":  # a mixture with uniform (explore 0.2), parameters uniform
            assert 0.1 - 1e-9 <= proposal["scenario"] <= 0.1 + 0.8 + 1e-9 and proposal["params"] == 1.0
        else:  # the bandit picks its buckets deterministically; split's cell avoidance leaves cells out
            assert proposal is None
    assert (out / "sampler.pkl").is_file()
    assert json.loads((out / "settings.json").read_text())["sampler"] == settings["sampler"]
    # the scenes are the sampler's draws in order, however many chunks went to the workers at once
    space = SceneSpace(MINE["scenarios"])
    sampler = make_sampler(settings["sampler"], space, settings["seed"], settings.get("sampler_options"))
    feedback = settings.get("feedback") or default_feedback(settings["sampler"])
    assert json.loads((out / "settings.json").read_text())["feedback"] == feedback
    expected = []
    if is_adaptive(settings["sampler"]):  # the window schedule: scene j is drawn once outcome j - batch was fed
        assert json.loads((out / "settings.json").read_text())["schedule"] == "window"
        drawn = sampler.draw(MINE["batch"])
        for index, record in enumerate(records):
            point, info = drawn[index]
            spec = space.decode(point)
            expected.append((spec.scenario, spec.params))
            sampler.feed(point, info, _fed(record, records, feedback))
            drawn += sampler.draw(1)
        assert [(r["scenario"], r["params"]) for r in rows] == expected
        return
    for _ in range(3):
        drawn = sampler.draw(MINE["batch"])
        for point, info in drawn:
            spec = space.decode(point)
            expected.append((spec.scenario, spec.params))
            record = records[len(expected) - 1] if len(expected) <= len(records) else None
            if record is not None:
                sampler.feed(point, info, _fed(record, records, feedback))
    assert [(r["scenario"], r["params"]) for r in rows] == expected[:10]


def _fed(record, records, feedback):
    """What the miner feeds back for ``record`` (written out here from the documented rule)."""
    from dv2s_gym.mining.cluster import cell_id

    row, rows = record.to_dict(), [r.to_dict() for r in records]
    if row["failure"] and feedback == "novelty":  # novelty is over parameter cells, not behaviour clusters
        earlier = {cell_id(r) for r, data in zip(records, rows) if data["index"] < row["index"] and data["failure"]}
        if cell_id(record) in earlier:
            return 9.0
    if row["failure"] and feedback == "state-novelty":  # over the failure-state descriptors, per scenario
        earlier = [r["failure_state"] for r in rows
                   if r["index"] < row["index"] and r["failure"] and r["scenario"] == row["scenario"]]
        if any(math.dist(row["failure_state"], other) <= NOVELTY_RADIUS for other in earlier):
            return 9.0
    return row["rho"]


def test_novelty_feedback_feeds_a_repeated_parameter_cell_as_an_easy_scene():
    from dv2s_gym.mining.cluster import cluster_id
    from dv2s_gym.mining.miner import _feedback

    failure = {"type": "collision", "kind": "collision:rear_end"}
    first = EpisodeRecord(index=0, scenario=BRAKES, family=BRAKES, seed=0, point=[0.1, 0.9], failure=failure, rho=-2.0)
    same_cell = first.replace(index=1, point=[0.2, 0.8], rho=-1.5)
    other_cell = first.replace(index=2, point=[0.5, 0.8], rho=-1.2)
    passed = first.replace(index=3, failure=None, rho=3.0)
    crashed = first.replace(index=4, failure=None, rho=None, error="crashed")
    seen: set = set()
    assert [_feedback(r, seen, "novelty") for r in (first, same_cell, other_cell, passed, crashed)] == [
        -2.0, 9.0, -1.2, 3.0, 1.0]
    seen = set()
    assert [_feedback(r, seen, "robustness") for r in (first, same_cell, other_cell)] == [-2.0, -1.5, -1.2]
    seen = set()  # scenario-novelty: only each scenario's first failure is fed as one
    elsewhere = other_cell.replace(index=5, scenario=LEFT_TURN, rho=-1.1)
    assert [_feedback(r, seen, "scenario-novelty") for r in (first, other_cell, passed, elsewhere)] == [
        -2.0, 9.0, 3.0, -1.1]
    seen = set()  # cluster-novelty: a failure in a behaviour cluster already found is fed as an easy scene
    behaviour = {"actor": "car", "actor_manoeuvre": "braking", "ego_manoeuvre": "following"}
    a = first.replace(behaviour=behaviour)
    same_cluster = a.replace(index=6, point=[0.9, 0.1], rho=-1.4)  # other cell, same behaviour
    other_actor = a.replace(index=7, behaviour={**behaviour, "actor_manoeuvre": "cut_in"}, rho=-1.3)
    assert cluster_id(a) == cluster_id(same_cluster) != cluster_id(other_actor)
    assert [_feedback(r, seen, "cluster-novelty") for r in (a, same_cluster, other_actor, passed, crashed)] == [
        -2.0, 9.0, -1.3, 3.0, 1.0]
    with pytest.raises(MiningError, match="unknown feedback 'curious'.*novelty"):
        mine("rule", out="unused", budget=1, feedback="curious")


@pytest.mark.slow
def test_a_killed_run_resumes_to_the_same_records(whole_run, tmp_path):
    out, run, settings = whole_run
    copy = tmp_path / "run"
    shutil.copytree(out, copy)
    data = (copy / "episodes.jsonl").read_bytes()
    lines = data.split(b"\n")
    # killed while writing the 7th record, before the sampler saw the second chunk's outcomes
    (copy / "episodes.jsonl").write_bytes(b"\n".join(lines[:6]) + b"\n" + lines[6][: len(lines[6]) // 2])
    (copy / "sampler.pkl").unlink()
    for index in range(6, 10):
        (copy / "traces" / f"{index:06d}.json.gz").unlink(missing_ok=True)
    resumed = mine(POLICY, out=copy, **settings)
    assert _stable(read_records(copy / "episodes.jsonl")) == _stable(read_records(out / "episodes.jsonl"))
    assert _stable(resumed.records) == _stable(run.records)
    assert (copy / "episodes.jsonl").read_bytes().count(b"\n") == 10  # the torn line is gone, nothing twice
    assert resumed.clusters == run.clusters
    # a finished run resumes to the same records without running anything
    again = mine(POLICY, out=copy, **settings)
    assert _stable(again.records) == _stable(run.records)


class _Planted:
    def __reduce__(self):
        import os

        return (os.system, (f"touch {os.environ['DV2S_TEST_MARKER']}",))


@pytest.mark.slow
def test_a_planted_sampler_checkpoint_is_not_unpickled_and_the_run_resumes_from_its_records(
        whole_run, tmp_path, monkeypatch):
    import pickle

    out, run, settings = whole_run
    copy = tmp_path / "run"
    shutil.copytree(out, copy)
    marker = tmp_path / "unpickled"
    monkeypatch.setenv("DV2S_TEST_MARKER", str(marker))
    (copy / "sampler.pkl").write_bytes(pickle.dumps(_Planted()))
    resumed = mine(POLICY, out=copy, **settings)
    assert not marker.exists()
    assert _stable(resumed.records) == _stable(run.records)


@pytest.mark.slow
def test_resuming_with_other_settings_is_refused(whole_run, tmp_path):
    out, _, settings = whole_run
    copy = tmp_path / "run"
    shutil.copytree(out, copy)
    before = (copy / "episodes.jsonl").read_bytes()
    other = "halton" if settings["sampler"] == "random" else "random"
    changes = [{"sampler": other, "sampler_options": None}, {"seed": 6}, {"env_config": {"duration": 4}},
               {"batch": 2}, {"reference": None}]
    if settings["sampler"] != "random":
        changes += [{"sampler_options": {"explore": 0.5} if settings["sampler"] == "novelty-bandit" else {"alpha": 0.5}},
                    {"feedback": "robustness" if (settings.get("feedback") or default_feedback(settings["sampler"]))
                     == "novelty" else "novelty"}]
    for change in changes:
        with pytest.raises(RunIdentityError) as error:
            mine(POLICY, out=copy, **{**settings, **change})
        message = str(error.value)
        assert "other settings" in message and "--out" in message and next(iter(change)) in message
    with pytest.raises(RunIdentityError, match="policy: run has"):
        mine("rule", out=copy, **settings)
    assert (copy / "episodes.jsonl").read_bytes() == before


def _mine_with_a_crash(tmp_path, once: bool):
    """Mine 3 random scenes with a policy whose worker crashes on the second one (every time, or once)."""
    crash_seed = episode_seed(0, 1)
    log = tmp_path / "attempts.log"
    policy = f"regress_helpers:FaultyPolicy?crash_seed={crash_seed}&log={log}" + ("&once=1" if once else "")
    run = mine(policy, out=tmp_path / "run", budget=3, sampler="random", scenarios=[BRAKES], workers=1, seed=0,
               reference=None, env_config={"duration": 2}, timeout=60, progress=False, reports=False)
    return run, crash_seed, log


@pytest.mark.slow
def test_a_crashing_worker_gives_an_error_record_and_the_run_completes(tmp_path):
    run, crash_seed, log = _mine_with_a_crash(tmp_path, once=False)
    assert [r.to_dict()["index"] for r in run.records] == [0, 1, 2]
    assert log.read_text().split() == [str(crash_seed)] * 2  # tried again once in a new worker
    error = run.records[1].to_dict()["error"]
    assert error and "crashed" in error and str(crash_seed) in error
    assert run.records[1].to_dict()["failure"] is None and run.records[1].to_dict()["result"] is None
    assert not run.records[0].to_dict()["error"] and not run.records[2].to_dict()["error"]
    assert run.records[0].to_dict()["result"]["trajectory_hash"]
    assert len(read_records(tmp_path / "run" / "episodes.jsonl")) == 3


@pytest.mark.slow
def test_an_episode_finished_after_its_worker_crashed_is_reported(tmp_path):
    # the retry used to succeed silently: nothing in the record, report or summary said a worker had died
    run, crash_seed, log = _mine_with_a_crash(tmp_path, once=True)
    assert log.read_text().split() == [str(crash_seed)]  # crashed once; the retry ran it to the end
    assert not any(r.to_dict()["error"] for r in run.records) and run.records[1].to_dict()["result"]["trajectory_hash"]
    restarts = run.records[1].to_dict()["worker_restarts"]
    assert len(restarts) == 1 and "crashed" in restarts[0]
    assert "worker_restarts" not in run.records[0].to_dict() and "worker_restarts" not in run.records[2].to_dict()
    assert "1 finished after their worker crashed or hung" in run.summary()
    assert "avoidability not checked" in run.summary()  # reference=None; it said "3 avoidable by no reference"
    from dv2s_gym.mining.report import write_reports

    paths = write_reports(tmp_path / "run")
    data = json.loads(paths["json"].read_text())
    assert data["counts"]["worker_restarts"] == 1 and data["worker_restarts"][0]["index"] == 1
    assert "### Worker restarts (1)" in paths["markdown"].read_text()
    assert "finished by a new worker" in paths["html"].read_text()


@pytest.mark.slow
def test_every_episode_crashing_still_completes_with_error_records(tmp_path):
    run = mine("regress_misbehaving_policies:crash", out=tmp_path / "run", budget=2, sampler="random",
               scenarios=[BRAKES], workers=2, seed=0, reference=None, env_config={"duration": 2}, progress=False,
               reports=False)
    assert [r.to_dict()["index"] for r in run.records] == [0, 1]
    assert all("crashed" in r.to_dict()["error"] for r in run.records) and not run.failures


_HOLDER = """
import sys
from mining_helpers import mine
if __name__ == "__main__":
    mine("regress_misbehaving_policies:hang", out=sys.argv[1], budget=1, sampler="random",
         scenarios=[{brakes!r}], workers=1, reference=None, timeout=600, progress=False, reports=False)
"""


@pytest.mark.slow
def test_a_second_miner_on_the_same_folder_is_refused(tmp_path):
    out = tmp_path / "run"
    script = tmp_path / "holder.py"
    script.write_text(_HOLDER.format(brakes=BRAKES))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), str(ROOT / "tests"),
                                                        os.environ.get("PYTHONPATH", "")])}
    holder = subprocess.Popen([sys.executable, str(script), str(out)], env=env, start_new_session=True,
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 120
        while not (out / "episodes.jsonl").exists():  # created once the first miner holds the lock
            assert holder.poll() is None, holder.stderr.read().decode()
            assert time.monotonic() < deadline, "the first miner did not start"
            time.sleep(0.2)
        with pytest.raises(MiningError) as error:
            mine("rule", out=out, budget=1, scenarios=[BRAKES], workers=1, reference=None, progress=False,
                 reports=False)
        assert "another miner is running" in str(error.value) and "--out" in str(error.value)
    finally:
        os.killpg(holder.pid, signal.SIGKILL)
        holder.wait()
    assert read_records(out / "episodes.jsonl") == []


def _start_bank(dest: str, barrier, results) -> None:
    from dv2s_gym.mining.miner import _own_bank

    barrier.wait()
    try:
        _own_bank(dest)
        results.put("ok")
    except Exception as error:  # noqa: BLE001 - the test reports what the losing miner raised
        results.put(f"{type(error).__name__}: {error}")


@pytest.mark.slow
def test_miners_started_together_on_a_new_bank_folder_share_one_copy(tmp_path):
    # both copied the shipped bank; the second rename failed and that miner died ("Directory not empty")
    import multiprocessing

    from scenario_bank.bank import Bank

    context = multiprocessing.get_context("spawn")
    for trial in range(3):
        dest = tmp_path / f"bank{trial}"
        barrier, results = context.Barrier(2), context.Queue()
        starters = [context.Process(target=_start_bank, args=(str(dest), barrier, results)) for _ in range(2)]
        for process in starters:
            process.start()
        outcomes = [results.get(timeout=120) for _ in starters]
        for process in starters:
            process.join(30)
        assert outcomes == ["ok", "ok"], outcomes
        assert Bank(dest).names() == Bank().names() and not Bank(dest).problems
        assert not [p for p in tmp_path.iterdir() if ".copy-" in p.name]  # no staging folder left behind


def test_an_empty_run_folder_another_miner_holds_is_not_removed(tmp_path):
    # a miner refused late removes the empty run folder it made, unless a miner started on it at the same moment
    import fcntl

    from dv2s_gym.mining.miner import _remove_if_empty

    out = tmp_path / "run"
    (out / "traces").mkdir(parents=True)
    (out / "episodes.jsonl").write_text("")
    with open(out / ".lock", "a+") as held:
        fcntl.flock(held.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        _remove_if_empty(out)
        assert out.is_dir()
    _remove_if_empty(out)
    assert not out.exists()


def test_the_failure_state_descriptor_and_state_novelty_feedback():
    """The descriptor reads speeds and geometry at the failure step from the trace; state-novelty feeds a failure
    as one only when its descriptor is far from every earlier failure's in the same scenario."""
    from dv2s_gym.mining.failure_state import failure_state
    from dv2s_gym.mining.miner import _feedback

    # ego at 20 m/s slowing to 15 over the last second, a car 10 m ahead in the same lane at 5 m/s, heading along
    states = [{"ego": [float(i), 0.0, 0.0, 20.0 - max(0, i - 5)], "Car1": [10.0 + i, 0.0, 0.0, 5.0]}
              for i in range(11)]
    trace = SimpleNamespace(states=states, config={"policy_frequency": 5, "duration": 20.0})
    state = failure_state(trace, Failure.of({"type": "collision", "with": "Car1", "step": 10}))
    assert len(state) == STATE_SIZE
    assert state[:4] == pytest.approx([15.0 / 30, -5.0 / 10, 0.0, 10 / 100])
    assert state[4:] == pytest.approx([1.0, 10.0 / 30, 0.0, (5.0 - 15.0) / 20, 0.0])
    assert failure_state(trace, None) is None
    failure = {"type": "collision", "kind": "collision:rear_end"}
    near = [x + 0.01 for x in state]
    far = [x + 0.5 for x in state]
    records = [{"index": 0, "scenario": BRAKES, "failure": failure, "rho": -2.0, "failure_state": state},
               {"index": 1, "scenario": BRAKES, "failure": failure, "rho": -1.5, "failure_state": near},
               {"index": 2, "scenario": BRAKES, "failure": failure, "rho": -1.2, "failure_state": far},
               {"index": 3, "scenario": LEFT_TURN, "failure": failure, "rho": -1.1, "failure_state": state},
               {"index": 4, "scenario": BRAKES, "failure": failure, "rho": -1.0, "failure_state": None},
               {"index": 5, "scenario": BRAKES, "failure": None, "rho": 3.0}]
    seen: set = set()
    records = [EpisodeRecord.from_dict({"seed": 0, **r}) for r in records]
    assert [_feedback(r, seen, "state-novelty") for r in records] == [-2.0, 9.0, -1.2, -1.1, -1.0, 3.0]
    assert default_feedback("novelty-bandit") == "state-novelty"


def test_novelty_bandit_options_are_checked(small_space):
    from dv2s_gym.mining.sampling.samplers import sampler_params

    assert sampler_params("novelty-bandit", {"explore": 0.5}) == {"explore": 0.5, "prior_new": 2.0, "prior_old": 1.0,
                                                                   "cover": 1}
    for bad, match in (({"explore": 0.0}, r"explore must be in \(0, 1\]"), ({"prior_old": -1}, "prior_old must be > 0"),
                       ({"alpha": 0.5}, "no option 'alpha'; it takes explore, prior_new, prior_old, cover")):
        with pytest.raises(MiningError, match=match):
            make_sampler("novelty-bandit", small_space.feature_space, 0, bad)


@pytest.mark.parametrize("content, needle", [
    ('{"schema": "dv2s-mine", garbage', "settings.json is not readable JSON"),
    ('[1, 2, 3]', "settings.json is not a mining run's settings"),
])
def test_a_damaged_settings_json_is_refused_in_one_line_naming_the_file_and_the_fix(tmp_path, content, needle):
    out = tmp_path / "run"
    out.mkdir()
    (out / "settings.json").write_text(content)
    with pytest.raises(MiningError) as error:
        mine("rule", out=out, budget=1, sampler="random", scenarios=[BRAKES], workers=1, progress=False,
             reports=False, env_config=SHORT)
    message = str(error.value)
    assert needle in message and str(out / "settings.json") in message and "\n" not in message
    assert "choose another --out" in message and (out / "settings.json").read_text() == content
