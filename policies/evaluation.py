"""Running a policy for whole episodes and summarising each one: the unit of evaluation.

An episode is named by ``(scenario, seed)``: ``env.reset(seed=seed,
options={"scenario": scenario})`` samples the same scene for every policy, so two
policies run on the same list of episodes are *paired*. :func:`run_episode` returns an
:class:`EpisodeResult` with the outcome measures the regression tests and the
training-time evaluation read, and a hash of the trajectory that a replay must match.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass
from typing import Any, Dict, Iterable, List, Optional, Sequence, Tuple

import gymnasium as gym
import numpy as np

from policies.registry import Policy, load_policy
from scenario_bank.records import EpisodeOutcome

__all__ = ["EpisodeResult", "run_episode", "evaluate", "trajectory_hash", "make_eval_env", "SUCCESS_MIN_DISTANCE",
           "EVAL_SEED_BASE", "TRAIN_SEED_LOW"]

EVAL_SEED_BASE = 10_000
"""Evaluation episodes use reset seeds ``EVAL_SEED_BASE + i`` (i < 1000) for every scenario."""
TRAIN_SEED_LOW = 1_000_000
"""Training episodes draw reset seeds from ``[TRAIN_SEED_LOW, 2**31 - 1)``: never an evaluation seed."""

SUCCESS_MIN_DISTANCE = 20.0
"""Metres the ego must travel for a collision-free, on-road episode to count as a success (not a stall)."""


@dataclass
class EpisodeResult:
    """The outcome of one episode of one policy.

    ``failed`` is the regression tests' failure event: a collision or leaving the road.
    ``success`` additionally asks that the ego kept going (at least
    :data:`SUCCESS_MIN_DISTANCE` metres) until the episode ended. ``min_ttc_time`` is when the minimum TTC
    happened [s] and ``min_ttc_with`` the road user it was measured against (``None``: no vehicle was on a
    collision course); the JSON form (:meth:`to_json`) keeps these two in its ``extra`` object. The episode
    records the files hold keep a result as its typed JSON form, :meth:`to_record`.
    """

    scenario: str
    seed: int
    scene_seed: int
    params: Dict[str, Any]
    collided: bool
    collisions: List[str]
    off_road: bool
    success: bool
    min_ttc: float
    mean_speed: float
    distance: float
    episode_return: float
    steps: int
    trajectory_hash: str
    error: Optional[str] = None
    min_ttc_time: Optional[float] = None
    min_ttc_with: Optional[str] = None

    @property
    def failed(self) -> bool:
        """A collision or leaving the road (errors are not failures of the policy)."""
        return self.error is None and (self.collided or self.off_road)

    def to_json(self) -> Dict[str, Any]:
        """A JSON-safe dict (infinite TTC becomes ``None``)."""
        data = asdict(self)
        data["min_ttc"] = None if not math.isfinite(self.min_ttc) else self.min_ttc
        data["extra"] = {key: data.pop(key) for key in _IN_EXTRA}
        data["failed"] = self.failed
        return data

    def to_record(self) -> EpisodeOutcome:
        """The JSON form (:meth:`to_json`) as the typed record an episode record holds as its ``result``; its
        :meth:`~scenario_bank.records.JsonRecord.to_dict` is :meth:`to_json`, key for key."""
        return EpisodeOutcome.from_dict(self.to_json())

    @classmethod
    def from_json(cls, data: Dict[str, Any]) -> "EpisodeResult":
        """Inverse of :meth:`to_json`."""
        data = {k: v for k, v in data.items() if k != "failed"}
        data["min_ttc"] = math.inf if data.get("min_ttc") is None else float(data["min_ttc"])
        extra = data.pop("extra", None) or {}
        return cls(**data, **{key: extra.get(key) for key in _IN_EXTRA})


_IN_EXTRA = ("min_ttc_time", "min_ttc_with")
"""The fields of :class:`EpisodeResult` its JSON form holds in its ``extra`` object (as results were first written)."""


def trajectory_hash(trace) -> str:
    """SHA-256 over a trace's actions and every actor state at every step (full float precision)."""
    payload = json.dumps({"actions": trace.actions, "states": trace.states}, sort_keys=True,
                         separators=(",", ":"), default=str)
    return hashlib.sha256(payload.encode("utf-8")).hexdigest()


