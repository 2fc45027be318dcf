"""A highway-env ``Road`` that reports who collided with whom.

highway-env marks both parties of a collision as ``crashed`` but does not say
with which object. Episodes here must report collisions by actor, so the
collision pass is done here, with a vectorised broad phase (all pairwise centre
distances at once) before the exact polygon test on the few candidate pairs.
"""

from __future__ import annotations

from typing import List, Tuple

import numpy as np
from highway_env.road.road import Road
from highway_env.vehicle.objects import Obstacle, RoadObject

__all__ = ["EventRoad"]


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
        pos = np.array([o.position for o in everything])
        reach = np.array([o.diagonal / 2.0 + abs(o.speed) * dt for o in everything])
        delta = pos[:n_movers, None, :] - pos[None, :, :]
        dist = np.sqrt(np.einsum("ijk,ijk->ij", delta, delta))
        close = dist <= reach[:n_movers, None] + reach[None, :]
        close[np.tril_indices(n_movers, 0, n)] = False
        for i, j in zip(*np.nonzero(close)):
            self._collide(everything[i], everything[j], dt)

    def _collide(self, a: RoadObject, b: RoadObject, dt: float) -> None:
        if not (a.check_collisions or b.check_collisions):
            return
        if not (a.collidable and b.collidable):
            return
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
