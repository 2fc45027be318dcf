"""The typed record of one loop round: :class:`RoundRecord`, a round of ``loop.json`` and of ``report.json``'s
``rounds``, as the loop writes it and the verdict and the reports read it.

A round holds its number, the policy it started from, the fine-tuned (``new_policy``) and control policies, the
policy the next round starts from and why, the seconds of each step (``timings``) and each finished step's
record (:class:`RoundSteps`). The held-out comparison (the ``after`` step) is typed in full
(:class:`HeldOutComparison`): the held-out counts the verdict's floors read, each arm's failures by type
(:class:`ArmFailureTypes`) and the fine-tuned policy against the control (:class:`VersusControl`, its paired
table :class:`ControlTable`). The other steps are typed too: ``mine`` (:class:`MiningSummary`, its kept scenarios
each a :class:`MinedEntry`), ``split`` (:class:`SplitRecord`), ``reference`` (:class:`ReferenceGate`), ``before``
(:class:`HeldOutBefore`), ``fine_tune`` and ``control`` (:class:`FineTuneArm`), ``untouched``
(:class:`UntouchedComparison`, its comparisons :class:`RegressComparison`) and ``regress``
(:class:`RegressSummary`). Maps keyed by scenario, policy or status (counts, errored episodes, per-scenario rows)
stay JSON objects inside them. The body of ``report.json`` (the settings, the rounds, the recommendation and the
cross-round check), which the Markdown and HTML reports are rendered from, is a :class:`LoopReportBody`.

Each is a :class:`~scenario_bank.records.JsonRecord`: :meth:`from_dict` reads the JSON object (a
:class:`~scenario_bank.records.RecordError` names a field of the wrong kind, ``round.steps.after.pairs``),
:meth:`to_dict` writes exactly the object read or recorded (unknown keys kept in ``extra``, ``null`` where it was).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar, Dict, FrozenSet, Mapping, Optional, Tuple

from policies.card_record import FineTuneMethod
from policies.stats import Rate
from scenario_bank.records import JsonRecord, recorded

__all__ = ["ErroredEpisodes", "LoopStart", "RecordedLoopSettings", "PairedTable", "PairedSummary",
           "FamilyHarmRow", "FamilyHarm", "HeldOutWorse", "HeldOutTests", "FinalVsStart",
           "RoundRecord", "RoundSteps", "HeldOutComparison", "ArmFailureTypes", "VersusControl", "ControlTable",
           "MinedEntry", "MiningSummary", "SplitRecord", "ReferenceGate", "HeldOutBefore", "FineTuneArm",
           "RegressComparison", "UntouchedComparison", "RegressSummary", "LoopReportBody", "STEPS", "recorded"]

STEPS = ("mine", "split", "reference", "before", "fine_tune", "control", "after", "untouched", "regress")
"""The steps of a round, in the order they run (a round that kept no mined scenario has ``skipped`` after
``split`` instead of the rest)."""


@dataclass(frozen=True, eq=False)
class ErroredEpisodes(JsonRecord):
    """The episodes of a step (or of one policy in it) that ended in an error
    (:func:`dv2s_gym.loop.errored.errored_episodes`): how many (``episodes``), how many per scenario
    (``scenarios``), each scenario's distinct kinds of error message with their counts (``messages``: ``{scenario:
    [{"message", "count"[, "example"]}]}``) and each scenario's first error (``examples``)."""

    episodes: Optional[int] = None
    scenarios: Optional[Mapping[str, int]] = None
    messages: Optional[Mapping[str, Any]] = None
    examples: Optional[Mapping[str, str]] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "errored episodes"


@dataclass(frozen=True, eq=False)
class LoopStart(JsonRecord):
    """Where a loop started (``loop.json``'s ``start``): its working ``bank`` and the bank ``scenarios`` it mines and
    regression-tests, chosen once when the loop began."""

    bank: Optional[str] = None
    scenarios: Tuple[str, ...] = field(kw_only=True)
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _REQUIRED: ClassVar[Tuple[str, ...]] = ("scenarios",)
    _WHAT: ClassVar[str] = "loop start"


