"""Failure monitors: what went wrong in an episode, when, and with whom.

:func:`detect_failure` reads an episode's :class:`~policies.evaluation.EpisodeResult` and
its :class:`~envs.trace.EpisodeTrace` and returns the first failure by severity:

- ``collision``: the ego touched another actor; ``with`` names it, ``with_kind`` says what
  it is, ``collision_type`` how they met (from their headings and positions at impact):
  ``rear_end`` (the ego ran into the back of an actor going its way), ``struck_from_behind``,
  ``side``, ``head_on``, ``pedestrian`` or ``obstacle``;
- ``off_road``: the ego left the road;
- ``low_ttc``: time-to-collision fell below ``ttc_threshold`` without a collision;
- ``stall``: the ego stood (speed below :data:`STALL_SPEED`) for ``stall_seconds`` with
  nothing ahead of it in its lane for :data:`FREE_PATH` metres.

:func:`robustness` turns the outcome into one number for VerifAI's adaptive samplers:
negative for a failure (the more negative, the worse), positive otherwise.

A failure is a :class:`~scenario_bank.records.Failure` record (importable from here too), the one episode records
hold. Both walk the failure table (:func:`scenario_bank.failure_types.failure_table`): each type has one
:class:`Detector` in :data:`DETECTORS` that finds it and scores it. A new failure type is its row (with its
label) in ``scenario_bank/failure_types.py`` and its detector here; a plug-in adds both at run time with
:func:`~scenario_bank.failure_types.register_failure_type` and :func:`register_detector`, from an importable
module that registers when it is imported: the registries remember that module and every worker process imports
it before its first episode (:mod:`scenario_bank.plugins`). The settings the monitors read travel as one
:class:`MonitorSettings`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Optional, Sequence

from envs.safety_metrics import (DEFAULT_STALL_SECONDS, DEFAULT_TTC_THRESHOLD, FREE_PATH, STANDING_SPEED,
                                 MonitorSettings, first_stall_step)
from scenario_bank.elements import ActorKind
from scenario_bank.errors import DV2SError
from scenario_bank.failure_types import (FAILURE_TYPES, FailureTypeError, UnknownDetectorError, attach_detection,
                                          detach_detection, failure_table, failure_type, type_label)
from scenario_bank.named_registry import Registry
from scenario_bank.plugins import forget_plugin, remember_plugin
from scenario_bank.read_files import detector_label, reading_for
from scenario_bank.records import Failure

__all__ = ["Failure", "FAILURE_TYPES", "COLLISION_TYPES", "COLLISION_LABELS", "kind_label", "MonitorSettings",
           "Detector", "DetectorResultError", "DETECTORS", "DEFAULT_MONITOR", "register_detector", "unregister_detector", "types_without_detector", "detect_failure",
           "robustness", "STALL_SPEED", "FREE_PATH", "DEFAULT_TTC_THRESHOLD", "DEFAULT_STALL_SECONDS"]

COLLISION_TYPES = ("rear_end", "struck_from_behind", "side", "head_on", "pedestrian", "obstacle")
COLLISION_LABELS = {"rear_end": "rear-end collision", "struck_from_behind": "collision struck from behind",
                    "side": "side collision", "head_on": "head-on collision",
                    "pedestrian": "collision with a pedestrian", "obstacle": "collision with an obstacle"}
"""What the terminal calls a collision of each of :data:`COLLISION_TYPES` (:func:`kind_label`)."""
STALL_SPEED = STANDING_SPEED
"""m/s under which the ego counts as standing."""
_VEHICLES = (ActorKind.CAR, ActorKind.TRUCK, ActorKind.BICYCLE, ActorKind.MOTORCYCLE, None)
"""The kinds (and no kind) a collision is typed by the actors' headings for; the others count as obstacles."""


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2 * math.pi) - math.pi


def kind_label(kind: str) -> str:
    """What the terminal calls a failure kind (:attr:`Failure.kind`, ``type`` or ``type:collision_type``): a
    collision by its type (:data:`COLLISION_LABELS`, ``"rear-end collision"``), any other type by its failure-table
    label (:func:`~scenario_bank.failure_types.type_label`, ``"off road"``), a refinement no table names after it in
    words (``"collision (t bone)"``). Reports written as JSON keep the kinds themselves."""
    name, _, refined = kind.partition(":")
    if name == "collision" and refined in COLLISION_LABELS:
        return COLLISION_LABELS[refined]
    return type_label(name) + (f" ({refined.replace('_', ' ')})" if refined else "")


