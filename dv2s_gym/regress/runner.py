"""``run_regression``: a candidate policy against a baseline on paired scenario x seed episodes.

Episode ``k`` of a scenario uses env seed ``seed + k`` for both policies, so each
candidate episode has a twin baseline episode on the identical scene (the env is
deterministic given the seed). Tasks go to a pool (:mod:`dv2s_gym.workers`)
round by round (seed ``k`` of every scenario before seed ``k + 1``); results stream into
``results.jsonl`` as they finish (:mod:`dv2s_gym.regress.store`), and the report
(:mod:`dv2s_gym.regress.report`) is built from them at the end.

With ``sequential=True`` the pooled paired table is examined after every batch of
seeds by :class:`~dv2s_gym.regress.stats.SequentialTest` (group-sequential, spending the
pooled test's share of alpha), and the run stops as soon as it reaches FAIL; PASS is decided
at the end, when every scenario has had its planned episodes.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import os
import socket
import sys
import time
from pathlib import Path
from typing import Any, Callable, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple, Union

from tqdm import tqdm

from dv2s_gym.regress import power as power_plan
from dv2s_gym.regress import stats
from dv2s_gym.regress.errors import RegressError, ReportMismatchError
from dv2s_gym.regress.failures import DEFAULT_STALL_SECONDS, apply_failure, missing_facts, parse_failure
from dv2s_gym.regress.report import (
    bank_info,
    build_report,
    check_baseline_code,
    check_baseline_report,
    load_report,
    paired_tables,
)
from dv2s_gym.regress.outputs import write_reports
from policies.run_identity import (CODE_IDENTITY, DETECTOR_READS, RESUME_FINGERPRINT, ReadsRecorder, code_identity,
                                   detector_reads, installed_version,
                                   report_code_identity,
                                   resume_fingerprint)
from dv2s_gym.regress.store import BASELINE_FINGERPRINT, RUN_FILE, RunStore
from dv2s_gym.regress.settings import ROLES, BaselineReport, RegressSettings
from dv2s_gym.regress.tasks import RegressTask
from dv2s_gym.workers.errors import WorkerError
from dv2s_gym.workers.backends import get_backend
from dv2s_gym.workers.settings import WorkerSettings
from dv2s_gym.workers.tasks import task_id
from envs.config_check import check_config
from envs.errors import UnknownConfigKeyError
from envs.safety_metrics import MonitorSettings
from scenario_bank import select_scenarios
from scenario_bank.bank import Bank
from scenario_bank.jail import JailUnavailableError, require_jail
from scenario_bank.maps import list_maps
from scenario_bank.shipped import is_shipped_text
from scenario_bank.records import JsonRecord, RecordError, RegressEpisode, recorded
from scenario_bank.run_identity import BANK_IDENTITY
from scenario_bank.run_paths import loop_folder
from dv2s_gym.regress.records import (BankInfo, PairedEpisode, PolicyInfo, PowerPlan, RegressReport, ReportSettings,
                                      SequentialOutcome)
from policies.card_record import ModelCard
from policies.registry import PolicySpaceError, load_policy

__all__ = ["run_regression", "run_size", "RegressSettings", "BaselineReport", "WorkerSettings", "bank_info",
           "plan_tasks", "DEFAULT_OUT", "ROLES"]

DEFAULT_OUT = "out/regress"
Scenarios = Union[None, str, Sequence[str]]


def plan_tasks(policies: Dict[str, str], scenarios: Sequence[str], seeds: Iterable[int], *,
               env_config: Dict[str, Any], bank_dir: Optional[str], trace_dir: Optional[str],
               failure: Optional[Sequence[str]] = None, monitor: Optional[MonitorSettings] = None
               ) -> List[RegressTask]:
    """The run's tasks, seed by seed (every scenario, then the next seed), each role in turn; which role goes first
    alternates from pair to pair, so neither role is always the first to meet a scene; ``failure`` ``None``: the
    default failure kinds; ``monitor``: the monitors' settings (``None``: the defaults)."""
    monitor = monitor or MonitorSettings()
    failure = parse_failure(failure)
    roles = list(policies.items())
    tasks = []
    for pair, (seed, scenario) in enumerate((seed, scenario) for seed in seeds for scenario in scenarios):
        for role, spec in (roles if pair % 2 == 0 else roles[::-1]):
            tasks.append(RegressTask(policy=spec, role=role, scenario=scenario, seed=int(seed),
                                     env_config=dict(env_config), bank_dir=bank_dir, trace_dir=trace_dir,
                                     failure=tuple(failure), monitor=monitor))
    return tasks


