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

import hashlib
import math
import os
import socket
import sys
import time
from pathlib import Path
from typing import Any, Callable, Dict, Iterable, List, Optional, Sequence, Tuple, Union

from dv2s_gym.regress import power as power_plan
from dv2s_gym.regress import stats
from dv2s_gym.regress.errors import RegressError, ReportMismatchError
from dv2s_gym.regress.failures import (DEFAULT_FAILURE, DEFAULT_STALL_SECONDS, apply_failure, missing_facts,
                                        parse_failure)
from dv2s_gym.regress.report import (
    bank_info,
    build_report,
    check_baseline_report,
    load_report,
    paired_tables,
)
from dv2s_gym.regress.outputs import write_reports
from dv2s_gym.regress.identity import policy_fingerprint
from dv2s_gym.regress.store import RunStore
from dv2s_gym.regress.tasks import KIND
from dv2s_gym.workers.errors import WorkerError
from dv2s_gym.workers.pool import get_backend
from dv2s_gym.workers.tasks import task_id

__all__ = ["run_regression", "bank_info", "plan_tasks", "DEFAULT_OUT", "ROLES"]

DEFAULT_OUT = "out/regress"
ROLES = ("candidate", "baseline")
Scenarios = Union[None, str, Sequence[str]]


def plan_tasks(policies: Dict[str, str], scenarios: Sequence[str], seeds: Iterable[int], *,
               env_config: Dict[str, Any], bank_dir: Optional[str], trace_dir: Optional[str],
               failure: Sequence[str] = DEFAULT_FAILURE, stall_seconds: float = DEFAULT_STALL_SECONDS
               ) -> List[Dict[str, Any]]:
    """Task dicts, seed by seed (every scenario, then the next seed), each role in turn; which role goes first
    alternates from pair to pair, so neither role is always the first to meet a scene."""
    roles = list(policies.items())
    tasks = []
    for pair, (seed, scenario) in enumerate((seed, scenario) for seed in seeds for scenario in scenarios):
        for role, spec in (roles if pair % 2 == 0 else roles[::-1]):
            tasks.append({"kind": KIND, "policy": spec, "role": role, "scenario": scenario, "seed": int(seed),
                          "env_config": dict(env_config), "bank_dir": bank_dir, "trace_dir": trace_dir,
                          "failure": list(failure), "stall_seconds": float(stall_seconds)})
    return tasks


def _policy_info(spec: str) -> Dict[str, Any]:
    """Load the policy here once: a bad spec fails before any worker starts; the model card goes in the report."""
    from policies.registry import load_policy

    policy = load_policy(spec)
    card = None
    while policy is not None and card is None:
        card = getattr(policy, "card", None) or None
        policy = getattr(policy, "inner", None)
    return {"spec": spec, "card": card}


def _check_settings(episodes: Optional[int], seed: int, margin: float, alpha: float, batch: Optional[int]) -> None:
    if episodes is not None and (isinstance(episodes, bool) or not isinstance(episodes, int) or episodes < 1):
        raise RegressError(f"--episodes must be a positive integer, not {episodes!r}")
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise RegressError(f"--seed must be a non-negative integer, not {seed!r}")
    if not 0.0 <= float(margin) < 1.0:
        raise RegressError(f"--margin is a failure-rate difference in [0, 1), e.g. 0.05 for 5 points; not {margin}")
    if not 0.0 < float(alpha) < 1.0:
        raise RegressError(f"--alpha must be strictly between 0 and 1, e.g. 0.05; not {alpha}")
    if batch is not None and (not isinstance(batch, int) or batch < 1):
        raise RegressError(f"the sequential batch must be a positive number of seeds, not {batch!r}")


def _check_env_config(env_config: Dict[str, Any], failure: Sequence[str], stall_seconds: float) -> None:
    """Refuse env settings under which the gate cannot see failures: unknown keys, a non-positive episode
    duration, or a stall time the episodes are too short to reach."""
    from envs.dv2s_env import DV2SEnv
    from envs.errors import UnknownConfigKeyError, check_config_keys

    defaults = DV2SEnv.default_config()
    try:
        check_config_keys(env_config, defaults)
    except (UnknownConfigKeyError, ValueError) as error:
        raise RegressError(f"--config: {error}") from None
    duration = env_config.get("duration", defaults["duration"])
    if isinstance(duration, bool) or not isinstance(duration, (int, float)) or not math.isfinite(duration) \
            or duration <= 0:
        raise RegressError(f"--config duration must be a positive number of seconds per episode, not {duration!r}")
    if "stall" in failure and float(stall_seconds) >= float(duration):
        raise RegressError(f"--stall-seconds {stall_seconds:g} is not shorter than the episodes ({duration:g} s): no "
                           "stall could ever be detected; lower --stall-seconds, lengthen the episodes with "
                           "--config '{\"duration\": ...}', or leave stall out of --failure")