def collision_type(ego: List[float], other: List[float], other_kind: Optional[str]) -> str:
    """How two actors met, from their ``[x, y, heading, speed]`` states at impact."""
    if other_kind == ActorKind.PEDESTRIAN:
        return "pedestrian"
    if other_kind == ActorKind.OBSTACLE or other_kind not in _VEHICLES:
        return "obstacle"
    relative = abs(_wrap(other[2] - ego[2]))
    if relative > 3 * math.pi / 4:
        return "head_on"
    if relative < math.pi / 4:
        dx, dy = other[0] - ego[0], other[1] - ego[1]
        ahead = dx * math.cos(ego[2]) + dy * math.sin(ego[2])
        lateral = -dx * math.sin(ego[2]) + dy * math.cos(ego[2])
        if abs(lateral) < abs(ahead):
            return "rear_end" if ahead > 0 else "struck_from_behind"
    return "side"


def _step_at(trace, time: float) -> int:
    period = 1.0 / float(trace.config.get("policy_frequency", 5))
    return max(0, min(len(trace.states) - 1, int(round(time / period))))


@dataclass(frozen=True)
class Detector:
    """How the miner finds the failure type ``name`` (a row of the failure table) and scores it:
    ``detect(result, trace, settings)`` returns the episode's failure of that type (a :class:`Failure`) or
    ``None``; ``score(result, failure, settings)`` is the failure's robustness for the adaptive samplers, below 0
    (the more negative, the worse)."""

    name: str
    detect: Callable[[Any, Any, MonitorSettings], Optional[Failure]]
    score: Callable[[Any, Failure, MonitorSettings], float]


class DetectorResultError(DV2SError, TypeError):
    """A detector's ``detect`` returned something other than a :class:`Failure` or ``None``."""


def _detected(detector: Detector, result, trace, settings: MonitorSettings) -> Optional[Failure]:
    """``detector.detect(result, trace, settings)``, checked: a :class:`Failure` or ``None``.

    Raises:
        DetectorResultError: naming the detector, its module, what it returned and the fix. A failure's JSON
            object (what ``episodes.jsonl`` shows) is refused too, not read: the detector's contract is the record.
    """
    with reading_for(detector_label(detector.name)):  # what it reads decides the kind: part of a run's identity
        failure = detector.detect(result, trace, settings)
    if failure is None or isinstance(failure, Failure):
        return failure
    module = getattr(detector.detect, "__module__", None) or "unknown"
    raise DetectorResultError(
        f"the detector of failure type {detector.name!r} (module {module}) returned a {type(failure).__name__}, not "
        f"a dv2s_gym.mining.monitors.Failure (or None): return Failure({detector.name!r}, time, step, ...) when "
        "the episode has the failure, None otherwise (docs/mining.md, 'Adding a failure type')")


def _time_of(trace, step: int) -> float:
    return step / float(trace.config.get("policy_frequency", 5))


def _collision(result, trace, settings: MonitorSettings) -> Optional[Failure]:
    if not result.collided:
        return None
    event = trace.ego_collision()
    if event is not None:
        other = trace.other_actor(event)
        step = _step_at(trace, float(event["time"]))
        kind = trace.kinds.get(other) if other else None
        states = trace.states[step]
        ctype = (collision_type(states["ego"], states[other], kind)
                 if other in states and "ego" in states else None)
        return Failure("collision", float(event["time"]), step, other, kind, ctype,
                       _finite(result.min_ttc), _ego_speed(states))
    step = len(trace.states) - 1
    return Failure("collision", _time_of(trace, step), step, result.collisions[0] if result.collisions else None)


def _collision_score(result, failure: Failure, settings: MonitorSettings) -> float:
    speed = failure.speed if failure.speed is not None else result.mean_speed
    return -1.0 - float(speed) / 10.0


def _off_road(result, trace, settings: MonitorSettings) -> Optional[Failure]:
    if not result.off_road:
        return None
    for event in trace.events:
        if event.get("kind") == "off_road":
            return Failure("off_road", float(event["time"]), _step_at(trace, float(event["time"])))
    step = len(trace.states) - 1
    return Failure("off_road", _time_of(trace, step), step)


def _low_ttc(result, trace, settings: MonitorSettings) -> Optional[Failure]:
    if not result.min_ttc < settings.ttc_threshold:
        return None
    time = float(result.min_ttc_time) if result.min_ttc_time is not None else 0.0
    other = result.min_ttc_with or None
    return Failure("low_ttc", time, _step_at(trace, time), other, trace.kinds.get(other) if other else None,
                   None, float(result.min_ttc))


def _low_ttc_score(result, failure: Failure, settings: MonitorSettings) -> float:
    return min(-1e-3, float(result.min_ttc) - settings.ttc_threshold)


def _off_road_score(result, failure: Failure, settings: MonitorSettings) -> float:
    return -1.0


def _stall_detect(result, trace, settings: MonitorSettings) -> Optional[Failure]:
    return _stall(trace, settings)


def _stall_score(result, failure: Failure, settings: MonitorSettings) -> float:
    return -0.5