@dataclass(frozen=True, eq=False)
class RecordedLoopSettings(JsonRecord):
    """``loop.json``'s ``settings``: the starting ``policy``, the loop's settings as recorded
    (:meth:`~dv2s_gym.loop.settings.LoopSettings.recorded`: the resolved ``bank_dir`` and every other
    setting, the latter kept in ``extra`` by name), the resolved number of ``workers``, how mined scenarios are held
    out (``holdout_by``), the env configs of the policy and of fine-tuning, and the starting policy's fingerprint (in
    ``extra``)."""

    policy: str
    bank_dir: Optional[str] = None
    workers: Optional[int] = None
    holdout_by: Optional[str] = None
    env_config: Optional[Mapping[str, Any]] = None
    fine_tune_env_config: Optional[Mapping[str, Any]] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _REQUIRED: ClassVar[Tuple[str, ...]] = ("policy",)
    _WHAT: ClassVar[str] = "loop settings"

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset({"bank_dir"})


@dataclass(frozen=True, eq=False)
class PairedTable(JsonRecord):
    """The paired held-out table of the fine-tuned policy (``after``) against the starting one (``before``): pairs
    where both failed, only the fine-tuned one, only the start, neither."""

    both_fail: Optional[int] = None
    after_only: Optional[int] = None
    before_only: Optional[int] = None
    neither: Optional[int] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "paired table"


@dataclass(frozen=True, eq=False)
class PairedSummary(JsonRecord):
    """Two policies' held-out episodes compared pair by pair (:func:`dv2s_gym.loop.heldout.paired_summary`):
    ``pairs`` tested and ``errors`` left out, the rates ``before`` and ``after``, the ``relative_drop`` with its
    bootstrap interval and what it resampled, the paired ``table`` and exact McNemar p, and each scenario's
    counts (``per_scenario``: ``{scenario: {"n", "before", "after"}}``)."""

    pairs: int = 0
    errors: int = 0
    before: Rate = field(default_factory=Rate)
    after: Rate = field(default_factory=Rate)
    relative_drop: Optional[float] = None
    relative_drop_interval: Tuple[Any, ...] = (None, None)
    relative_drop_interval_unit: Optional[str] = None
    relative_drop_interval_units: Optional[int] = None
    mcnemar_unit: Optional[str] = None
    pairs_per_family: Optional[Mapping[str, int]] = None
    table: PairedTable = field(default_factory=PairedTable)
    mcnemar_p: Optional[float] = None
    per_scenario: Mapping[str, Any] = field(default_factory=dict)
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "paired summary"

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset({"relative_drop", "mcnemar_p", "pairs_per_family"})


@dataclass(frozen=True, eq=False)
class FamilyHarmRow(JsonRecord):
    """One held-out family of the harm rule (:func:`dv2s_gym.loop.verdict.family_harm`): its tested ``pairs``,
    those only the fine-tuned policy failed (``fine_tuned_only``) and only the other failed (``other_only``), the
    ``difference`` in failure rate (fine-tuned minus other) with its two-sided 95 % Newcombe ``interval``, the
    one-sided non-inferiority p-value at the margin and its Holm adjustment (``holm_p``), whether that test showed
    the family ``non_inferior`` and whether the difference is a ``harm`` (worse than the margin)."""

    pairs: Optional[int] = None
    fine_tuned_only: Optional[int] = None
    other_only: Optional[int] = None
    difference: Optional[float] = None
    interval: Optional[Tuple[float, ...]] = None
    non_inferiority_p: Optional[float] = None
    holm_p: Optional[float] = None
    non_inferior: Optional[bool] = None
    harm: Optional[bool] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "held-out family"

    def default_null_fields(self) -> FrozenSet[str]:
        return self.json_fields()


