"""The typed record of one loop round: :class:`RoundRecord`, a round of ``loop.json`` and of ``report.json``'s
``rounds``, as the loop writes it and the verdict and the reports read it.

A round holds its number, the policy it started from, the fine-tuned (``new_policy``) and control policies, the
policy the next round starts from and why, the seconds of each step (``timings``) and each finished step's
record (:class:`RoundSteps`). The held-out comparison (the ``after`` step) is typed in full
(:class:`HeldOutComparison`): the held-out counts the verdict's floors read, each arm's failures by type
(:class:`ArmFailureTypes`) and the fine-tuned policy against the control (:class:`VersusControl`, its paired
table :class:`ControlTable`). The other steps are JSON objects as their steps make them.

Each is a :class:`~scenario_bank.records.JsonRecord`: :meth:`from_dict` reads the JSON object (a
:class:`~scenario_bank.records.RecordError` names a field of the wrong kind, ``round.steps.after.pairs``),
:meth:`to_dict` writes exactly the object read or recorded (unknown keys kept in ``extra``, ``null`` where it was).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar, Dict, FrozenSet, Mapping, Optional, Tuple

from scenario_bank.records import JsonRecord

__all__ = ["RoundRecord", "RoundSteps", "HeldOutComparison", "ArmFailureTypes", "VersusControl", "ControlTable",
           "STEPS"]

STEPS = ("mine", "split", "reference", "before", "fine_tune", "control", "after", "untouched", "regress")
"""The steps of a round, in the order they run (a round that kept no mined scenario has ``skipped`` after
``split`` instead of the rest)."""


@dataclass(frozen=True, eq=False)
class ControlTable(JsonRecord):
    """The paired held-out table of the fine-tuned policy against the control: pairs where both failed, only the
    fine-tuned one, only the control, neither."""

    both_fail: Optional[int] = None
    fine_tuned_only: Optional[int] = None
    control_only: Optional[int] = None
    neither: Optional[int] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _KINDS: ClassVar[Dict[str, str]] = {"both_fail": "int", "fine_tuned_only": "int", "control_only": "int",
                                        "neither": "int"}
    _WHAT: ClassVar[str] = "control table"


@dataclass(frozen=True, eq=False)
class VersusControl(JsonRecord):
    """The fine-tuned policy against the control on the held-out pairs: ``pairs`` tested and ``errors`` left out,
    the ``relative_drop`` of the failure rate, the paired ``table``, the exact McNemar p, the control's failures
    per scenario, and ``underpowered`` (why there is no test) below the loop's minimums."""

    pairs: Optional[int] = None
    errors: Optional[int] = None
    relative_drop: Optional[float] = None
    table: Optional[ControlTable] = None
    mcnemar_p: Optional[float] = None
    per_scenario: Optional[Mapping[str, Any]] = None
    underpowered: Optional[str] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _KINDS: ClassVar[Dict[str, str]] = {"pairs": "int", "errors": "int", "relative_drop": "number",
                                        "table": "object", "mcnemar_p": "number", "per_scenario": "object",
                                        "underpowered": "str"}
    _NESTED: ClassVar[Dict[str, type]] = {"table": ControlTable}
    _WHAT: ClassVar[str] = "comparison with the control"

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset({"relative_drop", "mcnemar_p"})


@dataclass(frozen=True, eq=False)
class ArmFailureTypes(JsonRecord):
    """Each arm's held-out failures by type (``{type: count}``): the starting policy's, the fine-tuned one's and,
    with a control arm, the control's."""

    start: Optional[Mapping[str, int]] = None
    fine_tuned: Optional[Mapping[str, int]] = None
    control: Optional[Mapping[str, int]] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _KINDS: ClassVar[Dict[str, str]] = {"start": "object", "fine_tuned": "object", "control": "object"}
    _WHAT: ClassVar[str] = "failures by type"


