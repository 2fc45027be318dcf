"""Closing the RL loop (``dv2s loop``): mine a policy's failures, grow the bank, fine-tune, measure.

One round, starting from policy ``P`` (an SB3 checkpoint spec, e.g. ``dv2s-ppo``):

a. **mine**: :func:`dv2s_gym.mining.miner.mine` runs ``P`` on sampled scenes of the starting
   bank's scenarios, clusters its failures, converts the representatives of at most
   ``max_conversions`` clusters (largest first; the rest are counted as not converted) through
   the D-V2S pipeline and adds the kept scenarios to the *working bank* (``out/bank``, a copy
   of the shipped bank, or the ``bank_dir`` given); every converted failure's scene is also kept
   exactly (its *exact replay* entry: the parent scenario narrowed around the failing parameters),
   and so is that of up to ``max_replays`` more clusters, the scenario families taking turns, each its largest
   cluster first (:func:`dv2s_gym.loop.replays.replay_clusters`: no video, description or script, only the narrowed
   parent checked to replay the failing episode step for step): these are mined scenarios of the
   round too, so a round whose conversions are all rejected still has families to split;
b. **split**: the newly kept scenarios (converted scripts and exact replays) are split by *family* (their parent bank scenario,
   :func:`dv2s_gym.loop.split.split_by_family`) into a fine-tuning part and a held-out part,
   deterministically from the seed; a family held out once stays held out;
c. **reference**, then **before**: the reference driver (:data:`REFERENCE_DRIVER`, the DAgger teacher and the
   miner's reference) drives every held-out episode first; an episode it does not pass (any failure of the
   monitors, or an error) is left out of every held-out rate and test, counted and named
   (:func:`reference_gate`: no imitation of the reference can fix a scene the reference fails, so its pair
   measures nothing); ``P`` runs on the held-out scenarios, ``k_eval`` evaluation seeds each
   (``EVAL_SEED_BASE + i``, never a training seed): failure rate (the miner's monitors) with
   a Wilson interval; fewer than ``min_heldout_episodes`` held-out episodes is said loudly and
   the round reports rates but no drop and no test;
d. **fine-tune**: :func:`policies.training.fine_tune` continues ``P`` on the working bank
   minus every held-out scenario and every held-out family's parent scenario (so the parent over
   its full range cannot leak the held-out failures), the mined fine-tuning scenarios drawn with ``mined_share``
   of the probability, the rest of the bank with the remainder (so it is not forgotten).
   The training reward is ``P``'s own with the terms of ``fine_tune_reward`` overridden
   (default ``{"standing": -0.3}``: standing still with a free path ahead, the miner's
   stall, is penalised like the monitors count it); only fine-tuning uses that env config:
   mining, the held-out evaluations and the regression test run ``P``'s own (a failure
   does not depend on the reward). That is ``fine_tune_method="ppo"``; with ``"dagger"``
   the policy instead imitates the reference driver (``rule``) on the states it visits
   itself in the same weighted scenario mix (:mod:`policies.imitation`; no reward; a killed
   DAgger run resumes from its last finished iteration, ``resumed`` in the step's record);
d'. **control**: the same fine-tuning (method, steps, seed, learning rate) on the same scenarios
   less every mined one, into ``round_<r>/control``: what the fine-tuning does without the mined
   scenarios, so a drop can be credited to them (``control=False`` leaves it out);
e. **after**: the fine-tuned policy and the control run on the same held-out episodes (paired):
   rates with Wilson intervals for start, control and fine-tuned, relative drop
   (scenario-bootstrap interval), exact two-sided McNemar p fine-tuned vs start and fine-tuned
   vs control;
e'. **untouched**: start, control and fine-tuned run on the scenario set the loop never mines or
   fine-tunes on (:data:`UNTOUCHED_BANK`: scripts written by others for Scenic's CARLA model),
   ``untouched_seeds`` seeds each, judged by :func:`dv2s_gym.regress.runner.run_regression`
   (failure rates, stalls apart, mean speed; fine-tuned vs start and control vs fine-tuned);
f. **regress**: :func:`dv2s_gym.regress.runner.run_regression` new against old on the starting
   bank's scenarios (PASS / FAIL / INCONCLUSIVE against ``margin``);
g. the next round starts from the policy the verdict on this round recommends
   (:func:`dv2s_gym.loop.verdict.recommendation` over the rounds so far): the fine-tuned policy when it
   was ACCEPTED, else the last accepted one, else the starting policy (``next_policy`` and
   ``next_policy_reason`` in the round's record).

Everything lives under ``out``: ``loop.json`` (settings and every finished step, written
atomically after each), ``bank/``, ``round_<r>/{mine,heldout.jsonl,policy,control,untouched,regress}`` and the
report (``report.json``, ``report.md``, ``report.html``).
Restarted with the same ``out`` and settings, the loop skips finished steps and resumes the
unfinished one (the miner, the held-out store, training and the regression run are each
resumable); ``rounds`` may be raised to add rounds to a finished loop.
"""

from __future__ import annotations

import dataclasses
import json
import os
import re
import time
from pathlib import Path
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Union

from dv2s_gym.mining import miner

from dv2s_gym.loop import heldout

from dv2s_gym.loop import report as loop_report
from dv2s_gym.mining.cluster import cluster_failures, group
from dv2s_gym.loop.errored import errored_episodes, merged_messages, messages_text
from dv2s_gym.mining.family import scenario_family
from dv2s_gym.loop.heldout import episode_failed, failure_types, HeldOutStore, paired_summary
from dv2s_gym.mining.conversion.record import read_conversions
from dv2s_gym.mining.errors import MiningError
from dv2s_gym.mining.jsonl import read_rows
from dv2s_gym.loop.record import (
    ErroredEpisodes, FineTuneArm, HeldOutBefore, HeldOutComparison, HeldOutTests, LoopStart, MinedEntry, MiningSummary,
    RecordedLoopSettings, ReferenceGate, RegressComparison, RegressSummary, RoundRecord, RoundSteps, SplitRecord,
    UntouchedComparison, recorded)
from dv2s_gym.loop.report import (errored_note, errored_text, rate_text, reference_gate_text,
                                         write_loop_reports)
from dv2s_gym.loop.settings import DEFAULTS, FINE_TUNE_METHODS, METHOD_LEARNING_RATES, LoopError, LoopSettings
from dv2s_gym.loop.verdict import (
    EVIDENCE_FLOOR, evidence_floor_note, HELDOUT_ALPHA, heldout_worse, Recommendation, recommendation)
from dv2s_gym.mining.miner import MineSettings, RunOrigin
from dv2s_gym.loop.replays import reference_passed, replay_clusters, replay_entries, REPLAYS_FILE
from dv2s_gym.loop.split import family_of, split_by_family
from dv2s_gym.progress_lines import log_line
from dv2s_gym.regress import runner
from dv2s_gym.regress.records import PairedComparison, RegressReport, ScenarioResult, Summary
from dv2s_gym.regress.runner import BaselineReport, RegressSettings
from dv2s_gym.regress.stats import PairedTable
from dv2s_gym.workers.pool import default_workers
from dv2s_gym.workers.settings import WorkerSettings
from scenario_bank import select_scenarios
from scenario_bank.atomic import atomic_write_json
from scenario_bank.bank import Bank
from scenario_bank.records import EpisodeRecord, HeldOutEpisode, RecordError
from scenario_bank.run_identity import (BANK_IDENTITY, bank_identity, check_bank_unchanged, check_format,
                                       check_identity, check_run_kind, record_format)
from policies.evaluation import EVAL_SEED_BASE
from policies.card_record import FineTune, FineTuneMethod
from policies.registry import SB3_ALGORITHMS, read_model_card
from policies.run_identity import (CODE_IDENTITY, RESUME_FINGERPRINT, check_code_unchanged, check_policy_unchanged,
                                   code_identity, resume_fingerprint)

__all__ = ["LoopError", "LoopReport", "LoopSettings", "run_loop", "DEFAULT_OUT", "DEFAULTS", "mined_entries",
           "fine_tune_weights", "arm_weights", "FINE_TUNE_METHODS", "METHOD_LEARNING_RATES"]

DEFAULT_OUT = "out/loop"
"""Where ``dv2s loop`` writes when ``--out`` is not given (rerunning resumes it)."""

IDENTITY = ("policy",) + LoopSettings.resume_keys()
"""The settings of ``loop.json`` a resumed loop must share with the recorded ones."""
HOLDOUT_BY = "family"
"""How a loop splits its mined scenarios (recorded in ``loop.json``)."""
REFERENCE_FINGERPRINT = "reference_fingerprint"
"""The key under which ``loop.json`` records the reference driver's
:func:`~policies.run_identity.resume_fingerprint`."""
STATE_SCHEMA = "dv2s-loop-state"
STATE_VERSION = 2
"""The format of ``loop.json`` (bumped when its fields change; a loop folder of another format is refused)."""
IN_FOLDER = "<loop>"
"""How ``loop.json`` writes a path inside the loop folder: relative to it, after this mark
(``<loop>/round_1/policy/model.zip``, ``ppo:<loop>/round_1/policy/model.zip``), read back as a path in the folder
where the loop is now, so a loop folder moved or copied elsewhere resumes there. A path outside the folder (a bank
given with ``--bank``, a starting checkpoint) is written as it is."""

