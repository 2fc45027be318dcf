"""Reproduce one episode of a regression report: ``dv2s replay REPORT --episode ID``.

A failed episode's trace is stored in the run's ``traces/`` folder: replaying it re-runs
the same scene with the recorded actions, checks every actor state step by step and the
trajectory hash the report holds. An episode without a stored trace (one that did not
fail), or any episode with ``from_policy=True``, is re-run from scratch instead: the same
policy spec, scenario, seed and env config, and its trajectory hash must match the
report's. Either way a video can be written.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, ClassVar, FrozenSet, List, Mapping, Optional, Tuple, Union
import difflib

from dv2s_gym.regress.errors import RegressError
from dv2s_gym.regress.records import BankInfo, RegressReport
from scenario_bank.records import JsonRecord, RegressEpisode, recorded
from dv2s_gym.regress.report import bank_info, load_report
from envs.recording import VideoWriter
from envs.trace import EpisodeTrace
from envs.trace_bounds import check_file_config
from policies.evaluation import trajectory_hash, make_eval_env, run_episode
from policies.registry import load_policy, spec_from_file

__all__ = ["EpisodeReplay", "find_episode", "replay_episode", "bank_for_scenario"]


@dataclass(frozen=True, eq=False)
class EpisodeReplay(JsonRecord):
    """What replaying one episode of a regression report found (:func:`replay_episode`): the episode's ``id`` and
    the policy's ``role``, how it was replayed (``source``: ``"trace"``, the stored trace step for step, or
    ``"policy"``, the policy re-run), the ``steps`` it ran, the ``trajectory_hash`` it produced and the
    ``expected_hash`` the report holds, whether they ``matches``, and the ``video`` written (``None`` without
    one). Every field is written, ``null`` when ``None``."""

    id: str
    role: str
    source: str
    steps: Optional[int] = None
    trajectory_hash: Optional[str] = None
    expected_hash: Optional[str] = None
    matches: Optional[bool] = None
    video: Optional[str] = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    null_fields: Optional[FrozenSet[str]] = None

    _REQUIRED: ClassVar[Tuple[str, ...]] = ("id", "role", "source")
    _WHAT: ClassVar[str] = "episode replay"

    def default_null_fields(self) -> FrozenSet[str]:
        return frozenset({"steps", "trajectory_hash", "expected_hash", "matches", "video"})


def find_episode(report: RegressReport, episode_id: str, role: str = "candidate") -> RegressEpisode:
    """The result of ``role`` in episode ``episode_id`` of a report (clear errors otherwise)."""
    if role not in ("candidate", "baseline"):
        raise RegressError(f"--policy must be 'candidate' or 'baseline', not {role!r}")
    episodes = {e.id: e for e in report.episodes or ()}
    if episode_id not in episodes:
        near = difflib.get_close_matches(episode_id, list(episodes), n=3, cutoff=0.6)
        hint = f" Did you mean {', '.join(near)}?" if near else ""
        failing = list(report.newly_failing or ()) or [i for i, e in episodes.items()
                                                        if e.candidate is not None and e.candidate.failed]
        examples = f" Failed episodes: {', '.join(failing[:5])}." if failing else ""
        raise RegressError(f"the report has no episode {episode_id!r} (ids are scenario/seed).{hint}{examples}")
    result = episodes[episode_id].result(role)
    if result is None:
        raise RegressError(f"episode {episode_id} has no {role} result (the run had no baseline); "
                           "use --policy candidate")
    if result.error:
        raise RegressError(f"episode {episode_id} ({role}) ended in an error and has nothing to replay: "
                           f"{result.error.splitlines()[0]}")
    return result


def replay_episode(report_path: Union[str, os.PathLike], episode_id: str, role: str = "candidate",
                   video: Optional[Union[str, os.PathLike]] = None, from_policy: bool = False,
                   spec: Optional[str] = None) -> EpisodeReplay:
    """Re-run one episode of a report and check its trajectory hash.

    A re-run loads the policy ``spec`` (the caller's), else the report's spec for ``role``, and that only if
    it is a built-in policy (:func:`~policies.registry.spec_from_file`): a report is data.

    Returns the :class:`EpisodeReplay` (its JSON object ``{"id", "role", "source": "trace" | "policy", "steps",
    "trajectory_hash", "expected_hash", "matches", "video"}``); ``matches`` is False when the hash differs (a
    diverging actor state in a trace replay raises :class:`~envs.trace.TraceMismatchError` instead).
    """
    report_path = Path(report_path)
    report = load_report(report_path)
    result = find_episode(report, episode_id, role)
    frames: Optional[List[Any]] = [] if video else None
    trace_path = result.trace
    if trace_path and not Path(trace_path).is_absolute():
        trace_path = str(report_path.parent / trace_path)
    if trace_path and not from_policy:
        if not Path(trace_path).is_file():
            raise RegressError(f"the trace of {episode_id} ({role}) is missing at {trace_path}; keep the run's "
                               "traces/ folder beside report.json, or re-run the policy with --from-policy")
        steps, digest, fps = _from_trace(trace_path, frames)
        source = "trace"
    else:
        if not spec:
            policy = report.candidate if role == "candidate" else report.baseline
            named = policy.spec if policy is not None else None
            if not named:
                raise RegressError(f"the report names no {role} policy to re-run")
            spec = spec_from_file(named, f"the report {report_path} ({role})", "--policy-spec SPEC")
        steps, digest, fps = _from_policy(report, result, spec, frames)
        source = "policy"
    written = None
    if video:
        with VideoWriter(video, fps=fps) as writer:
            for frame in frames or []:
                writer.write(frame)
        written = str(video)
    expected = result.trajectory_hash
    return EpisodeReplay(id=episode_id, role=role, source=source, steps=steps, trajectory_hash=digest,
                         expected_hash=expected, matches=digest == expected, video=written)


def _from_trace(path: str, frames: Optional[List[Any]]):
    from envs.replay import replay_trace

    trace = EpisodeTrace.load(path)
    env, replayed = replay_trace(trace, render_mode="rgb_array" if frames is not None else None, frames=frames)
    try:
        return len(replayed.actions), trajectory_hash(replayed), env.unwrapped.config["policy_frequency"]
    finally:
        env.close()


def _from_policy(report: RegressReport, result: RegressEpisode, spec: str, frames: Optional[List[Any]]):
    config = check_file_config(report.settings.env_config if report.settings is not None else None, "the report")
    bank = report.bank if recorded(report.bank) else BankInfo()
    scenario = result.scenario
    bank_dir = bank_for_scenario(bank, scenario)
    env = make_eval_env(None, config=config, bank_dir=bank_dir,
                        render_mode="rgb_array" if frames is not None else None)
    try:
        policy = load_policy(spec)
        policy.bind([env])
        rerun, _ = run_episode(env, policy, scenario, int(result.seed), frames=frames)
        return rerun.steps, rerun.trajectory_hash, env.unwrapped.config["policy_frequency"]
    finally:
        env.close()


def bank_for_scenario(bank: BankInfo, scenario: str) -> Optional[str]:
    """The report's bank folder, or the shipped bank when that folder is not on this machine, as long as
    the scenario's script is the one the report ran."""
    expected = (bank.hashes or {}).get(scenario)
    path = bank.path
    here = None
    for folder in ([path] if path and Path(path).is_dir() else []) + [None]:
        try:
            here = bank_info([scenario], folder).hashes[scenario]
        except Exception:  # not in that bank
            continue
        if here == expected:
            return folder
    raise RegressError(f"scenario {scenario} is not in the bank the report used ({path}) with the same script "
                       f"({str(expected)[:12]} in the report{f', {here[:12]} here' if here else ''}); "
                       "the episode cannot be reproduced")
