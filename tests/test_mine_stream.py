"""Streamed mining of adaptive samplers: the sliding-window schedule (dv2s_gym/mining/sampling/window.py), the local
pool's ``run(..., more=)`` and resuming a streamed run."""

from __future__ import annotations

import json
import shutil

import pytest

from dv2s_gym.mining.errors import MiningError
from dv2s_gym.mining.miner import episode_seed, read_records
from mining_helpers import mine
from dv2s_gym.mining.sampling.samplers import make_sampler
from dv2s_gym.mining.sampling.space import SceneSpace
from dv2s_gym.mining.settings import DEFAULT_BATCH, MineSettings
from mining_helpers import mine_killed_after
from dv2s_gym.mining.sampling.window import WindowSchedule
from dv2s_gym.regress.tasks import KIND
from dv2s_gym.workers.pool import LocalBackend, _ScenarioQueue
from dv2s_gym.workers.tasks import result_object

BRAKES = "highway_lead_vehicle_brakes"
LEFT_TURN = "urban_left_turn_oncoming"
POLICY = "rule?action_noise=0.4"
RUN = dict(budget=12, sampler="cross-entropy", scenarios=[BRAKES, LEFT_TURN], batch=4, seed=7, reference=None,
           env_config={"duration": 3}, progress=False, reports=False)


def _stable(records):
    return [json.dumps(r.to_dict(), sort_keys=True) for r in records]  # episode records, as their file lines


# --- the schedule on its own ----------------------------------------------------------------------------------------

def test_the_window_draws_scene_j_once_outcome_j_minus_w_is_fed_whatever_the_arrival_order():
    space = SceneSpace([BRAKES, LEFT_TURN])
    fresh = lambda: WindowSchedule(make_sampler("cross-entropy", space.feature_space, 3), 3)  # noqa: E731
    outcome = lambda index, seen: -1.0 if index % 3 == 0 else 2.0  # noqa: E731

    def run(order):
        window, done, log = fresh(), {}, []
        log.append(window.advance(done, 9, lambda r, seen: outcome(r["index"], seen)))
        for index in order:
            done[index] = {"index": index}
            log.append((index, window.fed, window.advance(done, 9, lambda r, seen: outcome(r["index"], seen))))
        return window, log

    in_order, log = run(range(9))
    assert log[0] == [0, 1, 2]  # W draws before any outcome
    assert [entry[2] for entry in log[1:]] == [[3], [4], [5], [6], [7], [8], [9], [10], [11]]  # drawn past budget
    assert in_order.fed == 9 and sorted(in_order.pending) == [9, 10, 11]
    shuffled, log = run([2, 1, 0, 5, 3, 4, 8, 6, 7])
    # nothing is fed (and nothing drawn) until every earlier outcome is in
    assert log[1][2] == [] and log[2][2] == [] and log[3][2] == [3, 4, 5]
    points = lambda w: {i: list(p[0]) for i, p in w.pending.items()}  # noqa: E731
    assert points(shuffled) == points(in_order) and shuffled.dumps() == in_order.dumps()


# --- the local pool accepts tasks while it runs ---------------------------------------------------------------------

@pytest.mark.slow
def test_the_local_pool_runs_tasks_added_while_it_runs_with_retries(tmp_path):
    log = tmp_path / "attempts.log"
    base = {"kind": KIND, "policy": f"regress_helpers:FaultyPolicy?crash_seed=13&log={log}", "role": "candidate",
            "scenario": BRAKES, "env_config": {"duration": 2}, "bank_dir": None, "trace_dir": None}
    results, calls = [], []

    def more():
        calls.append(len(results))
        seed = 10 + len(calls)
        return [{**base, "seed": seed}] if seed <= 14 else []

    with LocalBackend(workers=2, timeout=60) as pool:
        assert pool.streams
        pool.run([{**base, "seed": 10}], results.append, more=more)
        by_seed = {r["seed"]: r for r in map(result_object, results)}
        assert sorted(by_seed) == [10, 11, 12, 13, 14] and len(results) == 5
        assert "crashed" in by_seed[13]["error"] and "2 attempts" in by_seed[13]["error"]  # retried, then reported
        assert not any(by_seed[s].get("error") for s in (10, 11, 12, 14))
        assert log.read_text().split() == ["13", "13"]
        assert calls[0] == 1 and calls == sorted(calls)  # called after results were handed over
        later = []
        pool.run([{**base, "seed": 20}], later.append)  # without more: as before
        assert [result_object(r)["seed"] for r in later] == [20]


def test_the_scenario_queue_takes_appended_tasks_and_prefers_the_oldest_compiled_one():
    task = lambda scenario: {"scenario": scenario, "bank_dir": None, "env_config": {}}  # noqa: E731
    queue = _ScenarioQueue([task("a"), task("b")])
    assert queue.append(task("a")) == 2 and queue.append(task("c")) == 3
    key = lambda s: queue.group([0, 1, 3][["a", "b", "c"].index(s)])  # noqa: E731
    seen = {key("a"), key("b")}
    assert queue.pop_for(seen, [set()]) == 0 and queue.pop_for(seen, [set()]) == 1
    assert queue.pop_for(seen, [set()]) == 2
    assert queue.pop_for(seen, [set()]) == 3 and not queue


# --- mining runs ----------------------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def streamed(tmp_path_factory):
    out = tmp_path_factory.mktemp("streamed-1")
    return out, mine(POLICY, out=out, workers=1, **RUN)


