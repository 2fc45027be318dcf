"""How often the policy fails under each scenario's own parameter distribution, from a mining run.

A mining run does not draw scenes the way they occur: an adaptive sampler draws more where failures
were found. Each episode record keeps the density its scene was drawn with (``record.proposal``:
``scenario``, the probability of its scenario; ``params``, the density of its parameters in the
scenario's unit box; ``floor``, the smallest share the sampler gave any scenario or parameter bucket
at that draw, relative to uniform; see :func:`dv2s_gym.mining.sampling.samplers.proposal_density`). A scenario's
own distribution is uniform over that unit box (each parameter's range or set of values, as the scenario
declares it), so an episode's importance weight in its scenario is ``1 / params`` and, over the whole
run, with every mined scenario equally likely, ``(1 / S) / (scenario * params)``.

:func:`weighted_rate` is the plain importance-sampling estimate ``mean(w * y)`` (``y`` = 1 for a failed
episode): unbiased also when the proposal adapts to earlier outcomes, as long as it gives every region
some chance. Its 95 % interval is Wilson's at the estimate's effective sample size
``p (1 - p) / Var(estimate)`` (for equal weights: the number of episodes, and the usual Wilson interval), capped
at Kish's effective sample size of the weights (never more than the number of episodes: a single failure with a
small weight would otherwise claim an effective sample far larger than the run); without a failure, at Kish's; when heavy weights push the estimate to 1
or past it, the normal interval of the estimate cut at 1, with Kish's effective sample size. A per-scenario estimate averages
``y / params`` over the scenario's episodes.

An adaptive sampler that collapses (VerifAI's cross-entropy sampler moves almost all probability to the
buckets where failures were found, also along parameters that do not matter) stops drawing some regions;
the estimate then misses their failures and can be far too low. ``collapsed`` says when some draw gave a
region under :data:`COLLAPSE_FLOOR` of its uniform share. A ``random`` or ``halton`` run is uniform.
Records without a proposal density from a sampler that has none (``bandit``, ``split`` with cell avoidance) make
the estimate unavailable; a uniform sampler's records need none (a plug-in's sampler registered as uniform
records none: its weight is 1, as for ``random`` and ``halton``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from statistics import NormalDist
from typing import Any, Dict, Iterable, List, Mapping, Optional, Sequence

from dv2s_gym.mining.errors import MiningError
from dv2s_gym.mining.sampling.samplers import is_uniform
from dv2s_gym.regress.stats import wilson_interval
from scenario_bank.records import EpisodeRecord

__all__ = ["RateEstimate", "FailureRate", "failure_rate", "weighted_rate", "rate_estimates", "COLLAPSE_FLOOR"]

COLLAPSE_FLOOR = 0.01
"""A draw whose proposal gave some scenario or parameter bucket under this share of its uniform share marks the
estimate ``collapsed``."""


@dataclass(frozen=True)
class RateEstimate:
    """An importance-sampling estimate of a failure rate (:func:`weighted_rate`; ``Estimate`` in the mining report):
    ``value`` (capped at 1; ``None`` without outcomes), ``raw`` (the estimate itself, which a few heavy weights can
    push past 1), its 95 % interval ``low``..``high``, the effective sample size ``ess``, the ``n`` outcomes and
    the ``failures`` among them."""

    value: Optional[float]
    raw: Optional[float]
    low: Optional[float]
    high: Optional[float]
    ess: float
    n: int
    failures: int

    def to_dict(self) -> Dict[str, Any]:
        """The estimate's JSON object, as the mining report holds it."""
        return {"value": self.value, "raw": self.raw, "low": self.low, "high": self.high, "ess": self.ess,
                "n": self.n, "failures": self.failures}


@dataclass(frozen=True)
class FailureRate:
    """The failure rate of a run under its scenarios' own distributions (:func:`failure_rate`): whether it is
    ``available`` and, when not, the ``reason``; whether the sampler ``collapsed``; the ``overall`` estimate (each
    scenario equally likely), each scenario's (``scenarios``), and per scenario the episodes drawn that ended in an
    error (``errored``)."""

    available: bool
    reason: Optional[str] = None
    collapsed: bool = False
    overall: Optional[RateEstimate] = None
    scenarios: Mapping[str, RateEstimate] = field(default_factory=dict)
    errored: Mapping[str, int] = field(default_factory=dict)

    def to_dict(self) -> Dict[str, Any]:
        """The rate's JSON object, as the mining report holds it (``failure_rate``)."""
        return {"available": self.available, "reason": self.reason, "collapsed": self.collapsed,
                "overall": self.overall.to_dict() if self.overall is not None else None,
                "scenarios": {name: estimate.to_dict() for name, estimate in self.scenarios.items()},
                "errored": dict(self.errored)}


