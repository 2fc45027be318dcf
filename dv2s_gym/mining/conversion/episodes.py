"""The episodes a conversion runs on a new scenario and what each one says about the failure.

The same policy drives the new scenario over ``k`` scenes (:func:`reproduction_seeds`, :func:`reproduce`); an
episode reproduces the failure when it fails in the same failure class (:func:`same_failure_class`) with the same
kind of actor, and says whether its trace shows the failure's interaction. The reference driver drives the same
scenes: an episode of it counts as failing by :func:`reference_failed` (:func:`reference_outcome` counts them; the
same rule tells whether it passed a mined failure's own scene, :func:`reference_passed`). The actors of the
failure's scene and of the runs are counted by kind (:func:`actor_census`, :func:`compare_actors`), and one
reproduction episode is chosen to film (:func:`clip_episode`).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Tuple, Union

import numpy as np

from dv2s_gym.mining.conversion.settings import ConversionSettings
from dv2s_gym.mining.errors import MiningError
from dv2s_gym.mining.conversion.failure_video import VideoSettings
from dv2s_gym.mining.conversion.interaction import FailureInteraction, key_actor, trace_shows_interaction
from dv2s_gym.mining.monitors import detect_failure, MonitorSettings
from dv2s_gym.mining.settings import read_run_settings
from dv2s_gym.mining.tasks import reference_avoids
from dv2s_gym.pipeline.semantics.trace import trace_actor_kind
from policies.evaluation import run_episode
from policies.registry import load_policy
from scenario_bank.failure_types import is_contact, is_near_miss
from scenario_bank.records import EpisodeRecord, Failure, recorded

__all__ = ["same_failure_class", "reference_failed", "reference_passed", "reference_outcome", "reproduction_seeds",
           "detected_failure", "monitor_options", "policy_name", "video_settings", "reproduce", "clip_episode",
           "actor_census", "compare_actors"]


def same_failure_class(source: Failure, candidate: Optional[Failure]) -> bool:
    """Whether ``candidate`` (a failure, or None) is in the failure class of ``source`` (see the module doc)."""
    if candidate is None or candidate.type != source.type:
        return False
    if is_contact(source.type):
        for mine, theirs in ((source.with_kind, candidate.with_kind),
                             (source.collision_type, candidate.collision_type)):
            if mine is not None and theirs is not None and mine != theirs:
                return False
    return True


def reference_failed(source: Optional[Failure], reference_failure: Optional[Failure]) -> bool:
    """Whether the reference driver's episode counts as failing the new scenario: any collision, off-road or
    stall, whatever its class, and a near miss (``low_ttc``) when the source failure is no more severe than a
    near miss (the miner's avoidability, :func:`dv2s_gym.mining.tasks.reference_avoids`, would then call the
    source failure unavoidable too)."""
    if reference_failure is None or not reference_failure.type:
        return False
    if not is_near_miss(reference_failure.type):
        return True
    return not reference_avoids(source, reference_failure)


def reference_passed(record: EpisodeRecord) -> bool:
    """Whether the reference driver passed the failing scene of mined episode ``record`` (an
    :class:`~scenario_bank.records.EpisodeRecord`, or its JSON object as ``episodes.jsonl`` holds it) by the rule a
    conversion's avoidability uses on its new scenario (:func:`reference_failed`: any collision, off-road
    or stall of the reference counts, and a near miss unless the policy's failure was worse). The miner's
    ``avoidable`` flag is looser (a reference outcome less severe than the policy's failure, such as a stall where
    the policy came too close, counts as avoided), but the loop counts every failure of the held-out monitors, so an
    exact replay is kept only of a scene the reference driver passed. A record whose reference episode did not run
    (no reference driver) keeps the miner's flag."""
    record = EpisodeRecord.from_dict(record)
    if record.avoidable is False:
        return False
    if not recorded(record.reference):
        return True
    return not reference_failed(record.failure, record.reference.failure)