def _policy_info(spec: str, env_config: Optional[Dict[str, Any]] = None) -> PolicyInfo:
    """Load the policy here once: a bad spec, or a checkpoint trained with another observation than ``env_config``'s,
    fails before any worker starts; the model card goes in the report."""
    policy = load_policy(spec)
    try:
        policy.check_env_config(env_config or {})
    except PolicySpaceError as error:
        raise RegressError(f"--config: {error}") from None
    card = None
    while policy is not None and card is None:
        found = getattr(policy, "card", None)  # an empty card (a policy loaded without one) is no card
        card = (found if recorded(found) else None) if isinstance(found, JsonRecord) else (found or None)
        policy = getattr(policy, "inner", None)
    return PolicyInfo(spec=spec, card=ModelCard.from_dict(card) if card is not None else None)


def _check_env_config(env_config: Dict[str, Any], failure: Sequence[str], monitor: MonitorSettings) -> None:
    """Refuse env settings under which the gate cannot see failures: unknown keys, a non-positive episode
    duration, or a stall time the episodes are too short to reach."""
    from envs.dv2s_env import DV2SEnv
    defaults = DV2SEnv.default_config()
    try:
        check_config(env_config, defaults)
    except (UnknownConfigKeyError, ValueError) as error:
        raise RegressError(f"--config: {error}") from None
    duration = env_config.get("duration", defaults["duration"])
    if isinstance(duration, bool) or not isinstance(duration, (int, float)) or not math.isfinite(duration) \
            or duration <= 0:
        raise RegressError(f"--config duration must be a positive number of seconds per episode, not {duration!r}")
    if "stall" in failure and monitor.stall_seconds >= float(duration):
        raise RegressError(f"--stall-seconds {monitor.stall_seconds:g} is not shorter than the episodes ({duration:g} s): no "
                           "stall could ever be detected; lower --stall-seconds, lengthen the episodes with "
                           "--config '{\"duration\": ...}', or leave stall out of --failure")


def _select(scenarios: Scenarios, bank_dir: Optional[str], fallback: Optional[Sequence[str]]) -> List[str]:
    if isinstance(scenarios, str):
        scenarios = [scenarios]
    if scenarios is not None:
        scenarios = [s.strip() for s in scenarios if s and s.strip()]
        if not scenarios:
            raise RegressError("the scenario selection is empty; give bank names or tag:<tag> with --scenarios, "
                               "or leave --scenarios out to use the whole bank")
    names = select_scenarios(scenarios if scenarios is not None else fallback, bank_dir)
    if not names:
        raise RegressError("the scenario selection is empty; `dv2s bank list` shows the bank's scenarios and tags")
    return names


