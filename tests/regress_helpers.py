"""Policies for the regression-runner tests, loaded by spec (``regress_helpers:FaultyPolicy?...``).

:class:`FaultyPolicy` keeps the lane (action 1, IDLE) and misbehaves on chosen seeds: the
worker process dies (``os._exit``), hangs (sleeps far past any test timeout) or raises. Every
start of an episode on a chosen seed appends a line to ``log`` so a test can count attempts; with
``once=1`` it misbehaves only on the first attempt (the log has no line for the seed yet), so a retry succeeds.
"""

from __future__ import annotations

import os
import time

import numpy as np

from policies.registry import Policy


class FaultyPolicy(Policy):
    """IDLE every step; on ``crash_seed`` the process exits, on ``hang_seed`` it sleeps, on ``raise_seed`` it raises."""

    name = "faulty"

    def __init__(self, crash_seed: int = -1, hang_seed: int = -1, raise_seed: int = -1, log: str = "",
                 once: int = 0) -> None:
        self.crash_seed, self.hang_seed, self.raise_seed = int(crash_seed), int(hang_seed), int(raise_seed)
        self.log, self.once = log, bool(int(once))

    def seed(self, seed: int) -> None:
        if self.once and self.log and os.path.exists(self.log):
            with open(self.log, encoding="utf-8") as handle:
                if str(seed) in handle.read().split():
                    return  # misbehaved on an earlier attempt already
        if seed in (self.crash_seed, self.hang_seed, self.raise_seed) and self.log:
            with open(self.log, "a", encoding="utf-8") as handle:
                handle.write(f"{seed}\n")
        if seed == self.crash_seed:
            os._exit(3)
        if seed == self.hang_seed:
            time.sleep(3600)
        if seed == self.raise_seed:
            raise RuntimeError(f"deliberate failure on seed {seed}")

    def act(self, observations: np.ndarray, deterministic: bool = True) -> np.ndarray:
        return np.ones(len(observations), dtype=np.int64)


class BrokenPolicy(Policy):
    """Raises on its first action in every episode: a candidate whose every episode is an error."""

    name = "broken"

    def act(self, observations: np.ndarray, deterministic: bool = True) -> np.ndarray:
        raise RuntimeError("broken policy: no action")


class StopPolicy(Policy):
    """Brakes (SLOWER) every step: the ego comes to a standstill on a free road, and never collides."""

    name = "stop"

    def act(self, observations: np.ndarray, deterministic: bool = True) -> np.ndarray:
        return np.full(len(observations), 4, dtype=np.int64)


class EpisodeCountingPolicy(Policy):
    """Brakes (SLOWER) in the first ``slow`` episodes this instance drives, keeps the lane (IDLE) afterwards:
    a stateful policy whose behaviour depends on how many episodes it has seen."""

    name = "counting"

    def __init__(self, slow: int = 1) -> None:
        self.slow, self.episodes = int(slow), 0

    def seed(self, seed: int) -> None:
        self.episodes += 1

    def act(self, observations: np.ndarray, deterministic: bool = True) -> np.ndarray:
        return np.full(len(observations), 4 if self.episodes <= self.slow else 1, dtype=np.int64)
