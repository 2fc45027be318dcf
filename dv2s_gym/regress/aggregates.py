"""Aggregates in the manner of rliable (Agarwal et al. 2021), as context beside the paired test.

The verdict is the paired failure test's; these describe the episode *returns* the way RL papers
compare agents, with stratified bootstrap intervals (episodes resampled within each scenario, so
every resample keeps the run's scenario mix):

- :func:`interquartile_mean`: the mean of the middle 50 % of the returns (robust to a few extreme
  episodes, more efficient than the median);
- :func:`probability_of_improvement`: per scenario, the probability that a random candidate episode
  has a higher return than a random baseline episode (ties count half: the Mann-Whitney statistic
  over the number of pairs), averaged over the scenarios; 0.5 means no difference.

Implemented with numpy (no dependency on the rliable package).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Optional

import numpy as np

from dv2s_gym.regress.records import PairedEpisode

__all__ = ["interquartile_mean", "probability_of_improvement", "stratified_bootstrap", "return_aggregates"]

CONFIDENCE = 0.95
RESAMPLES = 2000


def interquartile_mean(values: Sequence[float]) -> float:
    """Mean of the values between the 25th and 75th percentile: 25 % cut from each end, as
    ``scipy.stats.trim_mean(values, 0.25)`` (NaN for no values)."""
    array = np.sort(np.asarray(values, dtype=float))
    if array.size == 0:
        return float("nan")
    cut = int(0.25 * array.size)
    return float(array[cut:array.size - cut].mean())


def _poi_one(candidate: np.ndarray, baseline: np.ndarray) -> float:
    greater = (candidate[:, None] > baseline[None, :]).mean()
    ties = (candidate[:, None] == baseline[None, :]).mean()
    return float(greater + 0.5 * ties)


def probability_of_improvement(candidate: Mapping[str, Sequence[float]], baseline: Mapping[str, Sequence[float]]
                               ) -> float:
    """P(candidate return > baseline return), ties half, per scenario, averaged over the scenarios both have."""
    names = [n for n in candidate if len(candidate[n]) and len(baseline.get(n, ()))]
    if not names:
        return float("nan")
    return float(np.mean([_poi_one(np.asarray(candidate[n], float), np.asarray(baseline[n], float)) for n in names]))


def _interval(estimate: float, draws: np.ndarray, confidence: float) -> dict[str, Optional[float]]:
    if not np.isfinite(estimate):
        return {"value": None, "low": None, "high": None}
    tail = (1.0 - confidence) / 2.0
    low, high = np.nanquantile(draws, [tail, 1.0 - tail])
    return {"value": float(estimate), "low": float(low), "high": float(high)}


def _resample(values: np.ndarray, resamples: int, rng: np.random.Generator) -> np.ndarray:
    """``(resamples, n)``: the values drawn with replacement, one row per resample."""
    return values[rng.integers(0, values.size, size=(resamples, values.size))]


def _iqm_rows(rows: np.ndarray) -> np.ndarray:
    ordered = np.sort(rows, axis=1)
    cut = int(0.25 * ordered.shape[1])
    return ordered[:, cut:ordered.shape[1] - cut].mean(axis=1)


def _poi_rows(candidate: np.ndarray, baseline: np.ndarray) -> np.ndarray:
    greater = (candidate[:, :, None] > baseline[:, None, :]).mean(axis=(1, 2))
    ties = (candidate[:, :, None] == baseline[:, None, :]).mean(axis=(1, 2))
    return greater + 0.5 * ties


def stratified_bootstrap(returns: Mapping[str, tuple[Sequence[float], Sequence[float]]], *,
                         resamples: int = RESAMPLES, confidence: float = CONFIDENCE, seed: int = 0
                         ) -> dict[str, Any]:
    """IQM per policy and probability of improvement, resampling each policy's episodes within each scenario.

    Args:
        returns: per scenario, ``(candidate returns, baseline returns)``.
        resamples / confidence / seed: the bootstrap's size, two-sided level and random seed.

    Returns:
        ``{"return_iqm": {"candidate", "baseline"}, "probability_of_improvement"}``, each ``{"value", "low", "high"}``.
    """
    rng = np.random.default_rng(seed)
    data = {name: (np.asarray(c, dtype=float), np.asarray(b, dtype=float)) for name, (c, b) in returns.items()}
    iqm = {}
    for index, role in enumerate(("candidate", "baseline")):
        parts = [p[index] for p in data.values() if p[index].size]
        if not parts:
            iqm[role] = {"value": None, "low": None, "high": None}
            continue
        rows = np.concatenate([_resample(part, resamples, rng) for part in parts], axis=1)
        iqm[role] = _interval(interquartile_mean(np.concatenate(parts)), _iqm_rows(rows), confidence)
    both = {name: p for name, p in data.items() if p[0].size and p[1].size}
    if both:
        draws = np.mean([_poi_rows(_resample(c, resamples, rng), _resample(b, resamples, rng))
                         for c, b in both.values()], axis=0)
        poi = _interval(probability_of_improvement({n: p[0] for n, p in both.items()},
                                                   {n: p[1] for n, p in both.items()}), draws, confidence)
    else:
        poi = {"value": None, "low": None, "high": None}
    return {"return_iqm": iqm, "probability_of_improvement": poi}


def return_aggregates(episodes: Sequence[PairedEpisode], *, resamples: int = RESAMPLES,
                      seed: int = 0) -> Optional[dict[str, Any]]:
    """IQM of the return per policy and the probability of improvement, with stratified bootstrap intervals.

    Args:
        episodes: the report's paired episodes (:class:`~dv2s_gym.regress.records.PairedEpisode`); results that
            ended in an error or have no return are left out.

    Returns:
        ``{"return_iqm": {"candidate", "baseline"}, "probability_of_improvement", "resamples", "confidence"}``
        with ``{"value", "low", "high"}`` entries, or None without a baseline or returns.
    """
    returns: dict[str, tuple[list, list]] = {}
    for episode in episodes:
        for index, role in enumerate(("candidate", "baseline")):
            result = episode.result(role)
            if result is not None and not result.error and result.episode_return is not None:
                returns.setdefault(str(episode.scenario), ([], []))[index].append(float(result.episode_return))
    if not returns or not any(base for _, base in returns.values()):
        return None
    found = stratified_bootstrap(returns, resamples=resamples, seed=seed)
    return {**found, "resamples": int(resamples), "confidence": CONFIDENCE}