def _no_detector(name: str, known: Sequence[str]) -> UnknownDetectorError:
    return UnknownDetectorError(f"failure type {name!r} has no detector in this process: register one with "
                                "dv2s_gym.mining.monitors.register_detector in the plug-in module that registers "
                                "the type")


DETECTORS: Registry[Detector] = Registry("detector", FailureTypeError, {detector.name: detector for detector in (
    Detector("collision", _collision, _collision_score),
    Detector("off_road", _off_road, _off_road_score),
    Detector("low_ttc", _low_ttc, _low_ttc_score),
    Detector("stall", _stall_detect, _stall_score),
)}, unknown=_no_detector)
"""Each failure type's detector, by the type's name (every row of the failure table has one, and each detector
a row); :func:`detect_failure` asks them in the order of :func:`~scenario_bank.failure_types.failure_table`
(most severe first)."""


def register_detector(detector: Detector, overwrite: bool = False) -> Detector:
    """Detect the failure type ``detector.name`` (a row of the failure table, e.g. one added with
    :func:`~scenario_bank.failure_types.register_failure_type`) with ``detector``; :func:`unregister_detector`
    undoes it. ``dv2s regress`` runs it too when its type has a ``result_field``
    (:func:`scenario_bank.failure_types.happened`). The module defining ``detector.detect`` is remembered as a
    plug-in module: every worker process imports it before its first episode, so it must register the detector
    when it is imported and be importable (not ``__main__``; :mod:`scenario_bank.plugins`). A type with a
    detector already needs ``overwrite=True``. Returns ``detector``."""
    if failure_type(detector.name) is None:
        raise FailureTypeError(f"no failure type {detector.name!r}: add its row to scenario_bank/failure_types.py first")
    if detector.name in DETECTORS and not overwrite:
        raise FailureTypeError(f"failure type {detector.name!r} has a detector already; pass overwrite=True to "
                               "replace it")
    module = getattr(detector.detect, "__module__", None)
    DETECTORS.register(detector.name, detector, overwrite=overwrite, module=module)
    remember_plugin(_plugin_name(detector.name), module)
    attach_detection(detector.name, lambda result, trace, settings: _detected(
        detector, result, trace, MonitorSettings.of(settings)) is not None, module)
    return detector


def unregister_detector(name: str) -> None:
    """Remove the detector :func:`register_detector` added for ``name``."""
    DETECTORS.unregister(name)
    detach_detection(name)
    forget_plugin(_plugin_name(name))


def _plugin_name(name: str) -> str:
    return f"the detector of failure type {name!r}"


def types_without_detector() -> List[str]:
    """The failure types of the table (with the rows registered at run time) that no detector finds in this
    process: the miner refuses to start while there is one."""
    return [row.name for row in failure_table() if row.name not in DETECTORS]


def _detector(name: str) -> Detector:
    return DETECTORS.get(name)


DEFAULT_MONITOR = MonitorSettings()


def detect_failure(result, trace, settings: MonitorSettings = DEFAULT_MONITOR) -> Optional[Failure]:
    """The episode's failure (see the module docstring): that of the most severe type whose detector finds one,
    or ``None``."""
    if result.error is not None:
        return None
    for row in failure_table():
        failure = _detected(_detector(row.name), result, trace, settings)
        if failure is not None:
            return failure
    return None


def _stall(trace, settings: MonitorSettings) -> Optional[Failure]:
    """The episode's first stall (the ego stood for the settings' ``stall_seconds`` with a free path ahead), or
    ``None``, whatever else happened in it."""
    start = first_stall_step(trace, settings.stall_seconds)
    if start is None:
        return None
    return Failure("stall", _time_of(trace, start), start)


def _ego_speed(states: Dict[str, List[float]]) -> Optional[float]:
    return float(states["ego"][3]) if "ego" in states else None


def _finite(value: float) -> Optional[float]:
    return float(value) if math.isfinite(value) else None


def robustness(result, failure: Optional[Failure], settings: MonitorSettings = DEFAULT_MONITOR) -> float:
    """One number per episode for the adaptive samplers: below 0 exactly when ``failure`` is set.

    A failure scores what its type's detector says (:data:`DETECTORS`): a collision ``-1 - (ego speed at
    impact) / 10``, leaving the road ``-1``, a stall ``-0.5``, a low TTC ``ttc - threshold``; an episode without
    failure scores its smallest TTC above the threshold (capped at 10 s), so near misses rank before easy scenes.
    """
    if result.error is not None:
        return 0.0
    if failure is not None:
        return _detector(failure.type).score(result, failure, settings)
    ttc = result.min_ttc if math.isfinite(result.min_ttc) else 10.0
    return max(1e-3, min(ttc, 10.0) - settings.ttc_threshold)