def _select(scenarios: Scenarios, bank_dir: Optional[str], fallback: Optional[Sequence[str]]) -> List[str]:
    from scenario_bank import select_scenarios

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


def _baseline_from_report(path: Union[str, os.PathLike], role: str, names: Sequence[str], seeds: Sequence[int],
                          bank: Dict[str, Any], env_config: Dict[str, Any], failure: Sequence[str],
                          stall_seconds: float, accept_failed: bool = False
                          ) -> Tuple[Dict[str, Any], Dict[str, Dict[str, Any]], str]:
    """The baseline info, the baseline result per episode id, and the report file's SHA-256."""
    path = Path(path)
    old = load_report(path)
    check_baseline_report(old, path=path, bank=bank, env_config=env_config)  # a report with errors: never
    if old.get("verdict") in ("FAIL", "ERROR") and not accept_failed:
        raise ReportMismatchError(
            f"baseline report {path} has the verdict {old['verdict']}: its candidate did not pass its own gate, so "
            "it is no baseline to compare against; compare against a report that passed, or give "
            "--accept-failed-baseline to use it anyway")
    if role not in ROLES:
        raise RegressError(f"--baseline-role must be 'candidate' or 'baseline', not {role!r}")
    if old.get(role) is None:
        raise RegressError(f"baseline report {path} has no {role} policy (it ran without a baseline); "
                           "use --baseline-role candidate")
    results: Dict[str, Dict[str, Any]] = {}
    for episode in old.get("episodes") or []:
        result = episode.get(role)
        if result is None:
            continue
        result = dict(result)
        trace = result.get("trace")
        if trace and not Path(trace).is_absolute():
            result["trace"] = str((path.parent / trace).resolve())  # the old folder's traces, wherever this run is
        results[episode["id"]] = result
    missing = [task_id(n, s) for s in seeds for n in names if task_id(n, s) not in results]
    if missing:
        settings = old.get("settings") or {}
        more = f" (and {len(missing) - 1} more)" if len(missing) > 1 else ""
        raise ReportMismatchError(
            f"baseline report {path} has no episode {missing[0]}{more}; it ran {settings.get('episodes')} "
            f"episode(s) per scenario from seed {settings.get('seed')}: use --episodes and --seed within those, "
            "or rerun the baseline with more episodes")
    wanted = [results[task_id(n, s)] for s in seeds for n in names]
    lacking = missing_facts(wanted, failure)
    if lacking:
        raise ReportMismatchError(
            f"baseline report {path} does not record {', '.join(lacking)} for its episodes (an older dv2s made it); "
            f"rerun the baseline with this version, or leave {', '.join(lacking)} out of --failure")
    their_stall = (old.get("settings") or {}).get("stall_seconds", DEFAULT_STALL_SECONDS)
    if "stall" in failure and float(their_stall) != float(stall_seconds):
        raise ReportMismatchError(f"baseline report {path} detected stalls after {their_stall:g} s, this run after "
                                  f"{stall_seconds:g} s; use the same stall time, or rerun the baseline")
    for result in results.values():
        apply_failure(result, failure)
    info = {"report": str(path.resolve()), "role": role, "spec": old[role].get("spec"), "card": old[role].get("card")}
    from dv2s_gym.regress.identity import installed_version

    theirs, ours = old.get("dv2s_version"), installed_version()
    if theirs != ours:
        info["warning"] = (f"baseline report {path} was made by dv2s-gym {theirs}, this is {ours}: the simulator or the "
                           "policies may have changed between them, so differences may not be the candidate's; "
                           "rerun the baseline with this version to be sure")
    return info, results, hashlib.sha256(path.read_bytes()).hexdigest()