@dataclass(frozen=True, eq=False)
class FamilyHarm(JsonRecord):
    """The held-out families' harm rule of one held-out test (:func:`dv2s_gym.loop.verdict.family_harm`): the
    ``margin`` and the ``rule`` in words, each tested family's row (``families``: :class:`FamilyHarmRow` by name),
    the families whose difference is worse than the margin (``harmed``) and those shown ``non_inferior``."""

    margin: Optional[float] = None
    rule: Optional[str] = None
    families: Mapping[str, FamilyHarmRow] = field(default_factory=dict)
    harmed: Tuple[str, ...] = ()
    non_inferior: Tuple[str, ...] = ()
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "family harm"

    def default_null_fields(self) -> FrozenSet[str]:
        return self.json_fields()


@dataclass(frozen=True, eq=False)
class HeldOutWorse(JsonRecord):
    """One held-out test (:func:`dv2s_gym.loop.verdict.heldout_worse`): is the fine-tuned policy significantly
    ``worse`` than the policy it is tested ``against`` (``start`` or ``control``) on the held-out families, by
    ``test``; the number of ``families`` and ``pairs`` tested, the pooled discordant counts (``fine_tuned_only``,
    ``other_only``) and pooled one-sided ``p_value``, the ``worse_families``, the ``reason`` in words and the
    families' harm rule (``family_harm``: :class:`FamilyHarm`)."""

    against: Optional[str] = None
    test: Optional[str] = None
    worse: Optional[bool] = None
    families: Optional[int] = None
    pairs: Optional[int] = None
    fine_tuned_only: Optional[int] = None
    other_only: Optional[int] = None
    p_value: Optional[float] = None
    worse_families: Tuple[str, ...] = ()
    reason: Optional[str] = None
    family_harm: Optional[FamilyHarm] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "held-out test"

    def default_null_fields(self) -> FrozenSet[str]:
        return self.json_fields()


@dataclass(frozen=True, eq=False)
class HeldOutTests(JsonRecord):
    """A round's held-out tests (the ``after`` step's ``significantly_worse``): against the ``start`` and against
    the ``control`` (:class:`HeldOutWorse`; ``None``, written ``null``, when that test did not run)."""

    start: Optional[HeldOutWorse] = None
    control: Optional[HeldOutWorse] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "held-out tests"

    def default_null_fields(self) -> FrozenSet[str]:
        return self.json_fields()


@dataclass(frozen=True, eq=False)
class FinalVsStart(JsonRecord):
    """The cross-round check (:func:`dv2s_gym.loop.report.final_vs_start`): round ``rounds[1]``'s fine-tuned policy
    (``final``) against the ``start`` on the starting bank, paired by episode over ``rounds`` (first and last
    regression-tested round): the regression test's ``verdict`` and ``reason``, the paired ``episodes``, both
    failure rates (``{"value", "low", "high", "count"}``), the ``difference`` with its interval, ``p_value``, the
    ``regressed`` scenarios and the paired ``report``'s path. When the check could not be made it holds only the
    ``error`` (why)."""

    start: Optional[str] = None
    final: Optional[str] = None
    rounds: Optional[Tuple[int, ...]] = None
    verdict: Optional[str] = None
    reason: Optional[str] = None
    episodes: Optional[int] = None
    new_failure_rate: Optional[Mapping[str, Any]] = None
    old_failure_rate: Optional[Mapping[str, Any]] = None
    difference: Optional[Mapping[str, Any]] = None
    p_value: Optional[float] = None
    regressed: Optional[Tuple[str, ...]] = None
    report: Optional[str] = None
    error: Optional[str] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "cross-round check"

    def default_null_fields(self) -> FrozenSet[str]:
        # a check that ran writes every field; one that could not be made writes only its error
        return frozenset() if self.error is not None else self.json_fields() - {"error"}

    @classmethod
    def failed(cls, error: str) -> "FinalVsStart":
        """The check that could not be made, and why."""
        return cls(error=error)


