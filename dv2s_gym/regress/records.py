"""Typed records of the regression report (schema ``dv2s-regress``, :mod:`dv2s_gym.regress.report`).

:func:`~dv2s_gym.regress.report.build_report` makes a :class:`RegressReport`; the runner, the text, JUnit and HTML
renderings, the pytest plugin and the loop's regression step read its parts by attribute:

- :class:`RegressReport`: the whole report (``report.json``);
- :class:`BankInfo`: the bank the run used (``bank``); :class:`ReportSettings`: the run's settings (``settings``);
- :class:`PolicyInfo`: the candidate or the baseline (``candidate``, ``baseline``);
- :class:`PairedEpisode`: one scenario x seed pair (``episodes``), each side a
  :class:`~scenario_bank.records.RegressEpisode`;
- :class:`ScenarioResult`: one scenario's (or all scenarios', ``overall``) :class:`Summary` per policy and their
  :class:`PairedComparison`;
- :class:`EpisodeError`: an episode that ended in an error (``errors``);
- :class:`SequentialOutcome`: the sequential test's looks and verdict (``sequential``);
- :class:`RunPower`: the power the run had (``power``), per scenario and pooled a :class:`PowerEstimate`;
- :class:`PowerPlan`: the power plan that chose the episodes per scenario (``settings.plan``), per scenario a
  :class:`ScenarioPlan`.

Each is a :class:`~scenario_bank.records.JsonRecord`: :meth:`from_json` (``from_dict``) reads the JSON object,
checking the kind of every field it knows (a :class:`~scenario_bank.records.RecordError` names a bad one),
:meth:`to_json` (``to_dict``) gives back exactly the JSON object: the same keys in the same order, ``null`` where
the report writes one, unknown keys kept. A record is read by its fields, not by key. The statistics'
leaves (the ``{"value", "low", "high"}`` intervals, the paired ``table`` and ``aggregates``, made by
:mod:`~dv2s_gym.regress.stats` and :mod:`~dv2s_gym.regress.aggregates` with their own documented shapes) stay JSON
objects.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar, Dict, FrozenSet, Mapping, Optional, Tuple, Union

from policies.card_record import ModelCard
from scenario_bank.records import JsonRecord, RecordError, RegressEpisode

__all__ = ["RegressReport", "BankInfo", "ReportSettings", "PolicyInfo", "PairedEpisode", "Summary",
           "PairedComparison", "ScenarioResult", "EpisodeError", "SequentialOutcome", "ReportRecord", "as_result",
           "PowerEstimate", "RunPower", "ScenarioPlan", "PowerPlan"]

Interval = Mapping[str, Any]
"""``{"value", "low", "high"}`` (a rate adds ``count``, a mean ``n``); values ``None`` without episodes."""


class ReportRecord(JsonRecord):
    """What the report's records share: :meth:`to_json` and :meth:`from_json`, the JSON object of ``report.json``."""

    def to_json(self) -> Dict[str, Any]:
        """The JSON object, as ``report.json`` holds it (a new dict each call; nested records as dicts)."""
        return self.to_dict()

    @classmethod
    def from_json(cls, data: Union[JsonRecord, Mapping[str, Any]]):
        """The record of a JSON object of ``report.json`` (or the record itself)."""
        return cls.from_dict(data)


@dataclass(frozen=True, eq=False)
class BankInfo(ReportRecord):
    """The bank a run used: its folder (``path``), its ``version`` (a SHA-256 over the scenarios used, name and
    script), the ``scenarios`` and each one's script ``hashes``."""

    path: Optional[str] = None
    version: Optional[Any] = None
    scenarios: Optional[Tuple[str, ...]] = None
    hashes: Optional[Mapping[str, str]] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "report bank"


@dataclass(frozen=True, eq=False)
class ScenarioPlan(ReportRecord):
    """One scenario of a power plan: the ``baseline_rate`` planned with, its ``source`` (``"measured"`` or
    ``"assumed"``), the probability of a discordant pair at the planned effect (``discordance``) and the
    ``episodes`` that reach the planned power."""

    baseline_rate: Optional[float] = None
    source: Optional[str] = None
    discordance: Optional[float] = None
    episodes: Optional[int] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "scenario plan"


@dataclass(frozen=True, eq=False)
class PowerPlan(ReportRecord):
    """The power plan that sized a run (:func:`~dv2s_gym.regress.power.plan_episodes`): the ``episodes`` per
    scenario, the ``mde`` and ``power`` planned for, the ``level`` each scenario is tested at, each scenario's
    :class:`ScenarioPlan` (``per_scenario``) and the model's ``assumption``. A run's report holds it without
    ``per_scenario`` and with the episodes the plan asked for (``planned``); ``episodes`` is then what the run had,
    fewer than planned when its baseline report has fewer, which ``note`` says."""

    episodes: Optional[int] = None
    mde: Optional[float] = None
    power: Optional[float] = None
    level: Optional[float] = None
    per_scenario: Optional[Mapping[str, ScenarioPlan]] = None
    assumption: Optional[str] = None
    planned: Optional[int] = None
    note: Optional[str] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "power plan"