UNTOUCHED_BANK = Path(__file__).resolve().parent / "untouched"
"""The scenario set no loop mines or fine-tunes on: a bank folder of scripts written by others for Scenic's
CARLA model (its ``SOURCES.md`` names them and their licence)."""

@dataclasses.dataclass
class LoopReport:
    """What :func:`run_loop` returns: the rounds' records and where the reports are."""

    out: Path
    rounds: List[RoundRecord]
    policy: str
    """The spec of the last round's fine-tuned policy (the starting policy if no round fine-tuned); the policy to
    use is :attr:`recommendation`'s."""
    paths: Dict[str, Path]
    settings: RecordedLoopSettings
    """The loop's settings as ``loop.json`` records them."""

    def to_json(self) -> Dict[str, Any]:
        """A JSON-safe dict (the body of ``report.json``)."""
        body = {"schema": "dv2s-loop", "schema_version": 1, "out": str(self.out),
                "settings": self.settings.to_dict(), "policy": self.policy,
                "rounds": [record.to_dict() for record in self.rounds]}
        return {**body, "recommendation": recommendation(body).to_dict()}

    @property
    def recommendation(self) -> Recommendation:
        """Which policy to use and why (:func:`dv2s_gym.loop.verdict.recommendation`), as ``report.json``
        has it once written (with the final-vs-starting comparison of two or more rounds); a written report without
        one is a :class:`LoopError` naming it."""
        path = self.paths.get("json")
        if path is not None and Path(path).is_file():
            written = json.loads(Path(path).read_text(encoding="utf-8")).get("recommendation")
            return Recommendation.from_dict(written, source=str(path))
        return recommendation(self.to_json())


# --------------------------------------------------------------------------- state
class _State:
    """``loop.json``: its settings (:attr:`settings`, a :class:`~dv2s_gym.loop.record.RecordedLoopSettings`),
    the starting bank and scenarios (:attr:`start`, a :class:`~dv2s_gym.loop.record.LoopStart` once chosen)
    and every round (:attr:`rounds`, each a :class:`~dv2s_gym.loop.record.RoundRecord` replaced as its steps
    finish); atomic writes."""

    def __init__(self, path: Path, settings: Dict[str, Any]) -> None:
        self.path = path
        check_run_kind(path.parent, STATE_SCHEMA, error=LoopError)
        if path.is_file():
            try:
                data = json.loads(path.read_text(encoding="utf-8"))
            except ValueError as error:
                raise LoopError(f"{path} is not readable JSON ({error}); choose another --out") from error
            _check_structure(data, path)
            check_format(data, STATE_SCHEMA, STATE_VERSION, folder=path.parent, what="a loop", file=path.name,
                         error=LoopError)
            recorded = data["settings"]
            check_identity(recorded, settings, IDENTITY, run=f"{path.parent} holds a loop",
                           fix="rerun with its settings to resume it, or choose another --out")
            # the same spec naming a checkpoint replaced in place is refused, naming what changed
            check_policy_unchanged(recorded, settings["policy"], folder=path.parent, run="loop", error=LoopError)
            check_policy_unchanged(data, REFERENCE_DRIVER, folder=path.parent, run="loop", error=LoopError,
                                   key=REFERENCE_FINGERPRINT, role="reference driver")
            check_code_unchanged(data, run=f"{path.parent} holds a loop", error=LoopError)
            data["settings"].update({k: settings[k] for k in settings if k not in IDENTITY})  # what may change
            data.update({key: _in_folder(data[key], path.parent, write=False) for key in ("start", "rounds")})
        else:
            data = {**record_format(STATE_SCHEMA, STATE_VERSION), "settings": settings, "start": None, "rounds": [],
                    REFERENCE_FINGERPRINT: resume_fingerprint(REFERENCE_DRIVER),
                    CODE_IDENTITY: code_identity(exclude=[path.parent, settings.get("bank_dir")])}
        self.rounds: List[RoundRecord] = _read_rounds(data.pop("rounds"), path)
        self.settings: RecordedLoopSettings = _read_part(RecordedLoopSettings, data.pop("settings"), path)
        start = data.pop("start", None)
        self.start: Optional[LoopStart] = None if start is None else _read_part(LoopStart, start, path)
        self.extra = data  # the record's format and any top-level keys, written back as read

    def save(self) -> None:
        self.path.parent.mkdir(parents=True, exist_ok=True)
        folder = self.path.parent
        start = None if self.start is None else _in_folder(self.start.to_dict(), folder, write=True)
        rounds = [_in_folder(record.to_dict(), folder, write=True) for record in self.rounds]
        atomic_write_json(self.path, {**self.extra, "settings": self.settings.to_dict(), "start": start,
                                      "rounds": rounds}, indent=1)

    def round(self, number: int) -> RoundRecord:
        """Round ``number``'s record (the rounds before it started when not yet)."""
        while len(self.rounds) < number:
            self.rounds.append(RoundRecord.started(len(self.rounds) + 1))
        return self.rounds[number - 1]

    def update(self, record: RoundRecord, save: bool = True) -> RoundRecord:
        """``record`` becomes its round's record (written to ``loop.json`` when ``save``); returns it."""
        self.round(record.round)
        self.rounds[record.round - 1] = record
        if save:
            self.save()
        return record


def _in_folder(value: Any, folder: Path, write: bool) -> Any:
    """``value`` (JSON of ``loop.json``) with each path inside the loop ``folder``, whole or in a text (a policy spec
    ``ppo:<path>``, a reason naming a checkpoint), written relative to it after :data:`IN_FOLDER` (``write``), or
    read back as a path in ``folder`` as it is now (not ``write``); paths outside it as they are."""
    if isinstance(value, dict):
        return {key: _in_folder(item, folder, write) for key, item in value.items()}
    if isinstance(value, list):
        return [_in_folder(item, folder, write) for item in value]
    if not isinstance(value, str):
        return value
    if not write:
        return value.replace(f"{IN_FOLDER}/", f"{folder}/")
    roots = sorted({str(folder.absolute()), str(folder.resolve())}, key=len, reverse=True)
    # an absolute path anywhere in the text; a relative one (the folder as given) where a word or a spec begins
    starts = [rf"(^|[^\w.~/-]){re.escape(root)}(?=/)" for root in roots]
    if not folder.is_absolute() and folder.parts:
        starts.append(rf"((?:^|[\s(])(?:(?:{'|'.join(SB3_ALGORITHMS)}):)?){re.escape(str(folder))}(?=/)")
    for start in starts:
        value = re.sub(start, rf"\1{IN_FOLDER}", value)
    return value


def _read_rounds(rounds: List[Any], path: Path) -> List[RoundRecord]:
    """The rounds of a ``loop.json`` whose structure is checked (:func:`_check_structure`) as records; a field of
    the wrong kind is refused in one line naming the round, the field and the fix."""
    records = []
    for number, data in enumerate(rounds, start=1):
        try:
            records.append(RoundRecord.from_dict(data))
        except RecordError as error:
            raise LoopError(f"{path} is not a dv2s loop record (round {number}: {error}); choose another --out, or "
                            "delete the file to start the loop over") from None
    return records


def _read_part(kind: type, data: Mapping[str, Any], path: Path) -> Any:
    """``loop.json``'s ``settings`` or ``start`` (structure checked by :func:`_check_structure`) as its record; a
    field of the wrong kind is refused in one line naming the field and the fix."""
    try:
        return kind.from_dict(data)
    except RecordError as error:
        raise LoopError(f"{path} is not a dv2s loop record ({error}); choose another --out, or delete the file to "
                        "start the loop over") from None


def _check_structure(data: Any, path: Path) -> None:
    """Refuse a ``loop.json`` that is JSON but not a loop's record, in one line naming the file and the fix."""
    problem = None
    if not isinstance(data, dict):
        problem = f"holds a {type(data).__name__}, not an object"
    elif not isinstance(data.get("settings"), dict):
        problem = "has no \"settings\" object"
    elif not isinstance(data.get("rounds"), list) or not all(
            isinstance(r, dict) and isinstance(r.get("steps", {}), dict) and isinstance(r.get("timings", {}), dict)
            for r in data["rounds"]):
        problem = "has no list of round objects under \"rounds\""
    elif data.get("start") is not None and not (isinstance(data["start"], dict)
                                                and isinstance(data["start"].get("scenarios"), list)):
        problem = "has a \"start\" that is not an object with a list of scenarios"
    else:
        problem = _round_problem(data["rounds"])
    if problem:
        raise LoopError(f"{path} is not a dv2s loop record ({problem}); choose another --out, or delete the file "
                        "to start the loop over")


_ROUND_TEXTS = ("policy", "new_policy", "control_policy", "next_policy", "next_policy_reason")
"""The fields of a round in ``loop.json`` that are text (or absent)."""