@dataclass(frozen=True, eq=False)
class MinedEntry(JsonRecord):
    """One scenario a round's mining kept (:func:`dv2s_gym.loop.mined.mined_entries`): its ``cluster``, the bank
    entry (``scenario``) and the failure's ``reproduction`` rate; an exact replay has ``replay`` true, its
    ``parent`` scenario and, when it leaves parameters at the parent's distribution, ``not_narrowed``
    (``{parameter: why}``). The loop gives every entry its family as ``parent`` before the split."""

    cluster: str
    scenario: str
    reproduction: Optional[float] = None
    parent: Optional[str] = None
    replay: Optional[bool] = None
    not_narrowed: Optional[Mapping[str, Any]] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _REQUIRED: ClassVar[Tuple[str, ...]] = ("cluster", "scenario")
    _WHAT: ClassVar[str] = "mined entry"

    def default_null_fields(self) -> FrozenSet[str]:
        # as the loop writes them: a converted entry's reproduction and an exact replay's parent are always there
        return frozenset({"reproduction"} | ({"parent"} if self.replay else set()))


@dataclass(frozen=True, eq=False)
class MiningSummary(JsonRecord):
    """A round's ``mine`` step: the mining run's counts (``episodes``, ``errors``, ``failures``,
    ``failures_against_policy``, ``clusters`` and those not converted, not kept or whose scenes the reference
    driver failed too), ``conversions`` and ``replays`` by status, the rejected conversions' reasons (at most 40,
    and their count), the ``errored`` episodes, the ``kept`` scenarios (:class:`MinedEntry`) and the run's
    ``folder``."""

    episodes: Optional[int] = None
    errors: Optional[int] = None
    errored: Optional[ErroredEpisodes] = None
    failures: Optional[int] = None
    failures_against_policy: Optional[int] = None
    clusters: Optional[int] = None
    conversions: Optional[Mapping[str, int]] = None
    replays: Optional[Mapping[str, int]] = None
    rejected_reasons: Optional[Tuple[str, ...]] = None
    rejected_reason_count: Optional[int] = None
    clusters_not_converted: Optional[int] = None
    clusters_not_kept: Optional[int] = None
    clusters_reference_failed: Optional[int] = None
    kept: Optional[Tuple[MinedEntry, ...]] = None
    folder: Optional[str] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _KIND_OVERRIDES: ClassVar[Dict[str, Optional[str]]] = {"rejected_reasons": "list", "kept": "list"}
    _WHAT: ClassVar[str] = "mining step"

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset({"clusters", "clusters_not_converted", "clusters_not_kept", "clusters_reference_failed"})

    @property
    def kept_entries(self) -> Tuple[MinedEntry, ...]:
        """The kept scenarios (none when not recorded)."""
        return self.kept or ()

    @property
    def converted(self) -> Tuple[MinedEntry, ...]:
        """The kept scenarios converted from a failure (not exact replays)."""
        return tuple(entry for entry in self.kept_entries if not entry.replay)

    @property
    def replayed(self) -> Tuple[MinedEntry, ...]:
        """The kept exact replays."""
        return tuple(entry for entry in self.kept_entries if entry.replay)


