"""Helpers for the Scenic simulator-interface tests: run a Scenic program in
``DV2SEnv`` and record what highway-env simulated.

Positions, headings and speeds are recorded in highway-env's frame (``y`` is the
negated Scenic ``y``; heading 0 is ``+x`` and grows clockwise on screen), as the
tests assert on highway-env state.
"""

from __future__ import annotations

import math
import textwrap
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional

import numpy as np

from envs.dv2s_env import DV2SEnv

ROOT = Path(__file__).resolve().parents[1]
TOWN01 = ROOT / "tests" / "data" / "maps" / "CARLA" / "Town01.xodr"
TOWN02 = ROOT / "tests" / "data" / "maps" / "CARLA" / "Town02.xodr"


@dataclass
class ActorState:
    x: float
    y: float
    heading: float
    speed: float
    lane_index: Any
    crashed: bool

    @property
    def position(self) -> np.ndarray:
        return np.array([self.x, self.y])


@dataclass
class Run:
    """What one episode did: per-step actor states (index 0 is after reset), infos, observations."""

    states: List[Dict[str, ActorState]] = field(default_factory=list)
    infos: List[dict] = field(default_factory=list)
    observations: List[Any] = field(default_factory=list)
    extra: List[Any] = field(default_factory=list)
    terminated: bool = False
    truncated: bool = False
    timestep: float = 0.2
    env: Any = None
    hw_kinds: Dict[str, str] = field(default_factory=dict)
    hw_sizes: Dict[str, tuple] = field(default_factory=dict)
    hw_types: Dict[str, str] = field(default_factory=dict)

    @property
    def final_info(self) -> dict:
        return self.infos[-1]

    @property
    def duration(self) -> float:
        """Simulated seconds."""
        return (len(self.states) - 1) * self.timestep

    def track(self, name: str) -> List[ActorState]:
        """States of one actor over the episode (steps where it exists); a name never seen is an error."""
        track = [step[name] for step in self.states if name in step]
        if not track:
            seen = sorted({n for step in self.states for n in step})
            raise KeyError(f"no actor named {name!r} in this run; the run has {seen}")
        return track

    def xy(self, name: str) -> np.ndarray:
        return np.array([[s.x, s.y] for s in self.track(name)])

    def speeds(self, name: str) -> np.ndarray:
        return np.array([s.speed for s in self.track(name)])

    def headings(self, name: str) -> np.ndarray:
        return np.array([s.heading for s in self.track(name)])

    def events(self, kind: Optional[str] = None) -> List[dict]:
        found = [e for info in self.infos for e in info.get("events", [])]
        return [e for e in found if kind is None or e["kind"] == kind]


def _snapshot(env) -> Dict[str, ActorState]:
    road = env.unwrapped.road
    states = {}
    for obj in list(road.vehicles) + list(road.objects):
        name = getattr(obj, "name", None)
        if not name:
            continue
        states[name] = ActorState(
            float(obj.position[0]),
            float(obj.position[1]),
            float(obj.heading),
            float(obj.speed),
            getattr(obj, "lane_index", None),
            bool(obj.crashed),
        )
    return states


def make_env(source: str, seconds: float, config: Optional[dict] = None) -> DV2SEnv:
    """An environment for a Scenic program; by default the ego runs its Scenic behaviour."""
    cfg = {
        "ego_policy": "scenic",
        "duration": seconds,
        "terminate_on_collision": False,
        "terminate_off_road": False,
    }
    cfg.update(config or {})
    return DV2SEnv(scenario=textwrap.dedent(source).strip() + "\n", config=cfg)


def run_scenario(
    source: str,
    seconds: float,
    *,
    seed: int = 0,
    config: Optional[dict] = None,
    action: Any = 1,
    observe: bool = False,
    probe: Optional[Callable[[Any], Any]] = None,
) -> Run:
    """Run ``source`` for at most ``seconds`` simulated seconds, recording every step.

    The environment is closed afterwards (two suspended simulations of the same
    compiled scenario cannot coexist), but stays available as ``run.env`` for
    read-only inspection (road network, converted map).
    """
    env = make_env(source, seconds, config)
    run = Run(env=env, timestep=1.0 / env.config["policy_frequency"])
    try:
        obs, info = env.reset(seed=seed)
        road = env.unwrapped.road
        for obj in list(road.vehicles) + list(road.objects):
            name = getattr(obj, "name", None)
            if name:
                run.hw_kinds[name] = getattr(obj, "scenic_kind", "")
                run.hw_sizes[name] = (float(obj.LENGTH), float(obj.WIDTH))
                run.hw_types[name] = type(obj).__name__
        run.states.append(_snapshot(env))
        run.infos.append(info)
        if observe:
            run.observations.append(obs)
        if probe is not None:
            run.extra.append(probe(env))
        done = False
        while not done:
            obs, _reward, terminated, truncated, info = env.step(action)
            run.states.append(_snapshot(env))
            run.infos.append(info)
            if observe:
                run.observations.append(obs)
            if probe is not None:
                run.extra.append(probe(env))
            done = terminated or truncated
        run.terminated, run.truncated = bool(terminated), bool(truncated)
    finally:
        env.close()
    return run


# --------------------------------------------------------------------------- geometry


def wrap(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


def converted_network(run_or_env):
    """The ``ConvertedNetwork`` (Scenic network + highway-env road) an episode used."""
    env = run_or_env.env if isinstance(run_or_env, Run) else run_or_env
    return env.unwrapped._converted


def lane_offset(converted, x: float, y: float, heading: float, max_heading_error: float = math.radians(60)):
    """Lateral offset [m] from the nearest lane centre going the vehicle's way, and that lane.

    Junction connecting lanes overlap, so the lane "the car is in" is the one whose
    centre is closest among those whose direction matches the vehicle's heading
    (within ``max_heading_error``). Returns ``(offset, lane_index, lane_width)``;
    ``(inf, None, None)`` when no such lane contains the point longitudinally.
    """
    best = (math.inf, None, None)
    network = converted.hw_network
    position = np.array([x, y])
    for start, ends in network.graph.items():
        for end, lanes in ends.items():
            for i, lane in enumerate(lanes):
                s, lat = lane.local_coordinates(position)
                if abs(lat) > 10 or not (-0.5 <= s <= lane.length + 0.5):
                    continue
                if abs(wrap(lane.heading_at(s) - heading)) > max_heading_error:
                    continue
                if abs(lat) < abs(best[0]):
                    best = (float(lat), (start, end, i), float(lane.width_at(s)))
    return best


def lateral_errors(run: Run, name: str = "ego") -> np.ndarray:
    """|lateral offset| from the nearest same-direction lane centre at every step."""
    converted = converted_network(run)
    return np.array([abs(lane_offset(converted, s.x, s.y, s.heading)[0]) for s in run.track(name)])


def hw_lane_of(run: Run, uid: str):
    """highway-env lane index of a Scenic lane uid in the episode's map."""
    return converted_network(run).index_of(uid)


def scenic_heading(hw_heading: float) -> float:
    """Scenic heading (0 = north, counter-clockwise) of a highway-env heading."""
    return wrap(-hw_heading - math.pi / 2)
