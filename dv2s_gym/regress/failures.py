"""What counts as a failure for ``dv2s regress``: collision, off-road and stall by default.

A worker records the facts of every episode (``collided``, ``off_road``, ``stalled``: the ego stood
below :data:`envs.safety_metrics.STANDING_SPEED` with a free road ahead for ``stall_seconds`` in
total over the episode, :func:`envs.safety_metrics.total_stall_step`; the failure miner looks for one
unbroken stretch instead, to find where a stall begins), and :func:`apply_failure` marks the episode ``failed``
when any of the chosen kinds happened, listing them in ``failure_kinds``. The paired test compares
``failed``; the reports show each kind apart.
"""

from __future__ import annotations

from typing import Any, Dict, Iterable, List, Optional, Sequence, Tuple, Union

from dv2s_gym.regress.errors import RegressError
from envs.safety_metrics import DEFAULT_STALL_SECONDS
from scenario_bank.failure_types import FAILURE_TABLE

__all__ = ["FAILURE_KINDS", "DEFAULT_FAILURE", "FAILURE_BEFORE_CHOICE", "DEFAULT_STALL_SECONDS", "parse_failure",
           "apply_failure", "missing_facts"]

FAILURE_KINDS: Dict[str, str] = {row.name: row.result_field for row in FAILURE_TABLE if row.result_field}
"""Failure kind -> the episode result's field that says it happened: the failure types
(:data:`scenario_bank.failure_types.FAILURE_TABLE`) that results record, most severe first."""

DEFAULT_FAILURE: Tuple[str, ...] = tuple(row.name for row in FAILURE_TABLE if row.regress_default)
"""A failure is any of these unless the run says otherwise (``--failure``)."""

FAILURE_BEFORE_CHOICE: Tuple[str, ...] = tuple(row.name for row in FAILURE_TABLE if row.counted_before_choice)
"""The failure kinds of a report that has no ``failure`` setting (made before runs chose their kinds)."""

def parse_failure(value: Union[None, str, Iterable[str]]) -> List[str]:
    """``"collision,stall"`` or a list of kinds -> the kinds in canonical order; None: the default.

    Raises:
        RegressError: for an empty selection or an unknown kind, naming the kinds there are.
    """
    if value is None:
        return list(DEFAULT_FAILURE)
    items = value.split(",") if isinstance(value, str) else list(value)
    kinds = [str(item).strip().replace("-", "_") for item in items if str(item).strip()]
    unknown = [kind for kind in kinds if kind not in FAILURE_KINDS]
    if unknown or not kinds:
        what = f"unknown failure kind {', '.join(map(repr, unknown))}" if unknown else "no failure kind given"
        raise RegressError(f"--failure: {what}; give a comma-separated list of {', '.join(FAILURE_KINDS)} "
                           f"(default {','.join(DEFAULT_FAILURE)})")
    return [kind for kind in FAILURE_KINDS if kind in kinds]


def apply_failure(result: Dict[str, Any], kinds: Sequence[str]) -> Dict[str, Any]:
    """``result`` with ``failed`` and ``failure_kinds`` set from the chosen kinds (errors stay unfailed)."""
    if result.get("error"):
        return result
    happened = [kind for kind in FAILURE_KINDS if bool(result.get(FAILURE_KINDS[kind]))]
    result["failure_kinds"] = [kind for kind in happened if kind in kinds]
    result["failed"] = bool(result["failure_kinds"])
    return result


def missing_facts(results: Iterable[Optional[Dict[str, Any]]], kinds: Sequence[str]) -> List[str]:
    """The chosen kinds some (non-error) result has no record of (a report made before they were recorded)."""
    lacking = set()
    for result in results:
        if result and not result.get("error"):
            lacking.update(kind for kind in kinds if FAILURE_KINDS[kind] not in result)
    return [kind for kind in FAILURE_KINDS if kind in lacking]