def _round_problem(rounds: List[Dict[str, Any]]) -> Optional[str]:
    """What is wrong with the rounds of a ``loop.json`` (``None``: nothing): each finished step is an object (a
    skipped round's reason is text), each policy field text, each timing a number."""
    for number, record in enumerate(rounds, start=1):
        for step, value in record.get("steps", {}).items():
            if step == "skipped":
                if not isinstance(value, str):
                    return f"round {number}'s \"skipped\" reason is not text"
            elif step in _STAGE_NAMES and not isinstance(value, dict):
                return f"round {number}'s {step!r} step is not an object"
        for key in _ROUND_TEXTS:
            if record.get(key) is not None and not isinstance(record[key], str):
                return f"round {number}'s {key!r} is not text"
        if any(isinstance(t, bool) or not isinstance(t, (int, float)) for t in record.get("timings", {}).values()):
            return f"round {number} has a timing that is not a number"
    return None


# --------------------------------------------------------------------------- helpers
def _round_spec(spec: Any, folder: Path, out: Path) -> str:
    """A round's policy spec read back from ``loop.json``: an SB3 checkpoint inside that round's own
    ``folder``, as the loop writes it. A spec naming anything else (code, a checkpoint elsewhere) is refused:
    ``loop.json`` is a file, not the user's command line."""
    text = spec if isinstance(spec, str) else repr(spec)
    algorithm, sep, path = text.partition(":")
    inside = False
    if sep and algorithm in SB3_ALGORITHMS and "?" not in path:
        try:
            inside = Path(path).resolve().is_relative_to(folder.resolve())
        except (OSError, ValueError):
            inside = False
    if not inside:
        raise LoopError(f"{out / 'loop.json'} names the round policy {text[:200]!r}, not a checkpoint in {folder}: "
                        "this loop folder was not written by this loop as it stands; choose another --out")
    return text


def _working_bank(out: Path, bank_dir: Optional[str]) -> str:
    """The bank the loop adds to: ``bank_dir`` itself, or a copy of the shipped bank in ``out/bank``."""
    if bank_dir is not None:
        return str(Path(bank_dir).resolve())

    target = out / "bank"
    if not target.is_dir() or not any(target.iterdir()):
        Bank().copy_to(target)  # atomic: a killed copy leaves no half bank behind
    return str(target.resolve())


def mined_entries(mine_out: os.PathLike | str, replays: bool = True) -> List[MinedEntry]:
    """The kept scenarios of a mining run (:class:`~dv2s_gym.loop.record.MinedEntry`: cluster, scenario,
    reproduction) from its ``conversions.jsonl`` (status ``kept`` with a bank entry), then (``replays``) the exact
    replays of its failing scenes (:func:`dv2s_gym.loop.replays.replay_entries`: ``replay`` true and ``parent``,
    from the conversions' ``replay_entry`` and from ``replays.jsonl``)."""
    records = read_conversions(Path(mine_out) / "conversions.jsonl")  # none when no cluster was converted
    entries: Dict[str, MinedEntry] = {}
    for record in records:
        if record.kept and record.bank_entry:
            entries[str(record.cluster)] = MinedEntry(cluster=str(record.cluster), scenario=record.bank_entry,
                                                      reproduction=(record.reproduction or {}).get("rate"))
    kept = {entry.scenario for entry in entries.values()}
    for record in records:  # a cluster merged into a scenario kept in this run is tied to it
        if record.merged and record.merged_into in kept:
            entries.setdefault(str(record.cluster), MinedEntry(
                cluster=str(record.cluster), scenario=record.merged_into,
                reproduction=(record.reproduction or {}).get("rate")))
    converted = [entries[key] for key in sorted(entries)]
    if not replays:
        return converted

    return converted + replay_entries(mine_out)


def _mining_summary(mine_out: Path) -> MiningSummary:
    """Counts read from a mining run folder (episodes, failures, avoidable ones, clusters, conversions)."""
    episodes, failures, counted, errors = 0, 0, 0, 0
    records = read_rows(mine_out / "episodes.jsonl")
    for record in records:
        episodes += 1
        errors += bool(record.get("error"))
        if record.get("failure"):
            failures += 1
            counted += record.get("avoidable") is not False  # as MineRun.avoidable
    episode_records: Optional[List[EpisodeRecord]] = None
    clusters = None
    try:
        episode_records = [EpisodeRecord.from_dict(r) for r in records]
        clusters = len(set(cluster_failures(episode_records).values()))
    except (RecordError, MiningError):  # a record the counts cannot read: they are informative, the loop goes on
        episode_records = None
    statuses: Dict[str, int] = {}
    reasons: List[str] = []
    conversions = read_conversions(mine_out / "conversions.jsonl")
    for record in conversions:
        status = str(record.status) if record.status is not None else "?"
        statuses[status] = statuses.get(status, 0) + 1
        if record.rejected and (record.rejections or record.reason):
            reasons += [str(r) for r in record.rejections or [record.reason]]  # every failed check
    converted = sum(statuses.values())
    tried = {str(record.cluster) for record in conversions}
    # clusters no conversion tried whose every failing scene the reference driver failed too: never replayed
    reference_failed = None
    try:
        reference_failed = None if episode_records is None else sum(
            1 for cluster, members in group(episode_records).items()
            if cluster not in tried and not any(reference_passed(r) for r in members))
    except (RecordError, MiningError):  # informative, as the cluster count
        pass

    replayed: Dict[str, int] = {}
    for row in read_rows(mine_out / REPLAYS_FILE):
        replayed[row.get("status", "?")] = replayed.get(row.get("status", "?"), 0) + 1
    return MiningSummary(replays=replayed, episodes=episodes, errors=errors, errored=errored_episodes(records),
                         failures=failures, failures_against_policy=counted,
                         clusters=clusters, conversions=statuses, rejected_reasons=tuple(reasons[:40]),
                         rejected_reason_count=len(reasons),
                         clusters_not_converted=None if clusters is None else max(0, clusters - converted),
                         clusters_not_kept=None if clusters is None else max(0, clusters - converted
                                                                             - sum(replayed.values())),
                         clusters_reference_failed=reference_failed)


def _regress_errored(report: Union[RegressReport, Mapping[str, Any]], roles: Mapping[str, str]) -> Dict[str, Dict[str, Any]]:
    """The errored episodes of a ``dv2s regress`` report (a :class:`~dv2s_gym.regress.records.RegressReport`) per
    policy: ``roles`` maps its roles (``candidate``, ``baseline``) to the loop's names for them
    (:func:`errored_episodes`' form)."""
    report = RegressReport.from_json(report)
    found: Dict[str, Dict[str, Any]] = {}
    for role, name in roles.items():
        found[name] = errored_episodes([{"scenario": e.scenario, "error": e.result(role).error}
                                        for e in report.episodes or () if e.result(role) is not None])
    return found


def fine_tune_weights(names: Sequence[str], mined: Sequence[str], mined_share: float) -> Dict[str, float]:
    """Scenario -> sampling weight: the ``mined`` scenarios share ``mined_share`` of the probability
    equally, the other ``names`` share the rest (everything else in ``names`` stays in the mix)."""
    mined = sorted(set(mined) & set(names))
    rest = sorted(set(names) - set(mined))
    if not mined:
        return {name: 1.0 for name in rest}
    if not rest:
        return {name: 1.0 for name in mined}
    share = min(max(float(mined_share), 0.0), 1.0)
    weights = {name: (1.0 - share) / len(rest) for name in rest}
    weights.update({name: share / len(mined) for name in mined})
    return weights


def _policy_env_config(spec: str) -> Dict[str, Any]:
    from policies.training import TrainingError, resolve_checkpoint

    try:
        _, _, card = resolve_checkpoint(spec)
    except TrainingError as error:
        raise LoopError(f"dv2s loop fine-tunes the policy, so it needs a stable-baselines3 checkpoint "
                        f"(dv2s-ppo, ppo:PATH or a `dv2s train` folder): {error}") from None
    return dict(card.env_config or {})


def _regress_summary(report: Union[RegressReport, Mapping[str, Any]], path: Path, parents: Sequence[str] = ()) -> RegressSummary:
    """The regression step's record; ``parents``: scenarios whose own results are kept apart (the held-out
    families' parents, never fine-tuned on: the regression test's view beyond the fine-tuning mix)."""
    report = RegressReport.from_json(report)
    overall = report.overall if report.overall is not None else ScenarioResult()
    per_scenario = report.scenarios or {}
    comparison = overall.comparison if overall.comparison is not None else PairedComparison()

    def rate(role: str) -> Optional[Mapping[str, Any]]:
        summary = overall.summary(role)
        return summary.failure_rate if summary is not None else None

    def measures(summary: Optional[Summary]) -> Dict[str, Any]:
        summary = summary if summary is not None else Summary()
        return {"failure_rate": summary.failure_rate, "stall_rate": summary.rate("stall"),
                "mean_speed": summary.mean_speed}

    return RegressSummary(
        verdict=report.verdict, reason=comparison.reason, episodes=comparison.n,
        new_failure_rate=rate("candidate"), old_failure_rate=rate("baseline"),
        difference=comparison.difference, p_value=comparison.p_value,
        regressed=tuple(report.regressed or ()), report=str(Path(path).resolve()),
        held_out_parents={name: {role: measures(per_scenario[name].summary(side))
                                 for role, side in (("new", "candidate"), ("old", "baseline"))}
                          for name in parents if name in per_scenario})


def _log_default(line: str) -> None:
    log_line(line)


