"""dv2s regress's stall: total standing time on a free road over the episode, not only one unbroken stretch."""

from types import SimpleNamespace

from envs.safety_metrics import MonitorSettings, first_stall_step, total_stall_step

FREQUENCY = 5  # steps per second


def _stop_and_go_trace(stand_seconds=4.6, creep_seconds=0.4, cycles=4):
    """An ego alone on the road that stands ``stand_seconds``, creeps ``creep_seconds`` at 2 m/s, and repeats."""
    states, x = [], 0.0
    for _ in range(cycles):
        for _ in range(round(stand_seconds * FREQUENCY)):
            states.append({"ego": [x, 0.0, 0.0, 0.0]})
        for _ in range(round(creep_seconds * FREQUENCY)):
            x += 2.0 / FREQUENCY
            states.append({"ego": [x, 0.0, 0.0, 2.0]})
    return SimpleNamespace(config={"policy_frequency": FREQUENCY}, states=states)


def test_stop_and_go_standing_adds_up_to_a_stall():
    trace = _stop_and_go_trace()
    assert first_stall_step(trace, 5.0) is None  # no single 5 s stretch
    step = total_stall_step(trace, 5.0)
    assert step is not None
    standing = sum(1 for s in trace.states[:step + 1] if s["ego"][3] == 0.0)
    assert standing == 5 * FREQUENCY  # found exactly when the standing time reaches 5 s


def test_standing_behind_traffic_is_not_a_stall():
    trace = _stop_and_go_trace()
    for states in trace.states:  # a car 10 m ahead in the ego's lane the whole time
        states["lead"] = [states["ego"][0] + 10.0, 0.0, 0.0, 0.0]
    assert total_stall_step(trace, 5.0) is None


def test_the_regression_worker_counts_total_standing_time(monkeypatch):
    import dv2s_gym.regress.tasks as regress_tasks
    import policies.worker_cache as worker_cache
    from dv2s_gym.regress.tasks import run_regress_task

    trace = _stop_and_go_trace()
    result = SimpleNamespace(to_json=lambda: {"scenario": "s", "seed": 0, "collided": False, "off_road": False,
                                              "error": None})
    monkeypatch.setattr(worker_cache, "env_for", lambda bank, config: (("k", "{}"), None))
    monkeypatch.setattr(worker_cache, "policy_for", lambda spec, key, env, owner="": None)
    monkeypatch.setattr(regress_tasks, "run_episode", lambda env, policy, scenario, seed: (result, trace))
    data = run_regress_task({"kind": "regress", "policy": "rule", "role": "candidate", "scenario": "s", "seed": 0,
                             "env_config": {}, "bank_dir": None, "trace_dir": None,
                             "monitor": MonitorSettings(stall_seconds=5.0)})
    assert data.to_dict()["stalled"] and data.to_dict()["failed"] and data.to_dict()["failure_kinds"] == ["stall"]