@dataclass(frozen=True, eq=False)
class SplitRecord(JsonRecord):
    """A round's ``split`` step (:meth:`dv2s_gym.loop.split.FamilySplit.record`): the scenarios, clusters and
    families to fine-tune on and to hold out, the number of family ``groups`` and the earlier held-out families
    moved to the fine-tuning side (``moved_to_fine_tune``). A list a loop did not record reads as empty."""

    by: Optional[str] = None
    fine_tune: Optional[Tuple[str, ...]] = None
    held_out: Optional[Tuple[str, ...]] = None
    fine_tune_clusters: Optional[Tuple[str, ...]] = None
    held_out_clusters: Optional[Tuple[str, ...]] = None
    fine_tune_families: Optional[Tuple[str, ...]] = None
    held_out_families: Optional[Tuple[str, ...]] = None
    groups: Optional[int] = None
    moved_to_fine_tune: Optional[Tuple[str, ...]] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "split"

    @property
    def held_out_scenarios(self) -> Tuple[str, ...]:
        """The held-out scenarios (none when not recorded)."""
        return self.held_out or ()

    @property
    def fine_tune_scenarios(self) -> Tuple[str, ...]:
        """The fine-tuning scenarios (none when not recorded)."""
        return self.fine_tune or ()

    @property
    def held_out_family_names(self) -> Tuple[str, ...]:
        """The held-out families (none when not recorded)."""
        return self.held_out_families or ()

    @property
    def fine_tune_family_names(self) -> Tuple[str, ...]:
        """The fine-tuning families (none when not recorded)."""
        return self.fine_tune_families or ()


@dataclass(frozen=True, eq=False)
class ReferenceGate(JsonRecord):
    """A round's ``reference`` step (:func:`dv2s_gym.loop.measures.reference_gate`): the ``reference`` driver's
    held-out ``episodes``, those ``kept`` and those ``excluded`` (``[scenario, seed]``: it ``failed`` or
    ``errored``), per scenario (``by_scenario``: ``{"episodes", "excluded", "failures": {type: n}}``) and the
    families whose every episode is left out (``excluded_families``)."""

    reference: Optional[str] = None
    episodes: Optional[int] = None
    kept: Optional[int] = None
    excluded: Optional[Tuple[Any, ...]] = None
    failed: Optional[int] = None
    errored: Optional[int] = None
    by_scenario: Optional[Mapping[str, Any]] = None
    excluded_families: Optional[Tuple[str, ...]] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "reference gate"

    @property
    def excluded_episodes(self) -> FrozenSet[Tuple[str, int]]:
        """The left-out episodes as ``(scenario, seed)``."""
        return frozenset((str(name), int(seed)) for name, seed in self.excluded or ())


@dataclass(frozen=True, eq=False)
class HeldOutBefore(JsonRecord):
    """A round's ``before`` step: the held-out ``episodes`` the starting policy ran (those the reference driver
    passed), whether any were recorded (``done``) and those that ``errored``."""

    episodes: Optional[int] = None
    done: Optional[bool] = None
    errored: Optional[ErroredEpisodes] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "before step"


@dataclass(frozen=True, eq=False)
class FineTuneArm(JsonRecord):
    """A round's ``fine_tune`` or ``control`` step: the checkpoint (``model``), the ``method`` (``ppo`` or
    ``dagger``), the ``scenarios`` in the mix, the mined ones upweighted or left out, the ``steps``, every
    ``families`` of the mix, the ``reward_weights`` (ppo; ``null`` for dagger) and the fine-tuning
    ``env_config``; a DAgger arm adds its ``reference``, ``agreement`` and the iterations ``resumed``."""

    model: Optional[str] = None
    method: Optional[str] = None
    scenarios: Optional[int] = None
    mined_upweighted: Optional[int] = None
    steps: Optional[int] = None
    mined_left_out: Optional[int] = None
    families: Optional[Tuple[str, ...]] = None
    reward_weights: Optional[Mapping[str, float]] = None
    env_config: Optional[Mapping[str, Any]] = None
    reference: Optional[str] = None
    agreement: Optional[Any] = None
    resumed: Optional[Tuple[Any, ...]] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _KIND_OVERRIDES: ClassVar[Dict[str, Optional[str]]] = {"reference": "any"}
    _WHAT: ClassVar[str] = "fine-tuning arm"

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset({"reward_weights", "reference", "agreement"} if self.method == FineTuneMethod.DAGGER else ())


