"""Probe ego drivers: egos that drive unlike traffic on purpose, to check that a scenario's actors adapt to the ego.

A bank scenario should play its story whatever the ego does within reason; these drivers push the
ego's timing or lane to the edges of that: one hangs back, one rushes, one speeds up mid-episode,
one weaves between lanes. They read the simulator state (:class:`policies.state_driver.StateDriver`)
and drive with highway-env's ``DiscreteMetaAction`` (target speeds 0, 5, ... 30 m/s).
"""

from __future__ import annotations

from typing import Optional

from policies.baselines import IDMEgo
from policies.state_driver import FASTER, IDLE, LANE_LEFT, LANE_RIGHT, StateDriver

__all__ = ["HangbackEgo", "RushEgo", "SurgeEgo", "WeaveEgo"]


def _seconds(env) -> float:
    """Simulated time of the env's current step [s]."""
    return float(env.unwrapped.time)


class HangbackEgo(IDMEgo):
    """Drives well below the traffic speed and keeps a long gap; never changes lanes.

    An :class:`~policies.baselines.IDMEgo` whose desired speed is 60% of the ego's speed at the
    start of the episode (at least 3 m/s), with a 3 s time headway and a 10 m minimum gap: it
    slows down from the first step and follows anything ahead of it in its lane from far back.
    """

    SPEED_SHARE = 0.6

    def __init__(self, env) -> None:
        super().__init__(env, time_headway=3.0, min_gap=10.0)

    def acceleration(self) -> float:
        """The IDM acceleration towards 60% of the start speed [m/s^2]."""
        base = self.env.unwrapped
        if base.steps == 0 or self.desired_speed is None:
            self.desired_speed = max(self.SPEED_SHARE * float(base.vehicle.speed), 3.0)
            self._v0 = self.desired_speed
        return super().acceleration()


class RushEgo(StateDriver):
    """Accelerates as hard as the action set allows to its top speed, whatever is ahead; never changes lanes.

    Its top speed is 10 m/s above its start speed (at most 30 m/s, the top of the speed grid): ``FASTER``
    on every policy step from the first one until its target speed reaches it, then ``IDLE``.
    """

    RISE = 10.0

    def __init__(self, env) -> None:
        super().__init__(env)
        self._top: Optional[float] = None

    def act(self) -> int:
        """``FASTER`` while the target speed is under the top speed, else ``IDLE``."""
        vehicle = self.env.unwrapped.vehicle
        if self._top is None:
            self._top = min(30.0, float(vehicle.speed) + self.RISE)
        return FASTER if float(vehicle.target_speed) < self._top - 1e-6 else IDLE


class SurgeEgo(StateDriver):
    """Holds its start speed, then speeds up mid-episode; never changes lanes.

    ``IDLE`` until ``start_s`` (3 s), then ``FASTER`` on ``steps`` (2) consecutive policy steps,
    which raises its target speed by two 5 m/s steps of the speed grid (at most 30 m/s), then
    ``IDLE`` for the rest of the episode.
    """

    def __init__(self, env, start_s: float = 3.0, steps: int = 2) -> None:
        super().__init__(env)
        self.start_s, self.steps = start_s, steps
        self._done = 0

    def act(self) -> int:
        """``FASTER`` on the first ``steps`` policy steps from ``start_s`` on, else ``IDLE``."""
        if _seconds(self.env) >= self.start_s and self._done < self.steps:
            self._done += 1
            return FASTER
        return IDLE


class WeaveEgo(StateDriver):
    """Changes lanes back and forth at its start speed.

    At 1 s, then every ``period_s`` (3 s), it asks for a lane change, alternating the side:
    the first towards the left; when the road has no lane on the asked side (highway-env leaves
    the target lane unchanged) it asks the other side on the next step. ``IDLE`` otherwise.
    """

    def __init__(self, env, first_s: float = 1.0, period_s: float = 3.0) -> None:
        super().__init__(env)
        self.first_s, self.period_s = first_s, period_s
        self._side = LANE_LEFT
        self._next_s = first_s
        self._asked: Optional[tuple] = None  # target lane when the last change was asked
        self._retried = False

    def act(self) -> int:
        """``LANE_LEFT`` or ``LANE_RIGHT`` at the weave times, else ``IDLE``."""
        vehicle = self.env.unwrapped.vehicle
        target = getattr(vehicle, "target_lane_index", None)
        if self._asked is not None:
            refused = target == self._asked
            self._asked = None
            self._side = LANE_RIGHT if self._side == LANE_LEFT else LANE_LEFT
            if refused and not self._retried:  # no lane on that side: ask the other side now
                self._asked, self._retried = target, True
                return self._side
        self._retried = False
        if _seconds(self.env) + 1e-9 >= self._next_s:
            self._next_s += self.period_s
            self._asked = target
            return self._side
        return IDLE
