"""The failure types of an episode, in one table: :data:`FAILURE_TABLE`.

Each row (:class:`FailureType`) says what the rest of the project reads about a type: its ``name`` (as mining
records and regression results write it), its ``severity`` (0 is the most severe; the table is in that order),
the field of a regression result that says it happened (``result_field``), whether ``dv2s regress`` counts it
as a failure by default (``regress_default``), whether the failure names the actor it met
(``with_actor``), the ``label`` reports show for it (``None``: reports show its ``name``; :func:`type_label`), and
what kind of failure it is, which the miner's conversion of a failure into a scenario reads: the ego touching
the actor (``contact``), the ego standing (``standstill``), a close call without harm (``near_miss``).

The failure miner detects every type of the table, each through its detector (:mod:`dv2s_gym.mining.monitors`),
and its reports list them in severity order (:func:`failure_table`: the table and the rows added at run time with
:func:`register_failure_type`); ``dv2s regress`` counts the types that have a result field (:mod:`dv2s_gym.regress.failures`).
"""

from __future__ import annotations

import dataclasses
import inspect
from dataclasses import dataclass
from typing import Any, Callable, Dict, Iterable, List, Mapping, Optional, Tuple

from scenario_bank.errors import DV2SError
from scenario_bank.named_registry import Registry
from scenario_bank.plugins import forget_plugin, remember_plugin
from scenario_bank.records import RegressEpisode

__all__ = ["FailureTypeError", "UnknownDetectorError", "FailureType", "FAILURE_TABLE", "FAILURE_TYPES", "failure_table",
           "failure_type", "severity_order",
           "register_failure_type", "unregister_failure_type", "type_label", "attach_detection", "detach_detection",
           "happened", "plugin_table", "is_contact", "is_standstill", "is_near_miss"]


class FailureTypeError(DV2SError, ValueError):
    """A failure type (or its detector) cannot be registered or removed as asked: the name or severity is taken,
    the severity is not a whole number, the type is not there. A :class:`ValueError`, so code catching that keeps
    working."""


class UnknownDetectorError(DV2SError, KeyError):
    """No detector is registered for a failure type in this process. A :class:`KeyError`, so code catching that
    keeps working."""


@dataclass(frozen=True)
class FailureType:
    """One failure type: one row of :data:`FAILURE_TABLE` (see the module docstring for the columns)."""

    name: str
    severity: int
    """0 for the most severe type, then 1, 2, ...: the order the miner prefers and its reports list."""
    result_field: Optional[str]
    """The regression result's field that is true when the type happened; ``None``: results do not record it."""
    regress_default: bool
    """Whether ``dv2s regress`` counts the type as a failure unless ``--failure`` says otherwise."""
    with_actor: bool
    """Whether the failure names the actor it met (a mined failure's ``with``)."""
    label: Optional[str]
    """What reports call the type (:func:`type_label`); ``None``: they call it by its ``name``."""
    contact: bool = False
    """Whether the failure is the ego touching the actor it names, as a collision is: the behaviour of the failure is
    read one state before it (the state at the impact already carries the speed it took away), a failure class also
    compares how they met (``collision_type``), the actor is the trace's first collision of the ego when the failure
    names none, and a scenario converted from it must show that actor colliding with the ego."""
    standstill: bool = False
    """Whether the failure is the ego standing, as a stall is: its video's window covers the standing frames, and
    the actor it involves, when it names none, is the one ahead of the ego where the failure began."""
    near_miss: bool = False
    """Whether the failure is a close call without harm, as a low time-to-collision is: the reference driver's
    failure of this type on a scenario converted from a failure fails the scenario only when the policy's failure
    was no more severe."""


FAILURE_TABLE: Tuple[FailureType, ...] = (
    FailureType("collision", severity=0, result_field="collided", regress_default=True, with_actor=True, label="collision",
                contact=True),
    FailureType("off_road", severity=1, result_field="off_road", regress_default=True, with_actor=False, label="off road"),
    FailureType("low_ttc", severity=2, result_field=None, regress_default=False, with_actor=True, label=None,
                near_miss=True),
    FailureType("stall", severity=3, result_field="stalled", regress_default=True, with_actor=False, label="stall",
                standstill=True),
)
"""Every failure type, most severe first."""

FAILURE_TYPES: Tuple[str, ...] = tuple(row.name for row in FAILURE_TABLE)
"""The failure types' names, most severe first."""