@dataclass(frozen=True, eq=False)
class RegressComparison(JsonRecord):
    """One ``dv2s regress`` comparison of the untouched set: its ``verdict`` and ``reason``, the ``episodes``
    compared, the ``difference`` (``{"value", "low", "high"}``) and ``p_value``, and the ``report`` it wrote."""

    verdict: Optional[str] = None
    reason: Optional[str] = None
    episodes: Optional[int] = None
    difference: Optional[Mapping[str, Any]] = None
    p_value: Optional[float] = None
    report: Optional[str] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "untouched comparison"

    def default_null_fields(self) -> FrozenSet[str]:
        return self.json_fields()


@dataclass(frozen=True, eq=False)
class UntouchedComparison(JsonRecord):
    """A round's ``untouched`` step (:func:`dv2s_gym.loop.comparisons.evaluate_untouched`): the ``scenarios`` and
    ``seeds`` of the untouched set, each policy's measures (``policies``: ``{"start" | "fine_tuned" | "control":
    {"episodes", "errors", "failure_rate", "stall_rate", "collision_rate", "mean_speed"}}``), the fine-tuned policy
    against the start and the control against the fine-tuned one (:class:`RegressComparison`) and the episodes
    that ``errored`` per policy."""

    scenarios: Optional[Tuple[str, ...]] = None
    seeds: Optional[int] = None
    policies: Optional[Mapping[str, Any]] = None
    fine_tuned_vs_start: Optional[RegressComparison] = None
    control_vs_fine_tuned: Optional[RegressComparison] = None
    errored: Optional[Mapping[str, ErroredEpisodes]] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _KIND_OVERRIDES: ClassVar[Dict[str, Optional[str]]] = {"scenarios": "list"}
    _WHAT: ClassVar[str] = "untouched step"

    def failure_rate(self, role: str) -> Optional[float]:
        """The failure rate of policy ``role`` (``start``, ``fine_tuned``, ``control``) on the set, or ``None``."""
        return (((self.policies or {}).get(role) or {}).get("failure_rate") or {}).get("value")

    def vacuous(self) -> Optional[str]:
        """Why the fine-tuned policy's comparison with the start on this set says nothing, or ``None``: a start
        that failed every episode (a policy that stands still fails them all) cannot be done worse than, so
        non-inferiority against it holds whatever the fine-tuned policy does."""
        if self.failure_rate("start") != 1.0:
            return None
        episodes = ((self.policies or {}).get("start") or {}).get("episodes")
        return (f"the starting policy failed every untouched episode ({episodes} of {episodes}): no policy can do "
                "worse, so the fine-tuned policy's non-inferiority against it is vacuous; read the control and "
                "fine-tuned rates and mean speeds instead")


@dataclass(frozen=True, eq=False)
class RegressSummary(JsonRecord):
    """A round's ``regress`` step: the regression test's ``verdict`` and ``reason``, the ``episodes`` compared, the
    new and old failure rates, the ``difference`` and ``p_value``, the ``regressed`` scenarios, the ``report`` it
    wrote, the held-out families' parents' own results (``held_out_parents``) and the ``errored`` episodes per
    policy."""

    verdict: Optional[str] = None
    reason: Optional[str] = None
    episodes: Optional[int] = None
    new_failure_rate: Optional[Mapping[str, Any]] = None
    old_failure_rate: Optional[Mapping[str, Any]] = None
    difference: Optional[Mapping[str, Any]] = None
    p_value: Optional[float] = None
    regressed: Optional[Tuple[Any, ...]] = None
    report: Optional[str] = None
    held_out_parents: Optional[Mapping[str, Any]] = None
    errored: Optional[Mapping[str, ErroredEpisodes]] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "regress step"

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset({"verdict", "reason", "episodes", "new_failure_rate", "old_failure_rate", "difference",
                          "p_value"})


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

    _WHAT: ClassVar[str] = "failures by type"