def _baseline_from_report(report: BaselineReport, names: Sequence[str], seeds: Sequence[int], bank: BankInfo,
                          env_config: Dict[str, Any], settings: RegressSettings, judged_by: Mapping[str, Any]
                          ) -> Tuple[PolicyInfo, Dict[str, RegressEpisode], str]:
    """The baseline info, the baseline result per episode id, and the report file's SHA-256 (``judged_by``: the code
    this run judges its episodes by, :func:`policies.run_identity.report_code_identity`)."""
    path, role, failure = Path(report.path), report.role, list(settings.failure)
    monitor, accept_failed = settings.monitor, report.accept_failed
    old = load_report(path)
    check_baseline_report(old, path=path, bank=bank, env_config=env_config)  # a report with errors: never
    code_warning = check_baseline_code(old, path=path, kinds=failure, code_identity=judged_by)
    if old.verdict in ("FAIL", "ERROR") and not accept_failed:
        raise ReportMismatchError(
            f"baseline report {path} has the verdict {old.verdict}: its candidate did not pass its own gate, so "
            "it is no baseline to compare against; compare against a report that passed, or give "
            "--accept-failed-baseline to use it anyway")
    if role not in ROLES:
        raise RegressError(f"--baseline-role must be 'candidate' or 'baseline', not {role!r}")
    their = old.candidate if role == "candidate" else old.baseline
    if their is None:
        raise RegressError(f"baseline report {path} has no {role} policy (it ran without a baseline); "
                           "use --baseline-role candidate")
    results: Dict[str, RegressEpisode] = {}
    for episode in old.episodes or ():
        result = episode.result(role)
        if result is None:
            continue
        if result.trace and not Path(result.trace).is_absolute():
            # the old folder's traces, wherever this run is
            result = result.replace(trace=str((path.parent / result.trace).resolve()))
        results[episode.id] = result
    missing = [task_id(n, s) for s in seeds for n in names if task_id(n, s) not in results]
    if missing:
        more = f" (and {len(missing) - 1} more)" if len(missing) > 1 else ""
        raise ReportMismatchError(
            f"baseline report {path} has no episode {missing[0]}{more}; it ran {old.settings.episodes} "
            f"episode(s) per scenario from seed {old.settings.seed}: use --episodes and --seed within those, "
            "or rerun the baseline with more episodes")
    wanted = [results[task_id(n, s)] for s in seeds for n in names]
    lacking = missing_facts([result.to_dict() for result in wanted], failure)  # the facts the file records
    if lacking:
        raise ReportMismatchError(
            f"baseline report {path} does not record {', '.join(lacking)} for its episodes (that run had no such failure "
            f"type registered); rerun the baseline with {', '.join(lacking)} registered, or leave {', '.join(lacking)} out of --failure")
    their_stall = old.settings.stall_seconds if old.settings.stall_seconds is not None else DEFAULT_STALL_SECONDS
    if "stall" in failure and float(their_stall) != monitor.stall_seconds:
        raise ReportMismatchError(f"baseline report {path} detected stalls after {their_stall:g} s, this run after "
                                  f"{monitor.stall_seconds:g} s; use the same stall time, or rerun the baseline")
    # judged by this run's failure kinds: the JSON object re-marked, read back as a record
    records = {episode_id: _baseline_record(path, apply_failure(result.to_dict(), failure))
               for episode_id, result in results.items()}
    theirs, ours = old.dv2s_version, installed_version()
    flagged = [None if theirs == ours else (
        f"baseline report {path} was made by dv2s-gym {theirs}, this is {ours}: the simulator or the "
        "policies may have changed between them, so differences may not be the candidate's; "
        "rerun the baseline with this version to be sure"), code_warning]
    warning = "; ".join(text for text in flagged if text) or None
    info = PolicyInfo(report=str(path.resolve()), role=role, spec=their.spec, card=their.card, warning=warning,
                      null_fields=frozenset({"spec", "card"}))
    return info, records, hashlib.sha256(path.read_bytes()).hexdigest()


def _baseline_record(path: Path, result: Dict[str, Any]) -> RegressEpisode:
    """A baseline report's result as a record; one that is no regression result is refused, naming its field."""
    try:
        return RegressEpisode.from_dict(result)
    except RecordError as error:
        raise ReportMismatchError(f"baseline report {path}, episode {result.get('id')}: {error}; give the report.json "
                                  "of an earlier `dv2s regress` run") from None


