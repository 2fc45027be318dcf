"""One decision path per failure kind: ``dv2s regress``'s worker decides every kind through the detector registry,
as ``dv2s mine`` does, so a plug-in detector replacing a built-in one changes what both commands count."""

from __future__ import annotations

import warnings

import pytest

from dv2s_gym.mining import monitors
from dv2s_gym.regress import tasks
from envs.safety_metrics import MonitorSettings, total_stall_step
from policies.evaluation import run_episode
from policies import worker_cache
from scenario_bank.errors import BuiltInReplacedWarning
from scenario_bank.failure_types import (FAILURE_TABLE, FailureType, FailureTypeError, failure_type,
                                         register_failure_type)
from scenario_bank.named_registry import replaced_built_ins
from tests.test_failure_types import _episode

__all__: list = []


def finds_no_collision(result, trace, settings):
    """A plug-in's collision detector that finds nothing."""
    return None


@pytest.fixture
def noop_collision(monkeypatch):
    """The built-in collision detector replaced by :func:`finds_no_collision`, in a copy of the registry."""
    table = monitors.DETECTORS.copy()
    monkeypatch.setattr(monitors, "DETECTORS", table)
    with pytest.warns(BuiltInReplacedWarning, match="'collision' was replaced"):
        monitors.register_detector(monitors.Detector("collision", finds_no_collision, table["collision"].score),
                                   overwrite=True)
    yield
    monitors.unregister_detector("collision")
    table.mark_built_in()


def _regress(monkeypatch, episode, failure=("collision", "off_road", "stall")):
    monkeypatch.setattr(tasks.worker_cache, "env_for", lambda bank_dir, config: (("bank", "config"), None))
    monkeypatch.setattr(tasks.worker_cache, "policy_for", lambda *args, **kwargs: None)
    monkeypatch.setattr(tasks, "run_episode", lambda env, policy, scenario, seed: episode)
    return tasks.run_regress_task({"kind": "regress", "policy": "rule", "role": "candidate", "scenario": "s",
                                   "seed": 0, "env_config": {}, "bank_dir": None, "trace_dir": None,
                                   "failure": list(failure), "monitor": MonitorSettings(stall_seconds=5.0)})


def test_a_replaced_collision_detector_changes_what_regress_and_mine_count(noop_collision, monkeypatch):
    episode = _episode([10.0, 9.0, 8.0], collided=True, collisions=["Car1"])
    assert monitors.detect_failure(*episode) is None  # mine: the plug-in finds no collision
    judged = _regress(monkeypatch, episode)
    assert judged.error is None and judged.collided is False and not judged.failed  # regress: the same
    assert f"detector 'collision' (replaced by {finds_no_collision.__module__})" in replaced_built_ins()


def test_the_built_in_detectors_decide_as_the_result_fields(monkeypatch):
    collided = _regress(monkeypatch, _episode([10.0, 9.0, 8.0], collided=True, collisions=["Car1"]))
    assert collided.collided is True and collided.failure_kinds == ("collision",)
    off_road = _regress(monkeypatch, _episode([10.0, 9.0, 8.0], off_road=True))
    assert off_road.off_road is True and off_road.failure_kinds == ("off_road",)


@pytest.mark.parametrize("policy, scenario, seed", [
    ("keep_lane", "highway_lead_vehicle_brakes", 0), ("rule", "highway_lead_vehicle_brakes", 0),
    ("keep_lane", "highway_cut_in_from_left", 1)])
def test_the_built_in_detectors_agree_with_the_result_fields_on_shipped_episodes(policy, scenario, seed):
    """On real episodes of shipped policies the built-in detectors find exactly what the regression worker's
    fields record (``collided``, ``off_road``; ``stalled`` with the same monitor settings)."""
    env_key, env = worker_cache.env_for(None, {})
    result, trace = run_episode(env, worker_cache.policy_for(policy, env_key, env, owner="detector-check"),
                                scenario, seed)
    settings = MonitorSettings()
    for name, fact in (("collision", result.collided), ("off_road", result.off_road),
                       ("stall", total_stall_step(trace, settings.stall_seconds) is not None)):
        found = monitors.DETECTORS[name].detect(result, trace, settings) is not None
        assert found == bool(fact), (name, policy, scenario, seed)


def test_a_result_field_the_result_records_already_is_refused():
    for field, owner in (("success", "records itself"), ("collided", "failure type 'collision'")):
        with pytest.raises(FailureTypeError, match=f"result_field '{field}' is .*{owner}.*a field of its own"):
            register_failure_type(FailureType("shadowing_probe", severity=len(FAILURE_TABLE) + 40,
                                              result_field=field, regress_default=False, with_actor=False,
                                              label=None))
        assert failure_type("shadowing_probe") is None


def test_no_warning_is_left_over():
    with warnings.catch_warnings():
        warnings.simplefilter("error", BuiltInReplacedWarning)
        assert not [entry for entry in replaced_built_ins() if "collision" in entry]


def collision_as_json(result, trace, settings):
    """A plug-in's collision detector returning the failure's JSON object, not a ``Failure``."""
    return {"type": "collision", "time": 0.4, "step": 2} if result.collided else None


def test_a_detector_returning_no_failure_record_is_named_with_the_fix(monkeypatch):
    """A detector's result that is not a ``Failure`` (nor ``None``) is refused where it is asked, naming the
    detector, its module, what it returned and the fix; not read as a record, and not an AttributeError later."""
    table = monitors.DETECTORS.copy()
    monkeypatch.setattr(monitors, "DETECTORS", table)
    with pytest.warns(BuiltInReplacedWarning):
        monitors.register_detector(monitors.Detector("collision", collision_as_json, table["collision"].score),
                                   overwrite=True)
    try:
        episode = _episode([10.0, 9.0, 8.0], collided=True, collisions=["Car1"])
        with pytest.raises(monitors.DetectorResultError) as raised:
            monitors.detect_failure(*episode)
        message = str(raised.value)
        assert f"detector of failure type 'collision' (module {collision_as_json.__module__}) returned a dict" \
            in message
        assert "return Failure('collision', time, step, ...)" in message and "docs/mining.md" in message
        with pytest.raises(monitors.DetectorResultError, match="failure type 'collision' .* returned a dict"):
            _regress(monkeypatch, episode)  # regress's worker asks the same detector: the same error
        assert monitors.detect_failure(*_episode([10.0, 9.0, 8.0])) is None  # None stays the answer for no failure
    finally:
        monitors.unregister_detector("collision")
        table.mark_built_in()
