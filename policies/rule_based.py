"""Rule-based ego drivers: baselines that need no training."""

from __future__ import annotations

import math
from typing import Any, Optional, Tuple

import numpy as np

from envs.safety_metrics import time_to_collision

__all__ = ["CautiousDriver"]

# highway-env DiscreteMetaAction indices
LANE_LEFT, IDLE, LANE_RIGHT, FASTER, SLOWER = 0, 1, 2, 3, 4


class CautiousDriver:
    """Keep lane, hold a cruise speed, slow down whenever something closes in.

    Reads the simulator state (privileged), so it works on any scenario without
    training; the SB3-style :meth:`predict` makes it usable wherever a trained
    policy is. Needs ``DiscreteMetaAction``.

    Args:
        env: the DV2S env (wrapped or not) this driver controls.
        cruise_speed: speed to hold on a free road [m/s]; ``None`` keeps the speed
            the scenario gave the ego at the start of the episode.
        ttc_brake: slow down when time-to-collision falls below this [s].
        headway: slow down when the gap ahead is shorter than this many seconds of travel.
    """

    def __init__(
        self, env, cruise_speed: Optional[float] = None, ttc_brake: float = 4.0, headway: float = 1.5
    ) -> None:
        self.env = env
        self.cruise_speed = cruise_speed
        self.ttc_brake = ttc_brake
        self.headway = headway
        self._cruise: Optional[float] = None
        action_type = env.unwrapped.config["action"]["type"]
        if action_type != "DiscreteMetaAction":
            raise ValueError(f"CautiousDriver drives with DiscreteMetaAction, not {action_type}")

    def act(self) -> int:
        """The next action for the current state of the env."""
        base = self.env.unwrapped
        ego = base.vehicle
        others = base.road.vehicles + base.road.objects
        if base.steps == 0 or self._cruise is None:
            self._cruise = self.cruise_speed if self.cruise_speed is not None else max(ego.speed, 5.0)
        ttc, _ = time_to_collision(ego, others, horizon=10.0, ahead_only=True)
        gap = self._gap_ahead(ego, others)
        if ttc < self.ttc_brake or gap < max(6.0, self.headway * ego.speed):
            return SLOWER
        if ego.speed < self._cruise - 2.0:
            return FASTER
        if ego.speed > self._cruise + 2.0:
            return SLOWER
        return IDLE

    @staticmethod
    def _gap_ahead(ego, others) -> float:
        heading = np.array([math.cos(ego.heading), math.sin(ego.heading)])
        best = math.inf
        for other in others:
            if other is ego:
                continue
            rel = np.asarray(other.position) - ego.position
            ahead = float(rel @ heading)
            lateral = abs(float(rel[0] * heading[1] - rel[1] * heading[0]))
            if ahead > 0 and lateral < (ego.WIDTH + other.WIDTH) / 2 + 0.5:
                best = min(best, ahead - (ego.LENGTH + other.LENGTH) / 2)
        return best

    def predict(
        self, observation: Any, state: Optional[Any] = None, episode_start: Optional[Any] = None,
        deterministic: bool = True,
    ) -> Tuple[np.ndarray, Optional[Any]]:
        """SB3-compatible: ``(action, state)`` for the env's current state."""
        return np.array(self.act()), state

    def __call__(self, observation: Any = None, info: Optional[dict] = None) -> int:
        return self.act()