def run_regression(candidate: str, baseline: Union[None, str, BaselineReport] = None,
                   settings: Optional[RegressSettings] = None, *, workers: Optional[WorkerSettings] = None,
                   out_dir: Optional[Union[str, os.PathLike]] = None, progress: bool = True,
                   on_result: Optional[Callable[[RegressEpisode], None]] = None,
                   clips: bool = True) -> RegressReport:
    """Run ``candidate`` (and ``baseline``) on scenario x seed pairs and write the reports.

    Args:
        candidate: policy spec of the policy under test (:func:`policies.registry.load_policy`).
        baseline: policy spec to compare against, run on the same episodes; or a
            :class:`~dv2s_gym.regress.settings.BaselineReport`: an earlier ``report.json`` whose episodes (of
            one of its policies) are the baseline, so only the candidate runs; ``None``: no comparison.
        settings: the scenarios, episodes, seeds, statistics and failure kinds
            (:class:`~dv2s_gym.regress.settings.RegressSettings`; default its defaults).
        workers: where episodes run: a ``"local"`` process pool (default every core) or ``"ray"``
            (:class:`~dv2s_gym.workers.settings.WorkerSettings`); ``timeout``: seconds one episode may take before
            its worker counts as hung (local backend).
        out_dir: output folder (default ``out/regress``): ``run.json``, ``results.jsonl``,
            ``traces/``, ``report.json``, ``junit.xml``, ``report.md``. Rerunning with the same
            folder and settings resumes: finished episodes are not run again.
        progress: a progress bar on stderr.
        on_result: called in this process with each finished episode's result (after it is saved), a
            :class:`~scenario_bank.records.RegressEpisode`.
        clips: render the HTML report's clips of the newly failing episodes (seconds each); ``False`` lists
            those episodes without clips.

    Returns:
        The report (:class:`~dv2s_gym.regress.records.RegressReport`; schema: :mod:`dv2s_gym.regress.report`).
    """
    started = time.time()
    settings = settings or RegressSettings()
    workers = workers or WorkerSettings()
    plan = _prepare(candidate, baseline, settings)
    root = Path(out_dir if out_dir is not None else DEFAULT_OUT)
    store = RunStore(root, _identity(plan, settings, root))
    done = {key: result for key, result in store.open().items() if not result.error}  # errors run again
    policies = {"candidate": candidate, **({"baseline": plan.baseline_spec} if plan.baseline_spec else {})}
    all_tasks = plan_tasks(policies, plan.names, plan.seeds, env_config=plan.env_config, bank_dir=plan.bank_dir,
                           trace_dir=str(store.traces_dir.resolve()), failure=plan.failure,
                           monitor=settings.monitor)
    if any(":" in spec.partition("?")[0] for spec in policies.values()):
        # module:attribute specs are found in this folder in the workers too
        all_tasks = [dataclasses.replace(task, python_path=(os.getcwd(),)) for task in all_tasks]
    episodes = _Episodes(plan, store, on_result)
    episodes.results.update({t.key: done[t.key] for t in all_tasks if t.key in done})
    episodes.bar = _progress(progress, total=len(all_tasks), initial=len(episodes.results))
    report_settings = _report_settings(plan, settings, workers)
    ran = _execute(plan, settings, workers, episodes, all_tasks, report_settings)
    if plan.plan is not None:
        report_settings["plan"] = plan.plan
    report_settings["mde"] = float(settings.mde if settings.mde is not None else power_plan.DEFAULT_MDE)
    report_settings["power"] = float(settings.power if settings.power is not None else power_plan.DEFAULT_POWER)
    report = build_report(bank=plan.bank, settings=ReportSettings.from_dict(report_settings),
                          candidate=plan.candidate_info, baseline=plan.baseline_info,
                          episodes=episodes.paired(ran.seeds), stopped_early=ran.stopped_early,
                          sequential=ran.sequential,
                          code_identity={**plan.judged_by, DETECTOR_READS: _with_earlier_reads(
                              store.root, detector_reads(plan.failure, ran.reads))})
    report = report.replace(hostname=socket.gethostname(),
                            timing={name: round(value, 3) for name, value in episodes.timing.items()},
                            duration=round(time.time() - started, 3))
    write_reports(report, store.root, progress=progress, clips=clips)
    return report