def run_regression(candidate: str, baseline: Optional[str] = None, *,
                   baseline_report: Optional[Union[str, os.PathLike]] = None,
                   bank_dir: Optional[Union[str, os.PathLike]] = None, scenarios: Scenarios = None,
                   episodes: Optional[int] = None, seed: int = 0, margin: float = stats.DEFAULT_MARGIN,
                   alpha: float = 0.05, mde: Optional[float] = None, power: Optional[float] = None,
                   backend: str = "local", workers: Optional[int] = None, address: Optional[str] = None,
                   out_dir: Optional[Union[str, os.PathLike]] = None, sequential: bool = False,
                   env_config: Optional[Dict[str, Any]] = None, progress: bool = True,
                   timeout: Optional[float] = None, batch: Optional[int] = None,
                   failure: Union[None, str, Sequence[str]] = None, stall_seconds: float = DEFAULT_STALL_SECONDS,
                   baseline_role: str = "candidate", accept_failed_baseline: bool = False,
                   on_result: Optional[Callable[[Dict[str, Any]], None]] = None) -> Dict[str, Any]:
    """Run ``candidate`` (and ``baseline``) on scenario x seed pairs and write the reports.

    Args:
        candidate: policy spec of the policy under test (:func:`policies.registry.load_policy`).
        baseline: policy spec to compare against, run on the same episodes; or
        baseline_report: an earlier ``report.json`` whose episodes (of its ``baseline_role``
            policy, by default the one it tested) are the baseline: only the candidate runs.
            Refused when its schema version, the bank scenarios' scripts or the env config differ, and
            when its verdict was FAIL or ERROR unless ``accept_failed_baseline``.
        bank_dir: bank folder (default: the shipped bank).
        scenarios: bank names and/or ``tag:<tag>`` (default: the whole bank, or the baseline
            report's scenarios); an empty selection is an error.
        episodes: seeds per scenario; episode ``k`` uses env seed ``seed + k``. Default: planned from
            ``mde`` and ``power`` (:func:`dv2s_gym.regress.power.plan_episodes`), with the baseline
            report's failure rates when there is one (and at most the episodes it has).
        mde / power: the regression of one scenario's failure rate the run must FAIL (default 0.30)
            and the probability it does (default 0.8); they choose ``episodes``, so not with it.
        margin: non-inferiority margin on the failure-rate difference (default 0.02 = 2 points, the margin the
            statistics are calibrated at: bench/calibrate_regress.py).
        alpha: level of the FAIL test (PASS is tested at ``alpha / 2``).
        backend / workers / address: ``"local"`` process pool (``workers`` processes, default
            every core) or ``"ray"`` (cluster ``address``).
        out_dir: output folder (default ``out/regress``): ``run.json``, ``results.jsonl``,
            ``traces/``, ``report.json``, ``junit.xml``, ``report.md``. Rerunning with the same
            folder and settings resumes: finished episodes are not run again.
        sequential: stop as soon as a group-sequential test of the pooled table (spending the pooled
            test's share of ``alpha``) settles FAIL, looking after every ``batch`` seeds (default: a
            fifth of ``episodes``); PASS is decided at the end, so every scenario gets its planned
            episodes. Needs a baseline.
        env_config: ``DV2S-v0`` config overrides for every episode (default: none, or the
            baseline report's).
        progress: a progress bar on stderr.
        timeout: seconds one episode may take before its worker counts as hung (local backend).
        on_result: called in this process with each finished episode's result (after it is saved).
        failure: what counts as a failure: kinds among ``collision``, ``off_road``, ``stall`` (a list or
            ``"collision,stall"``; default all three); each kind is also reported apart.
        stall_seconds: how long the ego must stand with a free road ahead for a stall.

    Returns:
        The report dict (schema: :mod:`dv2s_gym.regress.report`).
    """
    started = time.time()
    _check_settings(episodes, seed, margin, alpha, batch)
    failure = parse_failure(failure)
    if not float(stall_seconds) > 0:
        raise RegressError(f"--stall-seconds must be positive, not {stall_seconds}")
    if baseline is not None and baseline_report is not None:
        raise RegressError("give --baseline POLICY or --baseline-report REPORT, not both")
    if sequential and baseline is None and baseline_report is None:
        raise RegressError("--sequential stops when the comparison is settled: it needs --baseline or "
                           "--baseline-report")
    bank_dir = None if bank_dir is None else str(Path(bank_dir).resolve())  # workers may run elsewhere
    fallback = None
    if baseline_report is not None:
        old = load_report(baseline_report)
        fallback = (old.get("bank") or {}).get("scenarios") or None
        if env_config is None:
            env_config = (old.get("settings") or {}).get("env_config")
    env_config = dict(env_config or {})
    _check_env_config(env_config, failure, float(stall_seconds))
    names = _select(scenarios, bank_dir, fallback)
    bank = bank_info(names, bank_dir)
    if episodes is not None and (mde is not None or power is not None):
        raise RegressError("give --episodes, or --mde and --power to choose the episodes per scenario; not both")
    plan = None
    if episodes is None:
        episodes, plan = _planned_episodes(names, baseline_report, baseline_role, seed, mde, power, alpha)
    seeds = [seed + k for k in range(episodes)]

    candidate_info = _policy_info(candidate)
    if baseline is not None:  # a bad baseline spec is bad input too, before any episode
        baseline_info_early = _policy_info(baseline)
    old_results: Dict[str, Dict[str, Any]] = {}
    report_hash = None
    if baseline_report is not None:
        baseline_info, old_results, report_hash = _baseline_from_report(baseline_report, baseline_role, names, seeds,
                                                                        bank, env_config, failure, float(stall_seconds),
                                                                        accept_failed=accept_failed_baseline)
    elif baseline is not None:
        baseline_info = baseline_info_early
    else:
        baseline_info = None
    has_baseline = baseline_info is not None

    out = Path(out_dir if out_dir is not None else DEFAULT_OUT)
    batch = batch or max(1, math.ceil(episodes / 5))
    identity: Dict[str, Any] = {
        "candidate": candidate, "baseline": baseline, "baseline_report": report_hash,
        "baseline_role": baseline_role if baseline_report is not None else None,
        "bank_version": bank["version"], "scenarios": names, "episodes": episodes, "seed": seed,
        "env_config": env_config, "sequential": bool(sequential), "failure": failure,
        "stall_seconds": float(stall_seconds),
    }
    for role, spec in (("candidate", candidate), ("baseline", baseline)):
        if spec is not None:  # what the policy is, not what it is called
            identity.update({f"{role} {key}": value for key, value in policy_fingerprint(spec).items()})
    if sequential:  # the stopping point depends on these
        identity.update(margin=float(margin), alpha=float(alpha), batch=batch)
    settings = {"episodes": episodes, "seed": seed, "margin": float(margin), "alpha": float(alpha),
                "sequential": bool(sequential), "env_config": env_config, "backend": backend,
                "workers": workers, "timeout": timeout, "failure": failure, "stall_seconds": float(stall_seconds)}
    if sequential:
        settings["batch"] = batch

    store = RunStore(out, identity)
    done = store.open()
    done = {key: result for key, result in done.items() if not result.get("error")}  # errors run again
    policies = {"candidate": candidate}
    if baseline is not None:
        policies["baseline"] = baseline
    trace_dir = str(store.traces_dir.resolve())

    def task_key(task: Dict[str, Any]) -> Tuple[str, str]:
        return task_id(task["scenario"], task["seed"]), task["role"]

    all_tasks = plan_tasks(policies, names, seeds, env_config=env_config, bank_dir=bank_dir, trace_dir=trace_dir,
                           failure=failure, stall_seconds=float(stall_seconds))
    if any(":" in spec.partition("?")[0] for spec in policies.values()):
        for task in all_tasks:  # module:attribute specs are found in this folder in the workers too
            task["python_path"] = [os.getcwd()]
    results: Dict[Tuple[str, str], Dict[str, Any]] = {task_key(t): done[task_key(t)] for t in all_tasks
                                                      if task_key(t) in done}
    bar = _progress(progress, total=len(all_tasks), initial=len(results))

    timing: Dict[str, float] = {}

    def handle(result: Dict[str, Any]) -> None:
        result = dict(result)
        seconds = result.pop("seconds", None)  # wall time varies: kept apart, so episodes compare equal
        if seconds is not None:
            timing[result["scenario"]] = timing.get(result["scenario"], 0.0) + float(seconds)
        result["trace"] = store.relative(result.get("trace"))
        store.append(result)
        results[(result["id"], result["role"])] = result
        if bar is not None:
            bar.update(1)
        if on_result is not None:
            on_result(result)

    def paired(seed_list: Sequence[int]) -> List[Dict[str, Any]]:
        episodes_out = []
        for k in seed_list:
            for name in names:
                episode_id = task_id(name, k)
                candidate_result = results.get((episode_id, "candidate"))
                if candidate_result is None:
                    continue
                baseline_result = (old_results.get(episode_id) if baseline_report is not None
                                   else results.get((episode_id, "baseline")))
                episodes_out.append({"id": episode_id, "scenario": name, "seed": k, "candidate": candidate_result,
                                     "baseline": baseline_result if has_baseline else None})
        return episodes_out

    runner = None
    sequential_info = None
    stopped_early = False
    ran_seeds: List[int] = list(seeds)
    try:
        runner = get_backend(backend, workers=workers, address=address, timeout=timeout)
        settings["workers"] = getattr(runner, "workers", workers)
        if not sequential:
            pending = [t for t in all_tasks if task_key(t) not in results]
            if pending:
                runner.run(pending, handle)
        else:
            test = stats.SequentialTest(float(margin), float(alpha) * stats.DEFAULT_POOLED_WEIGHT,
                                        max_episodes=episodes * len(names), stop_for_pass=False)
            looks, last_n, verdict = 0, 0, None
            for start in range(0, episodes, batch):
                chunk = seeds[start:start + batch]
                pending = [t for t in all_tasks if t["seed"] in chunk and task_key(t) not in results]
                if pending:
                    runner.run(pending, handle)
                pooled = stats.PairedTable.pooled(list(paired_tables(paired(seeds[:start + batch]), names).values()))
                if pooled.n > last_n:
                    verdict = test.update(pooled)
                    looks, last_n = looks + 1, pooled.n
                if verdict is not None:
                    ran_seeds = seeds[:start + batch]
                    stopped_early = len(ran_seeds) < len(seeds)
                    break
            sequential_info = {"looks": looks, "episodes": last_n, "max_episodes": episodes * len(names),
                               "batch": batch, "spending": test.spending,
                               "verdict": None if verdict is None else verdict.name}
    except WorkerError as error:  # bad backend settings, or workers that cannot start: an error of this run
        raise RegressError(str(error)) from None
    finally:
        if bar is not None:
            bar.close()
        store.close()
        if runner is not None:
            runner.close()

    if plan is not None:
        settings["plan"] = plan
    settings["mde"] = float(mde if mde is not None else power_plan.DEFAULT_MDE)
    settings["power"] = float(power if power is not None else power_plan.DEFAULT_POWER)
    report = build_report(bank=bank, settings=settings, candidate=candidate_info, baseline=baseline_info,
                          episodes=paired(ran_seeds), stopped_early=stopped_early, sequential=sequential_info)
    report["hostname"] = socket.gethostname()
    report["timing"] = {name: round(value, 3) for name, value in timing.items()}
    report["duration"] = round(time.time() - started, 3)
    write_reports(report, out)
    return report