@dataclass(frozen=True, eq=False)
class HeldOutComparison(JsonRecord):
    """A round's ``after`` step (:func:`dv2s_gym.loop.measures.heldout_comparison`): the starting and the fine-tuned
    policy on the held-out pairs (``pairs`` tested, ``errors`` left out, the failure rates ``before`` and
    ``after``, the ``relative_drop`` with its interval over families, the paired ``table`` and McNemar p, each
    scenario's counts), the held-out counts (``heldout_scenarios``, ``heldout_families`` tested,
    ``sampled_families``) against the minimums, each arm's ``failure_types``, the ``control``'s rate and
    ``vs_control``, ``underpowered`` (why the drop and the tests are left out), the ``margin`` and the held-out tests
    (``significantly_worse``: ``start`` and ``control``), and the episodes that ``errored`` per policy."""

    pairs: Optional[int] = None
    errors: Optional[int] = None
    before: Optional[Rate] = None
    after: Optional[Rate] = None
    relative_drop: Optional[float] = None
    relative_drop_interval: Optional[Tuple[Any, ...]] = None
    relative_drop_interval_unit: Optional[str] = None
    relative_drop_interval_units: Optional[int] = None
    mcnemar_unit: Optional[str] = None
    pairs_per_family: Optional[Mapping[str, int]] = None
    table: Optional[PairedTable] = None
    mcnemar_p: Optional[float] = None
    per_scenario: Optional[Mapping[str, Any]] = None
    min_episodes: Optional[int] = None
    heldout_scenarios: Optional[int] = None
    heldout_families: Optional[int] = None
    sampled_families: Optional[int] = None
    min_families: Optional[int] = None
    failure_types: Optional[ArmFailureTypes] = None
    control: Optional[Rate] = None
    vs_control: Optional[VersusControl] = None
    underpowered: Optional[str] = None
    margin: Optional[float] = None
    significantly_worse: Optional[HeldOutTests] = None
    errored: Optional[Mapping[str, ErroredEpisodes]] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "held-out comparison"

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset({"relative_drop", "mcnemar_p", "pairs_per_family"})

    def held_out_test(self, against: str) -> Optional[HeldOutWorse]:
        """The recorded held-out test against ``start`` or ``control``
        (:func:`~dv2s_gym.loop.verdict.heldout_worse`; ``None`` when not tested)."""
        if self.significantly_worse is None or against not in ("start", "control"):
            return None
        return getattr(self.significantly_worse, against)


@dataclass(frozen=True, eq=False)
class RoundSteps(JsonRecord):
    """Each finished step's record of a round (:data:`STEPS`; a step not run yet is ``None``), or ``skipped``: why
    a round that kept no mined scenario measured nothing."""

    mine: Optional[MiningSummary] = None
    split: Optional[SplitRecord] = None
    skipped: Optional[str] = None
    reference: Optional[ReferenceGate] = None
    before: Optional[HeldOutBefore] = None
    fine_tune: Optional[FineTuneArm] = None
    control: Optional[FineTuneArm] = None
    after: Optional[HeldOutComparison] = None
    untouched: Optional[UntouchedComparison] = None
    regress: Optional[RegressSummary] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "steps"

    def done(self, step: str) -> bool:
        """Whether ``step`` (one of :data:`STEPS` or ``skipped``) is recorded."""
        return getattr(self, step) is not None


