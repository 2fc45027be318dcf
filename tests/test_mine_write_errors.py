"""A mining run whose own files cannot be written (a full disk): it stops before recording the episode, names the
file and the fix, and the resumed run counts every failure, as an uninterrupted run does."""

from __future__ import annotations

import errno
import json
from types import SimpleNamespace

import pytest

from dv2s_gym.mining.errors import MiningError
from dv2s_gym.mining import jsonl as jsonl_module
from dv2s_gym.mining.miner import read_records
from dv2s_gym.workers import backends
from dv2s_gym.workers.base import Backend
from dv2s_gym.workers.tasks import function_for, run_task
from envs.trace import EpisodeTrace
from mining_helpers import mine

BRAKES = "highway_lead_vehicle_brakes"
POLICY = "rule?action_noise=0.5"
RUN = dict(budget=8, sampler="random", scenarios=[BRAKES], batch=4, seed=0, reference=None,
           env_config={"duration": 3}, progress=False, reports=False, backend="inline")


class _Inline(Backend):
    """Runs each task in this process (so that a patched trace writer is the one the episodes use)."""

    name = "inline"

    def run(self, tasks, on_result):
        for task in tasks:
            on_result(run_task(function_for(task), task))


@pytest.fixture
def inline(monkeypatch):
    monkeypatch.setitem(backends._FACTORIES, "inline", lambda **_: _Inline())


def _stable(records):
    return [json.dumps(r.to_dict(), sort_keys=True) for r in records]


def _disk_full_once(monkeypatch, code=errno.ENOSPC):
    """Make the next trace write fail with ``code`` (as a full disk does), the later ones succeed."""
    original, calls = EpisodeTrace.save, []

    def save(self, path):
        calls.append(str(path))
        if len(calls) == 1:
            raise OSError(code, "No space left on device" if code == errno.ENOSPC else "write failed")
        return original(self, path)

    monkeypatch.setattr(EpisodeTrace, "save", save)
    return calls


@pytest.fixture(scope="module")
def whole(tmp_path_factory):
    import dv2s_gym.workers.backends as module

    module._FACTORIES["inline"] = lambda **_: _Inline()
    try:
        out = tmp_path_factory.mktemp("whole")
        run = mine(POLICY, out=out, **RUN)
    finally:
        del module._FACTORIES["inline"]
    assert len(run.failures) >= 2 and not run.errors  # the scenes below need failures to mean anything
    return run


@pytest.mark.slow
def test_a_trace_that_cannot_be_written_stops_the_run_and_the_resumed_run_counts_the_failure(
        whole, inline, tmp_path, monkeypatch):
    out = tmp_path / "run"
    calls = _disk_full_once(monkeypatch)
    with pytest.raises(MiningError) as stopped:
        mine(POLICY, out=out, **RUN)
    message = str(stopped.value)
    first = whole.failures[0].index
    assert calls[0].endswith(f"{first:06d}.json.gz") and calls[0] in message
    assert "the disk is full" in message and "free space on /" in message
    assert "rerun the same command to resume" in message
    recorded = read_records(out / "episodes.jsonl")
    assert first not in [r["index"] for r in recorded] and not any(r["error"] for r in recorded)
    resumed = mine(POLICY, out=out, **RUN)  # space freed: the same command
    assert not resumed.errors and len(resumed.failures) == len(whole.failures)
    assert _stable(resumed.records) == _stable(whole.records)


def test_an_episode_log_that_cannot_be_written_is_named_with_the_fix(tmp_path, monkeypatch, inline):
    def fsync(fd):
        raise OSError(errno.ENOSPC, "No space left on device")  # as the system says it: no file named

    monkeypatch.setattr(jsonl_module, "os", SimpleNamespace(fsync=fsync))
    with pytest.raises(MiningError) as stopped:
        mine(POLICY, out=tmp_path / "run", **dict(RUN, budget=1, batch=1))
    message = str(stopped.value)
    assert f"could not write {tmp_path / 'run' / 'episodes.jsonl'}: the disk is full; free space on /" in message
    assert "rerun the same command to resume" in message
    assert "[Errno" not in message


def test_a_read_only_file_system_and_a_quota_say_so():
    from dv2s_gym.mining.write_errors import run_write_error

    assert "the file system is read-only; make / writable" in str(run_write_error("/x", errno.EROFS))
    assert "the disk quota is exceeded" in str(run_write_error("/x", errno.EDQUOT))
