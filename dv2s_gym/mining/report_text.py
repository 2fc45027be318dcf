"""Sentences of the mining report shared by its Markdown, summary and HTML forms (no Scenic, no highway-env)."""

from __future__ import annotations

import math
from typing import Any, Mapping, Optional

__all__ = ["breadth", "rate_text", "number_text", "percent_text"]


def number_text(value: Any, digits: int = 1) -> str:
    """A finite number with ``digits`` decimals, else ``-``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(float(value)):
        return "-"
    return f"{value:.{digits}f}"


def percent_text(entry: Optional[Mapping[str, Any]]) -> str:
    """A rate with its interval in percent (``{"value", "low", "high"}``), else ``-``."""
    if not entry or entry.get("value") is None:
        return "-"
    return f"{100 * entry['value']:.1f}% [{100 * entry['low']:.1f}, {100 * entry['high']:.1f}]"


def breadth(counts: Mapping[str, Any]) -> str:
    """How broad the failures found are: failures, distinct behaviours, (scenario, failure type) pairs, scenarios
    with a failure, and stalls apart from collisions."""
    return (f"{counts['failures']} failure(s): {counts.get('behaviours', counts['clusters'])} distinct behaviour(s), "
            f"{counts.get('scenario_failure_types', 0)} (scenario, failure type) pair(s), "
            f"{counts.get('scenarios_failing', 0)} scenario(s) with a failure; "
            f"{counts.get('collisions', 0)} collision(s), {counts.get('stalls', 0)} stall(s)")


def rate_text(rate: Optional[Mapping[str, Any]]) -> str:
    """The estimated failure rate under the scenarios' own parameter distributions, as one sentence."""
    if not rate or not rate.get("available"):
        reason = (rate or {}).get("reason") or "no episodes"
        return f"Failure rate under the scenarios' own parameter distributions: not estimated ({reason})."
    overall = rate.get("overall") or {}
    return ("Failure rate under the scenarios' own parameter distributions (importance-weighted, each scenario "
            f"equally likely): {percent_text(overall)}, effective sample size {number_text(overall.get('ess'))} of "
            f"{overall.get('n', 0)} episodes."
            + (" The sampler almost stopped drawing some regions, so failures there are missing from the estimate: "
               "it can be far too low; a random-sampler run estimates it without that risk." if rate.get("collapsed")
               else ""))