# --------------------------------------------------------------------------- the loop
def run_loop(policy: str = "dv2s-ppo", settings: Optional[LoopSettings] = None, *,
             out: os.PathLike | str = DEFAULT_OUT, progress: bool = True,
             log: Callable[[str], None] = _log_default) -> LoopReport:
    """Run ``settings.rounds`` rounds of mine -> split -> evaluate -> fine-tune (+ control) -> evaluate -> regress
    (module docstring).

    Args:
        policy: the starting policy, an SB3 checkpoint spec (``dv2s-ppo``, ``ppo:PATH``, a run folder).
        settings: the loop's :class:`~dv2s_gym.loop.settings.LoopSettings` (default: its defaults).
        out: the loop folder (resumable).
        progress: progress bars on stderr.
        log: where the progress lines go (default stderr).

    Returns:
        A :class:`LoopReport`; the reports are written to ``out`` after every round.
    """
    settings = settings or LoopSettings()
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise LoopError(f"--out {out} is a file; choose a folder for the loop")
    loop = _open_loop(policy, settings, out, progress, log)

    note = evidence_floor_note(settings.min_heldout_episodes, settings.min_heldout_families)
    if note:
        log(f"WARNING: {note}")
    current = policy
    for number in range(1, settings.rounds + 1):
        current = _run_round(loop, number, current)
    return _write(out, loop.state)


@dataclasses.dataclass
class _Loop:
    """A loop being run: its settings, record, working bank and the env configs its steps use."""

    settings: LoopSettings
    state: "_State"
    out: Path
    bank: str
    start_names: List[str]
    env_config: Dict[str, Any]
    fine_tune_config: Dict[str, Any]
    workers: int
    progress: bool
    log: Callable[[str], None]


def _open_loop(policy: str, settings: LoopSettings, out: Path, progress: bool, log: Callable[[str], None]) -> _Loop:
    """The loop in ``out``: a new one recorded in ``loop.json``, or the recorded one checked against ``settings``;
    its working bank and starting scenarios."""
    from policies.training import TrainingError, with_reward_weights

    workers = int(settings.workers or default_workers())
    env_config = _policy_env_config(policy)
    try:
        fine_tune_config = with_reward_weights(env_config, settings.fine_tune_reward)
    except TrainingError as error:
        raise LoopError(f"--fine-tune-reward: {error}") from None
    state = _State(out / "loop.json", _recorded_settings(policy, settings, workers, env_config, fine_tune_config))
    bank = _working_bank(out, state.settings.bank_dir)
    if state.start is None:
        names = sorted(select_scenarios(list(settings.scenarios) if settings.scenarios is not None else None, bank,
                                           command="dv2s loop"))
        if not names:
            raise LoopError("the scenario selection is empty; name bank scenarios or tag:<tag>")
        state.start = LoopStart(bank=bank, scenarios=tuple(names))
        state.save()
    scripts = bank_identity(Bank(bank), state.start.scenarios)  # the starting scenarios of the working bank
    if BANK_IDENTITY in state.extra:
        check_bank_unchanged(state.extra[BANK_IDENTITY], scripts, run=f"{out} holds a loop", error=LoopError)
    else:
        state.extra[BANK_IDENTITY] = scripts
        state.save()
    return _Loop(settings=settings, state=state, out=out, bank=bank, start_names=list(state.start.scenarios),
                 env_config=env_config, fine_tune_config=fine_tune_config, workers=workers, progress=progress, log=log)


def _recorded_settings(policy: str, settings: LoopSettings, workers: int, env_config: Dict[str, Any],
                       fine_tune_config: Dict[str, Any]) -> Dict[str, Any]:
    """The ``settings`` of ``loop.json``: :meth:`LoopSettings.recorded` with the policy, the resolved number of
    workers, how mined scenarios are held out and the env configs (the keys :data:`IDENTITY` names are the loop's
    identity) and the starting policy's fingerprint (:func:`~policies.run_identity.resume_fingerprint`)."""
    return {"policy": policy, **settings.recorded(), "workers": workers, "holdout_by": HOLDOUT_BY,
            "env_config": env_config, "fine_tune_env_config": fine_tune_config,
            RESUME_FINGERPRINT: resume_fingerprint(policy)}


class _Timed:
    """Runs one step of a round: logs it, times it, records its value in ``loop.json``."""

    def __init__(self, loop: _Loop, number: int) -> None:
        self.loop, self.number = loop, number
        control, untouched = loop.settings.control, loop.settings.untouched_seeds
        self.stages = ["mine", "split", "reference", "before", "fine_tune"] + (["control"] if control else []) + ["after"] + (
            ["untouched"] if untouched else []) + ["regress"]

    def __call__(self, step: str, function: Callable[[], Any], plan: str = "") -> Any:
        """Run ``function`` as ``step``; ``plan`` says what it will do (its size), in the step's opening line."""
        log, state = self.loop.log, self.loop.state
        where = f"round {self.number} [{self.stages.index(step) + 1}/{len(self.stages)}] {_STAGE_NAMES[step]}"
        log(f"{where}: {plan} ..." if plan else f"{where} ...")
        began = time.perf_counter()
        value = function()
        seconds = round(time.perf_counter() - began, 1)  # of the run that finished the step
        state.update(state.round(self.number).with_step(step, value, seconds))
        log(f"{where}: done in {seconds:.0f} s")
        return value

    @property
    def steps(self) -> RoundSteps:
        """The round's steps as recorded so far."""
        return self.loop.state.round(self.number).steps


def _run_round(loop: _Loop, number: int, current: str) -> str:
    """Run (or finish) round ``number`` from policy ``current``; the policy the next round starts from."""
    record = loop.state.round(number)
    steps = record.steps
    if recorded(steps) and record.policy not in (None, current):
        raise LoopError(f"round {number} in {loop.out / 'loop.json'} was begun from {record.policy}, not from "
                        f"{current}, the policy the rounds before it recommend; choose another --out")
    if record.policy is None and "policy" not in (record.null_fields or ()):
        loop.state.update(record.replace(policy=current), save=False)
    round_dir = loop.out / f"round_{number}"
    if steps.done("regress") or steps.skipped:
        return _next_start(loop, number, current)
    loop.log(f"round {number}: policy {current}")
    timed = _Timed(loop, number)
    done = [_STAGE_NAMES[step] for step in timed.stages if steps.done(step)]
    if done:
        loop.log(f"round {number}: resuming: {len(done)} of {len(timed.stages)} steps already done and kept "
                 f"({', '.join(done)}); an interrupted step carries on from what it had kept")
    if not steps.done("mine"):
        mined = timed("mine", lambda: _mine_step(loop, number, current, round_dir), _mine_plan(loop))
        _log_mined(loop, number, mined)
        _log_errored(loop, number, "mining", {"mine": mined.errored})
    if not timed.steps.done("split"):
        _split_step(loop, number, current, timed)
    if not timed.steps.split.fine_tune_scenarios and not timed.steps.split.held_out_scenarios:
        _skip_round(loop, number, timed.steps)
    else:
        _tune_and_measure(loop, number, current, round_dir, timed)
        _log_round(loop.log, number, timed.steps)
    following = _next_start(loop, number, current)
    if number < loop.settings.rounds:
        loop.log(f"round {number}: round {number + 1} starts from {following}: "
                 f"{loop.state.round(number).next_policy_reason}")
    _write(loop.out, loop.state)
    return following


def _split_step(loop: _Loop, number: int, current: str, timed: "_Timed") -> None:
    """Split the round's kept scenarios into fine-tuning and held-out families. Families an earlier round held
    out stay held out where they can; families fine-tuned on by a round ``current`` descends from
    (:func:`_lineage`) cannot be held out; a discarded round's fine-tuning does not count."""
    earlier = loop.state.rounds[:number - 1]
    held_families, _ = _earlier_sides(earlier)
    _, tuned_families = _earlier_sides(_lineage(loop, earlier, current))
    kept = timed.steps.mine.kept_entries
    split = timed("split", lambda: split_by_family(_with_parents(kept, loop.bank), loop.settings.holdout_fraction,
                                                   loop.settings.seed * 1000 + number, held_families,
                                                   tuned_families).record(),
                  f"{len(kept)} kept mined scenario(s) into fine-tuning and held-out families")
    families = set(split.fine_tune_family_names)  # every kept family, when none is held out
    if kept and not split.held_out_scenarios and families and families <= set(tuned_families) - set(held_families):
        loop.log(f"round {number}: WARNING: nothing can be held out: every kept scenario's family "
                 f"({', '.join(sorted(families))}) was fine-tuned on by an earlier round that {current} descends from")
    if split.moved_to_fine_tune:
        loop.log(f"round {number}: WARNING: earlier held-out famil(ies) "
                 f"{', '.join(split.moved_to_fine_tune)} now share a mined scenario with a family "
                 "fine-tuned on earlier, so they are fine-tuned on from this round")


