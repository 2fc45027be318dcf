"""A feature sampler split in two: one VerifAI sampler picks the scenario, one per scenario its parameters.

VerifAI's own feature samplers (``FeatureSampler.crossEntropySamplerFor`` and the others) run
one domain sampler over the whole mining space (:mod:`dv2s_gym.mining.sampling.space`): the scenario
index and one unit box shared by every scenario, where coordinate ``i`` is a different
parameter in each scenario. What an adaptive sampler learns about coordinate ``i`` in one
scenario then skews coordinate ``i`` in all the others, and concentrating on the buckets
where failures were found makes the sampler repeat the same region of parameter space.

:class:`ScenarioSplitSampler` (a VerifAI ``FeatureSampler``) composes VerifAI domain samplers
differently:

- the **scenario** is drawn by an adaptive VerifAI sampler over the scenario index
  (``chooser``): ``"cross-entropy"`` (``DiscreteCrossEntropySampler``, which is also the
  discrete part of VerifAI's bandit: every failure moves probability ``1 - alpha`` to its
  scenario) or ``"ucb"`` (``ContinuousMultiArmedBanditSampler`` over a one-dimensional box cut
  into one bucket per scenario: the UCB1 rule over scenarios, failure rate plus a bonus for
  scenarios tried less often) or ``"epsilon-greedy"`` (``ContinuousEpsilonGreedySampler`` over the
  same buckets: cross-entropy, but drawing uniformly instead, with probability ``epsilon`` (0.5, halved
  every 100 failures) decided again after each failure);
- the **parameters** of each scenario are drawn by that scenario's own VerifAI sampler over a
  unit box of the scenario's own dimension (``params``): ``"halton"`` (``HaltonSampler``, a
  low-discrepancy sequence that spreads the points over the box, started at a seeded
  index), ``"random"`` (``RandomSampler``), ``"bandit"`` (``ContinuousMultiArmedBanditSampler``
  with ``buckets`` per parameter) or ``"cross-entropy"`` (``ContinuousCrossEntropySampler``).

Every outcome is fed to the chooser and to the drawn scenario's parameter sampler. Points are
points of the same feature space as the other samplers (unused coordinates of ``u`` are
0.5), so the miner, its records and its checkpoints treat this sampler like any other.

One extension (an option): ``avoid`` keeps drawing a scenario's parameter sampler (up to ``avoid`` more
points) while its point falls in a cell of the cluster grid (:mod:`dv2s_gym.mining.cluster`) where that
scenario already failed (under novelty feedback: where a cluster was found), so the Halton sequence is
spent on cells not yet failing.

``dv2s mine --sampler split`` uses the cross-entropy chooser (alpha 0.9), Halton parameters, ``avoid=81``
and ``novelty`` feedback (settings chosen on tuning seeds 7-14; bench/RESULTS.md). ``avoid=0`` turns the
redraws off, the earlier preset (2.56x the distinct failure clusters of random sampling on seeds 0-2).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, List, Sequence, Tuple

import numpy as np
from verifai.samplers.feature_sampler import FeatureSampler, default_sampler_params

from dv2s_gym.mining.cluster import region_of
from verifai.features import Box, DiscreteBox
from verifai.samplers.multi_armed_bandit import ContinuousMultiArmedBanditSampler
from verifai.samplers.cross_entropy import ContinuousCrossEntropySampler, DiscreteCrossEntropySampler
from verifai.samplers.eg_sampler import ContinuousEpsilonGreedySampler
from verifai.samplers.halton import HaltonSampler
from verifai.samplers.random_sampler import RandomSampler

__all__ = ["AdaptSettings", "ScenarioSplitSampler", "CHOOSERS", "PARAM_SAMPLERS", "scenario_dimensions"]

CHOOSERS = ("cross-entropy", "ucb", "epsilon-greedy")
"""VerifAI samplers that can pick the scenario."""

PARAM_SAMPLERS = ("halton", "random", "bandit", "cross-entropy")
"""VerifAI samplers that can draw a scenario's parameters."""

_HALTON_START = 10_000
"""The Halton sequence of each scenario starts at a seeded index below this (a randomised start: two seeds
draw different points)."""


def scenario_dimensions(space) -> List[int]:
    """The parameter count of each scenario of a :class:`~dv2s_gym.mining.sampling.space.SceneSpace`, in index order."""
    return [len(space.param_ranges(name)) for name in space.scenarios]


@dataclass(frozen=True)
class AdaptSettings:
    """VerifAI's parameters of the adaptive samplers."""

    alpha: float = 0.9
    thres: float = 0.0
    """A failure is ``rho < thres``."""
    buckets: int = 3
    """Per parameter, for the ``bandit`` and ``cross-entropy`` parameter samplers."""


def _make_chooser(kind: str, count: int, adapt: AdaptSettings):
    alpha, thres = adapt.alpha, adapt.thres
    if kind == "cross-entropy":
        return DiscreteCrossEntropySampler(domain=DiscreteBox([0, count - 1]), alpha=alpha, thres=thres)
    if kind == "epsilon-greedy":
        return ContinuousEpsilonGreedySampler(domain=Box([0.0, 1.0]), alpha=alpha, thres=thres, buckets=count)

    return ContinuousMultiArmedBanditSampler(domain=Box([0.0, 1.0]), alpha=alpha, thres=thres, buckets=count)


