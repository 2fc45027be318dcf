"""The task registry of dv2s_gym/workers: kinds registered by their packages, looked up in the caller,
run in any pool; a task of no registered kind fails before any worker starts."""

from __future__ import annotations

import os

import pytest

from dv2s_gym.workers.errors import WorkerError
from dv2s_gym.workers.pool import LocalBackend
from dv2s_gym.workers.tasks import function_for, gave_up_result, register, run_task, task_modules


def echo_pid(task):
    """A task kind of this test module: which process ran the task."""
    return {"id": f"{task['scenario']}/{task['seed']}", "role": task["role"], "pid": os.getpid()}


def _raise(task):
    raise KeyboardInterrupt


register("test-echo-pid", echo_pid)

TASK = {"kind": "test-echo-pid", "role": "candidate", "policy": "rule", "scenario": "s", "seed": 3}


def test_regress_and_mining_register_their_kinds_when_imported():
    from dv2s_gym.mining.tasks import HELDOUT, MINE, heldout_task, run_mine_task
    from dv2s_gym.regress.tasks import KIND, run_regress_task

    assert function_for({"kind": KIND}) is run_regress_task
    assert function_for({"kind": MINE}) is run_mine_task and function_for({"kind": HELDOUT}) is heldout_task
    assert {"dv2s_gym.regress.tasks", "dv2s_gym.mining.tasks", __name__} <= set(task_modules())


def test_an_unknown_kind_or_a_second_function_for_a_kind_is_a_clear_error():
    with pytest.raises(WorkerError, match="no task function is registered for kind 'nope'.*'test-echo-pid'"):
        function_for({"kind": "nope"})
    with pytest.raises(WorkerError, match="no task function is registered for kind None"):
        function_for({})
    register("test-echo-pid", echo_pid)  # the same function again: importing a module twice is harmless
    with pytest.raises(WorkerError, match="registered twice"):
        register("test-echo-pid", _raise)


def test_the_last_net_and_the_result_of_a_task_given_up():
    assert run_task(_raise, TASK) == {"id": "s/3", "role": "candidate", "scenario": "s", "seed": 3,
                                      "error": "KeyboardInterrupt: ", "trace": None}
    given_up = gave_up_result(TASK, ["the worker crashed (exit code -9)", "the worker hung (no result after 5 s)"], 2)
    assert given_up["error"] == ("the worker crashed (exit code -9); then the worker hung (no result after 5 s) "
                                 "running candidate 'rule' on s seed 3 (2 attempts)")


@pytest.mark.slow
def test_the_local_pool_runs_any_registered_kind_in_its_workers_and_refuses_an_unknown_one_at_once():
    results = []
    with LocalBackend(workers=1, timeout=120) as pool:
        with pytest.raises(WorkerError, match="kind 'nope'"):
            pool.run([TASK, {**TASK, "kind": "nope"}], results.append)
        assert results == [] and pool._pool == []  # refused before a worker started
        pool.run([TASK, {**TASK, "seed": 4}], results.append)
    assert sorted(r["id"] for r in results) == ["s/3", "s/4"]
    assert {r["pid"] for r in results} != {os.getpid()}