def _next_start(loop: _Loop, number: int, current: str) -> str:
    """The policy round ``number + 1`` starts from: the one the verdict on rounds 1..``number`` recommends
    (:func:`~dv2s_gym.loop.verdict.recommendation`: never a REJECTED or NOT ACCEPTED fine-tuned policy),
    recorded in round ``number``'s ``next_policy`` and ``next_policy_reason``."""
    rounds = loop.state.rounds[:number]
    record = rounds[-1]
    start = loop.state.settings.policy
    # as the report judges it: the cross-round check on each accepted round's policy
    body = loop_report.with_cross_round_checks({"settings": {"policy": start},
                                                "rounds": [r.to_dict() for r in rounds]}, folder=loop.out)
    advice = recommendation(body)
    # the policy to use, exactly as the report recommends it: the fine-tuned one only when it is the recommendation
    following = advice.policy
    if not record.fine_tuned:
        reason = f"this round fine-tuned no policy; {advice.sentence}"
    else:
        reason = advice.sentence
    if following != start:
        following = _earlier_round_spec(following, loop, number + 1)
    if (record.next_policy, record.next_policy_reason) != (following, reason):
        loop.state.update(record.replace(next_policy=following, next_policy_reason=reason))
    return following


def _earlier_round_spec(spec: Any, loop: _Loop, number: int) -> str:
    """``spec`` read back from ``loop.json`` as the starting policy or the fine-tuned checkpoint of a round
    before ``number`` (anything else is refused, as :func:`_round_spec` does)."""
    if spec == loop.state.settings.policy:
        return spec
    for earlier in range(number - 1, 0, -1):
        try:
            return _round_spec(spec, loop.out / f"round_{earlier}" / "policy", loop.out)
        except LoopError:
            continue
    return _round_spec(spec, loop.out / f"round_{max(number - 1, 1)}" / "policy", loop.out)  # raises, naming it


def _mine_step(loop: _Loop, number: int, current: str, round_dir: Path) -> MiningSummary:
    """The ``mine`` step: mine ``current``'s failures into the working bank, keep exact replays of more."""
    s = loop.settings
    miner.mine(current, MineSettings(budget=s.budget, sampler=s.sampler, scenarios=loop.start_names,
                                     bank_dir=loop.bank, seed=s.seed * 1000 + number, env_config=loop.env_config,
                                     convert=True, max_conversions=s.max_conversions),
               out=str(round_dir / "mine"), workers=WorkerSettings(workers=loop.workers), progress=loop.progress,
               origin=RunOrigin(command="dv2s loop", seed=s.seed, round=number))
    if s.max_replays != 0 and (round_dir / "mine" / "settings.json").is_file():  # a miner's run folder
        replay_clusters(round_dir / "mine", bank_dir=loop.bank, max_replays=s.max_replays, progress=loop.progress)
    return _mining_summary(round_dir / "mine").replace(kept=tuple(mined_entries(round_dir / "mine")),
                                                       folder=str(round_dir / "mine"))


def _mine_plan(loop: _Loop) -> str:
    """What the ``mine`` step will do, in words."""
    s = loop.settings

    def most(count: Optional[int], what: str) -> str:
        return f"every cluster {what}" if count is None else f"at most {count} cluster(s) {what}"

    return (f"{s.budget} episodes on {len(loop.start_names)} scenarios ({s.sampler} sampler), then "
            f"{most(s.max_conversions, 'converted')} and {most(s.max_replays, 'kept as exact replays')}")


def _count_scripts(bank: Path) -> int:
    return sum(1 for _ in Path(bank).glob("*/scenario.scenic"))


def _log_errored(loop: _Loop, number: int, stage: str, errored: Mapping[str, Optional[ErroredEpisodes]]) -> None:
    """Say loudly when a step's episodes errored: they count in no rate and no test."""
    text = errored_text(errored)
    if not text:
        return
    merged = merged_messages([found for found in errored.values() if recorded(found)])
    loop.log(f"round {number}: WARNING: episodes that errored in the {stage} step (left out of its rates and "
             f"tests): {text}" + "".join(f"; {name}: {messages_text(merged, name)}" for name in merged))


def _log_mined(loop: _Loop, number: int, mined: MiningSummary) -> None:
    s = loop.settings
    loop.log(f"round {number}: mined {mined.failures} failures in {mined.episodes} episodes"
             f"{errored_note(mined.errored)}, "
             f"{mined.clusters} clusters, "
             f"{len({e.scenario for e in mined.converted})} converted scenarios and "
             f"{len({e.scenario for e in mined.replayed})} exact replays kept"
             + (f"; {mined.clusters_not_converted} clusters not converted (--max-conversions "
                f"{'all' if s.max_conversions is None else s.max_conversions})"
                if mined.clusters_not_converted else "")
             + (f", {mined.clusters_not_kept} neither converted nor replayed (--max-replays "
                f"{'all' if s.max_replays is None else s.max_replays}"
                + (f"; {mined.clusters_reference_failed} of them because the reference driver {REFERENCE_DRIVER} "
                   "did not pass any of their failing scenes" if mined.clusters_reference_failed else "")
                + ")" if mined.clusters_not_kept else ""))


def _skip_round(loop: _Loop, number: int, steps: RoundSteps) -> None:
    """Record and log a round that kept no mined scenario (nothing to fine-tune on or to measure)."""
    mined = steps.mine
    tried = sum((mined.conversions or {}).values())
    replayed = sum((mined.replays or {}).values())
    skipped = (f"no mined scenario was kept this round ({tried} conversion(s) tried"
               + (f", {replayed} exact replay(s) tried" if replayed else "")
               + (f", {mined.clusters_not_converted} cluster(s) not converted: raise "
                  "--max-conversions, --max-replays or --budget"
                  if mined.clusters_not_converted else "")
               + "): nothing to fine-tune on or to measure")
    loop.state.update(loop.state.round(number).with_step("skipped", skipped))
    loop.log(f"round {number}: {skipped}")


def _tune_and_measure(loop: _Loop, number: int, current: str, round_dir: Path, timed: _Timed) -> str:
    """The steps after the split: held-out before, fine-tune (+ control), held-out after, untouched set,
    regression; the fine-tuned policy's spec."""
    s, split = loop.settings, timed.steps.split
    episodes = [(name, EVAL_SEED_BASE + i) for name in split.held_out_scenarios for i in range(s.k_eval)]
    families = _families_of(timed.steps.mine.kept_entries, split.held_out_scenarios, loop.bank)
    store_path = round_dir / "heldout.jsonl"
    if not timed.steps.done("reference"):
        gate = timed("reference", lambda: _reference_step(loop, episodes, HeldOutStore(store_path), families),
                     f"{len(episodes)} episodes ({len(split.held_out_scenarios)} held-out scenario(s) x {s.k_eval} seeds) "
                     f"for the reference driver {REFERENCE_DRIVER}: a held-out episode it does not pass is left out")
        _log_reference(loop, number, gate)
    excluded = timed.steps.reference.excluded_episodes
    episodes = [episode for episode in episodes if episode not in excluded]
    shortfall = underpowered(len(episodes), s.min_heldout_episodes,
                             len({families[name] for name, _ in episodes}), s.min_heldout_families)
    if shortfall:
        loop.log(f"round {number}: WARNING: {shortfall}")
    if not timed.steps.done("before"):
        def before_step() -> HeldOutBefore:
            records = heldout.evaluate_heldout("before", current, episodes, store=HeldOutStore(store_path),
                                               bank_dir=loop.bank, env_config=loop.env_config,
                                               workers=WorkerSettings(workers=loop.workers), progress=loop.progress)
            return HeldOutBefore(episodes=len(episodes), done=bool(records), errored=errored_episodes(records))

        before = timed("before", before_step,
                       f"{len(episodes)} episodes ({len(split.held_out_scenarios)} held-out scenario(s) x {s.k_eval} seeds"
                       + (f", {len(excluded)} left out: the reference driver does not pass them" if excluded else "")
                       + ")")
        _log_errored(loop, number, "held-out: starting policy", {"start": before.errored})
    new_policy, control_policy = _fine_tune_arms(loop, number, current, round_dir, timed)
    policies = {"before": current, "after": new_policy, "control": control_policy}
    if not timed.steps.done("after"):
        after = timed("after", lambda: _after_step(loop, policies, episodes, HeldOutStore(store_path), families),
                      f"{len(episodes)} episodes for the fine-tuned policy" + (" and as many for the control"
                                                                               if control_policy else ""))
        _log_errored(loop, number, "held-out: fine-tuned and control", after.errored or {})
    if s.untouched_seeds and not timed.steps.done("untouched"):
        untouched = timed("untouched", lambda: evaluate_untouched(
            current, new_policy, control_policy, settings=untouched_settings(s.untouched_seeds, loop.env_config,
                                                                             s.margin),
            out=round_dir / "untouched", workers=loop.workers, progress=loop.progress),
              f"{_count_scripts(UNTOUCHED_BANK)} scripts x {s.untouched_seeds} seed(s) for the starting, fine-tuned"
              + (" and control policies" if control_policy else " policies"))
        _log_errored(loop, number, "untouched scenario set", untouched.errored or {})
    if not timed.steps.done("regress"):
        regress = timed("regress", lambda: _regress_step(loop, new_policy, current, round_dir, split),
                        f"{len(loop.start_names)} scenarios x {s.regress_episodes} seed(s), fine-tuned against "
                        "starting policy")
        _log_errored(loop, number, "regression test", regress.errored or {})
    return new_policy