def make_eval_env(scenarios: Optional[Sequence[str]] = None, config: Optional[Dict[str, Any]] = None,
                  bank_dir: Optional[str] = None, render_mode: Optional[str] = None) -> gym.Env:
    """A DV2S-v0 env over ``scenarios`` (the whole bank when ``None``) for evaluation."""
    from envs.dv2s_env import DV2SEnv

    return DV2SEnv(scenario=list(scenarios) if scenarios else None, config=config, render_mode=render_mode,
                   bank_dir=bank_dir)


def run_episode(env: gym.Env, policy: Policy, scenario: str, seed: int, deterministic: bool = True,
                frames: Optional[List[np.ndarray]] = None,
                params: Optional[Dict[str, Any]] = None) -> Tuple[EpisodeResult, Any]:
    """Run ``policy`` (bound to ``env``) for one episode of ``scenario`` with ``seed``.

    Returns the result and the episode's :class:`~envs.trace.EpisodeTrace`. When
    ``frames`` is a list, rendered frames are appended to it (the env needs a render mode).
    ``params`` fixes the script's random global parameters (failure mining's scene features).
    """
    base = env.unwrapped
    options: Dict[str, Any] = {"scenario": scenario}
    if params:
        options["params"] = dict(params)
    observation, info = env.reset(seed=int(seed), options=options)
    policy.reset(0)
    if isinstance(policy, Policy):  # a stochastic policy acts alike on the same episode, whatever ran before
        policy.seed(int(seed))
    total, speeds, steps = 0.0, [], 0
    start = np.array(base.vehicle.position, dtype=float)  # a copy: highway-env moves it in place
    travelled = 0.0
    last = start
    if frames is not None:
        frames.append(env.render())
    while True:
        action = policy.act(np.asarray(observation)[None], deterministic=deterministic)[0]
        observation, reward, terminated, truncated, info = env.step(action)
        total += float(reward)
        steps += 1
        speeds.append(float(info["speed"]))
        here = np.array(base.vehicle.position, dtype=float)
        travelled += float(np.linalg.norm(here - last))
        last = here
        if frames is not None:
            frames.append(env.render())
        if terminated or truncated:
            break
    trace = base.trace
    collided = bool(info["crashed"] or info["collisions"])
    off_road = bool(info["off_road"])
    result = EpisodeResult(
        scenario=str(info["scenario"]), seed=int(seed), scene_seed=int(info["scene_seed"]),
        params=_json_safe(info["params"]), collided=collided, collisions=list(info["collisions"]),
        off_road=off_road, success=not collided and not off_road and travelled >= SUCCESS_MIN_DISTANCE,
        min_ttc=float(info["min_ttc"]), mean_speed=float(np.mean(speeds)) if speeds else 0.0,
        distance=travelled, episode_return=total, steps=steps, trajectory_hash=trajectory_hash(trace),
        min_ttc_time=info.get("min_ttc_time"), min_ttc_with=info.get("min_ttc_with"),
    )
    return result, trace


def evaluate(policy: Any, episodes: Iterable[Tuple[str, int]], config: Optional[Dict[str, Any]] = None,
             bank_dir: Optional[str] = None, deterministic: bool = True) -> List[EpisodeResult]:
    """Run ``policy`` (a :class:`Policy` or a spec) over ``(scenario, seed)`` pairs in this process."""
    episodes = list(episodes)
    scenarios = sorted({scenario for scenario, _ in episodes})
    env = make_eval_env(scenarios, config=config, bank_dir=bank_dir)
    try:
        policy = load_policy(policy)
        policy.bind([env])
        return [run_episode(env, policy, scenario, seed, deterministic)[0] for scenario, seed in episodes]
    finally:
        env.close()


def _json_safe(value: Any) -> Any:
    return json.loads(json.dumps(value, default=str))