def _with_earlier_reads(out: Path, reads: Dict[str, Dict[str, str]]) -> Dict[str, Dict[str, str]]:
    """``reads`` (per judged kind, the files its plug-in read in this session) with those the run's earlier sessions
    recorded in the ``report.json`` of ``out``: a resumed run whose episodes were all done runs no worker, and its
    report must still name the files that judged them (a changed one was refused when the run resumed)."""
    try:
        earlier = json.loads((out / "report.json").read_text(encoding="utf-8"))["code_identity"][DETECTOR_READS]
    except (OSError, ValueError, KeyError, TypeError):
        return reads
    if not isinstance(earlier, dict):
        return reads
    return {kind: {**(earlier.get(kind) if isinstance(earlier.get(kind), dict) else {}), **facts}
            for kind, facts in reads.items()}


@dataclasses.dataclass
class _Plan:
    """What a regression run runs, worked out from its settings before any episode."""

    candidate: str
    baseline_spec: Optional[str]
    report: Optional[BaselineReport]
    bank_dir: Optional[str]
    env_config: Dict[str, Any]
    failure: List[str]
    names: List[str]
    bank: BankInfo
    episodes: int
    plan: Optional[PowerPlan]
    seeds: List[int]
    batch: int
    candidate_info: PolicyInfo
    baseline_info: Optional[PolicyInfo]
    old_results: Dict[str, RegressEpisode]
    report_hash: Optional[str]
    judged_by: Dict[str, Any]
    """The code the run judges its episodes by (:func:`policies.run_identity.report_code_identity`)."""


def _prepare(candidate: str, baseline: Union[None, str, BaselineReport], settings: RegressSettings) -> _Plan:
    """The run's plan; bad input (a spec, a selection, a baseline report that does not fit) is refused here."""
    report = baseline if isinstance(baseline, BaselineReport) else None
    spec = None if report is not None else baseline
    if settings.sequential and baseline is None:
        raise RegressError("--sequential stops when the comparison is settled: it needs --baseline or "
                           "--baseline-report")
    bank_dir = None if settings.bank_dir is None else str(Path(settings.bank_dir).resolve())  # workers may run elsewhere
    fallback, env_config = None, settings.env_config
    if report is not None:
        old = load_report(report.path)
        fallback = list(old.bank.scenarios or ()) or None if old.bank is not None else None
        if env_config is None:
            env_config = old.settings.env_config
    env_config = dict(env_config or {})
    failure = list(settings.failure)
    _check_env_config(env_config, failure, settings.monitor)
    names, episodes, planned = _size(settings, bank_dir, fallback, report)
    bank = bank_info(names, bank_dir)
    _check_jail(bank_dir, env_config)
    seeds = [settings.seed + k for k in range(episodes)]
    candidate_info = _policy_info(candidate, env_config)
    baseline_info = _policy_info(spec, env_config) if spec is not None else None  # a bad baseline spec is bad input too
    old_results: Dict[str, RegressEpisode] = {}
    report_hash = None
    judged_by = report_code_identity(failure)
    if report is not None:
        baseline_info, old_results, report_hash = _baseline_from_report(report, names, seeds, bank, env_config,
                                                                        settings, judged_by)
    return _Plan(candidate=candidate, baseline_spec=spec, report=report, bank_dir=bank_dir, env_config=env_config,
                 failure=failure, names=names, bank=bank, episodes=episodes, plan=planned, seeds=seeds,
                 batch=settings.batch or max(1, math.ceil(episodes / 5)), candidate_info=candidate_info,
                 baseline_info=baseline_info, old_results=old_results, report_hash=report_hash,
                 judged_by=judged_by)


def _untrusted(bank_dir: Optional[str], env_config: Mapping[str, Any]) -> List[str]:
    """What the episodes' envs run in the jail: the bank's scripts that are not shipped ones (each worker's env holds
    the whole bank, :func:`policies.worker_cache.env_for`) and a map file of the user's (``env_config["map"]``)."""
    found = [f"map {env_config['map']!r}"] if env_config.get("map") not in (None, *list_maps()) else []
    bank = Bank(bank_dir)
    return found + [f"scenario {name!r}" for name in bank.names() if not is_shipped_text(bank.get(name).script)]