@dataclass(frozen=True, eq=False)
class PowerEstimate(ReportRecord):
    """What ``n`` paired episodes could detect (one scenario, or pooled): the ``baseline_rate`` and test ``level``
    it was worked out at, the power to FAIL an increase of the margin (``at_margin``) and of the planned effect
    (``at_mde``), and the smallest increase detected with the planned power (``detectable``); ``None`` where
    undefined."""

    n: Optional[int] = None
    baseline_rate: Optional[float] = None
    level: Optional[float] = None
    at_margin: Optional[float] = None
    at_mde: Optional[float] = None
    detectable: Optional[float] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "power estimate"

    def default_null_fields(self) -> FrozenSet[str]:
        return self.json_fields()


@dataclass(frozen=True, eq=False)
class RunPower(ReportRecord):
    """The power a run had (:func:`~dv2s_gym.regress.power.run_power`): a :class:`PowerEstimate` per scenario
    (``per_scenario``) and ``pooled``, the planned ``power`` and ``mde`` (``None``: not planned for one) and the
    model's ``assumption``; a report's ``power`` has all but ``mde``."""

    per_scenario: Optional[Mapping[str, PowerEstimate]] = None
    pooled: Optional[PowerEstimate] = None
    power: Optional[float] = None
    mde: Optional[float] = None
    assumption: Optional[str] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _REQUIRED: ClassVar[Tuple[str, ...]] = ("per_scenario", "pooled", "power", "assumption")
    _WHAT: ClassVar[str] = "run power"

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset({"mde"})



@dataclass(frozen=True, eq=False)
class ReportSettings(ReportRecord):
    """The settings a run used: ``episodes`` per scenario from ``seed``, the ``margin`` and ``alpha`` the verdicts
    use, ``sequential`` (with its ``batch``), the ``env_config``, where episodes ran (``backend``, ``workers``,
    ``timeout``), the ``failure`` kinds and ``stall_seconds``, the power ``plan`` that sized the run (when one
    did), and the planned ``mde`` and ``power``."""

    episodes: Optional[int] = None
    seed: Optional[int] = None
    margin: Optional[float] = None
    alpha: Optional[float] = None
    sequential: Optional[bool] = None
    env_config: Optional[Mapping[str, Any]] = None
    backend: Optional[str] = None
    workers: Optional[int] = None
    timeout: Optional[float] = None
    failure: Optional[Tuple[str, ...]] = None
    stall_seconds: Optional[float] = None
    batch: Optional[int] = None
    plan: Optional[PowerPlan] = None
    mde: Optional[float] = None
    power: Optional[float] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "report settings"

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset({"workers", "timeout"})


@dataclass(frozen=True, eq=False)
class PolicyInfo(ReportRecord):
    """A policy of the run: its ``spec`` and model ``card`` (``None`` without one); a baseline taken from an earlier
    report also names that ``report``, the ``role`` it had there and, when another dv2s-gym version made it, a
    ``warning``."""

    report: Optional[str] = None
    role: Optional[str] = None
    spec: Optional[str] = None
    card: Optional[ModelCard] = None
    warning: Optional[str] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "report policy"

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset({"card"})


def as_result(value: Any) -> Optional[RegressEpisode]:
    """A policy's result of one episode as a :class:`RegressEpisode` (``None`` for ``None``): a result of a run (it
    has the record's required fields) checked field by field; a partial one (a report other code made) taken as
    it is."""
    if isinstance(value, RegressEpisode):
        return value
    if isinstance(value, Mapping) and RegressEpisode.has_required(value):
        return RegressEpisode.from_dict(value)
    if value is not None and not isinstance(value, Mapping):
        raise RecordError(f"a regression result must be a JSON object, not {type(value).__name__}")
    return _partial_result(value) if value is not None else None


def _partial_result(value: Mapping[str, Any]) -> RegressEpisode:
    """The record of a partial result (one without an ``id``, ``role``, ``scenario`` or ``seed``, which every run's
    result has), its JSON object unchanged: the missing fields stay missing (or ``null``) in
    :meth:`~RegressEpisode.to_dict`."""
    placeholders = {key: blank for key, blank in (("id", ""), ("role", ""), ("scenario", ""), ("seed", 0))
                    if value.get(key) is None}
    record = RegressEpisode.from_checked({**value, **placeholders})
    nulls = frozenset(key for key in placeholders if key in value)
    return record.replace(**{key: None for key in placeholders}, null_fields=(record.null_fields or frozenset()) | nulls)


