"""Test helpers for mining runs."""

from __future__ import annotations

import json
import random
from pathlib import Path
from typing import Any, Tuple

import numpy as np
import pytest

import dv2s_gym.mining.sampling.space as space_module
from dv2s_gym.mining import miner as miner_module
from dv2s_gym.mining.jsonl import JsonlAppender
from dv2s_gym.mining.settings import MineSettings
from dv2s_gym.workers.settings import WorkerSettings

_WORKER_OPTIONS = ("backend", "workers", "address", "timeout")
_RUN_OPTIONS = ("progress", "reports", "origin")


def mine(policy: str, *, out: Any, **options: Any) -> "miner_module.MineRun":
    """:func:`dv2s_gym.mining.miner.mine` with its settings as keywords (the tests' shorthand): the worker
    options become a :class:`WorkerSettings`, ``progress``/``reports``/``origin`` are passed as they are and
    the rest make the :class:`MineSettings`."""
    workers = WorkerSettings(**{key: options.pop(key) for key in _WORKER_OPTIONS if key in options})
    run = {key: options.pop(key) for key in _RUN_OPTIONS if key in options}
    return miner_module.mine(policy, MineSettings(**options), out=out, workers=workers, **run)


def mine_killed_after(policy: str, out: Path, stop_after: int, monkeypatch: Any, **run: Any) -> None:
    """Run ``mine(policy, out=out, **run)`` and kill it (``KeyboardInterrupt``) as it is about to record
    episode number ``stop_after``: the first ``stop_after`` episode records are on disk, others may be in
    flight. The recorder is restored afterwards."""
    original = JsonlAppender.append
    count = [0]

    def append(self, record):
        if self._path.name == "episodes.jsonl":
            if count[0] == stop_after:
                raise KeyboardInterrupt  # killed with episodes in flight, some finished out of order
            count[0] += 1
        original(self, record)

    monkeypatch.setattr(JsonlAppender, "append", append)
    with pytest.raises(KeyboardInterrupt):
        mine(policy, out=out, **run)
    monkeypatch.setattr(JsonlAppender, "append", original)


def global_draws() -> Tuple[float, float]:
    """The next draw of Python's and of NumPy's global random generators."""
    return random.random(), np.random.random()


def seed_globals_and_peek(seed: int) -> Tuple[float, float]:
    """Seed both global generators with ``seed`` and return their next draws (:func:`global_draws`), leaving
    them seeded as before the peek: a caller that draws nothing from them sees the same draws again."""
    random.seed(seed)
    np.random.seed(seed)
    before = global_draws()
    random.seed(seed)
    np.random.seed(seed)
    return before


class SpaceBuilt(Exception):
    """Raised where a mining run would build its scene space: every resume check of ``mine`` comes before it."""


def recorded_run_folder(out: Path, scenarios: Tuple[str, ...], monkeypatch: Any) -> Path:
    """``out`` as a mining run folder whose ``settings.json`` a seed-0 run of ``rule`` over ``scenarios`` wrote;
    building a scene space then raises :class:`SpaceBuilt`, so a test sees the resume checks and nothing after."""
    (out / "traces").mkdir(parents=True)
    recorded = miner_module._recorded("rule", MineSettings(budget=2, scenarios=scenarios, seed=0, batch=4),
                                      scenarios, {})
    (out / "settings.json").write_text(json.dumps(recorded), encoding="utf-8")

    def no_space(*args: Any, **kwargs: Any) -> None:
        raise SpaceBuilt()

    monkeypatch.setattr(space_module, "SceneSpace", no_space)
    return out