def _check_jail(bank_dir: Optional[str], env_config: Mapping[str, Any]) -> None:
    """Refuse, before any episode, a run whose envs need the jail where it cannot start (no bubblewrap, or the code
    under /tmp, which the jail hides): each episode would end in the same error. A run on shipped scripts alone
    needs no jail and is not checked."""
    untrusted = _untrusted(bank_dir, env_config)
    if not untrusted:
        return
    more = f" (and {len(untrusted) - 1} more)" if len(untrusted) > 1 else ""
    try:
        require_jail(f"the bank's {untrusted[0]}{more}")
    except JailUnavailableError as error:
        raise RegressError(" ".join(str(error).split())) from None


def _size(settings: RegressSettings, bank_dir: Optional[str], fallback: Optional[Sequence[str]],
          report: Optional[BaselineReport]) -> Tuple[List[str], int, Optional[PowerPlan]]:
    """The scenarios, the episodes per scenario and the power plan that chose them (``None`` when given)."""
    names = _select(list(settings.scenarios) if settings.scenarios is not None else None, bank_dir, fallback)
    if settings.episodes is not None and (settings.mde is not None or settings.power is not None):
        raise RegressError("give --episodes, or --mde and --power to choose the episodes per scenario; not both")
    episodes, planned = settings.episodes, None
    if episodes is None:
        episodes, planned = _planned_episodes(names, report.path if report else None,
                                              report.role if report else "candidate", settings.seed, settings.mde,
                                              settings.power, settings.alpha)
    return names, episodes, planned


def run_size(settings: RegressSettings) -> Tuple[int, int]:
    """``(scenarios, episodes per scenario)`` of a run with ``settings`` and no baseline report, as
    :func:`run_regression` plans it (no policy is loaded): what a command says before it starts."""
    bank_dir = None if settings.bank_dir is None else str(Path(settings.bank_dir).resolve())
    names, episodes, _ = _size(settings, bank_dir, None, None)
    return len(names), episodes


def _own_folders(out: Path, plan: _Plan) -> List[Any]:
    """The folders whose files are the run's own, not code it runs: the run folder (and the ``dv2s loop`` folder
    holding it) and the bank."""
    return [folder for folder in (out, loop_folder(out), plan.bank_dir) if folder]


def _identity(plan: _Plan, settings: RegressSettings, out: Path) -> Dict[str, Any]:
    """What a resumed run must share with the run in its folder ``out`` (:class:`~dv2s_gym.regress.store.RunStore`)."""
    identity: Dict[str, Any] = {
        "candidate": plan.candidate, "baseline": plan.baseline_spec, "baseline_report": plan.report_hash,
        "baseline_role": plan.report.role if plan.report is not None else None,
        "scenarios": plan.names, "episodes": plan.episodes,
        "seed": settings.seed, "env_config": plan.env_config, "sequential": bool(settings.sequential),
        "failure": plan.failure, "stall_seconds": float(settings.stall_seconds),
    }
    # what the policies, the scenarios and the code *are*, checked as every resumable run kind checks them
    identity[RESUME_FINGERPRINT] = resume_fingerprint(plan.candidate)
    identity[BASELINE_FINGERPRINT] = resume_fingerprint(plan.baseline_spec) if plan.baseline_spec else None
    identity[BANK_IDENTITY] = dict(sorted((plan.bank.hashes or {}).items()))
    identity[CODE_IDENTITY] = code_identity(exclude=_own_folders(out, plan))
    if settings.sequential:  # the stopping point depends on these
        identity.update(margin=float(settings.margin), alpha=float(settings.alpha), batch=plan.batch)
    return identity


