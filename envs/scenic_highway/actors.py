"""highway-env objects that stand in for Scenic agents.

highway-env knows vehicles that follow its own controllers and static obstacles.
Scenic agents need three more things: vehicles driven by low-level controls
(throttle, brake, steering) computed by Scenic behaviours, pedestrians that walk
in a direction at a speed, and static props of any size. They live here, in
highway-env's frame (see :mod:`envs.coordinates`).
"""

from __future__ import annotations

import math
from typing import Optional, Sequence

import numpy as np
from highway_env.vehicle.kinematics import Vehicle
from highway_env.vehicle.objects import Obstacle

__all__ = ["ScenicVehicle", "Pedestrian", "Prop", "MAX_ACCELERATION", "MAX_BRAKING"]

MAX_ACCELERATION = 5.0
"""Acceleration at full throttle [m/s²]."""
MAX_BRAKING = 8.0
"""Deceleration at full brake [m/s²]."""
MAX_STEERING_ANGLE = math.radians(70)
"""Front-wheel angle at full steer [rad] (CARLA's cars steer up to about 70 degrees)."""


def _clip(value: float, low: float, high: float) -> float:
    """``np.clip`` for one float (a NumPy call costs more than the controls it clips)."""
    return min(max(value, low), high)


class ScenicVehicle(Vehicle):
    """A vehicle whose low-level controls are set by a Scenic behaviour.

    Scenic's driving-domain actions write throttle/brake/steer (each in ``[0, 1]``
    or ``[-1, 1]``), or set the velocity outright. They are held until the next
    Scenic time step and integrated by highway-env's bicycle model.
    """

    def __init__(
        self,
        road,
        position: Sequence[float],
        heading: float = 0.0,
        speed: float = 0.0,
        *,
        length: float = 4.5,
        width: float = 2.0,
        name: str = "",
    ) -> None:
        self.LENGTH = float(length)
        self.WIDTH = float(width)
        super().__init__(road, position, heading, speed)
        self.name = name
        self.throttle = 0.0
        self.brake = 0.0
        self.steer = 0.0
        self.hand_brake = False
        self.reverse = False
        self._hold_speed = False

    def set_controls(
        self,
        throttle: float,
        brake: float,
        steer: float,
        hand_brake: bool = False,
        reverse: bool = False,
    ) -> None:
        """Store Scenic controls; they take effect at the next :meth:`step`."""
        self.throttle = _clip(float(throttle), 0.0, 1.0)
        self.brake = _clip(float(brake), 0.0, 1.0)
        self.steer = _clip(float(steer), -1.0, 1.0)
        self.hand_brake = bool(hand_brake)
        self.reverse = bool(reverse)
        self._hold_speed = False

    def set_velocity(self, vx: float, vy: float) -> None:
        """Set speed from a velocity vector (highway-env frame), keeping the heading."""
        v = np.array([vx, vy], dtype=float)
        self.speed = float(np.dot(v, self.direction))
        self.throttle = self.brake = 0.0
        self._hold_speed = True

    def act(self, action: Optional[dict] = None) -> None:
        if action:
            self.action = action
            return
        if self._hold_speed:
            self.action = {"acceleration": 0.0, "steering": self._front_wheel_angle()}
            return
        braking = MAX_BRAKING * max(self.brake, 1.0 if self.hand_brake else 0.0)
        if braking > 0:
            acceleration = -math.copysign(braking, self.speed) if self.speed else 0.0
        else:
            acceleration = MAX_ACCELERATION * self.throttle * (-1.0 if self.reverse else 1.0)
        self.action = {"acceleration": acceleration, "steering": self._front_wheel_angle()}

    def _front_wheel_angle(self) -> float:
        # Scenic's positive steer turns right (clockwise seen from above), which is a
        # growing highway-env heading because y is drawn downward.
        return self.steer * MAX_STEERING_ANGLE

    def step(self, dt: float) -> None:
        speed_before = self.speed
        super().step(dt)
        # Brakes stop a car; they never push it backwards.
        if self.action["acceleration"] != 0.0 and speed_before * self.speed < 0 and (
            self.brake > 0 or self.hand_brake
        ):
            self.speed = 0.0


class Pedestrian(Vehicle):
    """A walking person: moves at a set speed along a set walking direction."""

    LENGTH = 0.75
    WIDTH = 0.75
    MAX_SPEED = 5.0
    MIN_SPEED = 0.0

    def __init__(
        self,
        road,
        position: Sequence[float],
        heading: float = 0.0,
        speed: float = 0.0,
        *,
        length: float = 0.75,
        width: float = 0.75,
        name: str = "",
    ) -> None:
        self.LENGTH = float(length)
        self.WIDTH = float(width)
        super().__init__(road, position, heading, speed)
        self.name = name
        self.walking_heading: Optional[float] = None

    def set_walking(self, heading: Optional[float], speed: Optional[float]) -> None:
        """Set the walking direction (highway-env heading) and/or speed; ``None`` keeps it."""
        if heading is not None:
            self.walking_heading = float(heading)
            self.heading = float(heading)
        if speed is not None:
            self.speed = float(max(0.0, speed))

    def set_velocity(self, vx: float, vy: float) -> None:
        """Walk with this velocity (highway-env frame)."""
        speed = math.hypot(vx, vy)
        self.set_walking(math.atan2(vy, vx) if speed > 1e-9 else None, speed)

    def act(self, action: Optional[dict] = None) -> None:
        pass

    def step(self, dt: float) -> None:
        if self.crashed:
            self.speed = 0.0
        self.position = self.position + self.speed * self.direction * dt
        if self.impact is not None:
            self.position += self.impact
            self.crashed = True
            self.impact = None
        self.on_state_update()


class Prop(Obstacle):
    """A static object (box, barrier, debris, parked obstacle) of any size."""

    def __init__(
        self,
        road,
        position: Sequence[float],
        heading: float = 0.0,
        *,
        length: float = 1.0,
        width: float = 1.0,
        name: str = "",
    ) -> None:
        self.LENGTH = float(length)
        self.WIDTH = float(width)
        super().__init__(road, position, heading, 0.0)
        self.name = name
