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
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import numpy as np
from verifai.samplers.feature_sampler import FeatureSampler, default_sampler_params

from dv2s_gym.mining.cluster import region_of
from dv2s_gym.mining.errors import MiningError
from verifai.features import Box, DiscreteBox
from verifai.samplers.multi_armed_bandit import ContinuousMultiArmedBanditSampler
from verifai.samplers.cross_entropy import ContinuousCrossEntropySampler, DiscreteCrossEntropySampler
from verifai.samplers.eg_sampler import ContinuousEpsilonGreedySampler
from verifai.samplers.halton import HaltonSampler
from verifai.samplers.random_sampler import RandomSampler

__all__ = ["AdaptSettings", "ScenarioSplitSampler", "CHOOSERS", "PARAM_SAMPLERS", "CHOOSER_TABLE", "PARAM_TABLE",
           "Chooser", "ParamSampler", "UNIFORM", "BUCKETS", "scenario_dimensions"]

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


@dataclass(frozen=True)
class Chooser:
    """A VerifAI sampler that picks the scenario: a row of :data:`CHOOSER_TABLE`."""

    build: Callable[[int, AdaptSettings], Any]
    """``build(scenario count, adapt)``: the VerifAI sampler."""
    bucketed: bool
    """It draws a point of ``[0, 1]`` cut into one bucket per scenario, the bucket (its ``info``) being the
    scenario; otherwise it draws the scenario index itself."""
    exact: bool
    """Each of its draws follows its distribution ``dist`` (so that is the scenario's proposal density)."""
    draw: Callable[[Any], Tuple[Any, Any]]
    """``draw(sampler) -> (sample, info)``: its next scenario draw."""
    weights: Callable[[Any], List[float]]
    """``weights(sampler)``: its current weight of each scenario (:meth:`ScenarioSplitSampler.scenario_weights`)."""


UNIFORM = "uniform"
"""A parameter sampler whose points are uniform over the unit box (density 1)."""
BUCKETS = "buckets"
"""A parameter sampler that draws each coordinate from its bucket distribution ``dist``."""


@dataclass(frozen=True)
class ParamSampler:
    """A VerifAI sampler that draws a scenario's parameters: a row of :data:`PARAM_TABLE`."""

    build: Callable[[Any, AdaptSettings], Any]
    """``build(unit box, adapt)``: the VerifAI sampler (with the generators seeded)."""
    density: Optional[str]
    """How its draws' density is told: :data:`UNIFORM`, :data:`BUCKETS`, or ``None`` (it cannot be)."""


def _get_sample(chooser) -> Tuple[Any, Any]:
    return chooser.getSample()


def _generate_sample(chooser) -> Tuple[Any, Any]:
    vector, info = chooser.generateSample()  # VerifAI's epsilon-greedy class has no getVector
    return chooser.domain.unstandardize(vector), info


def _distribution(chooser) -> List[float]:
    return [float(x) for x in chooser.dist[0]]


def _ucb_scores(chooser) -> List[float]:
    proportions = chooser.errors[0] / chooser.counts[0]
    return [float(x) for x in proportions + np.sqrt(2 / chooser.counts[0] * np.log(chooser.t))]


CHOOSER_TABLE: Dict[str, Chooser] = {
    "cross-entropy": Chooser(
        lambda count, adapt: DiscreteCrossEntropySampler(domain=DiscreteBox([0, count - 1]), alpha=adapt.alpha,
                                                         thres=adapt.thres),
        bucketed=False, exact=True, draw=_get_sample, weights=_distribution),
    "ucb": Chooser(
        lambda count, adapt: ContinuousMultiArmedBanditSampler(domain=Box([0.0, 1.0]), alpha=adapt.alpha,
                                                               thres=adapt.thres, buckets=count),
        bucketed=True, exact=False, draw=_get_sample, weights=_ucb_scores),
    "epsilon-greedy": Chooser(
        lambda count, adapt: ContinuousEpsilonGreedySampler(domain=Box([0.0, 1.0]), alpha=adapt.alpha,
                                                            thres=adapt.thres, buckets=count),
        bucketed=True, exact=False, draw=_generate_sample, weights=_distribution),
}
"""The scenario choosers by name (the module docstring says what each does)."""


def _halton(box, adapt: AdaptSettings):
    start = int(np.random.randint(0, _HALTON_START))  # the caller seeds the generators
    params = default_sampler_params("halton")  # VerifAI's DotMap: sample_index, bases_skipped
    params.sample_index = start
    return HaltonSampler(domain=box, halton_params=params)


PARAM_TABLE: Dict[str, ParamSampler] = {
    "halton": ParamSampler(_halton, UNIFORM),
    "random": ParamSampler(lambda box, adapt: RandomSampler(box), UNIFORM),
    "bandit": ParamSampler(lambda box, adapt: ContinuousMultiArmedBanditSampler(
        domain=box, alpha=adapt.alpha, thres=adapt.thres, buckets=adapt.buckets), None),
    "cross-entropy": ParamSampler(lambda box, adapt: ContinuousCrossEntropySampler(
        domain=box, alpha=adapt.alpha, thres=adapt.thres, buckets=adapt.buckets), BUCKETS),
}
"""The parameter samplers by name (the module docstring says what each does)."""

CHOOSERS = tuple(CHOOSER_TABLE)
"""VerifAI samplers that can pick the scenario."""

PARAM_SAMPLERS = tuple(PARAM_TABLE)
"""VerifAI samplers that can draw a scenario's parameters."""


def _row(table: Dict[str, Any], what: str, word: str):
    """``table[word]``, or a :class:`MiningError` naming the choices."""
    row = table.get(word) if isinstance(word, str) else None
    if row is None:
        raise MiningError(f"the split sampler's {what} must be one of {', '.join(table)}, not {word!r}")
    return row


def _make_params(kind: str, dimension: int, adapt: AdaptSettings):
    return PARAM_TABLE[kind].build(Box(*[[0.0, 1.0]] * max(dimension, 1)), adapt)


class ScenarioSplitSampler(FeatureSampler):
    """A scenario chooser and one parameter sampler per scenario (module docstring), all VerifAI's.

    Args:
        space: the VerifAI ``FeatureSpace`` of the mining space (``scenario``, ``u``).
        dimensions: each scenario's parameter count, in index order (:func:`scenario_dimensions`).
        chooser: :data:`CHOOSERS`; ``params``: :data:`PARAM_SAMPLERS` (another word raises
            :class:`~dv2s_gym.mining.errors.MiningError` naming the choices).
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
        kind = _row(CHOOSER_TABLE, "chooser", chooser)
        _row(PARAM_TABLE, "params", params)
        self.chooser_kind, self.params_kind = chooser, params
        self.chooser = kind.build(len(self.dimensions), adapt)
        self.param_samplers = [_make_params(params, d, adapt) for d in self.dimensions]
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
        chooser = CHOOSER_TABLE[self.chooser_kind]
        if self.drawn < len(self.warmup_order):  # warm-up: the chooser is only fed, as if it had drawn these
            index = self.warmup_order[self.drawn]
            if not chooser.bucketed:
                return index, (index,), None
            return index, ((index + 0.5) / len(self.dimensions),), np.array([index])
        sample, info = chooser.draw(self.chooser)
        index = int(info[0]) if chooser.bucketed else int(sample[0])  # a bucketed chooser's bucket is the scenario
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
        """The chooser's current probability of each scenario (``cross-entropy``, ``epsilon-greedy``), or its UCB
        scores (``ucb``)."""
        return CHOOSER_TABLE[self.chooser_kind].weights(self.chooser)
