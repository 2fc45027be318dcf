"""A scenario chooser that leaves scenarios which stop yielding: VerifAI's discrete cross-entropy, non-stationary.

VerifAI's :class:`~verifai.samplers.cross_entropy.DiscreteCrossEntropySampler` moves probability towards a
scenario every time it is fed a failure (``dist <- alpha * dist``, then ``1 - alpha`` to the failing scenario)
and leaves the distribution untouched on any other outcome. Under ``novelty`` feedback
(:func:`dv2s_gym.mining.miner._feedback`: a failure in a cluster already found is fed as an easy scene) a
scenario whose cells are all found stops giving reward but keeps its probability, and nothing moves it away
until other scenarios produce new failures: an early lock-on to a scenario with few cells costs tens of episodes.

:class:`ForgetfulCrossEntropySampler` subclasses it and adds, on top of VerifAI's update (which it calls
unchanged for failures):

- **forgetting** (``forget``, in ``[0, 1)``): an outcome that is not a failure (a pass, or under novelty a
  repeat) moves the fraction ``forget`` of the drawn scenario's probability to the other scenarios, spread
  uniformly over them; 0 is VerifAI's sampler;
- **a stagnation restart** (``patience``, draws): a scenario whose last ``patience`` draws gave no failure
  (no new cluster, under novelty feedback) has its probability cut to ``floor`` (of the uniform share
  ``1 / count``, if it is above that), the excess spread uniformly over the other scenarios, and its count
  starts again; 0: no restart;
- **remaining capacity** (``capacity``, with each scenario's ``cells``): a scenario drawn ``capacity x cells``
  times or more (its parameter sampler has had the chance to visit each of its grid cells ``capacity`` times)
  is treated as exhausted: every non-failure on it cuts its probability to ``floor`` as above, so only new
  failures keep it drawn; 0: off.

Every change keeps the distribution summing to 1; the draws are VerifAI's (``getVector`` unchanged).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Optional, Sequence

import numpy as np
from verifai.samplers.cross_entropy import DiscreteCrossEntropySampler

from dv2s_gym.mining.errors import MiningError

__all__ = ["ForgetfulCrossEntropySampler", "LeaveSettings"]


@dataclass(frozen=True)
class LeaveSettings:
    """How the chooser leaves scenarios that stop yielding failures (module docstring); all off: VerifAI's sampler."""

    forget: float = 0.0
    """Fraction of the drawn index's probability moved to the others on a non-failure."""
    patience: int = 0
    """Draws of an index without a failure before its probability is cut to ``floor / count``."""
    floor: float = 0.5
    """The cut, as a fraction of the uniform share."""
    capacity: float = 0.0
    """Draws per cell of an index after which its non-failures cut it to the floor; 0: off."""

    @property
    def active(self) -> bool:
        """Whether any of forgetting, restarts or capacity is on."""
        return bool(self.forget or self.patience or self.capacity)


class ForgetfulCrossEntropySampler(DiscreteCrossEntropySampler):
    """VerifAI's discrete cross-entropy sampler over one index (the scenario) that also forgets (module docstring).

    Args:
        domain: a one-dimensional VerifAI ``DiscreteBox`` (the scenario index).
        alpha, thres: VerifAI's (a failure is ``rho < thres``; each failure multiplies the distribution by
            ``alpha`` and adds ``1 - alpha`` to the drawn index).
        leave: forgetting, stagnation restarts and capacity (:class:`LeaveSettings`).
        cells: each index's cell count, for ``leave.capacity`` (no ``cells``: capacity off).
    """

    def __init__(self, domain, alpha: float, thres: float, leave: LeaveSettings = LeaveSettings(),
                 cells: Optional[Sequence[int]] = None, dist: Optional[Any] = None) -> None:
        super().__init__(domain, alpha=alpha, thres=thres, dist=dist)
        if len(self.dist) != 1:
            raise MiningError("ForgetfulCrossEntropySampler chooses one index; give it a one-dimensional DiscreteBox")
        self.forget = float(leave.forget)
        self.patience = int(leave.patience)
        self.floor = float(leave.floor)
        self.dry = np.zeros(len(self.dist[0]), dtype=int)
        """Per index: draws fed since its last failure."""
        self.restarts = 0
        """How many stagnation restarts (and capacity cuts) happened."""
        self.capacity = float(leave.capacity)
        count = len(self.dist[0])
        self.cells = np.array(list(cells) if cells is not None else [0] * count, dtype=float)
        if len(self.cells) != count:
            raise MiningError(f"cells has {len(self.cells)} entries for {count} indices")
        self.drawn = np.zeros(count, dtype=int)
        """Per index: outcomes fed."""

    def _move_away(self, index: int, amount: float) -> None:
        row = self.dist[0]
        others = len(row) - 1
        if others <= 0 or amount <= 0.0:
            return
        row[index] -= amount
        share = amount / others
        for j in range(len(row)):
            if j != index:
                row[j] += share

    def updateVector(self, vector, info, rho) -> None:
        """VerifAI's update on a failure; otherwise forgetting and the stagnation count (module docstring)."""
        index = int(vector[0]) - int(self.domain.standardizedIntervals[0][0])
        self.drawn[index] += 1
        if rho is not None and rho < self.thres:
            self.dry[index] = 0
            super().updateVector(vector, info, rho)
            return
        row = self.dist[0]
        self._move_away(index, self.forget * float(row[index]))
        self.dry[index] += 1
        exhausted = self.capacity > 0 and self.cells[index] > 0 and self.drawn[index] >= self.capacity * self.cells[index]
        if exhausted or self.patience and self.dry[index] >= self.patience:
            self.dry[index] = 0
            cut = self.floor / len(row)
            if row[index] > cut:
                self._move_away(index, float(row[index]) - cut)
                self.restarts += 1
