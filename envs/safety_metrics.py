"""Safety measures computed on highway-env state: time-to-collision, stalls; and :class:`MonitorSettings`, the
settings the failure monitors read (the miner's, :mod:`dv2s_gym.mining.monitors`, and ``dv2s regress``'s)."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any, Iterable, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

__all__ = ["time_to_collision", "path_is_free", "first_stall_step", "total_stall_step", "FREE_PATH", "STANDING_SPEED",
           "DEFAULT_STALL_SECONDS", "DEFAULT_TTC_THRESHOLD", "MonitorSettings"]

FREE_PATH = 40.0
"""Metres ahead of the ego that must be empty for its path to count as free."""
STANDING_SPEED = 0.5
"""m/s under which a vehicle counts as standing."""
DEFAULT_STALL_SECONDS = 5.0
"""Seconds the ego must stand with a free path ahead for a stall (the miner's monitors and ``dv2s regress``)."""
DEFAULT_TTC_THRESHOLD = 1.0
"""Seconds of time-to-collision under which the miner's monitors see a ``low_ttc`` failure."""


@dataclass(frozen=True)
class MonitorSettings:
    """The failure monitors' settings: ``ttc_threshold`` [s] (a smaller time-to-collision is a ``low_ttc``
    failure) and ``stall_seconds`` (standing that long with a free path ahead is a ``stall``). The one carrier of
    these settings from a command's options (``--ttc-threshold``, ``--stall-seconds``) to the code that reads them."""

    ttc_threshold: float = DEFAULT_TTC_THRESHOLD
    stall_seconds: float = DEFAULT_STALL_SECONDS

    @classmethod
    def from_recorded(cls, values: Mapping[str, Any]) -> "MonitorSettings":
        """The settings a mapping records under their names (a run's ``settings.json``, a conversion's ``monitor``
        option); a setting absent or ``None`` there takes its default."""
        given = {field.name: float(values[field.name]) for field in fields(cls) if values.get(field.name) is not None}
        return cls(**given)

    @classmethod
    def of(cls, value: Union["MonitorSettings", Mapping[str, Any], None]) -> "MonitorSettings":
        """``value`` as settings: settings as they are, a mapping read by :meth:`from_recorded`, ``None`` the
        defaults."""
        if isinstance(value, cls):
            return value
        return cls.from_recorded(value or {})


def time_to_collision(
    ego, others: Iterable, horizon: float = 10.0, ahead_only: bool = False
) -> Tuple[float, str]:
    """Smallest time until ``ego``'s footprint overlaps another object's, at constant velocities.

    Footprints are boxes aligned with the ego's heading (exact for traffic in the
    ego's direction, conservative for crossing traffic). Returns ``(inf, "")`` when
    nothing closes in within ``horizon`` seconds, else ``(ttc, name_of_other)``.
    With ``ahead_only``, objects behind the ego's front are ignored.
    """
    others = [o for o in others if o is not ego]
    if not others:
        return math.inf, ""
    c, s = math.cos(ego.heading), math.sin(ego.heading)
    rot = np.array([[c, s], [-s, c]])  # world -> ego frame
    pos = np.array([o.position for o in others]) - ego.position
    vel = np.array([o.velocity for o in others]) - ego.velocity
    # The frame change stays in NumPy (its BLAS rounding is part of the result); the
    # interval arithmetic on a handful of objects is cheaper in plain Python.
    p = (pos @ rot.T).tolist()
    v = (vel @ rot.T).tolist()
    best, best_other = math.inf, None
    for other, (px, py), (vx, vy) in zip(others, p, v):
        if ahead_only and not px > 0:
            continue
        enter, leave = 0.0, math.inf
        for pa, va, half in ((px, vx, (other.LENGTH + ego.LENGTH) / 2), (py, vy, (other.WIDTH + ego.WIDTH) / 2)):
            if abs(va) > 1e-9:
                t1, t2 = (-half - pa) / va, (half - pa) / va
                lo, hi = min(t1, t2), max(t1, t2)
            elif abs(pa) <= half:
                lo, hi = -math.inf, math.inf
            else:
                lo, hi = math.inf, -math.inf
            enter, leave = max(enter, lo), min(leave, hi)
        if enter <= leave and leave >= 0 and enter <= horizon:
            time = max(enter, 0.0)
            if time < best or best_other is None:
                best, best_other = time, other
    if best_other is None:
        return math.inf, ""
    return float(best), getattr(best_other, "name", type(best_other).__name__)


def path_is_free(ego: Sequence[float], others: Iterable[Sequence[float]], distance: float = FREE_PATH,
                 half_width: float = 2.0) -> bool:
    """True when no other object's centre lies in the ``distance`` m long, ``2 * half_width`` m wide
    strip ahead of the ego. ``ego`` is ``[x, y, heading, ...]``, ``others`` are ``[x, y, ...]``."""
    c, s = math.cos(ego[2]), math.sin(ego[2])
    for other in others:
        dx, dy = other[0] - ego[0], other[1] - ego[1]
        ahead, lateral = dx * c + dy * s, -dx * s + dy * c
        if 0 < ahead < distance and abs(lateral) < half_width:
            return False
    return True


def first_stall_step(trace, stall_seconds: float) -> Optional[int]:
    """The step where the trace's first stall begins (the ego below ``STANDING_SPEED`` for ``stall_seconds``
    with a free path ahead, :func:`path_is_free`), or ``None``."""
    period = 1.0 / float(trace.config.get("policy_frequency", 5))
    needed = max(1, int(math.ceil(stall_seconds / period)))
    run = 0
    for step, states in enumerate(trace.states):
        ego = states.get("ego")
        if ego is None or ego[3] >= STANDING_SPEED or not path_is_free(
                ego, (state for name, state in states.items() if name != "ego")):
            run = 0
            continue
        run += 1
        if run >= needed:
            return step - needed + 1
    return None


def _standing_free(states) -> bool:
    ego = states.get("ego")
    return ego is not None and ego[3] < STANDING_SPEED and path_is_free(
        ego, (state for name, state in states.items() if name != "ego"))


def total_stall_step(trace, stall_seconds: float) -> Optional[int]:
    """The step at which the ego's *total* standing time with a free path ahead reaches ``stall_seconds``, or ``None``.

    Unlike :func:`first_stall_step` the standing need not be one unbroken stretch: a policy that stands
    4.6 s on a free road, creeps a moment and stands again is stalling just the same.
    """
    period = 1.0 / float(trace.config.get("policy_frequency", 5))
    needed = max(1, int(math.ceil(stall_seconds / period)))
    standing = 0
    for step, states in enumerate(trace.states):
        if _standing_free(states):
            standing += 1
            if standing >= needed:
                return step
    return None