@pytest.mark.slow
def test_a_streamed_run_is_the_same_on_one_and_two_workers(streamed, tmp_path):
    out, one = streamed
    assert json.loads((out / "settings.json").read_text())["schedule"] == "window"
    two = mine(POLICY, out=tmp_path / "two", workers=2, **RUN)
    assert [r.to_dict()["index"] for r in two.records] == list(range(12))
    assert [r.to_dict()["seed"] for r in two.records] == [episode_seed(7, i) for i in range(12)]
    assert _stable(two.records) == _stable(one.records)
    assert any(r.to_dict()["failure"] for r in one.records) and any(not r.to_dict()["failure"] for r in one.records)


@pytest.mark.slow
@pytest.mark.parametrize("stop_after", [3, 6, 9])
def test_a_streamed_run_interrupted_mid_way_resumes_to_the_same_records(streamed, tmp_path, monkeypatch, stop_after):
    out, whole = streamed
    cut = tmp_path / "cut"
    mine_killed_after(POLICY, cut, stop_after, monkeypatch, workers=2, **RUN)
    assert len(read_records(cut / "episodes.jsonl")) == stop_after
    resumed = mine(POLICY, out=cut, workers=2, **RUN)
    assert _stable(resumed.records) == _stable(whole.records)
    assert (cut / "episodes.jsonl").read_bytes().count(b"\n") == 12  # nothing ran twice


@pytest.mark.slow
def test_resume_from_records_alone_and_with_a_larger_budget_equals_an_uninterrupted_run(streamed, tmp_path):
    out, whole = streamed
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    records = read_records(copy / "episodes.jsonl")
    kept = [r for r in records if r.index not in (4, 7, 8, 11)]  # holes: finished out of order, then killed
    (copy / "episodes.jsonl").write_text("".join(json.dumps(r.to_dict(), sort_keys=True) + "\n" for r in kept))
    (copy / "sampler.pkl").unlink()
    resumed = mine(POLICY, out=copy, workers=2, **RUN)
    assert _stable(resumed.records) == _stable(whole.records)
    # the finished run's checkpoint, and then a larger budget, continue as one longer run would
    longer = mine(POLICY, out=copy, workers=1, **{**RUN, "budget": 16})
    straight = mine(POLICY, out=tmp_path / "straight", workers=2, **{**RUN, "budget": 16})
    assert _stable(longer.records) == _stable(straight.records)
    assert _stable(longer.records[:12]) == _stable(whole.records)


@pytest.mark.slow
def test_a_run_folder_recorded_on_another_schedule_is_refused(streamed, tmp_path):
    """An adaptive sampler runs on the window schedule only: a run folder that records the chunk schedule (or
    an unknown one) for it is refused, naming the fix."""
    out, _ = streamed
    old = tmp_path / "old"
    old.mkdir()
    settings = json.loads((out / "settings.json").read_text())
    assert settings["schedule"] == "window"
    for schedule in ("chunks", "zigzag"):
        settings["schedule"] = schedule
        (old / "settings.json").write_text(json.dumps(settings))
        with pytest.raises(MiningError, match=f"schedule '{schedule}', not 'window'.*--out"):
            mine(POLICY, out=old, workers=1, **{**RUN, "budget": 8})


class _ChunkOnly(LocalBackend):
    """A pool that cannot take tasks while it runs (as the Ray backend)."""

    streams = False
    calls = 0

    def run(self, tasks, on_result):  # noqa: D102 - no ``more``
        type(self).calls += 1
        super().run(tasks, on_result)


@pytest.mark.slow
def test_a_backend_that_does_not_stream_runs_the_window_call_by_call_to_the_same_records(streamed, tmp_path,
                                                                                           monkeypatch):
    from dv2s_gym.workers import backends

    out, whole = streamed
    monkeypatch.setattr(backends, "get_backend", lambda name, workers=None, address=None, timeout=None:
                        _ChunkOnly(workers, timeout=timeout))
    run = mine(POLICY, out=tmp_path / "chunked", workers=2, **RUN)
    assert _stable(run.records) == _stable(whole.records)
    assert _ChunkOnly.calls >= 12 // 4


@pytest.mark.slow
@pytest.mark.parametrize("sampler", ["novelty-bandit", "random"])
def test_without_a_batch_one_and_two_workers_write_the_same_episodes(sampler, tmp_path):
    """The seed decides the run whatever the number of workers: the default window (adaptive samplers) or chunk
    (random) is not sized by the workers."""
    run = dict(RUN, batch=None, sampler=sampler, budget=10)
    one = mine(POLICY, out=tmp_path / "one", workers=1, **run)
    two = mine(POLICY, out=tmp_path / "two", workers=2, **run)
    settings = [json.loads((out / "settings.json").read_text()) for out in (tmp_path / "one", tmp_path / "two")]
    assert settings[0] == settings[1]
    assert settings[0]["schedule"] == ("window" if sampler == "novelty-bandit" else "chunks")
    # the run's settings as it ran on them: the batch and scenarios it resolved, as settings.json records them
    assert one.policy == POLICY and isinstance(one.settings, MineSettings)
    assert one.settings.batch == DEFAULT_BATCH and one.settings.scenarios == tuple(settings[0]["scenarios"])
    assert {key: settings[0][key] for key in one.settings.recorded()} == one.settings.recorded()
    assert [r.to_dict()["index"] for r in two.records] == list(range(10))
    lines = [sorted((out / "episodes.jsonl").read_text().splitlines()) for out in (tmp_path / "one", tmp_path / "two")]
    assert lines[0] == lines[1]