def _report_settings(plan: _Plan, settings: RegressSettings, workers: WorkerSettings) -> Dict[str, Any]:
    """The report's ``settings`` section (the workers are filled in once the backend has started)."""
    recorded = {"episodes": plan.episodes, "seed": settings.seed, "margin": float(settings.margin),
                "alpha": float(settings.alpha), "sequential": bool(settings.sequential), "env_config": plan.env_config,
                "backend": workers.backend, "workers": workers.workers, "timeout": workers.timeout,
                "failure": plan.failure, "stall_seconds": float(settings.stall_seconds)}
    if settings.sequential:
        recorded["batch"] = plan.batch
    return recorded


class _Episodes:
    """The run's results as they arrive (saved, counted on the progress bar, timed per scenario), and the
    candidate/baseline pairs they make."""

    def __init__(self, plan: _Plan, store: RunStore, on_result: Optional[Callable[[RegressEpisode], None]]) -> None:
        self.plan, self.store, self.on_result = plan, store, on_result
        self.results: Dict[Tuple[str, str], RegressEpisode] = {}
        self.timing: Dict[str, float] = {}
        self.bar = None
        self.reads: Optional[ReadsRecorder] = None  # the files the workers read, into run.json as they appear

    def handle(self, result: Mapping[str, Any]) -> None:
        """Take a worker's result (:func:`~dv2s_gym.regress.tasks.run_regress_task`'s record, or a backend's error
        result for a crashed or hung worker): time it, save it, count it."""
        record = RegressEpisode.from_dict(result)
        seconds = record.extra.get("seconds")  # wall time varies: kept apart, so episodes compare equal
        if seconds is not None:
            self.timing[record.scenario] = self.timing.get(record.scenario, 0.0) + float(seconds)
        record = record.replace(trace=self.store.relative(record.trace), null_fields=record.null_fields | {"trace"},
                                extra={key: value for key, value in record.extra.items() if key != "seconds"})
        if self.reads is not None:
            self.reads.record()
        self.store.append(record)
        self.results[record.key] = record
        if self.bar is not None:
            self.bar.update(1)
        if self.on_result is not None:
            self.on_result(record)

    def paired(self, seed_list: Sequence[int]) -> List[PairedEpisode]:
        """The candidate/baseline pairs of ``seed_list`` that have a candidate result, seed by seed."""
        plan, has_baseline = self.plan, self.plan.baseline_info is not None
        episodes_out = []
        for k in seed_list:
            for name in plan.names:
                episode_id = task_id(name, k)
                candidate_result = self.results.get((episode_id, "candidate"))
                if candidate_result is None:
                    continue
                baseline_result = (plan.old_results.get(episode_id) if plan.report is not None
                                   else self.results.get((episode_id, "baseline")))
                episodes_out.append(PairedEpisode(id=episode_id, scenario=name, seed=k, candidate=candidate_result,
                                                  baseline=baseline_result if has_baseline else None))
        return episodes_out


def _execute(plan: _Plan, settings: RegressSettings, workers: WorkerSettings, episodes: _Episodes,
             all_tasks: List[RegressTask], report_settings: Dict[str, Any]) -> "_Ran":
    """Run the episodes not done yet (all at once, or batch by batch until the sequential test settles)."""
    runner = None
    ran = _Ran(seeds=list(plan.seeds))
    try:
        runner = get_backend(workers.backend, workers=workers.workers, address=workers.address,
                             timeout=workers.timeout)
        report_settings["workers"] = getattr(runner, "workers", workers.workers)
        episodes.reads = ReadsRecorder(episodes.store.root / RUN_FILE, runner,
                                       _own_folders(episodes.store.root, plan), where=["settings"])
        if not settings.sequential:
            pending = [t.to_json() for t in all_tasks if t.key not in episodes.results]
            if pending:
                runner.run(pending, episodes.handle)
        else:
            ran = _run_sequential(plan, settings, runner, episodes, all_tasks)
    except WorkerError as error:  # bad backend settings, or workers that cannot start: an error of this run
        raise RegressError(str(error)) from None
    finally:
        if episodes.bar is not None:
            episodes.bar.close()
        episodes.store.close()
        if runner is not None:
            runner.close()
    ran.reads = list((getattr(runner, "files_read", None) or {}).values())
    return ran


