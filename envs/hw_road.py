"""A highway-env ``Road`` that reports who collided with whom.

highway-env marks both parties of a collision as ``crashed`` but does not say
with which object. Episodes here must report collisions by actor, so the
collision pass is done here, with a vectorised broad phase (all pairwise centre
distances at once), then a cheap separating-axis test that drops pairs clearly
apart (by more than :data:`SEPARATION_MARGIN`), and highway-env's own exact
polygon test on the pairs left. Dropped pairs are exactly those highway-env
would find neither intersecting nor about to intersect, so the outcome is the same.
"""

from __future__ import annotations

import math
from typing import List, Optional, Tuple

import numpy as np
from highway_env import utils
from highway_env.road.road import Road
from highway_env.vehicle.objects import Obstacle, RoadObject

__all__ = ["EventRoad", "clearly_apart"]

SEPARATION_MARGIN = 1e-6
"""Gap [m] on a separating axis above which a pair is skipped without highway-env's test
(far above the rounding differences between the two computations)."""


_PYTHON_BROAD_PHASE = 16
"""Up to this many objects the broad phase is a plain Python double loop (cheaper than NumPy)."""


def _is_plain_box(obj) -> bool:
    cls = type(obj)
    return cls.polygon is RoadObject.polygon and cls._is_colliding is RoadObject._is_colliding


def _shape(obj, dt: float, shapes: dict):
    """``(polygon, displacement)`` of ``obj`` in this collision pass (nothing moves during a pass)."""
    shape = shapes.get(id(obj))
    if shape is None:
        shape = shapes[id(obj)] = (obj.polygon(), obj.velocity * dt)
    return shape


def _is_colliding(a, b, dt: float, shapes: dict):
    """highway-env's ``RoadObject._is_colliding(a, b, dt)``, with each polygon built once per pass."""
    if np.linalg.norm(b.position - a.position) > (a.diagonal + b.diagonal) / 2 + a.speed * dt:
        return False, False, np.zeros(2)
    (poly_a, move_a), (poly_b, move_b) = _shape(a, dt, shapes), _shape(b, dt, shapes)
    return utils.are_polygons_intersecting(poly_a, poly_b, move_a, move_b)


def clearly_apart(a: RoadObject, b: RoadObject, dt: float) -> bool:
    """True when ``a`` and ``b`` neither overlap nor will within ``dt``, by a margin.

    A separating-axis test on the two boxes (``a`` swept by the relative
    displacement over ``dt``, as in highway-env's ``are_polygons_intersecting``).
    False means "maybe": the caller runs highway-env's exact test.
    """
    if not (_is_plain_box(a) and _is_plain_box(b)):
        return False
    ax, ay = float(a.position[0]), float(a.position[1])
    bx, by = float(b.position[0]), float(b.position[1])
    ca, sa = math.cos(a.heading), math.sin(a.heading)
    cb, sb = math.cos(b.heading), math.sin(b.heading)
    la, wa, lb, wb = a.LENGTH / 2, a.WIDTH / 2, b.LENGTH / 2, b.WIDTH / 2
    dx = (a.speed * ca - b.speed * cb) * dt
    dy = (a.speed * sa - b.speed * sb) * dt
    for ux, uy in ((ca, sa), (-sa, ca), (cb, sb), (-sb, cb)):
        ra = la * abs(ca * ux + sa * uy) + wa * abs(-sa * ux + ca * uy)
        rb = lb * abs(cb * ux + sb * uy) + wb * abs(-sb * ux + cb * uy)
        centre_a = ax * ux + ay * uy
        centre_b = bx * ux + by * uy
        sweep = dx * ux + dy * uy
        low_a = centre_a - ra + min(sweep, 0.0)
        high_a = centre_a + ra + max(sweep, 0.0)
        if max(centre_b - rb - high_a, low_a - (centre_b + rb)) > SEPARATION_MARGIN:
            return True
    return False


class EventRoad(Road):
    """Road whose :meth:`step` records the colliding pairs of each step."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.new_collisions: List[Tuple[RoadObject, RoadObject]] = []

    def step(self, dt: float) -> None:
        """Advance every vehicle by ``dt`` then resolve collisions, recording pairs."""
        for vehicle in self.vehicles:
            vehicle.step(dt)
        self.new_collisions = []
        movers = self.vehicles
        everything = movers + self.objects
        n_movers, n = len(movers), len(everything)
        if n_movers == 0 or n < 2:
            return
        shapes: dict = {}
        for i, j in self._candidate_pairs(everything, n_movers, dt):
            self._collide(everything[i], everything[j], dt, shapes)

    @staticmethod
    def _candidate_pairs(everything, n_movers: int, dt: float):
        """Pairs ``(i, j)``, ``i < j``, ``i`` a mover, whose reach circles meet, in row-major order.

        A superset of the pairs highway-env's own spherical pre-check lets through
        (the margin absorbs rounding); the exact tests decide.
        """
        n = len(everything)
        if n <= _PYTHON_BROAD_PHASE:
            xs = [float(o.position[0]) for o in everything]
            ys = [float(o.position[1]) for o in everything]
            reach = [o.diagonal / 2.0 + abs(o.speed) * dt for o in everything]
            return [
                (i, j)
                for i in range(n_movers)
                for j in range(i + 1, n)
                if math.hypot(xs[i] - xs[j], ys[i] - ys[j]) <= reach[i] + reach[j] + SEPARATION_MARGIN
            ]
        pos = np.array([o.position for o in everything])
        reach = np.array([o.diagonal / 2.0 + abs(o.speed) * dt for o in everything])
        delta = pos[:n_movers, None, :] - pos[None, :, :]
        dist = np.sqrt(np.einsum("ijk,ijk->ij", delta, delta))
        close = dist <= reach[:n_movers, None] + reach[None, :] + SEPARATION_MARGIN
        close[np.tril_indices(n_movers, 0, n)] = False
        return zip(*np.nonzero(close))

    def _collide(self, a: RoadObject, b: RoadObject, dt: float, shapes: Optional[dict] = None) -> None:
        if not (a.check_collisions or b.check_collisions):
            return
        if not (a.collidable and b.collidable):
            return
        if clearly_apart(a, b, dt):
            return
        if shapes is not None and _is_plain_box(a) and _is_plain_box(b):
            intersecting, will_intersect, transition = _is_colliding(a, b, dt, shapes)
        else:
            intersecting, will_intersect, transition = a._is_colliding(b, dt)
        both_solid = a.solid and b.solid
        if will_intersect and both_solid:
            if isinstance(b, Obstacle):
                a.impact = transition
            elif isinstance(a, Obstacle):
                b.impact = transition
            else:
                a.impact = transition / 2
                b.impact = -transition / 2
        if intersecting:
            if both_solid:
                a.crashed = b.crashed = True
            if not a.solid:
                a.hit = True
            if not b.solid:
                b.hit = True
        # highway-env separates solid bodies one step before they would overlap
        # (``impact``) and marks them crashed then; that is the collision.
        if intersecting or (will_intersect and both_solid):
            self.new_collisions.append((a, b))