_REGISTERED: Registry[FailureType] = Registry(
    "failure type", FailureTypeError,
    unknown=lambda name, _: FailureTypeError(f"failure type {name!r} was not registered at run time"))
"""Rows added at run time (:func:`register_failure_type`), by name, with the module that registered each."""
_TABLE: Tuple[FailureType, ...] = FAILURE_TABLE
_BY_NAME: Dict[str, FailureType] = {row.name: row for row in FAILURE_TABLE}
_BUILT_IN: Dict[str, FailureType] = dict(_BY_NAME)
_RESULT_FIELDS = frozenset(field.name for field in dataclasses.fields(RegressEpisode))
"""What a regression result records itself: no failure type's ``result_field`` may be one of them."""


def failure_table() -> Tuple[FailureType, ...]:
    """Every failure type, most severe first: :data:`FAILURE_TABLE` and the rows registered at run time."""
    return _TABLE


def failure_type(name: str) -> Optional[FailureType]:
    """The row of the failure type ``name``, or ``None`` for a name that is no failure type."""
    return _BY_NAME.get(name)


def type_label(name: str) -> str:
    """What reports call the failure type ``name``: its row's ``label``, else its name (also for a name that is no
    failure type, e.g. one a run recorded with a plug-in not loaded now)."""
    row = _BY_NAME.get(name)
    return row.label if row is not None and row.label else name


def is_contact(name: Optional[str]) -> bool:
    """Whether the failure type ``name`` is the ego touching an actor (its row's ``contact``; ``False`` for a name
    that is no failure type)."""
    row = _BY_NAME.get(name) if name is not None else None
    return row is not None and row.contact


def is_standstill(name: Optional[str]) -> bool:
    """Whether the failure type ``name`` is the ego standing (its row's ``standstill``; ``False`` for a name that is
    no failure type)."""
    row = _BY_NAME.get(name) if name is not None else None
    return row is not None and row.standstill


def is_near_miss(name: Optional[str]) -> bool:
    """Whether the failure type ``name`` is a close call without harm (its row's ``near_miss``; ``False`` for a name
    that is no failure type)."""
    row = _BY_NAME.get(name) if name is not None else None
    return row is not None and row.near_miss


def severity_order(names: Iterable[str]) -> List[str]:
    """The distinct ``names``: failure types most severe first, then any other names sorted."""
    names = set(names)
    return [row.name for row in _TABLE if row.name in names] + sorted(n for n in names if n not in _BY_NAME)


def register_failure_type(row: FailureType, module: Optional[str] = None, overwrite: bool = False) -> FailureType:
    """Add ``row`` to the table at run time (a plug-in's failure type; the product's own types are rows of
    :data:`FAILURE_TABLE`); its name and severity must be new, unless ``overwrite`` replaces a row registered at
    run time under its name. The miner detects it once its monitor registers a detector for it
    (:func:`dv2s_gym.mining.monitors.register_detector`). Returns ``row``.

    ``module``: the plug-in module that registers it (default: the caller's), which every worker process imports
    before its first episode so that the registration holds there too (:mod:`scenario_bank.plugins`): register
    at the module's import time, in a module other processes can import (not ``__main__``)."""
    if row.name in _BY_NAME and not (overwrite and row.name in _REGISTERED):
        fix = ("; pass overwrite=True to replace it" if row.name in _REGISTERED
               else " (a row of FAILURE_TABLE, which no registration replaces)")
        raise FailureTypeError(f"failure type {row.name!r} exists already{fix}")
    if not isinstance(row.severity, int) or isinstance(row.severity, bool) or row.severity < 0:
        raise FailureTypeError(f"failure type {row.name!r}: severity {row.severity!r} is not a whole number >= 0 (0 is the "
                         "most severe, the table's collision; a plug-in's type takes a number after the table's)")
    if any(other.severity == row.severity for other in _TABLE if other.name != row.name):
        raise FailureTypeError(f"failure type {row.name!r}: severity {row.severity} is taken; choose one no type has")
    _check_result_field(row)
    module = module or _caller_module()
    _REGISTERED.register(row.name, row, overwrite=overwrite, module=module)
    remember_plugin(_plugin_name(row.name), module)
    _rebuild()
    return row


