"""The paper's semantic metrics over sets of elements (see :mod:`scenario_bank.elements`).

* SCS = |GT ∩ S| / |GT|: how much of the ground truth a description covers.
* HR = 1 − |GT ∩ S| / |S|: how much of a description is not in the ground truth.
* SP = |S_de ∩ S_sc| / |S_de|: how much of a description the simulated scenario preserves.
* E2E-SC = |GT_v ∩ S_o| / |GT_v|: how much of a video's ground truth survives the pipeline.

Each takes element records (:class:`~scenario_bank.elements.Elements`, or their JSON objects as label files hold
them) or element sets. Empty denominators
follow the convention that nothing to cover is fully covered (1.0) and nothing
said hallucinates nothing (HR 0.0).
"""

from __future__ import annotations

import statistics
from typing import Any, Dict, FrozenSet, Iterable, List, Mapping, Union

from scenario_bank.elements import Elements, element_set, with_undirected

__all__ = ["scs", "hallucination_rate", "semantic_preservation", "e2e_sc", "mean_sd", "as_set"]

ElementsLike = Union[Elements, Mapping[str, Any], FrozenSet, set]
"""What the metrics score: an element record, its JSON object or an element set."""


def as_set(elements: ElementsLike) -> FrozenSet:
    """An element set from a record or a set."""
    if isinstance(elements, (set, frozenset)):
        return frozenset(elements)
    return element_set(elements)


def _recall(reference: ElementsLike, candidate: ElementsLike) -> float:
    ref, cand = as_set(reference), with_undirected(as_set(candidate))
    return len(ref & cand) / len(ref) if ref else 1.0


def scs(ground_truth: ElementsLike, description: ElementsLike) -> float:
    """Semantic Coverage Score: recall of ground-truth elements in the description."""
    return _recall(ground_truth, description)


def hallucination_rate(ground_truth: ElementsLike, description: ElementsLike) -> float:
    """Hallucination Rate: share of described elements absent from the ground truth."""
    gt, desc = with_undirected(as_set(ground_truth)), as_set(description)
    return 1.0 - len(gt & desc) / len(desc) if desc else 0.0


def semantic_preservation(description: ElementsLike, scenario: ElementsLike) -> float:
    """Semantic Preservation: recall of the description's elements in the simulated scenario."""
    return _recall(description, scenario)


def e2e_sc(video_ground_truth: ElementsLike, simulated: ElementsLike) -> float:
    """End-to-End Semantic Consistency: recall of the video's ground truth in the simulated output."""
    return _recall(video_ground_truth, simulated)


def mean_sd(values: Iterable[float]) -> Dict[str, float]:
    """``{"mean", "sd", "n"}`` (sample standard deviation; 0 for a single value)."""
    data: List[float] = list(values)
    if not data:
        return {"mean": float("nan"), "sd": float("nan"), "n": 0}
    return {"mean": statistics.fmean(data), "sd": statistics.stdev(data) if len(data) > 1 else 0.0, "n": len(data)}