def weighted_rate(outcomes: Sequence[float], weights: Sequence[float], confidence: float = 0.95) -> RateEstimate:
    """Plain importance-sampling estimate ``mean(w * y)`` of a rate from 0/1 ``outcomes`` and their ``weights``
    (:class:`RateEstimate`: ``value`` ``None`` without outcomes; ``raw`` is the estimate itself, which a few heavy
    weights can push past 1, ``value`` it capped at 1).
    """
    if len(outcomes) != len(weights):
        raise MiningError(f"{len(outcomes)} outcomes but {len(weights)} weights; give one weight per outcome")
    n = len(outcomes)
    failures = int(sum(1 for y in outcomes if y))
    if n == 0:
        return RateEstimate(value=None, raw=None, low=None, high=None, ess=0.0, n=0, failures=0)
    terms = [float(w) * (1.0 if y else 0.0) for w, y in zip(weights, outcomes)]
    value = sum(terms) / n
    variance = sum((t - value) ** 2 for t in terms) / n / n  # of the estimate
    shown = min(1.0, value)
    total, squares = sum(weights), sum(float(w) ** 2 for w in weights)
    kish = total * total / squares if squares > 0 else 0.0
    if failures and variance > 0.0 and shown >= 1.0:
        # heavy weights pushed the estimate to 1 or past it: p (1 - p) says nothing there, so the interval is the
        # normal one of the estimate itself (cut at 1) and the effective sample size Kish's
        z = NormalDist().inv_cdf(0.5 + confidence / 2)
        return RateEstimate(value=shown, raw=value, low=max(0.0, value - z * math.sqrt(variance)), high=1.0,
                            ess=kish, n=n, failures=failures)
    ess = shown * (1.0 - shown) / variance if failures and variance > 0.0 else kish
    # never more than Kish's effective sample size of the weights (itself at most the n episodes): a rare
    # failure with a small weight makes the variance tiny and p (1 - p) / variance far larger than n
    ess = min(ess, kish, float(n))
    low, high = _wilson(shown, ess, confidence)
    return RateEstimate(value=shown, raw=value, low=low, high=high, ess=ess, n=n, failures=failures)


def _wilson(p: float, n: float, confidence: float) -> tuple:
    """Wilson score interval of a proportion ``p`` observed on an effective sample of ``n`` (not necessarily
    whole)."""
    if n <= 0:
        return 0.0, 1.0
    if float(n).is_integer() and (p * n).is_integer() and confidence == 0.95:
        low, high = wilson_interval(int(round(p * n)), int(n))
        return float(low), float(high)

    z = NormalDist().inv_cdf(0.5 + confidence / 2)
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, centre - half), min(1.0, centre + half)


def _proposal(record: EpisodeRecord, sampler: str) -> Optional[Mapping[str, float]]:
    proposal = record.proposal
    if isinstance(proposal, Mapping) and proposal.get("scenario") and proposal.get("params"):
        return proposal
    if is_uniform(str(record.sampler or sampler)):  # a uniform plug-in sampler records none: weight 1
        return {"scenario": None, "params": 1.0, "floor": 1.0}
    return None


def failure_rate(records: Iterable[EpisodeRecord], *, scenarios: Optional[Sequence[str]] = None,
                 sampler: str = "", confidence: float = 0.95) -> FailureRate:
    """The failure rate of the run's policy under its scenarios' own distributions (module docstring).

    Args:
        records: the run's episode records (errors are left out).
        scenarios: the mined scenarios (the overall rate weighs each equally; default: those in ``records``).
        sampler: the run's sampler (for records that do not name theirs).

    Returns the :class:`FailureRate` (its :meth:`~FailureRate.to_dict`: ``{"available", "reason", "collapsed",
    "overall", "scenarios", "errored"}``) with each estimate as :func:`weighted_rate` returns it.
    """
    records = list(records)
    errored: Dict[str, int] = {}
    for record in records:
        if record.error:
            errored[str(record.scenario)] = errored.get(str(record.scenario), 0) + 1
    records = [r for r in records if not r.error]
    names = list(scenarios) if scenarios else sorted({str(r.scenario) for r in records})
    missing = [r for r in records if _proposal(r, sampler) is None]
    if missing:
        return FailureRate(available=False, reason=f"{len(missing)} of {len(records)} episodes have no proposal "
                           "density (the sampler draws without one, e.g. bandit or split with cell avoidance)",
                           collapsed=False, overall=None, scenarios={}, errored=errored)
    by_scenario: Dict[str, List[EpisodeRecord]] = {name: [] for name in names}
    for record in records:
        by_scenario.setdefault(str(record.scenario), []).append(record)
    estimates = {}
    for name, members in by_scenario.items():
        weights = [1.0 / float(_proposal(r, sampler)["params"]) for r in members]
        estimates[name] = weighted_rate([1.0 if r.failure else 0.0 for r in members], weights, confidence)
    count = len(by_scenario)
    overall_weights, outcomes = [], []
    for record in records:
        proposal = _proposal(record, sampler)
        chance = proposal["scenario"] if proposal["scenario"] else 1.0 / count
        overall_weights.append((1.0 / count) / (float(chance) * float(proposal["params"])))
        outcomes.append(1.0 if record.failure else 0.0)
    collapsed = any(float(_proposal(r, sampler).get("floor", 1.0)) < COLLAPSE_FLOOR for r in records)
    return FailureRate(available=True, reason=None, collapsed=collapsed,
                       overall=weighted_rate(outcomes, overall_weights, confidence),
                       scenarios=estimates, errored=errored)


def rate_estimates(settings: Mapping[str, Any], records: Sequence[EpisodeRecord]) -> FailureRate:
    """:func:`failure_rate` of a run from its ``settings.json`` and records."""
    return failure_rate(records, scenarios=settings.get("scenarios") or None, sampler=str(settings.get("sampler") or ""))