def reference_outcome(source: Failure, episodes: List[Mapping[str, Any]], reference: str) -> Dict[str, Any]:
    """The avoidability check's record from the reference driver's ``episodes`` (each with its ``failure``):
    ``{"reference", "k", "failed", "avoided_rate", "failures"}``, ``failures`` counting the failing episodes
    by failure class (``"collision:struck_from_behind": 3``; :func:`reference_failed` says which fail)."""
    failures: Dict[str, int] = {}
    for episode in episodes:
        failure = Failure.of(episode.get("failure"))
        if reference_failed(source, failure):
            failures[failure.kind] = failures.get(failure.kind, 0) + 1
    failed = sum(failures.values())
    return {"reference": reference, "k": len(episodes), "failed": failed,
            "avoided_rate": 1.0 - failed / len(episodes) if episodes else 0.0,
            "failures": dict(sorted(failures.items(), key=lambda item: (-item[1], item[0])))}


def reproduction_seeds(record_seed: int, k: int, seed: int = 0) -> List[int]:
    """The ``k`` scene seeds of the reproduction check: a function of the record's seed and ``seed`` only."""
    state = np.random.SeedSequence([int(seed) & 0xFFFFFFFF, int(record_seed) & 0xFFFFFFFF]).generate_state(k)
    return [int(s) & 0x7FFFFFFF for s in state]


def detected_failure(result, trace, options: Union[MonitorSettings, Mapping[str, Any], None]) -> Optional[Failure]:
    """The episode's failure (the miner's monitors, :func:`dv2s_gym.mining.monitors.detect_failure`)."""
    return detect_failure(result, trace, MonitorSettings.of(options))


def monitor_options(run_dir: Path, monitor: Union[MonitorSettings, Mapping[str, Any], None]) -> MonitorSettings:
    """The monitor settings: ``monitor`` when given, else the mining run's (``settings.json``), else the defaults."""
    if monitor is not None:
        return MonitorSettings.of(monitor)
    try:
        settings = read_run_settings(run_dir)
    except MiningError:
        return MonitorSettings()
    return MonitorSettings() if settings is None else settings.monitor


def policy_name(policy: Any) -> str:
    if isinstance(policy, (str, os.PathLike)):
        return os.fspath(policy)
    return str(getattr(policy, "name", None) or type(policy).__name__)


def video_settings(settings: ConversionSettings) -> VideoSettings:
    """The settings of the failure's video (:class:`~dv2s_gym.mining.conversion.failure_video.VideoSettings`)."""
    return VideoSettings(policy=settings.policy, bank_dir=settings.bank_dir, env_config=settings.env_config,
                         before=settings.before, after=settings.after,
                         monitor=settings.monitor)


def reproduce(script_path: Path, policy: Any, settings: ConversionSettings, record_seed: int,
              source_failure: Failure,
              interaction: Optional[FailureInteraction] = None
              ) -> Tuple[List[Dict[str, Any]], List[Any]]:
    """Run ``policy`` on the new scenario over the settings' ``k`` seeds derived from ``record_seed`` (with the
    settings' ``env_config`` and ``monitor``); per episode its seed, failure, the kind of
    the actor its failure involved (``actor_kind``, :func:`~dv2s_gym.mining.conversion.interaction.key_actor`), whether it
    shows the source failure's interaction (``interaction``) and ``reproduced``: the same failure class with
    the same kind of actor."""
    from envs.dv2s_env import DV2SEnv

    env = DV2SEnv(scenario=str(script_path), config=dict(settings.env_config or {}))
    try:
        bound = load_policy(policy)
        bound.bind([env])
        name = script_path.parent.name if script_path.name == "scenario.scenic" else script_path.stem
        episodes, traces = [], []
        for scene_seed in reproduction_seeds(record_seed, settings.k, settings.seed):
            result, trace = run_episode(env, bound, name, scene_seed)
            episodes.append(_reproduction_episode(scene_seed, result, trace, settings.monitor, source_failure,
                                                  interaction))
            traces.append(trace)
        return episodes, traces
    finally:
        env.close()