@dataclass(frozen=True, eq=False)
class PairedEpisode(ReportRecord):
    """One scenario x seed pair: its ``id`` (``"scenario/seed"``), ``scenario`` and ``seed``, and each policy's
    result (a :class:`~scenario_bank.records.RegressEpisode`; ``baseline`` ``None`` without a baseline)."""

    id: Optional[str] = None
    scenario: Optional[str] = None
    seed: Optional[int] = None
    candidate: Optional[RegressEpisode] = None
    baseline: Optional[RegressEpisode] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _NESTED: ClassVar[Dict[str, type]] = {}  # the results are read by _check_extra, as_result
    _WHAT: ClassVar[str] = "paired episode"

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset({"baseline"})

    @classmethod
    def _check_extra(cls, data: Mapping[str, Any]) -> Dict[str, Any]:
        return {role: as_result(data[role]) for role in ("candidate", "baseline") if data.get(role) is not None}

    def result(self, role: str) -> Optional[RegressEpisode]:
        """The ``"candidate"``'s or the ``"baseline"``'s result."""
        return self.candidate if role == "candidate" else self.baseline

    def errored(self, role: str) -> bool:
        """Whether ``role`` ran this pair and its episode ended in an error."""
        result = self.result(role)
        return result is not None and bool(result.error)

    def to_dict(self) -> Dict[str, Any]:
        out = super().to_dict()
        for role in ("candidate", "baseline"):
            if isinstance(out.get(role), JsonRecord):
                out[role] = out[role].to_dict()
        return out


@dataclass(frozen=True, eq=False)
class Summary(ReportRecord):
    """One policy on one scenario (or on all): the ``episodes`` without errors and the ``errors``; the ``rates``
    (``{kind}_rate`` per failure kind, ``failure_rate``, ``success_rate``: Wilson intervals with ``count``), in the
    report's order; and the means ``min_ttc``, ``mean_speed`` and ``episode_return`` (JSON ``return``: bootstrap
    intervals with ``n``)."""

    episodes: Optional[int] = None
    errors: Optional[int] = None
    rates: Mapping[str, Interval] = field(default_factory=dict)
    min_ttc: Optional[Interval] = None
    mean_speed: Optional[Interval] = None
    episode_return: Optional[Interval] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _ATTRIBUTES: ClassVar[Dict[str, str]] = {"return": "episode_return"}
    _KIND_OVERRIDES: ClassVar[Dict[str, Optional[str]]] = {"rates": None}  # the rates are keys of their own
    _WHAT: ClassVar[str] = "summary"

    @classmethod
    def from_dict(cls, data: Union[JsonRecord, Mapping[str, Any]]) -> "Summary":
        record = super().from_dict(data)
        if record is data:
            return record
        data = data.to_dict() if isinstance(data, JsonRecord) else data
        rates = {key: value for key, value in data.items() if key.endswith("_rate") and key not in cls.json_fields()}
        for key, value in rates.items():
            if not isinstance(value, Mapping):
                raise RecordError(f"summary field {key!r} must be a JSON object, not {type(value).__name__}")
        return record.replace(rates=rates, extra={k: v for k, v in record.extra.items() if k not in rates})

    def to_dict(self) -> Dict[str, Any]:
        out = super().to_dict()
        head = {key: out.pop(key) for key in ("episodes", "errors") if key in out}
        return {**head, **self.rates, **out}

    def rate(self, name: str) -> Optional[Interval]:
        """The rate ``name`` (``"failure"``, ``"success"``, ``"collision"``, ...), or ``None`` when not counted."""
        return self.rates.get(f"{name}_rate")

    @property
    def failure_rate(self) -> Optional[Interval]:
        """The rate of episodes with any failure the run counts."""
        return self.rate("failure")

    @property
    def success_rate(self) -> Optional[Interval]:
        """The rate of episodes that reached their goal."""
        return self.rate("success")


@dataclass(frozen=True, eq=False)
class PairedComparison(ReportRecord):
    """The candidate against the baseline on ``n`` pairs: the paired ``table`` (``both_fail``, ``candidate_only``,
    ``baseline_only``, ``neither``), both failure rates, the ``difference`` (Newcombe interval), the exact McNemar
    ``p_value`` and ``p_adjusted`` for the family of tests, the ``verdict`` and its ``reason``."""

    n: Optional[int] = None
    table: Optional[Mapping[str, int]] = None
    candidate_rate: Optional[float] = None
    baseline_rate: Optional[float] = None
    difference: Optional[Interval] = None
    p_value: Optional[float] = None
    p_adjusted: Optional[float] = None
    verdict: Optional[str] = None
    reason: Optional[str] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "comparison"

    def default_null_fields(self) -> FrozenSet[str]:
        return self.json_fields()