REFERENCE_DRIVER: str = MineSettings.reference
"""The reference driver of the loop: the miner's avoidability reference (:class:`~dv2s_gym.mining.settings.MineSettings`'
default) and the DAgger teacher (:class:`~policies.dagger_config.DaggerConfig`'s default, the same; read from the
miner's settings so that importing the loop does not load torch). The held-out evaluation keeps only the episodes it
passes (:func:`reference_gate`)."""


def reference_gate(records: Sequence[HeldOutEpisode], families: Mapping[str, str]) -> ReferenceGate:
    """The ``reference`` step's record from the reference driver's held-out ``records``: which held-out episodes
    the loop leaves out because the reference driver did not pass them (it failed, by the miner's monitors, or the
    episode errored, so that nobody knows), counted and named, never dropped silently.

    A policy that imitates the reference cannot be expected to pass a scene the reference itself fails, so such a
    pair measures nothing the fine-tuning can change and only adds noise to the held-out comparison. Returns the
    :class:`~dv2s_gym.loop.record.ReferenceGate` (``excluded``: ``[scenario, seed]`` pairs; ``by_scenario``:
    ``{scenario: {"episodes", "excluded", "failures": {type: n}}}``; ``excluded_families``: the families whose
    every episode is left out)."""
    by_scenario: Dict[str, Dict[str, Any]] = {}
    excluded, failed, errored = [], 0, 0
    kept_families, all_families = set(), set()
    for record in records:
        name, seed = str(record.scenario), int(record.seed)
        row = by_scenario.setdefault(name, {"episodes": 0, "excluded": 0, "failures": {}})
        row["episodes"] += 1
        family = families.get(name, name)
        all_families.add(family)
        outcome = episode_failed(record)
        if outcome is False:
            kept_families.add(family)
            continue
        excluded.append([name, seed])
        row["excluded"] += 1
        if outcome is None:
            errored += 1
            kind = "error"
        else:
            failed += 1
            kind = record.failure.type if record.failure is not None else "failure"
        row["failures"][kind] = row["failures"].get(kind, 0) + 1
    return ReferenceGate(reference=REFERENCE_DRIVER, episodes=len(records), kept=len(records) - len(excluded),
                         excluded=tuple(excluded), failed=failed, errored=errored,
                         by_scenario={name: by_scenario[name] for name in sorted(by_scenario)},
                         excluded_families=tuple(sorted(all_families - kept_families)))


def _reference_step(loop: _Loop, episodes: List[tuple], store, families: Mapping[str, str]) -> ReferenceGate:
    """The ``reference`` step: the reference driver on every held-out episode (role ``reference`` in the
    held-out store); :func:`reference_gate`'s record."""
    records = heldout.evaluate_heldout("reference", REFERENCE_DRIVER, episodes, store=store, bank_dir=loop.bank,
                                       env_config=loop.env_config, workers=WorkerSettings(workers=loop.workers),
                                       progress=loop.progress)
    return reference_gate(records, families)


def _log_reference(loop: _Loop, number: int, gate: ReferenceGate) -> None:
    text = reference_gate_text(gate)
    loop.log(f"round {number}: {'WARNING: ' if gate.excluded else ''}{text}")


def _fine_tune_arms(loop: _Loop, number: int, current: str, round_dir: Path, timed: _Timed) -> tuple:
    """The ``fine_tune`` and ``control`` steps: ``(fine-tuned policy spec, control policy spec or None)``."""
    from policies.training import resolve_checkpoint

    s, split = loop.settings, timed.steps.split
    excluded = set(split.held_out_scenarios) | set(split.held_out_family_names)
    for earlier in loop.state.rounds[:number - 1]:
        earlier_split = earlier.steps.split if earlier.steps.split is not None else SplitRecord()
        excluded.update(earlier_split.held_out_scenarios)
        excluded.update(earlier_split.held_out_family_names)
    arm = _Arm(bank=loop.bank, method=s.fine_tune_method, steps=s.fine_tune_steps, seed=s.seed * 1000 + number,
               n_envs=s.n_envs, env_config=loop.env_config, fine_tune_config=loop.fine_tune_config,
               reward=s.fine_tune_reward, learning_rate=s.fine_tune_lr, beta_decay=s.dagger_beta_decay,
               progress=loop.progress, log=loop.log)
    if not timed.steps.done("fine_tune"):
        timed("fine_tune", lambda: _fine_tune_arm(current, round_dir / "policy", excluded, s.mined_share, arm,
                                                  with_mined=True, label=f"round {number}"),
              f"{s.fine_tune_method} {s.fine_tune_steps} steps, the mined scenarios drawn with probability "
              f"{s.mined_share}")

    def spec_of(model: str, folder: Path) -> str:
        _round_spec(f"ppo:{model}", folder, loop.out)  # loop.json is a file: only this round's own checkpoint
        return f"{resolve_checkpoint(model)[0]}:{model}"

    new_policy = spec_of(timed.steps.fine_tune.model, round_dir / "policy")
    loop.state.update(loop.state.round(number).replace(new_policy=new_policy), save=False)
    control_policy = None
    if s.control:
        if not timed.steps.done("control"):
            timed("control", lambda: _fine_tune_arm(current, round_dir / "control", excluded, s.mined_share, arm,
                                                    with_mined=False, label=f"round {number} control"),
                  f"{s.fine_tune_method} {s.fine_tune_steps} steps without the mined scenarios")
        control_policy = spec_of(timed.steps.control.model, round_dir / "control")
        loop.state.update(loop.state.round(number).replace(control_policy=control_policy), save=False)
    return new_policy, control_policy


def _after_step(loop: _Loop, policies: Mapping[str, Optional[str]], episodes: List[tuple], store,
                families: Mapping[str, str]) -> HeldOutComparison:
    """The ``after`` step: start, fine-tuned and control on the held-out episodes, compared pairwise."""
    common = dict(store=store, bank_dir=loop.bank, env_config=loop.env_config,
                  workers=WorkerSettings(workers=loop.workers))
    before = heldout.evaluate_heldout("before", policies["before"], episodes, progress=False, **common)
    after = heldout.evaluate_heldout("after", policies["after"], episodes, progress=loop.progress, **common)
    control_records = None
    if policies["control"] is not None:
        control_records = heldout.evaluate_heldout("control", policies["control"], episodes, progress=loop.progress,
                                                   **common)
    s = loop.settings
    summary = heldout_comparison(before, after, control_records, min_episodes=s.min_heldout_episodes, seed=s.seed,
                                 families=families, min_families=s.min_heldout_families, margin=s.margin)
    return summary.replace(errored={
        "fine_tuned": errored_episodes(after),
        **({"control": errored_episodes(control_records)} if control_records is not None else {})})


def _regress_step(loop: _Loop, new_policy: str, current: str, round_dir: Path,
                  split: SplitRecord) -> RegressSummary:
    """The ``regress`` step: the fine-tuned policy against the round's start on the starting bank's scenarios."""
    s = loop.settings
    settings = RegressSettings(bank_dir=loop.bank, scenarios=loop.start_names, episodes=s.regress_episodes,
                               seed=EVAL_SEED_BASE, margin=s.margin, env_config=loop.env_config)
    report = runner.run_regression(new_policy, current, settings, workers=WorkerSettings(workers=loop.workers),
                                   out_dir=round_dir / "regress", progress=loop.progress)
    summary = _regress_summary(report, round_dir / "regress" / "report.json", split.held_out_family_names)
    return summary.replace(errored=_regress_errored(report, {"baseline": "start", "candidate": "fine_tuned"}))


_STAGE_NAMES = {"mine": "mining failures", "split": "splitting by family",
                "reference": "held-out: reference driver", "before": "held-out: starting policy",
                "fine_tune": "fine-tuning with the mined scenarios", "control": "control: fine-tuning without them",
                "after": "held-out: fine-tuned and control", "untouched": "untouched scenario set",
                "regress": "regression test on the starting bank"}


def underpowered(episodes: int, minimum: int, families: Optional[int] = None,
                 min_families: int = 0, tested: bool = False) -> Optional[str]:
    """The warning for a round with fewer than ``minimum`` held-out episodes or fewer than ``min_families``
    held-out families (``families``, when known; ``tested``: families with a tested pair), or ``None``. Whatever the
    minimums, a round needs :data:`~dv2s_gym.loop.verdict.EVIDENCE_FLOOR` episodes (below that no exact
    McNemar test can be significant) and one family."""
    reasons = []
    if episodes < max(minimum, EVIDENCE_FLOOR):
        reasons.append(f"only {episodes} held-out episode(s), fewer than the {minimum} needed "
                       "(--min-heldout-episodes)" if episodes < minimum else
                       f"only {episodes} held-out episode(s), fewer than {EVIDENCE_FLOOR}: below {EVIDENCE_FLOOR} "
                       f"discordant pairs the exact McNemar test cannot reach p < {HELDOUT_ALPHA:g}, so the loop "
                       "judges no round on so few whatever --min-heldout-episodes says")
    if families is not None and families < max(min_families, 1):
        reasons.append(f"only {families} held-out famil{'y' if families == 1 else 'ies'} (parent scenarios)"
                       f"{' with a tested pair' if tested else ''}, fewer "
                       f"than the {max(min_families, 1)} needed: episodes of one family are near-identical scenes, "
                       "not independent trials")
    if not reasons:
        return None
    return ("; ".join(reasons) + ": this round reports held-out rates but no drop and no test; raise --k-eval, "
            "--max-conversions, --max-replays or --budget for more held-out scenarios and families, or run "
            "`dv2s loop --profile evidence`")