@dataclass(frozen=True, eq=False)
class RoundRecord(JsonRecord):
    """One round of a loop: its number (``round``), each finished step (``steps``, :class:`RoundSteps`) and its
    seconds (``timings``), the ``policy`` it started from, the fine-tuned ``new_policy`` and ``control_policy``, and
    the ``next_policy`` the next round starts from with its ``next_policy_reason``. A round of ``report.json`` also
    carries its cross-round check (``final_vs_start``: :func:`dv2s_gym.loop.report.final_vs_start` over the
    rounds up to it, recorded for a round its own tests accepted; ``null`` when fewer than two rounds up to it were
    regression-tested, see :attr:`cross_round_checked`)."""

    round: int
    steps: RoundSteps = field(default_factory=RoundSteps)
    timings: Mapping[str, float] = field(default_factory=dict)
    policy: Optional[str] = None
    new_policy: Optional[str] = None
    control_policy: Optional[str] = None
    next_policy: Optional[str] = None
    next_policy_reason: Optional[str] = None
    final_vs_start: Optional[FinalVsStart] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _REQUIRED: ClassVar[Tuple[str, ...]] = ("round",)
    _WHAT: ClassVar[str] = "round"

    @classmethod
    def started(cls, number: int) -> "RoundRecord":
        """The record of round ``number`` before any step: no step, no timing."""
        return cls.from_dict({"round": number, "steps": {}, "timings": {}})

    def with_step(self, step: str, value: Any, seconds: Optional[float] = None) -> "RoundRecord":
        """A copy with ``step``'s record (its typed record or JSON object, or ``skipped``'s reason) and, when given,
        its ``seconds``."""
        # the step is kept as its JSON object reads back (as loop.json holds it, and as a resumed loop reads it)
        value = value.to_dict() if isinstance(value, JsonRecord) else value
        steps = RoundSteps.from_dict({**self.steps.to_dict(), step: value})
        timings = self.timings if seconds is None else {**self.timings, step: seconds}
        return self.replace(steps=steps, timings=timings)

    @property
    def cross_round_checked(self) -> bool:
        """Whether the round records its cross-round check (``final_vs_start``, its ``null`` included: no check
        could be made over the rounds up to it)."""
        return self.final_vs_start is not None or "final_vs_start" in (self.null_fields or ())

    def with_cross_round_check(self, checked: Optional[FinalVsStart]) -> "RoundRecord":
        """A copy recording its cross-round check ``checked`` (``None``: written as ``null``, no check could be
        made)."""
        nulls = self.default_null_fields() if self.null_fields is None else self.null_fields
        nulls = nulls | {"final_vs_start"} if checked is None else nulls - {"final_vs_start"}
        return self.replace(final_vs_start=checked, null_fields=nulls)

    @property
    def fine_tuned(self) -> bool:
        """Whether the round fine-tuned a policy (it has one, or its ``fine_tune`` step ran)."""
        return bool(self.new_policy) or self.steps.fine_tune is not None


@dataclass(frozen=True, eq=False)
class LoopReportBody(JsonRecord):
    """The body of a loop's ``report.json`` (:mod:`dv2s_gym.loop.report`), which its Markdown and HTML forms are
    rendered from: the format (``schema`` ``"dv2s-loop"``, ``schema_version``), the loop folder ``out``, the loop's
    ``settings`` (:class:`RecordedLoopSettings`), the last fine-tuned ``policy``, the ``rounds`` (each a
    :class:`RoundRecord`), the ``recommendation`` (the JSON object of
    :class:`dv2s_gym.loop.verdict.Recommendation`) and, with two or more regression-tested rounds, the report's own
    cross-round check (``final_vs_start``, :class:`FinalVsStart`). Every field is optional (the body of a report
    being written may not hold them all yet); the verdict and the reports say which one they need. Other keys are
    kept in ``extra``."""

    schema: Optional[str] = None
    schema_version: Optional[int] = None
    out: Optional[str] = None
    settings: Optional[RecordedLoopSettings] = None
    policy: Optional[str] = None
    rounds: Optional[Tuple[RoundRecord, ...]] = None
    recommendation: Optional[Mapping[str, Any]] = None
    final_vs_start: Optional[FinalVsStart] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "loop report"

    @property
    def start_policy(self) -> Optional[str]:
        """The policy the loop started from (its settings' ``policy``), or ``None`` without settings."""
        return self.settings.policy if self.settings is not None else None

    @property
    def round_records(self) -> Tuple[RoundRecord, ...]:
        """The rounds (none when the body holds none)."""
        return self.rounds or ()

    @property
    def cross_round_checked(self) -> bool:
        """Whether the body records its own cross-round check (``final_vs_start``, its ``null`` included)."""
        return self.final_vs_start is not None or "final_vs_start" in (self.null_fields or ())
