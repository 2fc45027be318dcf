"""``novelty-bandit``: spread the budget over the scenarios that keep producing failures unlike earlier ones.

Where the cross-entropy sampler goes wrong (bench/RESULTS.md, ``--part breadth``): it moves probability to
the scenarios and parameter buckets of the first failures and never moves it back on a pass, so a policy
that fails in many scenarios is mined in a few of them, and VerifAI's parameter buckets collapse along
parameters that do not matter. For breadth the budget has to go where *new* failures still come from, and
every scenario has to keep a chance.

:class:`NoveltyBanditSampler` (a VerifAI ``FeatureSampler``) draws each scene in two steps:

- **the scenario**: with probability ``explore`` uniformly over all scenarios (a defensive mixture, as in
  D2RL's defensive importance sampling: no scenario's chance ever falls below ``explore / S``, so importance
  weights stay below ``1 / explore``); otherwise the scenario with the highest estimated rate of new
  failures, ``(new_s + a) / (drawn_s + a + b)`` (a Beta(``a``, ``b``) prior; ties drawn uniformly). ``drawn_s``
  counts scenes drawn, also those not fed back yet, so the scenes drawn ahead of the feedback (the miner's
  window) spread over the best scenarios instead of piling onto one; an untried scenario starts at
  ``a / (a + b)`` (2/3 with the defaults), above a scenario whose one scene passed (1/2), and one that stops
  yielding new failures falls back behind the others. Until every scenario has had ``cover`` scenes (default 1)
  the non-uniform share goes to the scenarios still short of them instead (uniformly): without it a scenario whose
  first scenes failed (score 3/4 and up) is drawn again and again before the untried ones get a scene, and on a
  bank of 32 scenarios and a budget of 60 that costs more distinct failures than it finds;
- **the parameters**: uniformly over the scenario's own unit box (the scenario's own distribution).

Both steps have a density known at the moment of the draw (:func:`~dv2s_gym.mining.sampling.samplers.proposal_density`:
``explore / S + (1 - explore) / ties`` for a best scenario, ``explore / S`` for the others; 1 for the
parameters), which each episode record keeps, so :mod:`dv2s_gym.mining.sampling.rate` gives an unbiased failure-rate
estimate under the scenarios' own distributions.

What it learns from (``state-novelty`` feedback, :func:`dv2s_gym.mining.miner._feedback`): a failure counts as
new when its failure-state descriptor (:mod:`dv2s_gym.mining.failure_state`: ego speed and its change, the
ego's sideways motion, time of the failure, the position, relative speed and heading of the actor involved)
is farther than a fixed radius from every earlier failure's in that scenario; a repeat is fed as an easy
scene. That is novelty search over where on the road the failure happened. It is not what the breadth bench
scores (behaviour clusters: scenario, failure class, actor kind and manoeuvre labels, ego manoeuvre label;
(scenario, failure type) pairs): no class, kind or manoeuvre label, and no failure type, reaches the sampler.
"""

from __future__ import annotations

from typing import Any, List, Sequence, Tuple

import numpy as np
from verifai.samplers.feature_sampler import FeatureSampler

__all__ = ["NoveltyBanditSampler", "NOVELTY_DEFAULTS"]

NOVELTY_DEFAULTS = {"explore": 0.2, "prior_new": 2.0, "prior_old": 1.0, "cover": 1}
"""``explore``: the uniform share of the mixture; ``prior_new``, ``prior_old``: ``a`` and ``b`` of the Beta prior
of each scenario's rate of new failures; ``cover``: scenes of every scenario drawn before the scores rank the
scenarios (0: the scores rank from the first draw) (module docstring)."""


class NoveltyBanditSampler(FeatureSampler):
    """Scenario by estimated rate of new failures mixed with uniform, parameters uniform (module docstring).

    Args:
        space: the VerifAI ``FeatureSpace`` of the mining space (``scenario``, ``u``).
        dimensions: each scenario's parameter count, in index order.
        explore: probability of drawing the scenario uniformly (in ``(0, 1]``).
        prior_new, prior_old: the Beta prior ``(a, b)`` of each scenario's rate of new failures.
        thres: an outcome below it is a new failure (the miner feeds repeats as easy scenes).

    Build it with the generators seeded; draw with ``getSample`` and feed with ``update``.
    """

    def __init__(self, space, dimensions: Sequence[int], explore: float = 0.2, prior_new: float = 2.0,
                 prior_old: float = 1.0, thres: float = 0.0, cover: int = 0) -> None:
        super().__init__(space)
        self.dimensions = [int(d) for d in dimensions]
        self.width = max(self.dimensions + [1])
        self.explore, self.prior_new, self.prior_old = float(explore), float(prior_new), float(prior_old)
        self.thres = float(thres)
        self.cover = int(cover)
        count = len(self.dimensions)
        self.drawn = np.zeros(count, dtype=int)
        """Scenes drawn per scenario (fed or not)."""
        self.new = np.zeros(count, dtype=int)
        """New failures fed per scenario."""
        self.last_probabilities: List[float] = [1.0 / count] * count
        """The scenario distribution the last scene was drawn from."""

    def scores(self) -> np.ndarray:
        """Each scenario's estimated rate of new failures (the posterior mean)."""
        return (self.new + self.prior_new) / (self.drawn + self.prior_new + self.prior_old)

    def best(self) -> np.ndarray:
        """The scenarios the non-uniform share goes to: those drawn fewer than ``cover`` times while any is, else
        the best-scoring ones."""
        short = np.flatnonzero(self.drawn < getattr(self, "cover", 0))  # a checkpoint from before cover: 0
        if len(short):
            return short
        scores = self.scores()
        return np.flatnonzero(scores >= scores.max() - 1e-12)

    def probabilities(self) -> List[float]:
        """The distribution the next scenario is drawn from: ``explore`` uniform, the rest on :meth:`best`."""
        count = len(self.dimensions)
        best = self.best()
        share = (1.0 - self.explore) / len(best)
        row = [self.explore / count] * count
        for index in best:
            row[int(index)] += share
        return row

    def getSample(self) -> Tuple[Any, Any]:
        """The next ``(point, info)``; ``info`` is the scenario index."""
        count = len(self.dimensions)
        row = self.probabilities()
        if np.random.random() < self.explore:
            index = int(np.random.randint(count))
        else:
            best = self.best()
            index = int(best[np.random.randint(len(best))])
        self.last_probabilities = row
        self.drawn[index] += 1
        own = tuple(float(x) for x in np.random.random(self.dimensions[index]))
        u = own + (0.5,) * (self.width - self.dimensions[index])
        return self.space.makePoint(scenario=(index,), u=u), index

    def update(self, sample, info, rho) -> None:
        """Count a new failure (``rho`` below ``thres``) for the scene's scenario."""
        if rho is not None and rho < self.thres:
            self.new[int(info)] += 1