def _make_params(kind: str, dimension: int, alpha: float, thres: float, buckets: int):
    box = Box(*[[0.0, 1.0]] * max(dimension, 1))
    if kind == "halton":
        start = int(np.random.randint(0, _HALTON_START))  # the caller seeds the generators
        params = default_sampler_params("halton")  # VerifAI's DotMap: sample_index, bases_skipped
        params.sample_index = start
        return HaltonSampler(domain=box, halton_params=params)
    if kind == "random":
        return RandomSampler(box)
    if kind == "bandit":
        return ContinuousMultiArmedBanditSampler(domain=box, alpha=alpha, thres=thres, buckets=buckets)

    return ContinuousCrossEntropySampler(domain=box, alpha=alpha, thres=thres, buckets=buckets)


class ScenarioSplitSampler(FeatureSampler):
    """A scenario chooser and one parameter sampler per scenario (module docstring), all VerifAI's.

    Args:
        space: the VerifAI ``FeatureSpace`` of the mining space (``scenario``, ``u``).
        dimensions: each scenario's parameter count, in index order (:func:`scenario_dimensions`).
        chooser: :data:`CHOOSERS`; ``params``: :data:`PARAM_SAMPLERS`.
        adapt: VerifAI's parameters of the adaptive parts (:class:`AdaptSettings`).
        warmup: the first ``warmup * len(dimensions)`` scenes try every scenario ``warmup`` times (each
            round in a seeded order) and are fed to the chooser like its own draws; 0: none.
        avoid: up to this many further points of the scenario's parameter sampler are drawn while the point
            falls in a cell of the cluster grid where a failure (``rho < thres``; under novelty feedback a new
            cluster) was already found in that scenario; 0: the sampler's first point.

    Build it with the generators seeded (the Halton starts are drawn here); then draw with
    ``getSample`` and feed with ``update`` like any VerifAI feature sampler.
    """

    def __init__(self, space, dimensions: Sequence[int], chooser: str = "cross-entropy", params: str = "halton",
                 adapt: AdaptSettings = AdaptSettings(), warmup: int = 0, avoid: int = 0) -> None:
        super().__init__(space)
        self.width = max([int(d) for d in dimensions] + [1])
        """Coordinates of ``u`` in the feature space (the largest parameter count)."""
        self.dimensions = [int(d) for d in dimensions]
        self.chooser_kind, self.params_kind = chooser, params
        self.chooser = _make_chooser(chooser, len(self.dimensions), adapt)
        self.param_samplers = [_make_params(params, d, adapt.alpha, adapt.thres, adapt.buckets)
                               for d in self.dimensions]
        self.draws = [0] * len(self.dimensions)
        """Scenes drawn per scenario."""
        count = len(self.dimensions)
        self.warmup_order = [int(i) for _ in range(int(warmup)) for i in np.random.permutation(count)]
        """The scenarios of the first draws: every scenario ``warmup`` times, each round in a seeded order."""
        self.drawn = 0
        self.avoid = int(avoid)
        """Redraws allowed per scene to leave the cells where a failure was already found (0: none)."""
        self.found: List[set] = [set() for _ in self.dimensions]
        """Per scenario: the cluster-grid cells (:func:`~dv2s_gym.mining.cluster.region_of`) of its failures."""

    def _scenario(self) -> Tuple[int, Any, Any]:
        if self.drawn < len(self.warmup_order):  # warm-up: the chooser is only fed, as if it had drawn these
            index = self.warmup_order[self.drawn]
            if self.chooser_kind == "cross-entropy":
                return index, (index,), None
            return index, ((index + 0.5) / len(self.dimensions),), np.array([index])
        if self.chooser_kind == "epsilon-greedy":  # VerifAI's class draws with generateSample (no getVector)
            vector, info = self.chooser.generateSample()
            sample = self.chooser.domain.unstandardize(vector)
        else:
            sample, info = self.chooser.getSample()
        if self.chooser_kind in ("ucb", "epsilon-greedy"):
            index = int(info[0])  # the bucket is the scenario
        else:
            index = int(sample[0])
        return min(max(index, 0), len(self.dimensions) - 1), sample, info

    def getSample(self):
        """The next ``(point, info)``: a scenario from the chooser, its parameters from its own sampler."""
        index, choice, choice_info = self._scenario()
        self.drawn += 1
        own, own_info = self.param_samplers[index].getSample()
        for _ in range(self.avoid):  # the sampler's next points, past the cells already failing
            if region_of(own[: self.dimensions[index]]) not in self.found[index]:
                break
            own, own_info = self.param_samplers[index].getSample()
        own = tuple(float(x) for x in own)
        u = own[: self.dimensions[index]] + (0.5,) * (self.width - self.dimensions[index])
        self.draws[index] += 1
        point = self.space.makePoint(scenario=(index,), u=u)
        return point, (index, choice, choice_info, own, own_info)

    def update(self, sample, info, rho) -> None:
        """Feed the outcome ``rho`` of a drawn point to the chooser and to its scenario's parameter sampler."""
        index, choice, choice_info, own, own_info = info
        if rho < self.chooser.thres:
            self.found[index].add(region_of(own[: self.dimensions[index]]))
        self.chooser.update(choice, choice_info, rho)
        self.param_samplers[index].update(own, own_info, rho)

    def scenario_weights(self) -> List[float]:
        """The chooser's current probability of each scenario (``cross-entropy``), or its UCB scores (``ucb``)."""
        if self.chooser_kind in ("cross-entropy", "epsilon-greedy"):
            return [float(x) for x in self.chooser.dist[0]]
        proportions = self.chooser.errors[0] / self.chooser.counts[0]
        return [float(x) for x in proportions + np.sqrt(2 / self.chooser.counts[0] * np.log(self.chooser.t))]