def _planned_episodes(names: Sequence[str], baseline_report: Optional[Union[str, os.PathLike]], role: str,
                      seed: int, mde: Optional[float], power: Optional[float], alpha: float
                      ) -> Tuple[int, Dict[str, Any]]:
    """Episodes per scenario from the power plan; with a baseline report, its failure rates and at most its episodes."""
    rates: Dict[str, Optional[float]] = {}
    available = None
    if baseline_report is not None:
        old = load_report(baseline_report)
        for name in names:
            summary = ((old.get("scenarios") or {}).get(name) or {}).get(role) or {}
            rates[name] = (summary.get("failure_rate") or {}).get("value")
        settings = old.get("settings") or {}
        if isinstance(settings.get("episodes"), int) and isinstance(settings.get("seed"), int):
            available = settings["seed"] + settings["episodes"] - seed
    try:
        plan = power_plan.plan_episodes(names, mde=power_plan.DEFAULT_MDE if mde is None else mde,
                                        power=power_plan.DEFAULT_POWER if power is None else power, alpha=alpha,
                                        baseline_rates=rates)
    except ValueError as error:
        raise RegressError(str(error)) from None
    episodes = plan["episodes"]
    plan = {key: value for key, value in plan.items() if key != "per_scenario"}
    plan["planned"] = episodes
    if available is not None and available < episodes:
        episodes = max(1, available)
        plan["note"] = (f"the baseline report has {available} episode(s) per scenario from seed {seed}, fewer than "
                        f"the {plan['planned']} planned: the run has less power than planned (see its power)")
    plan["episodes"] = episodes
    return episodes, plan


def _progress(enabled: bool, total: int, initial: int):
    if not enabled:
        return None
    from tqdm import tqdm

    return tqdm(total=total, initial=initial, desc="regress", unit="episode", file=sys.stderr, dynamic_ncols=True)