@dataclasses.dataclass
class _Ran:
    """What :func:`_execute` ran: the seeds the report covers, whether the sequential test stopped the run early, and
    its record (``None`` for a run that is not sequential)."""

    seeds: List[int]
    stopped_early: bool = False
    sequential: Optional[SequentialOutcome] = None
    reads: List[Any] = dataclasses.field(default_factory=list)
    """The user's files the workers read (:attr:`dv2s_gym.workers.pool.LocalBackend.files_read`)."""


def _run_sequential(plan: _Plan, settings: RegressSettings, runner: Any, episodes: _Episodes,
                    all_tasks: List[RegressTask]) -> _Ran:
    """Run ``plan.batch`` seeds at a time, testing the pooled table after each, until it settles FAIL."""
    seeds, batch, names = plan.seeds, plan.batch, plan.names
    test = stats.SequentialTest(float(settings.margin), float(settings.alpha) * stats.DEFAULT_POOLED_WEIGHT,
                                max_episodes=plan.episodes * len(names), stop_for_pass=False)
    looks, last_n, verdict = 0, 0, None
    ran_seeds, stopped_early = list(seeds), False
    for start in range(0, plan.episodes, batch):
        chunk = seeds[start:start + batch]
        pending = [t.to_json() for t in all_tasks if t.seed in chunk and t.key not in episodes.results]
        if pending:
            runner.run(pending, episodes.handle)
        pooled = stats.PairedTable.pooled(list(paired_tables(episodes.paired(seeds[:start + batch]), names).values()))
        if pooled.n > last_n:
            verdict = test.update(pooled)
            looks, last_n = looks + 1, pooled.n
        if verdict is not None:
            ran_seeds = seeds[:start + batch]
            stopped_early = len(ran_seeds) < len(seeds)
            break
    return _Ran(seeds=ran_seeds, stopped_early=stopped_early,
                sequential=SequentialOutcome(looks=looks, episodes=last_n, max_episodes=plan.episodes * len(names),
                                             batch=batch, spending=test.spending,
                                             verdict=None if verdict is None else verdict.name))


def _planned_episodes(names: Sequence[str], baseline_report: Optional[Union[str, os.PathLike]], role: str,
                      seed: int, mde: Optional[float], power: Optional[float], alpha: float
                      ) -> Tuple[int, PowerPlan]:
    """Episodes per scenario from the power plan; with a baseline report, its failure rates and at most its episodes."""
    rates: Dict[str, Optional[float]] = {}
    available = None
    if baseline_report is not None:
        old = load_report(baseline_report)
        for name in names:
            entry = (old.scenarios or {}).get(name)
            summary = entry.summary(role) if entry is not None else None
            rates[name] = ((summary.failure_rate if summary is not None else None) or {}).get("value")
        if old.settings.episodes is not None and old.settings.seed is not None:
            available = old.settings.seed + old.settings.episodes - seed
    try:
        plan = power_plan.plan_episodes(names, mde=power_plan.DEFAULT_MDE if mde is None else mde,
                                        power=power_plan.DEFAULT_POWER if power is None else power, alpha=alpha,
                                        baseline_rates=rates)
    except ValueError as error:
        raise RegressError(str(error)) from None
    planned = plan.episodes
    note = None
    if available is not None and available < planned:
        note = (f"the baseline report has {available} episode(s) per scenario from seed {seed}, fewer than "
                f"the {planned} planned: the run has less power than planned (see its power)")
    episodes = planned if note is None else max(1, available)
    plan = dataclasses.replace(plan, episodes=episodes, per_scenario=None, planned=planned, note=note)
    return episodes, plan


def _progress(enabled: bool, total: int, initial: int):
    if not enabled:
        return None
    return tqdm(total=total, initial=initial, desc="regress", unit="episode", file=sys.stderr, dynamic_ncols=True)