@dataclass(frozen=True, eq=False)
class HeldOutComparison(JsonRecord):
    """A round's ``after`` step (:func:`dv2s_gym.mining.loop.heldout_comparison`): the starting and the fine-tuned
    policy on the held-out pairs (``pairs`` tested, ``errors`` left out, the failure rates ``before`` and
    ``after``, the ``relative_drop`` with its interval over families, the paired ``table`` and McNemar p, each
    scenario's counts), the held-out counts (``heldout_scenarios``, ``heldout_families`` tested,
    ``sampled_families``) against the minimums, each arm's ``failure_types``, the ``control``'s rate and
    ``vs_control``, ``underpowered`` (why the drop and the tests are left out), the ``margin`` and the held-out tests
    (``significantly_worse``: ``start`` and ``control``), and the episodes that ``errored`` per policy."""

    pairs: Optional[int] = None
    errors: Optional[int] = None
    before: Optional[Mapping[str, Any]] = None
    after: Optional[Mapping[str, Any]] = None
    relative_drop: Optional[float] = None
    relative_drop_interval: Optional[Tuple[Any, ...]] = None
    relative_drop_interval_unit: Optional[str] = None
    relative_drop_interval_units: Optional[int] = None
    mcnemar_unit: Optional[str] = None
    pairs_per_family: Optional[Mapping[str, int]] = None
    table: Optional[Mapping[str, int]] = None
    mcnemar_p: Optional[float] = None
    per_scenario: Optional[Mapping[str, Any]] = None
    min_episodes: Optional[int] = None
    heldout_scenarios: Optional[int] = None
    heldout_families: Optional[int] = None
    sampled_families: Optional[int] = None
    min_families: Optional[int] = None
    failure_types: Optional[ArmFailureTypes] = None
    control: Optional[Mapping[str, Any]] = None
    vs_control: Optional[VersusControl] = None
    underpowered: Optional[str] = None
    margin: Optional[float] = None
    significantly_worse: Optional[Mapping[str, Any]] = None
    errored: Optional[Mapping[str, Any]] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _KINDS: ClassVar[Dict[str, str]] = {
        "pairs": "int", "errors": "int", "before": "object", "after": "object", "relative_drop": "number",
        "relative_drop_interval": "list", "relative_drop_interval_unit": "str", "relative_drop_interval_units": "int",
        "mcnemar_unit": "str", "pairs_per_family": "object", "table": "object", "mcnemar_p": "number",
        "per_scenario": "object", "min_episodes": "int", "heldout_scenarios": "int", "heldout_families": "int",
        "sampled_families": "int", "min_families": "int", "failure_types": "object", "control": "object",
        "vs_control": "object", "underpowered": "str", "margin": "number", "significantly_worse": "object",
        "errored": "object",
    }
    _NESTED: ClassVar[Dict[str, type]] = {"failure_types": ArmFailureTypes, "vs_control": VersusControl}
    _LISTS: ClassVar[Tuple[str, ...]] = ("relative_drop_interval",)
    _WHAT: ClassVar[str] = "held-out comparison"

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset({"relative_drop", "mcnemar_p", "pairs_per_family"})

    def held_out_test(self, against: str) -> Optional[Mapping[str, Any]]:
        """The recorded held-out test against ``start`` or ``control``
        (:func:`~dv2s_gym.mining.loop_verdict.heldout_worse`; ``None`` when not tested)."""
        return (self.significantly_worse or {}).get(against)


@dataclass(frozen=True, eq=False)
class RoundSteps(JsonRecord):
    """Each finished step's record of a round (:data:`STEPS`; a step not run yet is ``None``), or ``skipped``: why
    a round that kept no mined scenario measured nothing."""

    mine: Optional[Mapping[str, Any]] = None
    split: Optional[Mapping[str, Any]] = None
    skipped: Optional[str] = None
    reference: Optional[Mapping[str, Any]] = None
    before: Optional[Mapping[str, Any]] = None
    fine_tune: Optional[Mapping[str, Any]] = None
    control: Optional[Mapping[str, Any]] = None
    after: Optional[HeldOutComparison] = None
    untouched: Optional[Mapping[str, Any]] = None
    regress: Optional[Mapping[str, Any]] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _KINDS: ClassVar[Dict[str, str]] = {"mine": "object", "split": "object", "skipped": "str", "reference": "object",
                                        "before": "object", "fine_tune": "object", "control": "object",
                                        "after": "object", "untouched": "object", "regress": "object"}
    _NESTED: ClassVar[Dict[str, type]] = {"after": HeldOutComparison}
    _WHAT: ClassVar[str] = "steps"

    def done(self, step: str) -> bool:
        """Whether ``step`` (one of :data:`STEPS` or ``skipped``) is recorded."""
        return getattr(self, step) is not None


@dataclass(frozen=True, eq=False)
class RoundRecord(JsonRecord):
    """One round of a loop: its number (``round``), each finished step (``steps``, :class:`RoundSteps`) and its
    seconds (``timings``), the ``policy`` it started from, the fine-tuned ``new_policy`` and ``control_policy``, and
    the ``next_policy`` the next round starts from with its ``next_policy_reason``. A round of ``report.json`` also
    carries its cross-round check (``final_vs_start``, in ``extra``)."""

    round: int
    steps: RoundSteps = field(default_factory=RoundSteps)
    timings: Mapping[str, float] = field(default_factory=dict)
    policy: Optional[str] = None
    new_policy: Optional[str] = None
    control_policy: Optional[str] = None
    next_policy: Optional[str] = None
    next_policy_reason: Optional[str] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _KINDS: ClassVar[Dict[str, str]] = {"round": "int", "steps": "object", "timings": "object", "policy": "str",
                                        "new_policy": "str", "control_policy": "str", "next_policy": "str",
                                        "next_policy_reason": "str"}
    _REQUIRED: ClassVar[Tuple[str, ...]] = ("round",)
    _NESTED: ClassVar[Dict[str, type]] = {"steps": RoundSteps}
    _WHAT: ClassVar[str] = "round"

    @classmethod
    def started(cls, number: int) -> "RoundRecord":
        """The record of round ``number`` before any step: no step, no timing."""
        return cls.from_dict({"round": number, "steps": {}, "timings": {}})

    def with_step(self, step: str, value: Any, seconds: Optional[float] = None) -> "RoundRecord":
        """A copy with ``step``'s record (a JSON object, or ``skipped``'s reason) and, when given, its ``seconds``."""
        steps = RoundSteps.from_dict({**self.steps.to_dict(), step: value})
        timings = self.timings if seconds is None else {**self.timings, step: seconds}
        return self.replace(steps=steps, timings=timings)

    @property
    def fine_tuned(self) -> bool:
        """Whether the round fine-tuned a policy (it has one, or its ``fine_tune`` step ran)."""
        return bool(self.new_policy) or self.steps.fine_tune is not None