@dataclass(frozen=True, eq=False)
class ScenarioResult(ReportRecord):
    """A scenario's entry of ``scenarios`` (or the ``overall`` one): each policy's :class:`Summary` (``baseline``
    ``None`` without a baseline) and their :class:`PairedComparison` (``None`` without a baseline)."""

    candidate: Optional[Summary] = None
    baseline: Optional[Summary] = None
    comparison: Optional[PairedComparison] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "scenario result"

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset({"baseline", "comparison"})

    def summary(self, role: str) -> Optional[Summary]:
        """The ``"candidate"``'s or the ``"baseline"``'s summary."""
        return self.candidate if role == "candidate" else self.baseline

    @property
    def verdict(self) -> Optional[str]:
        """The comparison's verdict (``None`` without one)."""
        return self.comparison.verdict if self.comparison is not None else None


@dataclass(frozen=True, eq=False)
class EpisodeError(ReportRecord):
    """An episode that ended in an error: its ``id``, the ``role`` that ran it and the ``error``."""

    id: Optional[str] = None
    role: Optional[str] = None
    error: Optional[Any] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "episode error"

    @property
    def scenario(self) -> str:
        """The scenario of the episode (its id without the seed)."""
        return str(self.id).rsplit("/", 1)[0]

    @property
    def first_line(self) -> str:
        """The error's first line (empty without one)."""
        return str(self.error or "").splitlines()[0] if self.error else ""


@dataclass(frozen=True, eq=False)
class SequentialOutcome(ReportRecord):
    """The sequential test of a ``--sequential`` run: its ``looks`` at the pooled table, the paired ``episodes``
    it saw of ``max_episodes``, the seeds per look (``batch``), the alpha ``spending`` and the ``verdict`` it
    reached (``None``: none before the end)."""

    looks: Optional[int] = None
    episodes: Optional[int] = None
    max_episodes: Optional[int] = None
    batch: Optional[int] = None
    spending: Optional[Any] = None
    verdict: Optional[str] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "sequential test"

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset({"verdict"})


@dataclass(frozen=True, eq=False)
class RegressReport(ReportRecord):
    """A regression report (``report.json``, schema in :mod:`dv2s_gym.regress.report`): the code that judged its
    episodes (``code_identity``: :func:`policies.run_identity.report_code_identity`), what ran (``bank``,
    ``settings``, ``candidate``, ``baseline``, the paired ``episodes``), each scenario's and the ``overall``
    :class:`ScenarioResult`, the ``verdict`` (``None``: measures only) with ``error_reason`` when errors make it
    ERROR, the ``regressed`` scenarios, the ``newly_failing`` episode ids, the ``errors``, the sequential test
    (``stopped_early``, ``sequential``), the run's ``power`` and the return ``aggregates`` (context), and where and
    how long it ran (``hostname``, ``duration``, ``timing`` per scenario)."""

    schema: Optional[str] = None
    schema_version: Optional[int] = None
    created: Optional[str] = None
    dv2s_version: Optional[str] = None
    code_identity: Optional[Mapping[str, Any]] = None
    bank: Optional[BankInfo] = None
    settings: Optional[ReportSettings] = None
    candidate: Optional[PolicyInfo] = None
    baseline: Optional[PolicyInfo] = None
    episodes: Optional[Tuple[PairedEpisode, ...]] = None
    scenarios: Optional[Mapping[str, ScenarioResult]] = None
    overall: Optional[ScenarioResult] = None
    verdict: Optional[str] = None
    regressed: Optional[Tuple[str, ...]] = None
    newly_failing: Optional[Tuple[str, ...]] = None
    errors: Optional[Tuple[EpisodeError, ...]] = None
    stopped_early: Optional[bool] = None
    sequential: Optional[SequentialOutcome] = None
    power: Optional[RunPower] = None
    aggregates: Optional[Mapping[str, Any]] = None
    error_reason: Optional[str] = None
    hostname: Optional[str] = None
    timing: Optional[Mapping[str, float]] = None
    duration: Optional[float] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _WHAT: ClassVar[str] = "regression report"

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset({"baseline", "verdict", "sequential", "power", "aggregates"})

    @property
    def has_baseline(self) -> bool:
        """Whether the run compared against a baseline (else it only measured the candidate)."""
        return self.baseline is not None

    def scenario(self, name: str) -> ScenarioResult:
        """The entry of scenario ``name``."""
        return (self.scenarios or {})[name]

    def episode(self, episode_id: str) -> Optional[PairedEpisode]:
        """The paired episode ``episode_id`` (``"scenario/seed"``), or ``None``."""
        return next((e for e in self.episodes or () if e.id == episode_id), None)