def _families_of(kept: Sequence[MinedEntry], held_out: Sequence[str], bank: Optional[str]) -> Dict[str, str]:
    """``{held-out scenario: its family}`` (:func:`dv2s_gym.loop.split.family_of`)."""
    wanted = set(held_out)
    families = {str(e.scenario): family_of(e) for e in _with_parents(kept, bank) if e.scenario in wanted}
    return {name: families.get(name, name) for name in held_out}


@dataclasses.dataclass(frozen=True)
class _Arm:
    """What the two fine-tuning arms of a round share (everything but the mined scenarios)."""

    bank: str
    method: str
    steps: int
    seed: int
    n_envs: int
    env_config: Dict[str, Any]
    fine_tune_config: Dict[str, Any]
    reward: Mapping[str, float]
    learning_rate: float
    beta_decay: float
    progress: bool
    log: Callable[[str], None]

    def config(self, out: Path, weights: Mapping[str, float]):
        """The arm's :class:`~policies.training.TrainConfig` into ``out``, drawing scenarios by ``weights``."""
        from policies.training import TrainConfig

        return TrainConfig.fine_tuning(out, steps=self.steps, weights=weights, bank_dir=self.bank, seed=self.seed,
                                       n_envs=self.n_envs, env_config=self.env_config, progress_bar=self.progress)


def arm_weights(bank_dir: str, excluded: set, mined_share: float, *,
                with_mined: bool) -> tuple:
    """The scenario sampling weights of one fine-tuning arm on the working bank ``bank_dir`` less ``excluded``
    (held-out scenarios and families): ``(weights, facts)``. ``with_mined``: the mined scenarios drawn with
    probability ``mined_share`` (the fine-tuned arm); otherwise left out (the control arm)."""
    # a held-out family's every member stays out too: exact replays of its failures and entries of earlier rounds,
    # at any depth (a member's family is the root of its provenance chain, not its immediate parent)
    bank = list(Bank(bank_dir))
    roots = {e.name: scenario_family(e.name, bank_dir) for e in bank}
    entries = [e for e in bank if e.name not in excluded and e.source.parent not in excluded
               and roots[e.name] not in excluded]
    mined = sorted(e.name for e in entries if e.source.mined)
    names = sorted(e.name for e in entries if with_mined or e.name not in mined)
    weights = fine_tune_weights(names, mined if with_mined else [], mined_share)
    return weights, {"scenarios": len(names), "mined_upweighted": len(mined) if with_mined else 0,
                     "mined_left_out": 0 if with_mined else len(mined),
                     "families": sorted({roots[e.name] for e in entries if e.name in names})}


def _fine_tune_arm(current: str, out: Path, excluded: set, mined_share: float, arm: _Arm, *, with_mined: bool,
                   label: str) -> FineTuneArm:
    """Fine-tune ``current`` into ``out`` on the working bank less ``excluded``: the mined scenarios upweighted
    (``with_mined``) or left out (the control arm); everything else identical between the two arms."""
    weights, facts = arm_weights(arm.bank, excluded, mined_share, with_mined=with_mined)
    common = dict(scenarios=facts["scenarios"], mined_upweighted=facts["mined_upweighted"], steps=arm.steps,
                  mined_left_out=facts["mined_left_out"], families=tuple(facts["families"]))
    if arm.method == FineTuneMethod.DAGGER:
        return FineTuneArm.from_dict(_dagger_arm(current, out, weights, arm, label)).replace(
            method=FineTuneMethod.DAGGER.value, **common)
    from policies.training import fine_tune

    config = dataclasses.replace(arm.config(out, weights), reward_weights=dict(arm.reward) or None,
                                 learning_rate=arm.learning_rate)
    path = fine_tune(current, config, log=arm.log)
    return FineTuneArm(model=str(path.resolve()), method=FineTuneMethod.PPO.value, **common, reward_weights=dict(arm.reward),
                       env_config=arm.fine_tune_config)


def _dagger_arm(current: str, out: Path, weights: Dict[str, float], arm: _Arm, label: str) -> FineTuneArm:
    """A fine-tuning arm by DAgger (:func:`policies.imitation.dagger_fine_tune`); a killed one resumes."""
    from policies.imitation import DaggerConfig, dagger_fine_tune

    # a resumed run says so itself ("DAgger: resumed from ...", after the step's own line naming the arm)
    path = dagger_fine_tune(current, arm.config(out, weights), DaggerConfig(learning_rate=arm.learning_rate,
                                                                             beta_decay=arm.beta_decay), log=arm.log)
    dagger = read_model_card(path).fine_tune
    dagger = dagger if recorded(dagger) else FineTune()
    return FineTuneArm(model=str(path.resolve()), method=FineTuneMethod.DAGGER.value, reward_weights=None,
                       env_config=arm.env_config, reference=dagger.reference, agreement=dagger.agreement,
                       resumed=tuple(dagger.resumed or ()))


def heldout_comparison(before: Sequence[HeldOutEpisode], after: Sequence[HeldOutEpisode],
                       control: Optional[Sequence[HeldOutEpisode]], *, min_episodes: int,
                       seed: int = 0, families: Optional[Mapping[str, str]] = None,
                       min_families: int = 0, margin: Optional[float] = None) -> HeldOutComparison:
    """The ``after`` step (a :class:`~dv2s_gym.loop.record.HeldOutComparison`):
    :func:`~dv2s_gym.loop.heldout.paired_summary` of fine-tuned against start, plus the control's rate and the
    paired fine-tuned-vs-control table and exact McNemar p (``vs_control``), and each policy's failures by type
    (``failure_types``: stalls apart from collisions and the rest).

    ``families`` maps each held-out scenario to its family (default: each scenario its own); ``heldout_scenarios``
    and ``sampled_families`` count those the episodes came from, ``heldout_families`` the families with at least
    one tested pair (no error on either side) against the start and, with a control, against the control too. Below ``min_episodes`` pairs or
    ``min_families`` families the drop, its interval and both p-values are ``None`` and ``underpowered``
    says why (the rates, with their wide intervals, stay). ``significantly_worse`` holds, for ``start`` and
    ``control``, whether the fine-tuned policy is significantly worse on the held-out families
    (:func:`dv2s_gym.loop.verdict.heldout_worse`, the verdict's held-out tests; ``None`` when not tested:
    below the minimums, or no control), each with its held-out families' harm rule at ``margin`` (default: the
    loop's default margin; :func:`dv2s_gym.loop.verdict.family_harm`)."""
    scenarios = sorted({str(r.scenario) for r in before})
    # the drop's interval resamples families, the unit the split holds out (scenarios of one family are not
    # independent); a scenario without a family stands for itself
    summary = paired_summary(before, after, seed=seed,
                             families={name: (families or {}).get(name, name) for name in scenarios}).to_dict()
    summary["min_episodes"] = min_episodes
    summary["heldout_scenarios"] = len(scenarios)
    # a family counts only with a tested pair (no error on either side) in each held-out test: one whose episodes
    # all errored tests nothing, so it never makes a round large enough to judge
    def tested_families(baseline: Sequence[HeldOutEpisode]) -> set:
        return {family for family, table in _family_tables(baseline, after, families).items() if table.n}

    tested = tested_families(before)
    if control is not None:
        tested &= tested_families(control)
    summary["heldout_families"] = len(tested)
    summary["sampled_families"] = len({(families or {}).get(name, name) for name in scenarios})
    summary["min_families"] = min_families
    summary["failure_types"] = {"start": failure_types(before), "fine_tuned": failure_types(after)}
    if control is not None:
        versus = paired_summary(control, after, seed=seed, bootstrap=0)
        summary["control"] = versus.before.to_dict()
        summary["failure_types"]["control"] = failure_types(control)
        summary["vs_control"] = {"pairs": versus.pairs, "errors": versus.errors, "relative_drop": versus.relative_drop,
                                 "table": {"both_fail": versus.table.both_fail,
                                           "fine_tuned_only": versus.table.after_only,
                                           "control_only": versus.table.before_only, "neither": versus.table.neither},
                                 "mcnemar_p": versus.mcnemar_p,
                                 "per_scenario": {name: row["before"] for name, row in versus.per_scenario.items()}}
    shortfall = underpowered(summary["pairs"], min_episodes, summary["heldout_families"], min_families, tested=True)
    if shortfall:
        summary["underpowered"] = shortfall
        summary.update(relative_drop=None, relative_drop_interval=[None, None], mcnemar_p=None)
        if "vs_control" in summary:
            summary["vs_control"].update(relative_drop=None, mcnemar_p=None)
    # the test against the control needs the same evidence on its own pairs: a control that errored on most
    # episodes leaves few tested pairs against it, and a test on those says nothing
    control_shortfall = None if control is None else _control_shortfall(summary["vs_control"]["pairs"], tested,
                                                                        min_episodes, min_families)
    if control_shortfall:
        summary["vs_control"].update(underpowered=control_shortfall, relative_drop=None, mcnemar_p=None)
    # is the fine-tuned policy significantly worse than the start / the control on the held-out families
    # (loop_verdict.heldout_worse: the dv2s regress gate over the families); not tested below the minimums

    margin = DEFAULTS["margin"] if margin is None else float(margin)
    summary["margin"] = margin
    tests = HeldOutTests(
        start=None if shortfall else heldout_worse(_family_tables(before, after, families), "start", margin),
        control=None if shortfall or control_shortfall or control is None else heldout_worse(
            _family_tables(control, after, families), "control", margin))
    return HeldOutComparison.from_dict(summary).replace(significantly_worse=tests)


