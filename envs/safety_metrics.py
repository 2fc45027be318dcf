"""Safety measures computed on highway-env state: time-to-collision."""

from __future__ import annotations

import math
from typing import Iterable, Tuple

import numpy as np

__all__ = ["time_to_collision"]


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
    p = pos @ rot.T
    v = vel @ rot.T
    if ahead_only:
        keep = p[:, 0] > 0
        if not keep.any():
            return math.inf, ""
        others = [o for o, k in zip(others, keep) if k]
        p, v = p[keep], v[keep]
    half_l = np.array([(o.LENGTH + ego.LENGTH) / 2 for o in others])
    half_w = np.array([(o.WIDTH + ego.WIDTH) / 2 for o in others])
    enter = np.zeros(len(others))
    leave = np.full(len(others), np.inf)
    for axis, half in ((0, half_l), (1, half_w)):
        pa, va = p[:, axis], v[:, axis]
        moving = np.abs(va) > 1e-9
        with np.errstate(divide="ignore", invalid="ignore"):
            t1 = np.where(moving, (-half - pa) / va, -np.inf)
            t2 = np.where(moving, (half - pa) / va, np.inf)
        lo, hi = np.minimum(t1, t2), np.maximum(t1, t2)
        inside = np.abs(pa) <= half
        lo = np.where(moving, lo, np.where(inside, -np.inf, np.inf))
        hi = np.where(moving, hi, np.where(inside, np.inf, -np.inf))
        enter = np.maximum(enter, lo)
        leave = np.minimum(leave, hi)
    hit = (enter <= leave) & (leave >= 0) & (enter <= horizon)
    if not hit.any():
        return math.inf, ""
    times = np.where(hit, np.maximum(enter, 0.0), np.inf)
    i = int(np.argmin(times))
    return float(times[i]), getattr(others[i], "name", type(others[i]).__name__)
