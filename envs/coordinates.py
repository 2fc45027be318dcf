"""Coordinate conventions between Scenic and highway-env.

Scenic (driving domain, 2D mode): right-handed map frame, ``x`` east, ``y`` north,
heading ``0`` points along ``+y`` and grows counter-clockwise.

highway-env: ``x`` right, ``y`` drawn *downward*; heading measured from ``+x``
toward ``+y`` (clockwise on screen).

We map a Scenic point ``(x, y)`` to highway-env ``(x, -y)`` so that a map keeps
its handedness on screen (north is up). Every module that crosses the boundary
goes through these functions; nothing else flips signs.
"""

from __future__ import annotations

import math
from typing import Tuple

import numpy as np

__all__ = [
    "wrap_angle",
    "scenic_to_hw_position",
    "hw_to_scenic_position",
    "scenic_to_hw_heading",
    "hw_to_scenic_heading",
    "scenic_to_hw_velocity",
    "hw_to_scenic_velocity",
    "scenic_heading_vector",
    "hw_heading_vector",
]


def wrap_angle(angle: float) -> float:
    """Wrap an angle to ``[-pi, pi)``."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


def scenic_to_hw_position(x: float, y: float) -> np.ndarray:
    """Scenic map point to a highway-env world point."""
    return np.array([float(x), -float(y)])


def hw_to_scenic_position(x: float, y: float) -> Tuple[float, float]:
    """highway-env world point to a Scenic map point."""
    return float(x), -float(y)


def scenic_to_hw_heading(heading: float) -> float:
    """Scenic heading (0 = +y, CCW) to highway-env heading (0 = +x, toward +y)."""
    return wrap_angle(-heading - math.pi / 2.0)


def hw_to_scenic_heading(heading: float) -> float:
    """highway-env heading to Scenic heading; inverse of :func:`scenic_to_hw_heading`."""
    return wrap_angle(-heading - math.pi / 2.0)


def scenic_to_hw_velocity(vx: float, vy: float) -> np.ndarray:
    """Scenic velocity vector to highway-env velocity vector."""
    return np.array([float(vx), -float(vy)])


def hw_to_scenic_velocity(vx: float, vy: float) -> Tuple[float, float]:
    """highway-env velocity vector to Scenic velocity vector."""
    return float(vx), -float(vy)


def scenic_heading_vector(heading: float) -> np.ndarray:
    """Unit vector a Scenic heading points along, in the Scenic frame."""
    return np.array([-math.sin(heading), math.cos(heading)])


def hw_heading_vector(heading: float) -> np.ndarray:
    """Unit vector a highway-env heading points along, in the highway-env frame."""
    return np.array([math.cos(heading), math.sin(heading)])
