"""Baseline ego drivers for story checks: a keep-lane ego and an IDM ego.

Both drive with highway-env's ``DiscreteMetaAction`` and never change lanes; they
share :class:`policies.rule_based.CautiousDriver`'s call interface (``act()``,
``__call__(obs, info)``, SB3-style ``predict``).
"""

from __future__ import annotations

import math
from typing import Optional, Tuple

import numpy as np

from policies.state_driver import FASTER, IDLE, SLOWER, StateDriver

__all__ = ["KeepLaneEgo", "IDMEgo"]


class KeepLaneEgo(StateDriver):
    """Holds its lane at the speed it starts with: ``IDLE`` every step, whatever happens.

    The env's ego keeps the script's start speed as its target until the policy asks for ``FASTER``
    or ``SLOWER``, so ``IDLE`` alone is constant speed, and an episode replays from its actions.
    """

    def act(self) -> int:
        """Always ``IDLE``."""
        return IDLE


class IDMEgo(StateDriver):
    """Stays in its lane; speeds up, slows down or holds from an IDM acceleration.

    The Intelligent Driver Model acceleration
    ``a = a_max * (1 - (v / v0)^4 - (s* / s)^2)`` with
    ``s* = s0 + v T + v (v - v_lead) / (2 sqrt(a_max b))`` is computed from the
    gap ``s`` to the nearest actor ahead whose centre lies within the ego's lane
    width (ego frame); above ``+threshold`` the ego asks for ``FASTER``, below
    ``-threshold`` for ``SLOWER``, else ``IDLE``.

    Args:
        env: the DV2S env (wrapped or not) this driver controls.
        desired_speed: ``v0`` [m/s]; ``None`` keeps the ego's speed at the start of the episode.
        time_headway: ``T`` [s]; min_gap: ``s0`` [m]; max_accel: ``a_max``; comfort_brake: ``b`` [m/s^2].
        threshold: acceleration [m/s^2] beyond which the ego changes its target speed.
    """

    def __init__(self, env, desired_speed: Optional[float] = None, time_headway: float = 1.5,
                 min_gap: float = 4.0, max_accel: float = 1.5, comfort_brake: float = 2.0,
                 threshold: float = 0.4) -> None:
        super().__init__(env)
        self.desired_speed = desired_speed
        self.time_headway, self.min_gap = time_headway, min_gap
        self.max_accel, self.comfort_brake, self.threshold = max_accel, comfort_brake, threshold
        self._v0: Optional[float] = None

    def acceleration(self) -> float:
        """The IDM acceleration for the current state [m/s^2]."""
        base = self.env.unwrapped
        ego = base.vehicle
        if base.steps == 0 or self._v0 is None:
            self._v0 = self.desired_speed if self.desired_speed is not None else max(ego.speed, 5.0)
        v = max(float(ego.speed), 0.0)
        gap, lead_speed = self._leader(ego, base.road.vehicles + base.road.objects)
        free = 1.0 - (v / self._v0) ** 4
        if math.isinf(gap):
            return self.max_accel * free
        desired = self.min_gap + v * self.time_headway + v * (v - lead_speed) / (
            2.0 * math.sqrt(self.max_accel * self.comfort_brake))
        return self.max_accel * (free - (max(desired, 0.0) / max(gap, 0.1)) ** 2)

    def act(self) -> int:
        """``FASTER``, ``SLOWER`` or ``IDLE`` from :meth:`acceleration`."""
        accel = self.acceleration()
        if accel > self.threshold:
            return FASTER
        if accel < -self.threshold:
            return SLOWER
        return IDLE

    @staticmethod
    def _leader(ego, others) -> Tuple[float, float]:
        """Bumper gap [m] to and speed along the ego's heading of the nearest actor ahead in its lane."""
        heading = np.array([math.cos(ego.heading), math.sin(ego.heading)])
        best, speed = math.inf, 0.0
        for other in others:
            if other is ego:
                continue
            rel = np.asarray(other.position, dtype=float) - np.asarray(ego.position, dtype=float)
            ahead = float(rel @ heading)
            lateral = abs(float(rel[0] * heading[1] - rel[1] * heading[0]))
            if ahead > 0 and lateral < 1.75 + other.WIDTH / 2:
                gap = ahead - (ego.LENGTH + other.LENGTH) / 2
                if gap < best:
                    velocity = getattr(other, "velocity", None)
                    speed = float(np.asarray(velocity) @ heading) if velocity is not None else 0.0
                    best = gap
        return best, speed
