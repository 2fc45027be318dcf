"""What counts as a failure for ``dv2s regress``: collision, off-road and stall by default.

A worker records the facts of every episode (``collided``, ``off_road``, ``stalled``: the ego stood
below :data:`envs.safety_metrics.STANDING_SPEED` with a free road ahead for ``stall_seconds`` in
total over the episode, :func:`envs.safety_metrics.total_stall_step`; the failure miner looks for one
unbroken stretch instead, to find where a stall begins), and :func:`apply_failure` marks the episode ``failed``
when any of the chosen kinds happened, listing them in ``failure_kinds``. The paired test compares
``failed``; the reports show each kind apart.

The kinds are read from the live failure table (:func:`scenario_bank.failure_types.failure_table`) at each call,
so a type a plug-in adds with :func:`~scenario_bank.failure_types.register_failure_type` and a ``result_field``
(its detector registered with :func:`dv2s_gym.mining.monitors.register_detector`) is a kind of ``--failure``
too: the worker records its field by running the detector on the episode's trace
(:mod:`dv2s_gym.regress.tasks`). A plug-in must register in each process that detects: the worker processes of
the local pool (forkserver or spawn) and of Ray import only the product's modules, so a type registered in the
calling process alone is refused by the workers with a message saying so (see ``docs/mining.md``).
"""

from __future__ import annotations

import dataclasses

from typing import Any, Dict, Iterable, List, Optional, Sequence, Tuple, Union

from dv2s_gym.regress.errors import RegressError
from envs.safety_metrics import DEFAULT_STALL_SECONDS
from scenario_bank.failure_types import failure_table
from scenario_bank.records import RegressEpisode

__all__ = ["failure_kinds", "default_failure", "DEFAULT_STALL_SECONDS", "parse_failure",
           "apply_failure", "missing_facts", "result_value"]

_RECORD_FIELDS = frozenset(f.name for f in dataclasses.fields(RegressEpisode)) - {"extra", "null_fields",
                                                                                   "result_extra"}


def failure_kinds() -> Dict[str, str]:
    """Failure kind -> the episode result's field that says it happened: the failure types of the live table
    (:func:`scenario_bank.failure_types.failure_table`, registered ones included) that results record, most
    severe first."""
    return {row.name: row.result_field for row in failure_table() if row.result_field}


def default_failure() -> Tuple[str, ...]:
    """A failure is any of these unless the run says otherwise (``--failure``): the live table's
    ``regress_default`` types."""
    return tuple(row.name for row in failure_table() if row.regress_default)



def parse_failure(value: Union[None, str, Iterable[str]]) -> List[str]:
    """``"collision,stall"`` or a list of kinds -> the kinds in canonical order; None: the default.

    Raises:
        RegressError: for an empty selection or an unknown kind, naming the kinds there are.
    """
    kinds_known = failure_kinds()
    if value is None:
        return list(default_failure())
    items = value.split(",") if isinstance(value, str) else list(value)
    kinds = [str(item).strip().replace("-", "_") for item in items if str(item).strip()]
    unknown = [kind for kind in kinds if kind not in kinds_known]
    if unknown or not kinds:
        what = f"unknown failure kind {', '.join(map(repr, unknown))}" if unknown else "no failure kind given"
        raise RegressError(f"--failure: {what}; give a comma-separated list of {', '.join(kinds_known)} "
                           f"(default {','.join(default_failure())})")
    return [kind for kind in kinds_known if kind in kinds]


def apply_failure(result: Dict[str, Any], kinds: Sequence[str]) -> Dict[str, Any]:
    """``result`` with ``failed`` and ``failure_kinds`` set from the chosen kinds (errors stay unfailed)."""
    if result.get("error"):
        return result
    fields = failure_kinds()
    happened = [kind for kind, field in fields.items() if bool(result.get(field))]
    result["failure_kinds"] = [kind for kind in happened if kind in kinds]
    result["failed"] = bool(result["failure_kinds"])
    return result


def missing_facts(results: Iterable[Optional[Dict[str, Any]]], kinds: Sequence[str]) -> List[str]:
    """The chosen kinds some (non-error) result has no record of (a run made without that failure type
    registered)."""
    fields = failure_kinds()
    lacking = set()
    for result in results:
        if result and not result.get("error"):
            lacking.update(kind for kind in kinds if fields[kind] not in result)
    return [kind for kind in fields if kind in lacking]


def result_value(result: RegressEpisode, field: str) -> Any:
    """The value of ``field`` of an episode's result (a failure kind's ``result_field`` or another measure): the
    record's attribute, or for a field a plug-in's failure type adds, the value the result carries beside the
    fields the record knows."""
    return getattr(result, field) if field in _RECORD_FIELDS else result.extra.get(field)