def _control_shortfall(pairs: int, families: set, min_episodes: int, min_families: int) -> Optional[str]:
    """Why the held-out test against the control does not run (too few tested pairs against the control, or too
    few families with one: :func:`underpowered`'s minimums and evidence floor), or ``None``."""
    shortfall = underpowered(pairs, min_episodes, len(families), min_families, tested=True)
    return None if shortfall is None else "against the control: " + shortfall


def _family_tables(baseline: Sequence[HeldOutEpisode], candidate: Sequence[HeldOutEpisode],
                   families: Optional[Mapping[str, str]]) -> Dict[str, Any]:
    """``{held-out family: PairedTable}`` of ``candidate`` against ``baseline`` records, paired by (scenario, seed);
    a pair with an error on either side is left out."""
    twins = {(r.scenario, int(r.seed)): r for r in candidate}
    outcomes: Dict[str, tuple] = {}
    for record in baseline:
        twin = twins.get((record.scenario, int(record.seed)))
        old, new = episode_failed(record), episode_failed(twin) if twin is not None else None
        if old is None or new is None:
            continue
        family = (families or {}).get(str(record.scenario), str(record.scenario))
        pair = outcomes.setdefault(family, ([], []))
        pair[0].append(new)
        pair[1].append(old)
    return {family: PairedTable.from_outcomes(new, old) for family, (new, old) in sorted(outcomes.items())}


def untouched_settings(seeds: int, env_config: Mapping[str, Any], margin: float,
                       bank_dir: Optional[os.PathLike | str] = None):
    """The regression settings of the untouched set: ``bank_dir`` (default :data:`UNTOUCHED_BANK`), ``seeds``
    seeds per scenario from ``EVAL_SEED_BASE``, the policy's ``env_config`` and the loop's ``margin``."""
    return RegressSettings(bank_dir=str(Path(bank_dir or UNTOUCHED_BANK).resolve()), episodes=seeds,
                           seed=EVAL_SEED_BASE, margin=margin, env_config=dict(env_config))


def evaluate_untouched(start: str, fine_tuned: str, control: Optional[str], *, settings: Any, out: Path,
                       workers: int, progress: bool) -> UntouchedComparison:
    """Start, fine-tuned and control on the untouched scenario set (:func:`untouched_settings`: its bank, its
    seeds per scenario, the env config and margin) with ``dv2s regress``: fine-tuned
    against start (``out/vs_start``), then the control against the fine-tuned policy's episodes of that run
    (``out/vs_control``: only the control runs). Failure rates, stall rates and mean speeds per policy, and
    the two comparisons' verdicts, differences and p-values."""
    first = RegressReport.from_json(runner.run_regression(fine_tuned, start, settings,
                                                          workers=WorkerSettings(workers=workers),
                                                          out_dir=out / "vs_start", progress=progress))
    overall = first.overall if first.overall is not None else ScenarioResult()
    policies = {"start": _measures(overall.baseline), "fine_tuned": _measures(overall.candidate)}
    result = UntouchedComparison(scenarios=tuple((first.bank.scenarios if first.bank is not None else None) or ()),
                                 seeds=settings.episodes, policies=policies,
                                 fine_tuned_vs_start=_comparison(first, out / "vs_start" / "report.json"),
                                 errored=_regress_errored(first, {"baseline": "start", "candidate": "fine_tuned"}))
    if control is not None:
        # a measurement, not a gate: the fine-tuned policy is the reference whatever its own verdict was
        baseline = BaselineReport(out / "vs_start" / "report.json", role="candidate", accept_failed=True)
        second = RegressReport.from_json(runner.run_regression(control, baseline, settings,
                                                               workers=WorkerSettings(workers=workers),
                                                               out_dir=out / "vs_control", progress=progress))
        result = result.replace(
            policies={**policies,
                      "control": _measures(second.overall.candidate if second.overall is not None else None)},
            control_vs_fine_tuned=_comparison(second, out / "vs_control" / "report.json"),
            errored={**result.errored, **_regress_errored(second, {"candidate": "control"})})
    return result


def _measures(summary: Optional[Summary]) -> Dict[str, Any]:
    summary = summary if summary is not None else Summary()
    return {"episodes": summary.episodes, "errors": summary.errors,
            "failure_rate": summary.failure_rate, "stall_rate": summary.rate("stall"),
            "collision_rate": summary.rate("collision"), "mean_speed": summary.mean_speed}


def _comparison(report: RegressReport, path: Path) -> RegressComparison:
    overall = report.overall if report.overall is not None else ScenarioResult()
    comparison = overall.comparison if overall.comparison is not None else PairedComparison()
    return RegressComparison(verdict=report.verdict, reason=comparison.reason, episodes=comparison.n,
                             difference=comparison.difference, p_value=comparison.p_value,
                             report=str(Path(path).resolve()))


def _lineage(loop: _Loop, rounds: Sequence[RoundRecord], current: str) -> List[RoundRecord]:
    """The earlier ``rounds`` whose fine-tuned policy ``current`` descends from, latest first: a round whose
    policy was not adopted (REJECTED, NOT ACCEPTED) trained nothing the next rounds start from."""
    chain: List[RoundRecord] = []
    for number in range(len(rounds), 0, -1):
        record = rounds[number - 1]
        if record.new_policy is None:
            continue
        try:
            spec = _earlier_round_spec(record.new_policy, loop, number + 1)
        except LoopError:
            continue
        if spec == current:
            chain.append(record)
            current = record.policy
    return chain


def _earlier_sides(rounds: Sequence[RoundRecord]) -> tuple:
    """``(held, tuned)``: the families earlier ``rounds`` held out, and those they fine-tuned on in any form
    (their split's fine-tuning families and every family in a fine-tuning arm's mix, parents included)."""
    held: set = set()
    tuned: set = set()
    for earlier in rounds:
        split = earlier.steps.split if earlier.steps.split is not None else SplitRecord()
        held.update(split.held_out_family_names)
        tuned.update(split.fine_tune_family_names)
        for arm in (earlier.steps.fine_tune, earlier.steps.control):
            tuned.update((arm.families if arm is not None else None) or ())
    return sorted(held), sorted(tuned)


def _with_parents(kept: Sequence[MinedEntry], bank: Optional[str]) -> List[MinedEntry]:
    """The kept entries with ``parent``: the scenario family their bank provenance goes back to
    (:func:`dv2s_gym.mining.family.scenario_family`, the family their failures were clustered by)."""
    entries = [MinedEntry.from_dict(e) for e in kept]
    if bank is None:
        return entries

    found = []
    for entry in entries:  # a parent's near-duplicate twins are its family too (scenario_bank.families)
        family = scenario_family(str(entry.parent or entry.scenario), str(bank))
        found.append(entry.replace(parent=family) if family != entry.scenario or entry.parent else entry)
    return found


def _log_round(log: Callable[[str], None], number: int, steps: RoundSteps) -> None:
    after = steps.after

    if recorded(after):
        line = (f"round {number}: held-out failure rate start {rate_text(after.before)}, "
                + (f"control {rate_text(after.control)}, " if recorded(after.control) else "")
                + f"fine-tuned {rate_text(after.after)}")
        if after.underpowered:
            log(line + f"; NO DROP OR TEST REPORTED: {after.underpowered}")
        else:
            drop, versus = after.relative_drop, after.vs_control
            log(line + (f", relative drop {drop:.0%}" if drop is not None else "")
                + (f", McNemar p (two-sided) vs start = {after.mcnemar_p:.3g}" if after.mcnemar_p is not None else "")
                + (f", vs control = {versus.mcnemar_p:.3g}"
                   if versus is not None and versus.mcnemar_p is not None else ""))
    untouched = steps.untouched
    if recorded(untouched):
        def share(role: str) -> str:
            value = untouched.failure_rate(role)
            return "-" if value is None else f"{value:.2f}"

        vacuous = untouched.vacuous()
        log(f"round {number}: untouched set failure rate start {share('start')}, control {share('control')}, "
            f"fine-tuned {share('fine_tuned')}; fine-tuned vs start "
            f"{(untouched.fine_tuned_vs_start.verdict if untouched.fine_tuned_vs_start is not None else None)}"
            + (f"; WARNING: {vacuous}" if vacuous else ""))
    regress = steps.regress if steps.regress is not None else RegressSummary()
    log(f"round {number}: rest of the bank: {regress.verdict} ({regress.reason})")


def _write(out: Path, state: _State) -> LoopReport:
    tuned = [r.new_policy for r in state.rounds if r.new_policy]
    last = tuned[-1] if tuned else state.settings.policy
    report = LoopReport(out=out, rounds=list(state.rounds), policy=last, paths={}, settings=state.settings)
    report.paths = write_loop_reports(report.to_json(), out)
    return report