def _reproduction_episode(scene_seed: int, result: Any, trace: Any,
                          monitor: Union[MonitorSettings, Mapping[str, Any], None],
                          source_failure: Failure, interaction: Optional[FailureInteraction]
                          ) -> Dict[str, Any]:
    """One episode of :func:`reproduce`, judged (its ``failure`` as its JSON object)."""
    failure = detected_failure(result, trace, monitor)
    actor = key_actor(trace, failure) if failure is not None else None
    actor_kind = None
    if actor is not None:
        actor_kind = (failure.with_kind if failure.with_ == actor and failure.with_kind
                      else trace_actor_kind(trace, actor))
    wanted_kind = interaction.kind if interaction is not None else None
    same = same_failure_class(source_failure, failure) and (wanted_kind is None or actor_kind == wanted_kind)
    shown = trace_shows_interaction(interaction, trace) if recorded(interaction) else None
    return {"seed": scene_seed, "failure": failure.to_dict() if failure is not None else None, "steps": result.steps, "trajectory_hash": result.trajectory_hash,
            "actor_kind": actor_kind, "interaction": shown, "reproduced": same}


def clip_episode(episodes: List[Mapping[str, Any]]) -> Tuple[Mapping[str, Any], str]:
    """The reproduction episode to film and why it was chosen: the first that reproduced the failure (the same
    class with the same kind of actor), else the first that failed at all, else the first."""
    for episode in episodes:
        if episode.get("reproduced"):
            return episode, "the first reproduction episode that failed the same way"
    for episode in episodes:
        if episode.get("failure"):
            return episode, "no reproduction episode failed the same way; the first that failed"
    return episodes[0], "no reproduction episode failed; the first"


def actor_census(trace: Any) -> Dict[str, int]:
    """The actors of an episode's trace besides the ego, counted by kind (``{"car": 2, "pedestrian": 1}``)."""
    names = set(getattr(trace, "kinds", {}) or {})
    for state in getattr(trace, "states", None) or []:
        names.update(state)
    names.discard("ego")
    census: Dict[str, int] = {}
    for name in names:
        kind = trace_actor_kind(trace, name)
        census[kind] = census.get(kind, 0) + 1
    return dict(sorted(census.items()))


def compare_actors(source: Mapping[str, int], scripts: List[Mapping[str, int]],
                   adversary: Optional[str]) -> Dict[str, Any]:
    """The failure's actors (``source``, :func:`actor_census` of its trace) against the new scenario's (the census
    of each reproduction episode; the most frequent one is the script's): ``{"failure", "script", "missing",
    "extra", "adversary", "same"}``; ``missing`` and ``extra`` count per kind what the script lacks or adds,
    ``same`` is whether the two agree kind for kind and the failure's actors are the scene in a majority of the runs
    (``runs_matching`` of ``runs``)."""
    script: Dict[str, int] = {}
    if scripts:
        keys = [json.dumps(dict(sorted(c.items()))) for c in scripts]
        script = json.loads(max(sorted(set(keys)), key=keys.count))
    kinds = sorted(set(source) | set(script))
    missing = {k: source.get(k, 0) - script.get(k, 0) for k in kinds if source.get(k, 0) > script.get(k, 0)}
    extra = {k: script.get(k, 0) - source.get(k, 0) for k in kinds if script.get(k, 0) > source.get(k, 0)}
    # the failure's actors must be the scene in most reproduction runs, not only in the most common of several sets
    matching = sum(1 for c in scripts if {k: n for k, n in c.items() if n} == {k: n for k, n in source.items() if n})
    majority = not scripts or 2 * matching > len(scripts)
    return {"failure": dict(source), "script": script, "missing": missing, "extra": extra, "adversary": adversary,
            "runs": len(scripts), "runs_matching": matching, "same": not missing and not extra and majority}