def _check_result_field(row: FailureType) -> None:
    """Refuse a ``result_field`` the regression result already has (a measure such as ``success``, or another
    type's field): the worker writes the type's detection into it, which would overwrite that fact."""
    if not row.result_field:
        return
    taken = {other.result_field: other.name for other in _TABLE if other.result_field and other.name != row.name}
    if row.result_field in taken:
        owner = f"the field of failure type {taken[row.result_field]!r}"
    elif row.result_field in _RESULT_FIELDS:
        owner = "a field the regression result records itself"
    else:
        return
    raise FailureTypeError(f"failure type {row.name!r}: result_field {row.result_field!r} is {owner}; give the "
                           f"type a field of its own (e.g. {row.name + '_seen'!r}), which the regression worker "
                           "fills from its detector")


def _plugin_name(name: str) -> str:
    return f"failure type {name!r}"


def _caller_module() -> Optional[str]:
    """The module of the code that called :func:`register_failure_type`."""
    frame = inspect.currentframe()
    caller = frame.f_back.f_back if frame is not None and frame.f_back is not None else None
    return caller.f_globals.get("__name__") if caller is not None else None


def unregister_failure_type(name: str) -> None:
    """Remove the failure type ``name`` added by :func:`register_failure_type` (the table's own rows stay)."""
    _REGISTERED.unregister(name)
    forget_plugin(_plugin_name(name))
    _rebuild()


Detection = Callable[[Any, Any, Any], bool]
"""``(episode result, trace, monitor settings) -> whether the type happened``; the settings are an
:class:`envs.safety_metrics.MonitorSettings` (a mapping of them, as a run records them, is read too)."""

_DETECTION: Dict[str, Detection] = {}
"""How a registered type is found, by name: set by :func:`dv2s_gym.mining.monitors.register_detector`, so that
a part that may not import the miner (``dv2s regress``'s worker task) can run the detector."""


_DETECTION_MODULES: Dict[str, Optional[str]] = {}
"""The module defining each attached detection (its detector's ``detect``)."""


def attach_detection(name: str, detection: Detection, module: Optional[str] = None) -> None:
    """Let :func:`happened` find the failure type ``name`` with ``detection``, defined in ``module`` (the miner's
    detector registry does this when a detector registers; :func:`detach_detection` undoes it)."""
    _DETECTION[name] = detection
    _DETECTION_MODULES[name] = module


def detach_detection(name: str) -> None:
    """Undo :func:`attach_detection` for ``name``."""
    _DETECTION.pop(name, None)
    _DETECTION_MODULES.pop(name, None)


def plugin_table() -> Dict[str, Dict[str, Optional[str]]]:
    """What plug-ins registered in this process: ``{"failure types": {name: module}, "detectors": {name:
    module}}``, each sorted by name (a detector registered at run time, over a built-in type too; the built-in
    detectors are dv2s's own code and not listed)."""
    types = {name: _REGISTERED.module(name) for name in sorted(_REGISTERED)}
    detectors = {name: _DETECTION_MODULES.get(name) for name in sorted(_DETECTION)}
    return {"failure types": types, "detectors": detectors}


def happened(name: str, result: Any, trace: Any, settings: Any,
             recorded: Optional[Mapping[str, Any]] = None) -> bool:
    """Whether the failure type ``name`` happened in the episode (``result``, ``trace``), decided as every command
    decides it: by the detector registered for it at run time (a plug-in's type, or a plug-in's detector replacing
    a built-in one) with the monitor ``settings`` (an :class:`envs.safety_metrics.MonitorSettings`); a type of
    :data:`FAILURE_TABLE` whose built-in detector stands is decided by the fact the episode's record holds for it
    (``recorded[row.result_field]``: the result's ``collided`` and ``off_road``, which the built-in collision and
    off-road detectors read, and the worker's ``stalled``, :mod:`dv2s_gym.regress.failures`).

    Raises:
        UnknownDetectorError: (a ``KeyError``) when no detector is registered for ``name`` in this process (a plug-in module registers its
            type and detector when it is imported, and every worker process imports it).
    """
    detection = _DETECTION.get(name)
    row = _BUILT_IN.get(name)
    if detection is None and row is not None and row.result_field and recorded is not None \
            and row.result_field in recorded:
        return bool(recorded[row.result_field])
    if detection is None:
        raise UnknownDetectorError(f"failure type {name!r} has no detector registered in this process; its plug-in module "
                       "must register the type and its detector (dv2s_gym.mining.monitors.register_detector) "
                       "when it is imported")
    return bool(detection(result, trace, settings))


def _rebuild() -> None:
    global _TABLE, _BY_NAME
    _TABLE = tuple(sorted(FAILURE_TABLE + tuple(_REGISTERED.values()), key=lambda row: row.severity))
    _BY_NAME = {row.name: row for row in _TABLE}
