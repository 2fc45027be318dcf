"""The training envs and how their episodes are chosen: the scenario sampler (uniform, weighted, curriculum),
the wrapper that draws each episode's scenario and reset seed, the vectorized envs in worker processes, and the
held-out evaluation episodes."""

from __future__ import annotations

import dataclasses
import functools
import os
import signal
import sys
from collections import deque
from typing import Any, Callable, Deque, Dict, List, Mapping, Optional, Sequence, Tuple

import gymnasium as gym
import numpy as np
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv

from envs.dv2s_env import DV2SEnv
from policies.evaluation import EVAL_SEED_BASE, TRAIN_SEED_LOW
from policies.training.config import SAMPLERS, TRAIN_SEED_HIGH, TrainingError

__all__ = [
    "ScenarioSampler",
    "ScenarioSchedule",
    "TrainEnvSpec",
    "make_train_env",
    "make_vec_env",
    "close_vec_env",
    "evaluation_episodes",
]


class ScenarioSampler:
    """The probability of each scenario being a training episode's scenario.

    Args:
        names: the scenarios trained on.
        mode: ``uniform``; ``weighted`` (``weights``, scenario -> weight, absent = 0);
            ``curriculum``: ``p_i = floor / K + (1 - floor) * f_i / sum(f)`` where ``f_i``
            is scenario ``i``'s failure rate over its last ``window`` training episodes,
            smoothed as ``(failures + 1) / (episodes + 2)`` so an unseen scenario counts as
            0.5 and none ever drops to zero.
    """

    def __init__(self, names: Sequence[str], mode: str = "uniform", weights: Optional[Mapping[str, float]] = None,
                 floor: float = 0.25, window: int = 20) -> None:
        self.names = list(dict.fromkeys(names))
        if not self.names:
            raise TrainingError("the scenario selection is empty; name at least one bank scenario")
        if mode not in SAMPLERS:
            raise TrainingError(f"unknown sampler {mode!r}; use one of {', '.join(SAMPLERS)}")
        self.mode = mode
        self.floor = float(floor)
        self.window = int(window)
        self.weights = None
        if mode == "weighted":
            weights = dict(weights or {})
            stray = sorted(set(weights) - set(self.names))
            if stray:
                raise TrainingError(f"--weights names scenario(s) not trained on: {', '.join(stray)}; "
                                    f"weights are for {', '.join(self.names)}")
            values = [float(weights.get(name, 0.0)) for name in self.names]
            if any(v < 0 or not np.isfinite(v) for v in values) or sum(values) <= 0:
                raise TrainingError("--weights must be non-negative with a positive sum")
            self.weights = dict(zip(self.names, values))
        self.history: Dict[str, Deque[bool]] = {name: deque(maxlen=self.window) for name in self.names}
        self.episodes: Dict[str, int] = {name: 0 for name in self.names}

    def record(self, scenario: str, failed: bool) -> None:
        """Remember one finished training episode of ``scenario`` (others are ignored)."""
        if scenario in self.history:
            self.history[scenario].append(bool(failed))
            self.episodes[scenario] += 1

    def failure_rates(self) -> Dict[str, float]:
        """Smoothed failure rate of each scenario over its remembered episodes."""
        return {name: (sum(h) + 1.0) / (len(h) + 2.0) for name, h in self.history.items()}

    def probabilities(self) -> Dict[str, float]:
        """Scenario -> probability of being drawn next (sums to 1)."""
        k = len(self.names)
        if self.mode == "weighted":
            total = sum(self.weights.values())
            return {name: w / total for name, w in self.weights.items()}
        if self.mode == "uniform":
            return {name: 1.0 / k for name in self.names}
        rates = self.failure_rates()
        total = sum(rates.values())
        return {name: self.floor / k + (1.0 - self.floor) * rates[name] / total for name in self.names}

    def state_dict(self) -> Dict[str, Any]:
        """JSON-safe state (saved beside every checkpoint)."""
        return {"mode": self.mode, "history": {n: [bool(x) for x in h] for n, h in self.history.items()},
                "episodes": dict(self.episodes)}

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Restore :meth:`state_dict` (scenarios no longer trained on are dropped)."""
        for name, outcomes in state.get("history", {}).items():
            if name in self.history:
                self.history[name].clear()
                self.history[name].extend(bool(x) for x in outcomes)
        for name, count in state.get("episodes", {}).items():
            if name in self.episodes:
                self.episodes[name] = int(count)


class ScenarioSchedule(gym.Wrapper):
    """Chooses each episode's scenario and reset seed (training envs; see the module docstring).

    ``reset(seed=s)`` restarts the wrapper's stream from ``(s, stream)``; every reset then
    draws a scenario by the current probabilities and a reset seed in
    ``[TRAIN_SEED_LOW, 2**31 - 1)``, unless ``options`` names the scenario.
    """

    def __init__(self, env: gym.Env, probabilities: Mapping[str, float], seed: int = 0, stream: int = 0) -> None:
        super().__init__(env)
        self.stream = int(stream)
        self.rng = np.random.default_rng([int(seed), self.stream])
        self.set_scenario_probabilities(probabilities)

    def set_scenario_probabilities(self, probabilities: Mapping[str, float]) -> None:
        """Use these scenario -> probability weights from the next episode on."""
        names = list(probabilities)
        values = np.array([float(probabilities[n]) for n in names], dtype=float)
        if not names or np.any(values < 0) or values.sum() <= 0:
            raise TrainingError("scenario probabilities must be non-negative with a positive sum")
        self.names, self.probabilities = names, values / values.sum()

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None):
        if seed is not None:
            self.rng = np.random.default_rng([int(seed), self.stream])
        options = dict(options or {})
        if "scenario" not in options:
            options["scenario"] = self.names[int(self.rng.choice(len(self.names), p=self.probabilities))]
        episode_seed = int(self.rng.integers(TRAIN_SEED_LOW, TRAIN_SEED_HIGH))
        return self.env.reset(seed=episode_seed, options=options)


@dataclasses.dataclass(frozen=True)
class TrainEnvSpec:
    """What every training env of a run is: DV2S-v0 on ``names`` with ``config`` (scenarios from ``bank_dir``,
    ``None``: the default bank), each episode's scenario drawn with ``probabilities``.

    ``wrap(env, seed, stream)``, a picklable callable, replaces SB3's Monitor as the outer wrapper
    (DAgger's reference labels, :mod:`policies.imitation`)."""

    names: Sequence[str]
    config: Mapping[str, Any]
    bank_dir: Optional[str]
    probabilities: Mapping[str, float]
    wrap: Optional[Callable[[gym.Env, int, int], gym.Env]] = None

    def __post_init__(self) -> None:  # plain containers: the spec is pickled into every worker process
        object.__setattr__(self, "names", list(self.names))
        object.__setattr__(self, "config", dict(self.config))
        object.__setattr__(self, "probabilities", dict(self.probabilities))


def _build_train_env(spec: TrainEnvSpec, seed: int, stream: int) -> gym.Env:
    os.environ["OMP_NUM_THREADS"] = "1"

    env = DV2SEnv(scenario=list(spec.names), config=dict(spec.config), bank_dir=spec.bank_dir)
    scheduled = ScenarioSchedule(env, spec.probabilities, seed=seed, stream=stream)
    return Monitor(scheduled) if spec.wrap is None else spec.wrap(scheduled, seed, stream)


def make_train_env(spec: TrainEnvSpec, seed: int, stream: int = 0) -> Callable[[], gym.Env]:
    """A picklable factory of one training env (DV2S-v0 in a :class:`ScenarioSchedule` and SB3's Monitor, or
    ``spec.wrap``)."""
    return functools.partial(_build_train_env, spec, int(seed), int(stream))


def make_vec_env(spec: TrainEnvSpec, n_envs: int, seed: int, stream: int = 0, vec_env: str = "subproc"):
    """``n_envs`` training envs in a ``SubprocVecEnv`` (or ``DummyVecEnv``); env ``i`` is seeded ``seed + i``."""
    os.environ["OMP_NUM_THREADS"] = "1"  # inherited by the worker processes
    factories = [make_train_env(spec, seed + rank, stream) for rank in range(n_envs)]
    if vec_env == "dummy":
        return DummyVecEnv(factories)
    return SubprocVecEnv([functools.partial(_worker_env, factory) for factory in factories])


def close_vec_env(venv: Any) -> None:
    """Close ``venv``; after Ctrl-C (an interrupt on its way out), without waiting for step results.

    Ctrl-C can cut a ``SubprocVecEnv`` step between two workers' answers; its own ``close`` then waits for an
    answer from every worker, and one that already answered sends none: the command would hang. Here the
    unread answers are dropped and every worker is told to stop (stopped by force if it does not)."""
    interrupted = isinstance(sys.exc_info()[1], KeyboardInterrupt)
    processes = getattr(venv, "processes", None)
    if interrupted and processes is not None and not venv.closed:
        venv.waiting = False
        for remote in venv.remotes:
            try:
                remote.send(("close", None))
            except OSError:
                pass
        for process in processes:
            process.join(5)
            if process.is_alive():
                process.terminate()
                process.join(5)
        for remote in venv.remotes:
            remote.close()
        venv.closed = True
        return
    venv.close()


def _worker_env(factory: Callable[[], gym.Env]) -> gym.Env:
    """``factory()`` in a vec-env worker process, which leaves Ctrl-C to the main process: a terminal's Ctrl-C
    reaches the whole process group, and a worker stopped by it would cut the main process off mid-step before
    it saves its checkpoint; the main process closes the workers itself."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    return factory()


def evaluation_episodes(names: Sequence[str], seeds: int) -> List[Tuple[str, int]]:
    """The held-out episodes: every scenario with seeds ``EVAL_SEED_BASE .. EVAL_SEED_BASE + seeds - 1``."""
    return [(name, EVAL_SEED_BASE + offset) for name in sorted(names) for offset in range(seeds)]
