"""From a mined failure to validated bank entries: the failing scene kept exactly, and its D-V2S conversion judged.

:func:`convert_failure` takes one failure record of the miner (an episode record of
``episodes.jsonl`` whose ``failure`` is set) through these stages, each timed, and returns the
conversion record of ``conversions.jsonl``:

1. ``video``: re-run the episode and write its bird's-eye video and trace
   (:func:`dv2s_gym.mining.failure_video.record_failure_video`; a diverging replay is a rejection);
2. ``interaction``: the failure's interaction read from its own trace
   (:func:`dv2s_gym.mining.interaction.failure_interaction`): the actor involved (the collision partner, or
   the actor the ego slowed down for, however far ahead), its kind and its manoeuvres;
3. ``replay``: the exact replay of the failing scene goes into the bank whatever becomes of the conversion
   (:mod:`dv2s_gym.mining.exact_replay`): the parent script narrowed around the failing parameters, tagged
   ``replay``, its provenance ``replay`` holding the parameters, seed and trajectory hash that pin the
   scene; it is checked to replay the recorded episode step for step first (else a ``replay`` rejection);
4. ``describe``: the Driving Record Analyzer turns the video into a description, and the trace's account of
   the interaction is added to it (:func:`~dv2s_gym.mining.interaction.interaction_sentence`), so the
   description names what caused the failure even when the clip does not show it;
5. ``generate``: the Scenario Generator turns the description into a Scenic script;
6. ``check``: safety allowlist, then compile, sample and run in the sandbox
   (:func:`dv2s_gym.pipeline.convert.check_scenario`);
7. ``reproduction``: the same policy drives the new scenario over ``k`` scenes whose seeds derive
   from the record's seed (``numpy.random.SeedSequence([seed, record seed])``); an episode reproduces the
   failure when it fails in the *same failure class* with the *same kind of actor*; each episode also says
   whether its trace shows the failure's interaction (an actor of the key actor's kind doing one of its
   manoeuvres and, for a collision, the ego colliding with that actor: :func:`~dv2s_gym.mining.interaction.trace_shows_interaction`);
8. ``avoidability``: the reference driver (``rule``) drives the same ``k`` scenes; an episode counts as a
   reference failure when it has *any* collision, off-road or stall, whatever its class
   (:func:`reference_failed`), as the miner calls a failure unavoidable when the reference fails in its
   scene; the record counts the reference's failures by class (``failures``);
9. ``e2e_sc``: E2E-SC between the source failure's trace (its elements are the ground truth) and each
   simulated trace of the reproduction, averaged over the ``k`` traces;
10. the judge: the script is rejected, each reason with its own stage and every failed one listed in
    ``rejections``, when the interaction shows in fewer than ``threshold`` of the episodes
    (``interaction: ...``), the failure reproduces in fewer than ``threshold`` (``reproduction: ...``), or
    the reference driver fails in half of the episodes or more (``avoidability: ...``, naming its failures'
    classes), the new scenario's actors differ from the failure's, kind for kind (``actors: ...``: fewer actors,
    the adversary missing, or more; the failure's trace against the reproduction runs' traces), or a range of
    the new script does not contain the failing value of the parameter that means the same (``parameters: ...``:
    by name, else by the quantity of the same actor it sets, :mod:`dv2s_gym.mining.param_meaning`; the failing
    parameters it could pair with none are listed in the record's ``parameters.not_comparable``, with why);
11. ``bank``: :meth:`scenario_bank.bank.Bank.add` with ``on_duplicate="merge"`` adds the script with ``mined``
    provenance, or merges the failure into the entry it (nearly) duplicates, a converted entry of the same family
    (parent and failure type) whose code differs in at most :data:`~scenario_bank.bank.NEAR_COPY_LINES`
    lines included. The failure video and trace are copied into the entry's folder in the same atomic
    step (provenance ``video: "failure.webm"``, ``trace: "trace.json.gz"``, relative to the entry folder; a
    merge puts them under ``merged/<n>/``), and a map path in ``params`` is kept as its file name: the entry
    stands alone once the run folder is gone. The two entries of one failure link each other
    (``replay_entry`` on the script, ``converted`` on the replay) and the replay records the converted
    script's E2E-SC (``converted_e2e_sc``) and rejections beside its own E2E-SC (1.0 for an exact replay).

Failure class (:func:`same_failure_class`): the failure types must be equal; for collisions the
other party's kind (``with_kind``: car, truck, pedestrian, obstacle...) and the collision type
(``collision_type``: rear_end, struck_from_behind, side, head_on...) must be equal too, each
compared only when both failures know it (a ``None`` matches anything). Actor names are never
compared (a generated script names its actors anew).

Nothing raises out of :func:`convert_failure` for a bad failure: every rejection is a record with
``status: "rejected"``, the ``stage`` and a ``reason`` ``"<stage>: <message>"``.
"""

from __future__ import annotations

import dataclasses
import datetime
import json
import os
import re
import time
import warnings
from dataclasses import asdict
from pathlib import Path
from typing import Any, Dict, List, Mapping, Optional, Tuple, Union

import numpy as np

from dv2s_gym.mining.conversion_settings import ConversionSettings
from dv2s_gym.mining.errors import MiningError
from dv2s_gym.mining.exact_replay import NARROW, narrowed_script, replay_name, REPLAY_TAG, replay_versions, run_replay
from dv2s_gym.mining.interaction import (FailureInteraction, failure_interaction, interaction_sentence, key_actor,
                                         trace_shows_interaction)
from dv2s_gym.mining.monitors import MonitorSettings, detect_failure
from dv2s_gym.mining.report_text import not_compared_names_text
from dv2s_gym.mining.param_meaning import (actor_objects, behaviour_overrides, counterpart_objects, fixed_quantities,
                                           key_uses, lengths_along, meaning_map, name_mismatch, object_behaviour_heads,
                                           object_behaviours, placements, quantity_uses, script_objects,
                                           script_parameters, tied_objects)
from dv2s_gym.mining.scenic_values import (joint_interval, placement_parts, quantity_of, read_interval, read_support,
                                           support_contains, support_hull, support_text)
from dv2s_gym.mining.settings import read_run_settings
from dv2s_gym.mining.tasks import reference_avoids
from dv2s_gym.pipeline import stages
from dv2s_gym.pipeline.convert import check_scenario, conversion_provenance
from dv2s_gym.pipeline.errors import (EndpointHTTPError, EndpointTimeoutError, EndpointUnreachableError,
                                      MissingAPIKeyError)
from dv2s_gym.pipeline.metrics import e2e_sc
from dv2s_gym.pipeline.semantics.text import elements_from_text
from dv2s_gym.pipeline.semantics.trace import elements_from_trace, trace_actor_kind
from dv2s_gym.regress.stats import wilson_interval
from scenario_bank.atomic import atomic_write_text
from scenario_bank.bank import Bank, DuplicateScenarioError
from scenario_bank.dedup import param_ranges
from scenario_bank.errors import BankError, NearDuplicateWarning, WrongTypeError
from scenario_bank.records import Provenance, Sidecar
from policies.evaluation import run_episode
from policies.registry import load_policy
from dv2s_gym.mining.failure_video import VideoSettings, write_failure_video, write_script_episode_video

SETUP_ERRORS = (EndpointUnreachableError, EndpointTimeoutError, EndpointHTTPError, MissingAPIKeyError)
"""Errors of the model backends' setup (no connection, no answer, an HTTP error, no API key):
:func:`convert_failure` raises them instead of rejecting the failure, so a run stops and can be resumed
when the endpoint works, rather than rejecting every cluster."""

__all__ = ["convert_failure", "replay_failure_entry", "same_failure_class", "reference_failed", "reference_passed", "reference_outcome",
           "reproduction_seeds", "cluster_slug", "CONVERSION_DIR", "ENTRY_VIDEO",
           "ENTRY_TRACE", "ENTRY_CONVERTED_VIDEO", "clip_episode", "SETUP_ERRORS"]

CONVERSION_DIR = "conversion"
ENTRY_VIDEO = "failure.webm"
"""The failure video's name in a kept entry's bank folder (its provenance ``video``; a merged failure's is
``merged/<n>/failure.webm``)."""
ENTRY_TRACE = "trace.json.gz"
"""The source episode's trace in a kept entry's bank folder (its provenance ``trace``)."""
ENTRY_CONVERTED_VIDEO = "converted.webm"
"""The clip of the converted script driven by the policy (one reproduction episode) in a kept entry's bank folder
(its provenance ``converted_video``; a merged failure's is ``merged/<n>/converted.webm``) and in the mining run's
``failures/<cluster>/conversion/`` folder."""
PathLike = Union[str, os.PathLike]


class _Rejected(MiningError):
    def __init__(self, stage: str, message: str) -> None:
        super().__init__(f"{stage}: {message}")
        self.stage, self.message = stage, message


def same_failure_class(source: Mapping[str, Any], candidate: Optional[Mapping[str, Any]]) -> bool:
    """Whether ``candidate`` (a failure dict, or None) is in the failure class of ``source`` (see the module doc)."""
    if not candidate or candidate.get("type") != source.get("type"):
        return False
    if source.get("type") == "collision":
        for key in ("with_kind", "collision_type"):
            if source.get(key) is not None and candidate.get(key) is not None and source[key] != candidate[key]:
                return False
    return True


def reference_failed(source: Mapping[str, Any], reference_failure: Optional[Mapping[str, Any]]) -> bool:
    """Whether the reference driver's episode counts as failing the new scenario: any collision, off-road or
    stall, whatever its class, and a near miss (``low_ttc``) when the source failure is no more severe than a
    near miss (the miner's avoidability, :func:`dv2s_gym.mining.tasks.reference_avoids`, would then call the
    source failure unavoidable too)."""
    if not reference_failure or not reference_failure.get("type"):
        return False
    if reference_failure["type"] != "low_ttc":
        return True
    return not reference_avoids(dict(source), dict(reference_failure))


def reference_passed(record: Mapping[str, Any]) -> bool:
    """Whether the reference driver passed the failing scene of mined episode ``record`` by the rule a conversion's
    avoidability uses on its new scenario (:func:`reference_failed`: any collision, off-road
    or stall of the reference counts, and a near miss unless the policy's failure was worse). The miner's
    ``avoidable`` flag is looser (a reference outcome less severe than the policy's failure, such as a stall where
    the policy came too close, counts as avoided), but the loop counts every failure of the held-out monitors, so an
    exact replay is kept only of a scene the reference driver passed. A record whose reference episode did not run
    (no reference driver) keeps the miner's flag."""
    if record.get("avoidable") is False:
        return False
    reference = record.get("reference")
    if not reference:
        return True
    return not reference_failed(dict(record.get("failure") or {}), reference.get("failure"))


def reference_outcome(source: Mapping[str, Any], episodes: List[Mapping[str, Any]], reference: str) -> Dict[str, Any]:
    """The avoidability check's record from the reference driver's ``episodes`` (each with its ``failure``):
    ``{"reference", "k", "failed", "avoided_rate", "failures"}``, ``failures`` counting the failing episodes
    by failure class (``"collision:struck_from_behind": 3``; :func:`reference_failed` says which fail)."""
    failures: Dict[str, int] = {}
    for episode in episodes:
        failure = episode.get("failure")
        if reference_failed(source, failure):
            label = str(failure.get("kind") or failure["type"])
            failures[label] = failures.get(label, 0) + 1
    failed = sum(failures.values())
    return {"reference": reference, "k": len(episodes), "failed": failed,
            "avoided_rate": 1.0 - failed / len(episodes) if episodes else 0.0,
            "failures": dict(sorted(failures.items(), key=lambda item: (-item[1], item[0])))}


def reproduction_seeds(record_seed: int, k: int, seed: int = 0) -> List[int]:
    """The ``k`` scene seeds of the reproduction check: a function of the record's seed and ``seed`` only."""
    state = np.random.SeedSequence([int(seed) & 0xFFFFFFFF, int(record_seed) & 0xFFFFFFFF]).generate_state(k)
    return [int(s) & 0x7FFFFFFF for s in state]


def cluster_slug(cluster: Optional[str], index: Any) -> str:
    """A folder name for a failure cluster (``"<scenario>/<type>/<actor>-<manoeuvre>/ego-<manoeuvre>"`` -> its
    parts joined by ``__``, other characters replaced)."""
    if not cluster:
        return f"episode-{int(index):06d}" if isinstance(index, int) else "failure"
    return re.sub(r"[^A-Za-z0-9_.\-]+", "_", str(cluster).replace("/", "__")).strip("._")[:120] or "failure"


def _detect(result, trace, options: Union[MonitorSettings, Mapping[str, Any], None]) -> Optional[Dict[str, Any]]:
    """The episode's failure as a dict (the miner's monitors, :func:`dv2s_gym.mining.monitors.detect_failure`)."""
    found = detect_failure(result, trace, MonitorSettings.of(options))
    return None if found is None else found.to_json()


def _monitor_options(run_dir: Path, monitor: Union[MonitorSettings, Mapping[str, Any], None]) -> MonitorSettings:
    """The monitor settings: ``monitor`` when given, else the mining run's (``settings.json``), else the defaults."""
    if monitor is not None:
        return MonitorSettings.of(monitor)
    try:
        settings = read_run_settings(run_dir)
    except MiningError:
        return MonitorSettings()
    return MonitorSettings() if settings is None else settings.monitor


def _policy_name(policy: Any) -> str:
    if isinstance(policy, (str, os.PathLike)):
        return os.fspath(policy)
    return str(getattr(policy, "name", None) or type(policy).__name__)


def _write(path: Path, text: str) -> None:
    atomic_write_text(path, text, fsync=False)


def _rel(path: Path, root: Path) -> str:
    try:
        return str(path.resolve().relative_to(root.resolve()))
    except ValueError:
        return str(path)


def _in_run(text: str, run_dir: Path) -> str:
    """``text`` (a rejection reason, a clip's error) naming files inside the run folder ``run_dir`` by their path
    relative to it, not by this machine's absolute path (the record travels with the run folder)."""
    for where in dict.fromkeys((str(run_dir), str(run_dir.absolute()), str(run_dir.resolve()))):
        text = text.replace(where.rstrip(os.sep) + os.sep, "")
    return text


def _video_settings(settings: ConversionSettings) -> VideoSettings:
    """The settings of the failure's video (:class:`~dv2s_gym.mining.failure_video.VideoSettings`)."""
    return VideoSettings(policy=settings.policy, bank_dir=settings.bank_dir, env_config=settings.env_config,
                         before=settings.before, after=settings.after,
                         monitor=settings.monitor)


def _reproduce(script_path: Path, policy: Any, settings: ConversionSettings, record_seed: int,
               source_failure: Mapping[str, Any], interaction: Optional[Mapping[str, Any]] = None
               ) -> Tuple[List[Dict[str, Any]], List[Any]]:
    """Run ``policy`` on the new scenario over the settings' ``k`` seeds derived from ``record_seed`` (with the
    settings' ``env_config`` and ``monitor``); per episode its seed, failure, the kind of
    the actor its failure involved (``actor_kind``, :func:`~dv2s_gym.mining.interaction.key_actor`), whether it
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
                          source_failure: Mapping[str, Any], interaction: Optional[Mapping[str, Any]]
                          ) -> Dict[str, Any]:
    """One episode of :func:`_reproduce`, judged."""
    failure = _detect(result, trace, monitor)
    actor = key_actor(trace, failure) if failure else None
    actor_kind = None
    if actor is not None:
        actor_kind = (failure.get("with_kind") if failure.get("with") == actor and failure.get("with_kind")
                      else trace_actor_kind(trace, actor))
    wanted_kind = (interaction or {}).get("kind")
    same = same_failure_class(source_failure, failure) and (wanted_kind is None or actor_kind == wanted_kind)
    shown = trace_shows_interaction(interaction, trace) if interaction else None
    return {"seed": scene_seed, "failure": failure, "steps": result.steps, "trajectory_hash": result.trajectory_hash,
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


def compare_parameters(failing: Mapping[str, Any], script: str, parent: Optional[str] = None,
                       interaction: Optional[Mapping[str, Any]] = None) -> Dict[str, Any]:
    """The failing parameter values against the ranges of the new script's global parameters that mean the same:
    first by name, without regard to case (``param x = Range(a, b)`` and the other numeric forms
    :func:`scenario_bank.dedup.param_ranges` reads), then, given the ``parent`` script the failure ran, by meaning
    for the rest (:func:`dv2s_gym.mining.param_meaning.meaning_map`: the same quantity of the same actor, read
    from the two scripts' structure). Returns ``{"compared": {name: {"value", "range": [low, high]}} (plus
    ``"script_name"`` when the script spells it differently, and ``"by": "meaning"`` with ``"basis"`` when paired
    by meaning), "outside": [names whose range does not contain the failing value], "not_comparable": {failing
    parameter: why it could not be compared}, "not_in_script": [the same names]}``.

    A distribution built from ``Range``/``Uniform`` and numbers by sums, differences, products and quotients with
    numbers and unary minus (``Range(2, 4) * 2 + 1``) is read as the interval it produces
    (:func:`~dv2s_gym.mining.scenic_values.read_interval`). Given the parent, a counterpart that sets the quantity
    through an affine expression of itself alone (``CutIn(globalParameters.g + 10)``) is compared through that
    expression: the quantity the failing value set in the parent (through the parent's own expression) against
    the interval the new expression produces over the counterpart's range (``"expression"``, ``"interval"``,
    ``"quantity"`` in its comparison; ``"parent_expression"`` when the parent's is not the bare parameter), on every
    quantity the parameter sets in both scripts (``"where"`` names the one kept when there are several). A
    distribution that is not one interval (``Uniform(5, 9)``, ``DiscreteRange(5, 9)``, ``Uniform(Range(1, 2),
    100)``) keeps its values in ``"support"`` (:func:`~dv2s_gym.mining.scenic_values.read_support`): the failing
    value must be one of them.

    Given the parent, ``"key"`` holds ``{failing parameter: the quantity it sets}`` for the numeric failing parameters
    that set a quantity of the failure's interaction in the parent (the ego's or the key actor's, the
    ``interaction``'s ``actor``, else an actor's of its ``kind``, every actor's when neither is known:
    :func:`~dv2s_gym.mining.param_meaning.key_parameters`): the judge requires each of them compared
    (:func:`_judge`); ``"key_fixed_outside"`` those whose key quantity the new script fixes without a parameter away
    from the failing value (:func:`_key_fixed_outside`), ``"key_overridden"`` (when any) those whose key behaviour
    argument the new script's behaviour assigns anew (:func:`_key_overridden`), ``"key_unread"`` (when any) those
    whose key actor's placement the new script writes in another quantity or form the judge cannot read
    (:func:`_key_placement_unread`), and ``"quantities_not_compared"`` (when any) ``{parameter:
    why}`` for a compared parameter's other quantity the judge could not read (:func:`_through_quantities`). A key
    parameter the new script sets by parameters of its own is compared jointly when both scripts' expressions can
    be read so (:func:`_compare_jointly`)."""
    ranges, supports = _script_ranges(script), _script_supports(script)
    folded: Dict[str, str] = {}
    for script_name in sorted(ranges):
        folded.setdefault(script_name.casefold(), script_name)
    compared: Dict[str, Any] = {}
    outside: List[str] = []
    absent: List[str] = []
    numeric = {name: value for name, value in sorted(failing.items())
               if not isinstance(value, bool) and isinstance(value, (int, float)) and np.isfinite(value)}
    for name, value in numeric.items():
        script_name = name if name in ranges else folded.get(str(name).casefold())
        if script_name is None:
            absent.append(name)
            continue
        compared[name] = {"value": float(value), "range": [float(v) for v in ranges[script_name]]}
        if script_name in supports:
            compared[name]["support"] = supports[script_name]
        if script_name != name:
            compared[name]["script_name"] = script_name
    why = {name: "the new script defines no numeric parameter of that name" for name in absent}
    keyed: Dict[str, List[Tuple[str, str, str, str]]] = {}
    if parent is not None:
        interaction = interaction or {}
        keyed = {name: where for name, where in key_uses(parent, interaction.get("kind"),
                                                         interaction.get("actor")).items() if name in numeric}
        meanings = {name: {(obj == "ego", kind, slot) for obj, kind, slot, _ in where} for name, where in keyed.items()}
        why = _by_meaning(parent, script, numeric, compared, absent, ranges, meanings)
    for name in sorted(compared):
        if not _contains(name, compared[name]):
            outside.append(name)
    not_comparable = {name: why[name] for name in sorted(why) if name not in compared}
    out = {"compared": dict(sorted(compared.items())), "outside": outside, "not_comparable": not_comparable,
           "not_in_script": list(not_comparable)}
    partly = {name: comparison.pop("quantities_not_compared") for name, comparison in out["compared"].items()
              if "quantities_not_compared" in comparison}
    if partly:
        out["quantities_not_compared"] = partly
    if parent is not None:
        _check_keys(parent, script, keyed, numeric, out, interaction.get("actor"))
    return out


def _check_keys(parent: str, script: str, keyed: Mapping[str, Sequence[Tuple[str, str, str, str]]],
                numeric: Mapping[str, float], out: Dict[str, Any], actor: Optional[str]) -> None:
    """:func:`compare_parameters`' checks of the key parameters (``keyed``: ``{name: where it sets a key quantity in
    the parent}``), into ``out``: ``key``, ``key_not_compared``, the joint comparison, ``key_fixed_outside``, and
    ``key_unread`` and ``key_overridden`` when any."""
    out["key"] = {name: where[0][3] for name, where in keyed.items()}
    out["key_not_compared"] = _key_set_otherwise(parent, script, keyed, out)
    _compare_jointly(parent, script, keyed, numeric, out, actor)
    out["key_fixed_outside"] = _key_fixed_outside(parent, script, keyed, numeric, actor)
    unread = _key_placement_unread(parent, script, keyed, out, actor)
    if unread:
        out["key_unread"] = unread
    overridden = _key_overridden(parent, script, keyed, numeric, actor)
    if overridden:
        out["key_overridden"] = overridden


FIXED_TOLERANCE = NARROW
"""How far a key quantity the new script fixes at a value (``with speed 20``, ``CutIn(2.5)``) may lie from the
failing value's quantity and still hold it, as a share of the width the parent's range of the parameter gives
that quantity: the exact replay narrows each parameter to this share of its width on either side of the failing
value (:data:`~dv2s_gym.mining.exact_replay.NARROW`) and takes any value in that band as the failing scene's, so
a fixed value as close stands for the failing scene as well as the replay's draws do. A parent range of no width
allows no distance."""


def _counterpart_finder(parent: str, script: str, actor: Optional[str] = None):
    """``counterpart(object, kind)``: the new script's object that stands for the parent's (the ego for the ego; the
    paired object; the key ``actor``'s object by its name; the only object of the kind on both sides), or ``None``."""
    objects = counterpart_objects(parent, script)
    new_objects = script_objects(script)
    named = actor_objects(script)
    old_named = actor_objects(parent)
    old_objects = script_objects(parent)

    def counterpart(obj: str, kind: str) -> Optional[Tuple[str, str]]:
        if obj == "ego":
            return ("ego", kind) if ("ego", kind) in new_objects else None
        if (obj, kind) in objects:
            return objects[(obj, kind)]
        if actor and old_named.get(actor) == obj and named.get(actor):
            found = [o for o in new_objects if o[0] == named[actor] and o[1] == kind]
            if found:
                return found[0]
        same = [o for o in new_objects if o[1] == kind and o[0] != "ego"]
        old_same = [o for o in old_objects if o[1] == kind and o[0] != "ego"]
        return same[0] if len(same) == 1 and len(old_same) == 1 else None
    return counterpart


def _key_checks(parent: str, script: str, keyed: Mapping[str, Sequence[Tuple[str, str, str, str]]],
                actor: Optional[str] = None):
    """``[(parameter, parent's (object, kind, slot), the new script's (object, kind, slot), words, the parent's
    quantity function, tolerance, read as a target speed?)]`` for each key quantity the parent sets as one known function of the parameter
    alone and whose object has a counterpart in the new script (:func:`_counterpart_finder`); ``tolerance`` is
    :data:`FIXED_TOLERANCE` of the width that function takes over the parent's range of the parameter. The ego's
    or an actor's speed is checked as its behaviour's ``target_speed`` too when the parent sets no target speed of
    its own there (``FollowLaneBehavior(target_speed=30)`` keeps the object at 30 whatever its start speed)."""
    old_uses = quantity_uses(parent)
    parent_fixed = fixed_quantities(parent)
    ranges = _script_ranges(parent)
    counterpart = _counterpart_finder(parent, script, actor)
    out = []
    for name in sorted(keyed):
        for obj, kind, slot, words in keyed[name]:
            functions = {q.key: q for _, q, _ in old_uses.get(name, {}).get((obj, kind, slot), ()) if q is not None}
            other = counterpart(obj, kind)
            if len(functions) != 1 or other is None:
                continue
            function = next(iter(functions.values()))
            tolerance = 0.0
            if name in ranges:
                start, end = function.over(*ranges[name])
                tolerance = FIXED_TOLERANCE * abs(end - start)
            out.append((name, (obj, kind, slot), (other[0], other[1], slot), words, function, tolerance, False))
            target = "behavior:targetspeed"
            parent_sets_target = ((obj, kind, target) in parent_fixed
                                  or any((obj, kind, target) in by_slot for by_slot in old_uses.values()))
            if slot == "speed" and not parent_sets_target:
                out.append((name, (obj, kind, target), (other[0], other[1], target),
                            f"{words} (as its behaviour's target speed)", function, tolerance, True))
    return out


def _key_fixed_outside(parent: str, script: str, keyed: Mapping[str, Sequence[Tuple[str, str, str, str]]],
                       numeric: Mapping[str, float], actor: Optional[str] = None) -> Dict[str, str]:
    """``{key parameter: the key quantity and the value the new script fixes it at}`` for each key parameter whose
    key quantity (the ego's, or the key actor's: the same quantity of its counterpart in the new script;
    :func:`_key_checks`, a speed read as a target speed too) the new script sets without a parameter, to a value (a
    number, an inline ``Range``, discrete values: :func:`~dv2s_gym.mining.param_meaning.fixed_quantities`) that
    does not hold the failing value's quantity (the parameter's value through the parent's expression) within
    :data:`FIXED_TOLERANCE`: the new script cannot produce the failing scene's quantity, whatever else it does with
    the parameter. A key quantity the parent sets other than as a known function of the parameter alone, or that
    the new script sets with a parameter (compared as a parameter) or not at all, is not checked here; nor is a
    behaviour argument of an object that runs another behaviour than in the parent, by name or argument names
    (:func:`~dv2s_gym.mining.param_meaning.object_behaviour_heads`: the argument may mean something else there; a
    behaviour of the same name and arguments whose body differs is held to the same meaning)."""
    fixed = fixed_quantities(script)
    if not fixed:
        return {}
    new_uses = quantity_uses(script)
    set_by_parameter = {where for by_slot in new_uses.values() for where in by_slot}
    old_heads, new_heads = object_behaviour_heads(parent), object_behaviour_heads(script)
    found: Dict[str, str] = {}
    for name, (obj, _, slot), where, words, function, tolerance, target in _key_checks(parent, script, keyed, actor):
        value = fixed.get(where) if where not in set_by_parameter else None
        if value is None and where[2] in _OPPOSITE:
            value = _flipped(script, where, fixed, set_by_parameter)
        if name in found or value is None:
            continue
        if slot.startswith("behavior:") and not target and old_heads.get(obj) != new_heads.get(where[0]):
            continue  # another behaviour: its argument of that name may mean something else
        parts = read_support(value)
        quantity = function.at(float(numeric[name]))
        if parts is not None and not support_contains(parts, quantity, tolerance=tolerance):
            made = (f", which the parent's {function.text} makes {_exact(quantity)}"
                    if function.text != f"globalParameters.{name}" else "")
            found[name] = (f"{words}, which the new script fixes at {value} without a parameter, while the "
                           f"failing {name} = {_exact(float(numeric[name]))}{made} (held within "
                           f"{_exact(round(tolerance, 12))})")
    return found


_OPPOSITE = {"longitudinal": "longitudinal:behind", "longitudinal:behind": "longitudinal"}
"""A distance ahead and a distance behind: each is the other read with its sign flipped (:func:`_flipped`)."""


def _flipped(script: str, where: Tuple[str, str, str], fixed: Mapping[Tuple[str, str, str], str],
             set_by_parameter: Any) -> Optional[str]:
    """The distance ``where`` (an object's distance ahead or behind) as the new script fixes it in the opposite
    direction (``ahead of ego by Range(-60, -50)`` for a distance behind): ``-(d) - lengths``, the two forms measuring
    from opposite faces (:func:`~dv2s_gym.mining.param_meaning.lengths_along`); ``None`` when it is not fixed so or
    the lengths are not known."""
    obj, kind, slot = where
    opposite = (obj, kind, _OPPOSITE[slot])
    if opposite not in fixed or opposite in set_by_parameter:
        return None
    lengths = lengths_along(script, obj)
    return None if lengths is None else f"-({fixed[opposite]}) - {lengths:.12g}"


def _key_placement_unread(parent: str, script: str, keyed: Mapping[str, Sequence[Tuple[str, str, str, str]]],
                          out: Mapping[str, Any], actor: Optional[str] = None) -> Dict[str, str]:
    """``{key parameter: its quantity and how the new script places the actor}`` for each key parameter that sets
    where an actor (not the ego) is, a distance ahead, behind or to a side (the parent's slot), when that actor has a
    counterpart in the new script (:func:`_counterpart_finder`) whose placement does not give that quantity: not
    compared, not listed already (``key_not_compared``, ``key_fixed_outside``), and not fixed by the new script in
    that direction (or, for a distance ahead or behind, the opposite one: :func:`_flipped`). The new script then places
    the actor by another quantity or form (a vector in the world's frame, an offset along another direction, a
    distance to the side for one ahead, a distance in the opposite direction set by a parameter of its own), and the
    failing value cannot be checked: a rejection, whatever share of the parameters was compared."""
    done = set(out["compared"]) | set(out.get("key_not_compared") or {}) | set(out.get("key_fixed_outside") or {})
    fixed = fixed_quantities(script)
    counterpart = _counterpart_finder(parent, script, actor)
    placed = placements(script)
    found: Dict[str, str] = {}
    for name in sorted(set(keyed) - done):
        for obj, kind, slot, words in keyed[name]:
            other = counterpart(obj, kind)
            if obj == "ego" or slot.split(":", 1)[0] not in ("longitudinal", "lateral") or other is None:
                continue
            if any((other[0], other[1], s) in fixed for s in {slot, _OPPOSITE.get(slot, slot)}):
                continue
            how = "; ".join(placed.get(other[0], [])) or "no placement"
            found[name] = (f"{words}: the new script places its {other[1]} {other[0]} by {how}, "
                           f"{_unread_form(placed.get(other[0], []), slot)}")
            break
    return found


def _unread_form(specifiers: Sequence[str], slot: str) -> str:
    """Why a placement (``specifiers``) gives no reading of the quantity ``slot``, in words."""
    text = " ".join(specifiers)
    if slot.startswith("longitudinal") and re.search(r"\b(left|right) of\b", text):
        return "a distance to the side, not along the ego's heading"
    side = {"lateral:left": "right", "lateral:right": "left"}.get(slot)
    if side and re.search(rf"\b{side} of\b", text):
        return f"a distance to the {side}, the other side"
    if re.search(r"\boffset\s+along\b", text):
        return "an offset along a direction the judge does not read as the reference's heading or the road's"
    if re.search(r"\.position\b|\bVector\s*\(|\bat\s+\(?\s*\d", text):
        return ("a point in the world's frame: how far ahead of or beside the ego it lies depends on the ego's "
                "heading")
    if re.search(r"\b(ahead of|behind)\b", text):
        return "a distance in the other direction set by a parameter of its own or a form the judge does not read"
    return "a placement from which the judge reads no distance in that direction"


def _key_overridden(parent: str, script: str, keyed: Mapping[str, Sequence[Tuple[str, str, str, str]]],
                    numeric: Mapping[str, float], actor: Optional[str] = None) -> Dict[str, str]:
    """``{key parameter: the key quantity and the statement}`` for each key parameter whose key quantity is a
    behaviour argument that the new script's behaviour assigns anew in its body
    (:func:`~dv2s_gym.mining.param_meaning.behaviour_overrides`) where the parent's does not do so alike: the
    parameter passed there does not decide what the behaviour uses. An override to a value
    (``extraSpeed = 25``) that holds the failing value's quantity within :data:`FIXED_TOLERANCE` is no rejection."""
    overrides = behaviour_overrides(script)
    if not overrides:
        return {}
    old_overrides = behaviour_overrides(parent)
    found: Dict[str, str] = {}
    for name, old_where, where, words, function, tolerance, _ in _key_checks(parent, script, keyed, actor):
        statement = overrides.get(where)
        if name in found or statement is None or old_overrides.get(old_where) == statement:
            continue
        value = statement.split("=", 1)[1].strip() if re.match(r"^\w+\s*=", statement) else None
        parts = read_support(value) if value is not None else None
        quantity = function.at(float(numeric[name]))
        if parts is not None and support_contains(parts, quantity, tolerance=tolerance):
            continue
        found[name] = (f"{words}: the new script's behaviour assigns that argument anew ({statement}), so the "
                       f"value passed does not decide it (failing {name} = {_exact(float(numeric[name]))})")
    return found


def _compare_jointly(parent: str, script: str, keyed: Mapping[str, Sequence[Tuple[str, str, str, str]]],
                     numeric: Mapping[str, float], out: Dict[str, Any], actor: Optional[str] = None) -> None:
    """Compare jointly each key parameter the judge could not compare although the new script sets its key quantity
    by parameters of its own (``out["key_not_compared"]``) when both scripts set that quantity by expressions of
    parameters, numbers and inline ``Range``s in the same frame (the same slot; a placement along a lane in the same
    form, :func:`~dv2s_gym.mining.scenic_values.placement_parts`): the parent's expression at the failing values
    (all of them failing parameters, and more than the parameter alone: a quantity the parent sets as a function of
    the parameter alone is compared as a parameter) gives the failing quantity; the new expression's interval
    (:func:`~dv2s_gym.mining.scenic_values.joint_interval`) holds each of its parameters that stands for a compared
    failing parameter (compared bare, by name or meaning) at that failing value and lets the others range over
    their ranges (each quantity on its own: a parameter of the new script that sets two of them may take one value
    for one and another for the other): ``ego_speed * (first_arrival + ego_gap_time)`` with the failing ego_speed and the two times over
    their ranges against the parent's ``ego_distance``. The parameter then moves to ``compared`` (``"jointly"``: the
    quantity), inside or outside (a rejection) like any other. Updates ``out``."""
    missing = out.get("key_not_compared") or {}
    if not missing:
        return  # (a parameter named as a failing one but not compared means something else: it is not let range)
    old_uses, new_uses = quantity_uses(parent), quantity_uses(script)
    counterpart = _counterpart_finder(parent, script, actor)
    script_ranges = _script_ranges(script)
    values: Dict[str, Tuple[float, float]] = {}
    standing = {comparison.get("script_name", name): comparison for name, comparison in out["compared"].items()}
    for param in script_parameters(script):
        if param in standing:
            comparison = standing[param]
            if not any(field in comparison for field in ("expression", "support")):
                values[param] = (comparison["value"], comparison["value"])
        elif param in script_ranges and param not in _script_supports(script) and param not in numeric:
            values[param] = tuple(script_ranges[param])
    failing = {name: (float(value), float(value)) for name, value in numeric.items()}
    for name in sorted(missing):
        for obj, kind, slot, words in keyed[name]:
            other = counterpart(obj, kind)
            if other is None:
                continue
            old_texts = {(q is None, text) for _, q, text in old_uses.get(name, {}).get((obj, kind, slot), ())}
            new_texts = {(q is None, text) for by_slot in new_uses.values()
                         for _, q, text in by_slot.get((other[0], other[1], slot), ())}
            if len(old_texts) != 1 or len(new_texts) != 1:
                continue
            (old_whole, old_text), (new_whole, new_text) = next(iter(old_texts)), next(iter(new_texts))
            if not old_whole:
                continue  # the parent's quantity is a function of the parameter alone: compared as a parameter
            if "pointAlongBy" in new_text and not new_whole:
                continue  # a placement read from a reference point on one side: not the same frame
            (old_frame, old_value), (new_frame, new_value) = placement_parts(old_text), placement_parts(new_text)
            if old_frame != new_frame:
                continue
            quantity = joint_interval(old_value, failing)
            interval = joint_interval(new_value, values)
            if quantity is None or quantity[0] != quantity[1] or interval is None:
                continue
            comparison = {"value": float(numeric[name]), "range": list(interval), "interval": list(interval),
                          "quantity": quantity[0], "expression": new_value, "parent_expression": old_value,
                          "jointly": words}
            missing.pop(name)
            out["not_comparable"].pop(name, None)
            out["not_in_script"] = [n for n in out["not_in_script"] if n != name]
            out["compared"][name] = comparison
            out["compared"] = dict(sorted(out["compared"].items()))
            if not _contains(name, comparison):
                out["outside"] = sorted(set(out["outside"]) | {name})
            break


def _key_set_otherwise(parent: str, script: str, keyed: Mapping[str, Sequence[Tuple[str, str, str, str]]],
                       out: Mapping[str, Any]) -> Dict[str, str]:
    """``{key parameter not comparable: the quantity and how the new script sets it}`` for each key parameter the
    judge could not compare although the new script sets one of its key quantities (the same quantity of the paired
    object) with a parameter of its own, one that stands for no compared failing parameter (``g * g``, ``10 / g``,
    ``min(g, 3)``, ``e + 100``, a ``Normal``): the new script then decides that quantity by a parameter the judge
    cannot check. A key quantity the new script sets with no parameter of its own (a number, a random term, a
    compared parameter alone) or not at all is not listed: it is no comparison the judge failed, it counts within
    :data:`COMPARED_SHARE`."""
    unchecked = out["not_comparable"]
    if not any(name in unchecked for name in keyed):
        return {}
    paired = {comparison.get("script_name", name) for name, comparison in out["compared"].items()}
    objects = counterpart_objects(parent, script)
    new_uses = quantity_uses(script)
    found: Dict[str, str] = {}
    for name in sorted(keyed):
        if name not in unchecked:
            continue
        for obj, kind, slot, words in keyed[name]:
            other = objects.get((obj, kind))
            if other is None:
                continue
            own = sorted({(param, text) for param, by_slot in new_uses.items() if param not in paired
                          for (o, k, s), items in by_slot.items() if (o, k, s) == (other[0], other[1], slot)
                          for _, _, text in items})
            if own:
                found[name] = (f"{words}, which the new script sets by {own[0][1]} (its own parameter "
                               f"{own[0][0]}): {unchecked[name]}")
                break
    return found


def _script_ranges(script: str) -> Dict[str, Tuple[float, float]]:
    """``{parameter: (low, high)}`` of the script's numeric parameters: :func:`scenario_bank.dedup.param_ranges`'s
    forms, the affine expressions of ``Range``/``Uniform``/numbers
    :func:`~dv2s_gym.mining.scenic_values.read_interval` reads, and ``Normal(mean, sd)`` read as
    ``mean ± NORMAL_SPREAD * sd`` (:data:`NORMAL_SPREAD`)."""
    ranges: Dict[str, Tuple[float, float]] = {}
    for name, text in script_parameters(script).items():
        interval = read_interval(text)
        if interval is None:
            interval = _normal_interval(text)
        if interval is not None:
            ranges[name] = interval
    ranges.update(param_ranges(script))
    for name, parts in _script_supports(script).items():
        ranges.setdefault(name, support_hull(parts))
    return ranges


NORMAL_SPREAD = 3.0
"""A parameter drawn from ``Normal(mean, sd)`` is read as the interval ``mean ± NORMAL_SPREAD * sd``: a normal draw
falls there 997 times in 1000, so a failing value inside is one the new script draws in practice, and one outside
is one it almost never draws."""

_NORMAL = re.compile(r"^\s*Normal\s*\(\s*(-?\d+(?:\.\d+)?)\s*,\s*(\d+(?:\.\d+)?)\s*\)\s*(#.*)?$")


def _normal_interval(text: str) -> Optional[Tuple[float, float]]:
    """``(mean - NORMAL_SPREAD * sd, mean + NORMAL_SPREAD * sd)`` for ``Normal(mean, sd)`` of numbers (sd > 0), else
    ``None``."""
    match = _NORMAL.match(text)
    if match is None or float(match.group(2)) <= 0:
        return None
    mean, spread = float(match.group(1)), NORMAL_SPREAD * float(match.group(2))
    return mean - spread, mean + spread


def _script_supports(script: str) -> Dict[str, List[Any]]:
    """``{parameter: its values part by part}`` (:func:`~dv2s_gym.mining.scenic_values.read_support`) of the
    script's parameters whose distribution is not one interval: ``Uniform(5, 9)`` takes 5 or 9, never 6;
    ``DiscreteRange(5, 9)`` integers only."""
    supports: Dict[str, List[Any]] = {}
    for name, text in script_parameters(script).items():
        parts = read_support(text)
        if parts is None:
            continue
        single = len(parts) == 1 and (parts[0][0] == "interval" or (parts[0][0] == "points" and len(parts[0][1]) == 1)
                                      or (parts[0][0] == "grid" and parts[0][3] == 1))
        if not single:
            supports[name] = [list(part) for part in parts]
    return supports


def _contains(name: str, comparison: Mapping[str, Any]) -> bool:
    """Whether the comparison's quantity (the failing value, or its quantity in the parent) is one the new script
    produces: inside the interval (``interval`` or ``range``) and, for a distribution that is not one interval
    (``support``), among its values (through the new script's ``expression`` when there is one)."""
    low, high = comparison.get("interval") or comparison["range"]
    quantity = float(comparison.get("quantity", comparison["value"]))
    if not low - 1e-9 <= quantity <= high + 1e-9:
        return False
    support = comparison.get("support")
    if not support:
        return True
    function = None
    if comparison.get("expression"):
        function = quantity_of(comparison["expression"], comparison.get("script_name", name))
        if function is None:
            return True  # read at the comparison; unreachable
    return support_contains([tuple(part) for part in support], quantity, function)


def _through_quantities(parent: str, script: str, compared: Dict[str, Any],
                        key_meanings: Optional[Mapping[str, Any]] = None) -> Dict[str, str]:
    """Each compared parameter is checked on every quantity it sets in both scripts (the same kind of object, the
    ego or not, and slot; :func:`~dv2s_gym.mining.param_meaning.quantity_uses`), bare uses included: the failing
    value's quantity in the parent (through the parent's own expression) against the interval the new script's
    expression takes over the counterpart's range. A quantity the judge cannot read on one side but can on the
    other (``ego_speed + extra`` against ``e + 100``, ``g`` against ``min(g, 3)``), that neither side reads and
    the two set differently, or that several objects of a kind set with different expressions, cannot be
    compared. The first quantity outside is kept in the comparison (``expression``, ``interval``, ``quantity``,
    ``parent_expression``, ``where``), else, with every quantity inside, the first set through an expression;
    with none outside and one that cannot be compared, the parameter leaves ``compared``, unless one of its key
    quantities (``key_meanings``: ``{parameter: {(the ego?, kind, slot)}}``, the ego's or the key actor's) was
    checked: the parameter is then compared on it (its key quantities first, in the reason too) and each quantity
    that could not be is listed (``quantities_not_compared`` in its comparison). Returns ``{parameter: why it is not
    comparable}``."""
    old_all, new_all = quantity_uses(parent), quantity_uses(script)

    def by_meaning(found: Mapping[Tuple[str, str, str], Any]) -> Dict[Tuple[bool, str, str], List[Any]]:
        keyed: Dict[Tuple[bool, str, str], List[Any]] = {}
        for (name, kind, slot), items in sorted(found.items()):
            keyed.setdefault((name == "ego", kind, slot), []).extend((name,) + tuple(item) for item in items)
        return keyed

    why: Dict[str, str] = {}
    for name, comparison in list(compared.items()):
        target = comparison.get("script_name", name)
        old, new = by_meaning(old_all.get(name, {})), by_meaning(new_all.get(target, {}))
        low, high = comparison["range"]
        outside, shown, unreadable, ambiguous, checked, key_checked = None, None, None, None, False, False
        own_keys = set((key_meanings or {}).get(name, ()))
        shared = sorted(set(old) & set(new), key=lambda key: (key not in own_keys, key))
        for key in shared:
            where = _quantity_words(key, new[key])
            checks, problem = _quantity_checks(old[key], new[key], name, comparison)
            if problem in (AMBIGUOUS, SET_OTHERWISE):  # left aside when another quantity is checked
                ambiguous = ambiguous or f"the {where}: {problem}"
                continue
            if problem is not None:
                unreadable = unreadable or f"the {where}: {problem}"
                continue
            checked = True
            key_checked = key_checked or key in own_keys
            for found, inside in checks:
                if len(shared) > 1:  # which of its quantities, in the reason
                    found["where"] = where
                if not inside and outside is None:
                    outside = found
                if inside and shown is None and "expression" in found:
                    shown = found
        if outside is not None:
            comparison.update(outside)
        elif unreadable is not None and key_checked:
            # compared on its key quantity; the quantity the judge could not read is listed, it does not cancel it
            comparison["quantities_not_compared"] = f"the quantity it also sets cannot be compared: {unreadable}"
            if shown is not None:
                comparison.update(shown)
        elif unreadable is not None or (ambiguous is not None and not checked):
            why[name] = f"the quantity it sets cannot be compared: {unreadable or ambiguous}"
            del compared[name]
        elif shown is not None:
            comparison.update(shown)
    return why


def _quantity_checks(old: Sequence[Tuple[Any, ...]], new: Sequence[Tuple[Any, ...]], name: str,
                     comparison: Mapping[str, Any]) -> Tuple[List[Tuple[Dict[str, Any], bool]], Optional[str]]:
    """``([(comparison fields, inside?)], None)`` for one quantity the parameter sets in both scripts (``old`` and
    ``new``: ``(object, how, quantity or None, text)`` of each use there), or ``([], why it cannot be compared)``:
    one object on each side whose expressions the judge reads, or does not read but sets it the same way (the
    parameter's own range then); several objects of the kind, or several expressions, only when both scripts set
    it with the same expressions (each then checked)."""
    def keys(uses: Sequence[Tuple[Any, ...]]) -> Dict[Any, Any]:
        return {(q.key if q is not None else ("unread", how)): q for _, how, q, _ in uses}

    value, (low, high) = comparison["value"], comparison["range"]
    old_keys, new_keys = keys(old), keys(new)
    if len(old_keys) == 1 and len(new_keys) == 1:
        pairs = [(next(iter(old_keys.items())), next(iter(new_keys.items())))]
    elif set(old_keys) == set(new_keys):
        pairs = [((k, old_keys[k]), (k, new_keys[k])) for k in sorted(old_keys, key=repr)]
    elif len({use[0] for use in old}) > 1 or len({use[0] for use in new}) > 1:
        return [], AMBIGUOUS
    else:
        pairs = []
    checks: List[Tuple[Dict[str, Any], bool]] = []
    for (old_key, before), (new_key, after) in pairs:
        if before is None and after is None and old_key == new_key:
            # neither read, set the same way (the same direction and constant terms): the parameter's own range
            checks.append(({}, _contains(name, comparison)))
            continue
        if before is None and after is None:
            return [], SET_OTHERWISE  # neither read, set differently: left aside when another quantity is checked
        if before is None or after is None:
            pairs = []
            break
        quantity = before.at(value)
        start, end = after.over(low, high)
        found: Dict[str, Any] = {}
        if (before.key, after.key) != (_BARE, _BARE):
            found = {"expression": after.text, "interval": [start, end], "quantity": quantity}
            if before.key != _BARE:
                found["parent_expression"] = before.text
        checks.append((found, _contains(name, {**comparison, **found})))
    if not pairs:
        shown = lambda uses: "; ".join(sorted({text for _, _, _, text in uses}))  # noqa: E731
        return [], (f"the parent sets it by {shown(old)}, the new script by {shown(new)}, and the judge cannot "
                    "read both as the same known function of the parameter")
    return checks, None


_BARE = ("affine", 1.0, 0.0)
AMBIGUOUS = ("several objects of that kind set it with different expressions: which stands for which is not "
             "known")
SET_OTHERWISE = ("the two scripts compute it differently, each with more than the parameter, and the judge reads "
                 "neither")


def _quantity_words(key: Tuple[bool, str, str], uses: Sequence[Tuple[Any, ...]]) -> str:
    """``"ego's speed"``, ``"Car car1's behaviour argument gap"``: the quantity ``key`` names in the new script."""
    ego, kind, slot = key
    quantity = (f"behaviour argument {slot.split(':', 1)[1]}" if slot.startswith("behavior:")
                else f"{slot.split(':', 1)[1]} property" if slot.startswith("with:") else f"{slot} placement"
                if slot in ("longitudinal", "lateral", "offset", "position") else slot)
    names = sorted({use[0] for use in uses})
    return f"ego's {quantity}" if ego else f"{kind} {', '.join(names)}'s {quantity}"


def _by_meaning(parent: str, script: str, numeric: Mapping[str, float], compared: Dict[str, Any],
                absent: List[str], ranges: Mapping[str, Any],
                key_meanings: Optional[Mapping[str, Any]] = None) -> Dict[str, str]:
    """:func:`compare_parameters` given the parent script: a name match that does not mean the same (another actor,
    quantity, direction or constant term, or reaching no object) is not comparable; the rest are paired by meaning
    (their counterpart must be read as an interval); no object of the new script may stand for two parent actors.
    Updates ``compared``; returns ``{failing parameter: why it is not comparable}``."""

    declared, supports = script_parameters(script), _script_supports(script)
    why: Dict[str, str] = {}
    for name in list(compared):
        mismatch = name_mismatch(parent, script, name, compared[name].get("script_name", name))
        if mismatch:
            why[name] = mismatch
            del compared[name]
    folded = {n.casefold(): n for n in declared}
    for name in list(absent):
        other = name if name in declared else folded.get(str(name).casefold())
        if other is not None:
            why[name] = (f"its counterpart {other} in the new script has a distribution the judge cannot read as an "
                         f"interval ({declared[other]})")
            absent.remove(name)
    named = {compared[name].get("script_name", name) for name in compared} | {
        folded.get(str(n).casefold(), n) for n in why}
    mapped = meaning_map(parent, script, absent, [n for n in sorted(declared) if n not in named])
    for name, pair in mapped["pairs"].items():
        if pair["target"] not in ranges:
            why[name] = (f"its counterpart {pair['target']} in the new script ({_basis_text(pair)}) has a "
                         f"distribution the judge cannot read as an interval ({declared[pair['target']]})")
            continue
        compared[name] = {"value": float(numeric[name]), "range": [float(v) for v in ranges[pair["target"]]],
                          "script_name": pair["target"], "by": "meaning", "basis": _basis_text(pair)}
        if pair["target"] in supports:
            compared[name]["support"] = supports[pair["target"]]
    why.update({name: f"no parameter of the new script means the same ({reason})"
                for name, reason in mapped["unpaired"].items()})
    why.update({name: "the new script defines no numeric parameter of that name" for name in absent
                if name not in mapped["pairs"] and name not in mapped["unpaired"]})
    why.update(_tied_twice(parent, script, compared))
    why.update(_through_quantities(parent, script, compared, key_meanings))
    return why


def _tied_twice(parent: str, script: str, compared: Dict[str, Any]) -> Dict[str, str]:
    """The compared parameters whose object in the new script is tied (by another compared parameter) to another
    actor of the parent too: one actor cannot stand for two; they leave ``compared``, each with why."""

    ties: Dict[str, Dict[str, List[str]]] = {}
    for name, comparison in compared.items():
        for old, new in tied_objects(parent, script, name, comparison.get("script_name", name)):
            ties.setdefault(new, {}).setdefault(old, []).append(name)
    why: Dict[str, str] = {}
    for new, olds in ties.items():
        if len(olds) > 1:
            for names in olds.values():
                for name in names:
                    why[name] = (f"the new script's {new} would stand for the parent's {' and '.join(sorted(olds))}: "
                                 "one actor cannot be two")
    for name in why:
        compared.pop(name, None)
    return why


def _parent_script(record: Mapping[str, Any], bank_dir: Optional[PathLike]) -> Optional[str]:
    """The script of the bank scenario the failure ran (``None`` when it cannot be read: the judge then compares by
    name only)."""
    try:
        return (Bank(bank_dir) if bank_dir else Bank()).get(record["scenario"]).script
    except (BankError, OSError):  # the comparison by meaning is an addition; without the parent, names only
        return None


def _basis_text(pair: Mapping[str, Any]) -> str:
    """What a parameter paired by meaning sets, in words: ``"the car's behaviour argument gap (car1; cutter in the
    parent)"``."""
    slot = str(pair["slot"])
    quantity = (f"behaviour argument {slot.split(':', 1)[1]}" if slot.startswith("behavior:")
                else f"{slot.split(':', 1)[1]} property" if slot.startswith("with:") else f"{slot} placement"
                if slot in ("longitudinal", "lateral", "offset", "position") else slot)
    what = "the ego" if pair["object"] == "ego" else f"the {pair['kind']} {pair['object']}"
    parent = "" if pair["object"] == "ego" else f" ({pair['source_object']} in the parent)"
    return f"{what}'s {quantity}{parent}" + (", as a factor" if pair["how"] == "scaled" else "")


def _outside_text(name: str, comparison: Mapping[str, Any]) -> str:
    """``name = value outside low..high``, every number exact (10.00001 against 5..10 is not "10"), so a value
    outside never prints as one inside."""
    low, high = comparison["range"]
    spelled = f" (the script's {comparison['script_name']})" if comparison.get("script_name") else ""
    if comparison.get("by") == "meaning":
        spelled = f" (the script's {comparison['script_name']}: {comparison.get('basis')})"
    where = f" (as the {comparison['where']})" if comparison.get("where") else ""
    if comparison.get("jointly"):
        return (f"{name} = {_exact(float(comparison['value']))}, which the parent's {comparison['parent_expression']} "
                f"makes {_exact(float(comparison['quantity']))} as {comparison['jointly']}, outside "
                f"{_exact(float(comparison['interval'][0]))}..{_exact(float(comparison['interval'][1]))}, the "
                f"interval the new script's {comparison['expression']} takes with its parameters that stand for "
                f"compared ones at their failing values and the others over their ranges")
    if comparison.get("interval"):
        own = comparison.get("script_name", name)
        parent = (f", which the parent's {comparison['parent_expression']} makes "
                  f"{_exact(float(comparison['quantity']))}," if comparison.get("parent_expression") else "")
        start, end = comparison["interval"]
        if comparison.get("support") and start - 1e-9 <= float(comparison["quantity"]) <= end + 1e-9:
            return (f"{name}{spelled} = {_exact(float(comparison['value']))}{parent} not among the values the new "
                    f"script's {comparison['expression']} takes with {own} one of "
                    f"{support_text(comparison['support'])}{where}")
        return (f"{name}{spelled} = {_exact(float(comparison['value']))}{parent} outside "
                f"{_exact(float(start))}..{_exact(float(end))}, the interval the new script's "
                f"{comparison['expression']} takes with {own} in {_exact(float(low))}..{_exact(float(high))}{where}")
    if comparison.get("support") and low - 1e-9 <= float(comparison["value"]) <= high + 1e-9:
        return (f"{name}{spelled} = {_exact(float(comparison['value']))} not among the values "
                f"{comparison.get('script_name', name)} takes ({support_text(comparison['support'])}){where}")
    return (f"{name}{spelled} = {_exact(float(comparison['value']))} outside "
            f"{_exact(float(low))}..{_exact(float(high))}{where}")


def _exact(number: float) -> str:
    """``number`` short (``10``) when that is exact, else every digit it takes (a range end is never rounded)."""
    short = f"{number:g}"
    return short if float(short) == number else repr(number)


def _census_text(census: Mapping[str, int]) -> str:
    total = sum(census.values())
    return f"{total} actor{'' if total == 1 else 's'}" + (
        f" ({', '.join(f'{kind} {n}' for kind, n in census.items())})" if census else "")


_KEY_REJECTIONS = (
    ("key_fixed_outside", "that the new script fixes must hold the failing value, and it does not"),
    ("key_overridden", "that the new script passes to a behaviour must be what the behaviour uses, and the behaviour "
                       "assigns it anew"),
    ("key_unread", "is placed by another quantity or form, from which the judge cannot read it, so the failing value "
                   "is not checked"),
)
"""The key-parameter findings of :func:`compare_parameters` that reject a conversion, each with what is wrong, in the
order the rejection reasons list them."""


def _judge(out: Mapping[str, Any], interaction: Mapping[str, Any], source_failure: Mapping[str, Any],
           threshold: float) -> List[_Rejected]:
    """The checks a converted script must pass, each failing one a rejection with its own stage:
    ``interaction`` (its runs show the failure's actor doing its manoeuvre), ``reproduction`` (the policy
    fails the same way with the same kind of actor), ``avoidability`` (the reference driver drives most
    episodes without any collision, off-road or stall), ``actors`` (the script's actors are the failure's, kind
    for kind: none missing, the adversary above all, none added; ``out["actors"]``, :func:`compare_actors`) and
    ``parameters`` (the script's ranges of the failure's parameters contain the failing values;
    ``out["parameters"]``, :func:`compare_parameters`)."""
    found: List[_Rejected] = []
    repro = out["reproduction"]
    k = repro["k"]
    what = f"{interaction.get('kind')} ({', '.join(interaction.get('manoeuvres') or []) or 'no manoeuvre'})"
    if interaction.get("kind") and repro["interaction_shown"] / k < threshold:
        found.append(_Rejected("interaction", f"the new scenario's runs show the failure's {what} in "
                                              f"{repro['interaction_shown']} of {k} episodes "
                                              f"(share {repro['interaction_shown'] / k:.2f} < threshold {threshold:g})"))
    if repro["rate"] < threshold:
        with_kind = f" with a {interaction['kind']}" if interaction.get("kind") else ""
        found.append(_Rejected("reproduction", f"the new scenario reproduced the {source_failure['type']} failure"
                                               f"{with_kind} in {repro['reproduced']} of {k} episodes "
                                               f"(rate {repro['rate']:.2f} < threshold {threshold:g})"))
    avoid = out.get("avoidability")
    if avoid and not avoid["avoided_rate"] > 0.5:
        classes = ", ".join(f"{label} {n}" for label, n in (avoid.get("failures") or {}).items())
        found.append(_Rejected("avoidability", f"the reference driver {avoid['reference']} failed in "
                                               f"{avoid['failed']} of {avoid['k']} episodes of the new scenario"
                                               + (f" ({classes})" if classes else "")
                                               + "; it must drive most of them without any collision, "
                                                 "off-road or stall"))
    actors = out.get("actors")
    if actors and not actors.get("same"):
        adversary = actors.get("adversary")
        problems = []
        if adversary and adversary in actors.get("missing", {}) and not actors["script"].get(adversary):
            problems.append(f"the failure's adversary, a {adversary}, is missing")
        problems += [f"{n} {kind} fewer" for kind, n in actors.get("missing", {}).items()
                     if not (kind == adversary and not actors["script"].get(adversary))]
        problems += [f"{n} {kind} more" for kind, n in actors.get("extra", {}).items()]
        if not problems and actors.get("runs") and 2 * actors.get("runs_matching", 0) <= actors["runs"]:
            problems.append(f"the failure's actors, kind for kind, in only {actors['runs_matching']} of "
                            f"{actors['runs']} runs (a majority needed)")
        found.append(_Rejected("actors", f"the failure's scene has {_census_text(actors['failure'])}, the new "
                                         f"scenario's {_census_text(actors['script'])}: {', '.join(problems)}"))
    parameters = out.get("parameters")
    for field, problem in _KEY_REJECTIONS:
        listed = (parameters or {}).get(field) or {}
        if listed:
            reasons = "; ".join(f"{name} ({why})" for name, why in sorted(listed.items()))
            found.append(_Rejected("parameters", f"a key quantity (of the failure's interaction) {problem}: {reasons}"))
    unchecked_key = _key_not_compared(parameters)
    if unchecked_key:
        found.append(_Rejected("parameters", unchecked_key))
    few = _too_few_compared(parameters)
    if few:
        found.append(_Rejected("parameters", few))
    if parameters and parameters.get("outside"):
        unchecked = parameters.get("not_comparable") or {}
        found.append(_Rejected("parameters", "the new scenario's ranges do not contain the failing values: " + ", ".join(
            _outside_text(name, parameters["compared"][name]) for name in parameters["outside"])
            + (f" (not compared: {not_compared_names_text(unchecked)})" if unchecked else "")))
    return found


COMPARED_SHARE = 0.5
"""The judge rejects a new scenario when it could compare fewer than this share of the failure's parameters with
the new script's ranges: with most of them unchecked, a script could drop or change what made the scene fail and
still pass (docs/mining.md). Whatever the share, a key parameter (one that sets a quantity of the failure's
interaction: the ego's or the key actor's, ``compare_parameters``' ``"key"``) that the new script sets with a
parameter of its own must be compared and contain the failing value: one not comparable is a rejection with its
reason (``"key_not_compared"``, :func:`_key_not_compared`). Within the share may go unchecked: parameters of other
actors (traffic beside the interaction), and key quantities the new script fixes without a parameter of its own or
leaves out (a generated script parameterises a scene its own way: the rule-based generator leaves most behaviour
timings fixed), as long as a fixed key quantity holds the failing value (``"key_fixed_outside"``,
:func:`_key_fixed_outside`); a key actor's placement the new script writes in a form the judge cannot read is a
rejection (``"key_unread"``, :func:`_key_placement_unread`)."""


def _key_not_compared(parameters: Optional[Mapping[str, Any]]) -> Optional[str]:
    """The rejection for key parameters (``parameters["key"]``) the judge could not compare, each with the quantity
    it sets and why, or ``None``."""
    if not parameters:
        return None
    missing = parameters.get("key_not_compared") or {}
    if not missing:
        return None
    return ("a key parameter (it sets a quantity of the failure's interaction) that the new script sets with a "
            "parameter of its own must be compared, and the judge could not: " + "; ".join(
                f"{name} ({why})" for name, why in sorted(missing.items())))


def _too_few_compared(parameters: Optional[Mapping[str, Any]]) -> Optional[str]:
    """The rejection for a comparison of fewer than :data:`COMPARED_SHARE` of the failing parameters, or ``None``."""
    if not parameters:
        return None
    compared, unchecked = parameters.get("compared") or {}, parameters.get("not_comparable") or {}
    total = len(compared) + len(unchecked)
    if not total or len(compared) >= COMPARED_SHARE * total:
        return None
    return (f"only {len(compared)} of the failure's {total} parameters could be compared with the new script, fewer "
            f"than half: " + "; ".join(f"{name}: {reason}" for name, reason in sorted(unchecked.items())))


def _family(parent: str, failure_type: str):
    """Whether a bank entry is a converted (not replay) mined entry from ``parent`` with a ``failure_type`` failure."""
    def same(entry) -> bool:
        source = entry.source
        return (source.mined and not source.is_replay and source.parent == parent
                and source.failure_type == failure_type)
    return same


def _link(bank, name: str, fields: Mapping[str, Any]) -> None:
    bank.update_source(name, dict(fields))


@dataclasses.dataclass
class _ReplaySource:
    """The failure an exact replay keeps: its failure dict, cluster, the mining run folder, and what the conversion
    read from it so far (its trace, interaction and files: ``None`` when no video was made)."""

    source_failure: Mapping[str, Any]
    cluster: Optional[str]
    run_dir: Path
    source_trace: Any = None
    interaction: Optional[FailureInteraction] = None
    files: Optional[Mapping[str, Path]] = None


def _add_replay(record: Mapping[str, Any], bank, settings: ConversionSettings, source: _ReplaySource
                ) -> Dict[str, Any]:
    """Add the exact replay of the failing scene to ``bank`` (:mod:`dv2s_gym.mining.exact_replay`): the parent
    script (in the settings' ``bank_dir``) narrowed around the failing parameters, checked to replay the recorded
    episode step for step with the settings' ``policy``, ``env_config`` and ``monitor``.
    Returns ``{"entry", "params", "intervals", "not_narrowed", "seed", "trajectory_hash", "e2e_sc", "note"}``
    (``not_narrowed``: ``{parameter: why}`` of those left at the parent's distribution; ``entry`` None,
    with a ``note``, when the narrowed script is the parent itself and the parent is in ``bank``).

    Without a ``source_trace`` (no failure video was made), the replay's own trace stands for it once its
    trajectory hash matches the record's, and is what the entry keeps (``files``: the trace only, no video);
    without an ``interaction`` it is read from that trace. A scene the reference driver failed too
    (:func:`reference_passed`) is not replayed: ``{"entry": None, "note", "not_narrowed": {}}``."""
    if not reference_passed(record):
        failed = ((record.get("reference") or {}).get("failure") or {}).get("type") or "not avoided"
        return {"entry": None, "not_narrowed": {}, "note": f"no replay entry: the reference driver failed this scene "
                                                          f"too ({failed}), so it is no failure the policy could have "
                                                          "avoided"}
    parent = (Bank(settings.bank_dir) if settings.bank_dir else Bank()).get(record["scenario"])
    params = dict(record.get("params") or {})
    script, intervals, not_narrowed, trace, failure, source = _run_narrowed(record, parent, params, settings, source)
    replay = {"params": params, "intervals": intervals, "not_narrowed": not_narrowed, "seed": int(record["seed"]),
              "trajectory_hash": record["result"]["trajectory_hash"],
              "policy": _policy_name(settings.policy), **replay_versions(settings.policy)}
    out = {"entry": None, **replay, "failure": failure, "note": None,
           "e2e_sc": e2e_sc(elements_from_trace(source.source_trace), elements_from_trace(trace))}
    _bank_replay(out, record, bank, parent, script, replay, settings, source)
    return out


def _run_narrowed(record: Mapping[str, Any], parent: Any, params: Dict[str, Any], settings: ConversionSettings,
                  source: _ReplaySource) -> tuple:
    """Write the parent narrowed around the failing ``params`` and replay the recorded episode on it:
    ``(script, intervals, not_narrowed, trace, failure, source)``, ``source`` completed from the replay when it had no trace.
    A replay that diverges is a ``replay`` rejection."""
    script, intervals, not_narrowed = narrowed_script(parent.script, params)
    seed = int(record["seed"])
    expected = record["result"]["trajectory_hash"]
    folder = source.run_dir / "failures" / cluster_slug(source.cluster, record.get("index")) / CONVERSION_DIR
    path = folder / "replay.scenic"
    _write(path, script)
    result, trace, failure = run_replay(path, policy=settings.policy, seed=seed, params=params,
                                        env_config=settings.env_config, monitor=settings.monitor)
    if result.trajectory_hash != expected:
        raise _Rejected("replay", f"the parent {record['scenario']!r} narrowed around the failing parameters does not "
                                  f"replay the failing episode (trajectory hash {result.trajectory_hash[:12]} != "
                                  f"recorded {expected[:12]})")
    if source.source_trace is None:  # the same episode step for step: its trace is the failure's own
        trace.save(folder / ENTRY_TRACE)
        source_failure = source.source_failure
        if failure and failure.get("type") == source_failure.get("type"):
            source_failure = {**failure, **{k: v for k, v in source_failure.items() if v is not None}}
        interaction = source.interaction
        if interaction is None:
            interaction = failure_interaction(trace, source_failure)
        source = dataclasses.replace(source, source_trace=trace, files={ENTRY_TRACE: folder / ENTRY_TRACE},
                                     source_failure=source_failure, interaction=interaction)
    return script, intervals, not_narrowed, trace, failure, source


def _bank_replay(out: Dict[str, Any], record: Mapping[str, Any], bank, parent: Any, script: str,
                 replay: Mapping[str, Any], settings: ConversionSettings, source: _ReplaySource) -> None:
    """Add the narrowed script to ``bank`` as the failure's exact replay entry (``out["entry"]``), or say in
    ``out["note"]`` why there is none."""
    files = dict(source.files or {})
    seed, params, policy = replay["seed"], replay["params"], settings.policy
    source_failure = source.source_failure
    events = interaction_sentence(source.interaction)
    description = (f"{parent.description.strip()} Exact replay of a failure of {_policy_name(policy)}: seed {seed}, "
                   f"parameters narrowed around the failing values"
                   + (f" (not narrowed, drawn as in the parent: {', '.join(sorted(replay.get('not_narrowed') or {}))})"
                      if replay.get("not_narrowed") else "") + "." + (f" {events}" if events else ""))
    provenance = Provenance(kind="mined", parent=record["scenario"], seed=seed, params=params,
                            video=ENTRY_VIDEO if ENTRY_VIDEO in files else None,
                            trace=ENTRY_TRACE if ENTRY_TRACE in files else None, generator="exact replay",
                            policy=_policy_name(policy), failure=dict(source_failure), cluster=source.cluster,
                            run=str(source.run_dir.resolve()), index=record.get("index"),
                            interaction=FailureInteraction.from_dict(source.interaction).to_dict(),
                            replay=dict(replay), e2e_sc=out["e2e_sc"],
                            date=datetime.date.today().isoformat())
    base = replay_name(record["scenario"], source_failure["type"])
    name, n = base, 2
    while name in bank:
        name, n = f"{base}_{n}", n + 1
    try:
        fields = Sidecar(description=description, name=name, elements=parent.elements, map=parent.map,
                         tags=("mined", REPLAY_TAG, source_failure["type"]), source=provenance)
        with warnings.catch_warnings():  # a replay is by construction a near-duplicate of its parent
            warnings.simplefilter("ignore", NearDuplicateWarning)
            entry = bank.add(script, fields, files=files)
        out["entry"] = entry.name
    except DuplicateScenarioError as error:
        existing = bank.get(error.existing).source.replay or {}
        if existing.get("seed") == seed and existing.get("params") == params:
            out["entry"] = error.existing  # this failing scene is in the bank already (a resumed run)
        elif error.existing == record["scenario"]:
            out["note"] = (f"no replay entry: {record['scenario']!r} has no free parameters to narrow, so the failing "
                           f"scene is that scenario itself with seed {seed}")
        else:
            out["note"] = f"no replay entry: {error}"


def replay_failure_entry(record: Mapping[str, Any], run_dir: PathLike, settings: ConversionSettings, *, bank: Any,
                         cluster: Optional[str] = None) -> Dict[str, Any]:
    """Keep one failure exactly, without converting it: only the exact replay entry of the failing scene
    (stage 3 of :func:`convert_failure`, with no video, description or script; the entry keeps the replay's
    trace). Never raises for a bad failure; raises ``WrongTypeError`` when ``settings`` is not a
    :class:`ConversionSettings` with a policy.

    Of ``settings`` the replay reads the ``policy`` that failed, the run's ``env_config``, the ``bank_dir`` holding
    the record's scenario (default the ``bank`` when it holds it, else the shipped bank) and the ``monitor``
    (default the run's ``settings.json``'s).

    Returns ``{"cluster", "index", "scenario", "status": "kept"|"rejected", "replay_entry", "reason",
    "note", "seconds"}`` (and ``replay_not_narrowed`` when kept: ``{parameter: why}`` of those the replay leaves at
    the parent's distribution): ``kept`` with the entry's name, or ``rejected`` with the reason (a replay that
    diverges from the recorded episode, a bad record); ``kept`` with no entry and a ``note`` when the bank
    holds the scene already under another name."""
    _check_settings(settings, "replay_failure_entry")
    start = time.perf_counter()
    run_dir = Path(run_dir)
    cluster = cluster if cluster is not None else record.get("cluster")
    out: Dict[str, Any] = {"cluster": cluster, "index": record.get("index"), "scenario": record.get("scenario"),
                           "status": "rejected", "replay_entry": None, "reason": None, "note": None, "seconds": None}
    try:
        failure = dict(record.get("failure") or {})
        if not failure.get("type"):
            raise _Rejected("input", "the record holds no failure (record['failure'] is empty)")
        if not (record.get("result") or {}).get("trajectory_hash"):
            raise _Rejected("input", "the record holds no trajectory hash to check the replay against")
        if isinstance(bank, (str, os.PathLike)):
            bank = Bank(bank)
        if settings.bank_dir is None and getattr(bank, "root", None) is not None and record.get("scenario") in bank:
            settings = settings.replace(bank_dir=bank.root)
        settings = settings.replace(monitor=_monitor_options(run_dir, settings.monitor))
        replay = _add_replay(record, bank, settings, _ReplaySource(failure, cluster, run_dir))
        out.update(status="kept", replay_entry=replay["entry"], note=replay["note"],
                   replay_not_narrowed=dict(replay.get("not_narrowed") or {}))
    except _Rejected as rejection:
        out["reason"] = str(rejection)
    except SETUP_ERRORS:
        raise
    except Exception as error:  # a bad failure is a rejection, never an exception
        first = (str(error).strip().splitlines() or [""])[0]
        out["reason"] = f"replay: {type(error).__name__}: {first}"[:500]
    if out["reason"]:
        out["reason"] = _in_run(out["reason"], run_dir)
    out["seconds"] = round(time.perf_counter() - start, 3)
    return out


def _stage_error(stage: str, error: BaseException) -> str:
    """A stage's failure as a rejection reason: ``"<stage>: <message>"``, an unexpected error named by its type."""
    if isinstance(error, _Rejected):
        return str(error)
    first = (str(error).strip().splitlines() or [""])[0]
    return f"{stage}: {type(error).__name__}: {first}"[:500]


def _replay_without_video(out: Dict[str, Any], video_error: str, record: Mapping[str, Any], bank,
                          details: Dict[str, Any], settings: ConversionSettings, source: _ReplaySource) -> None:
    """After the video stage failed: keep the exact replay all the same (its own trace stands for the failure's)
    and record both outcomes in ``out``: ``rejections`` holds the video's reason, then the replay's if it
    failed too."""
    out["rejections"] = [_in_run(video_error, source.run_dir)]
    try:
        replay = _add_replay(record, bank, settings, source)
    except SETUP_ERRORS:
        raise
    except Exception as error:
        out["rejections"].append(_in_run(_stage_error("replay", error), source.run_dir))
        return
    out["replay_entry"] = replay["entry"]
    out["replay_not_narrowed"] = dict(replay.get("not_narrowed") or {})
    details["replay"] = replay
    if replay["entry"]:
        _link(bank, replay["entry"], {"converted_rejections": list(out["rejections"])})


def _portable_params(params: Mapping[str, Any]) -> Dict[str, Any]:
    """The sampled parameters as the bank keeps them: a map given by a path becomes its file name (the
    entry's ``map`` names it; shipped maps are found by name), so no path into this machine is kept."""
    out = dict(params)
    if isinstance(out.get("map"), str) and ("/" in out["map"] or os.sep in out["map"]):
        out["map"] = Path(out["map"]).name
    return out


def _mined_name(parent: str, failure_type: str) -> str:
    base = re.sub(r"[^a-z0-9_\-]+", "_", f"mined_{parent}_{failure_type}".lower()).strip("_-")
    return base[:90] or "mined"


def _check_settings(settings: Any, function: str) -> None:
    """Refuse ``settings`` that are not a :class:`ConversionSettings` naming the policy that failed."""
    if not isinstance(settings, ConversionSettings):
        raise WrongTypeError(f"{function} takes its settings as one ConversionSettings, not {type(settings).__name__}")
    if settings.policy is None:
        raise WrongTypeError(f"{function} needs the policy that failed: pass ConversionSettings(policy=<its spec>)")


def convert_failure(record: Mapping[str, Any], run_dir: PathLike, settings: ConversionSettings, *,
                    bank: Any, cluster: Optional[str] = None) -> Dict[str, Any]:
    """Turn one failure record into a bank entry; returns the conversion record (never raises for a bad failure).

    Args:
        record: an episode record of the miner with a ``failure`` (see the mining contract).
        run_dir: the mining run folder; files go to ``failures/<cluster slug>/`` (``failure.webm``,
            ``trace.json.gz``, ``conversion/{description.txt, elements.json, scenario.scenic, report.json}``).
        settings: the :class:`ConversionSettings` (the policy that failed, the backends, the reproduction check,
            the video window, the reference driver...). The video covers ``before`` seconds before the failure
            and ``after`` after it (a stall's clip covers the stall, up to the monitor's ``stall_seconds``, between
            them: :func:`~dv2s_gym.mining.failure_video.write_failure_video`).
        bank: the bank to add to (a :class:`~scenario_bank.bank.Bank` or its folder).
        cluster: the failure's cluster id (default ``record["cluster"]``).

    Raises the model backends' setup errors (:data:`SETUP_ERRORS`), and ``WrongTypeError`` (a ``TypeError``)
    for settings that are not a :class:`ConversionSettings` or name no policy; every other problem is a rejection.

    Returns ``{"cluster", "index", "status": "kept"|"merged"|"rejected", "reason", "stage", "video",
    "description", "script", "reproduction", "e2e_sc", "bank_entry", "merged_into", "seconds",
    "timings", "interaction", "replay_entry", "avoidability", "rejections", "actors", "parameters"}`` (paths
    relative to ``run_dir``; ``actors`` and ``parameters``: the judge's comparisons of the failure with the new
    script, :func:`compare_actors` and :func:`compare_parameters`;
    ``timings``: seconds per stage; ``status`` is the converted script's; ``replay_entry``: the exact replay's
    bank entry, kept whatever the script's fate, and ``replay_not_narrowed`` (once the replay is made) the
    parameters it leaves at the parent's distribution, with why; ``rejections``: every judge check that failed,
    the first one is ``reason``).
    """
    _check_settings(settings, "convert_failure")
    return _Conversion(record, Path(run_dir), settings, bank, cluster).run()


class _Conversion:
    """One run of :func:`convert_failure`: its stages in order (each a method, timed), the record being built
    (``out``) and what goes only into ``report.json`` (``details``)."""

    def __init__(self, record: Mapping[str, Any], run_dir: Path, settings: ConversionSettings, bank: Any,
                 cluster: Optional[str]) -> None:
        self.record, self.run_dir, self.settings, self.bank = record, run_dir, settings, bank
        self.cluster = cluster if cluster is not None else record.get("cluster")
        self.folder = run_dir / "failures" / cluster_slug(self.cluster, record.get("index"))
        self.conversion = self.folder / CONVERSION_DIR
        self.out: Dict[str, Any] = {
            "cluster": self.cluster, "index": record.get("index"), "status": "rejected", "reason": None,
            "stage": None, "video": None, "description": None, "script": None, "reproduction": None,
            "e2e_sc": None, "bank_entry": None, "merged_into": None, "seconds": None, "timings": {},
            "interaction": None, "replay_entry": None, "avoidability": None, "rejections": [], "actors": None,
            "parameters": None, "converted_video": None}
        self.details: Dict[str, Any] = {}
        self.stage = "input"
        self._stage_start = time.perf_counter()

    def lap(self, stage: str) -> None:
        now = time.perf_counter()
        self.out["timings"][stage] = round(now - self._stage_start, 4)
        self._stage_start = now

    def run(self) -> Dict[str, Any]:
        start = time.perf_counter()
        out = self.out
        try:
            for step in (self._input, self._video, self._interaction, self._replay, self._describe, self._generate,
                         self._check, self._reproduction, self._avoidability, self._e2e_sc, self._judge,
                         self._clip, self._add_to_bank):
                step()
        except _Rejected as rejection:
            out.update(stage=rejection.stage, reason=str(rejection))
        except SETUP_ERRORS:
            raise  # the endpoint's or its configuration's fault, not the failure's: not a rejection
        except Exception as error:  # a bad failure is a rejection with its stage, never an exception
            first = (str(error).strip().splitlines() or [""])[0]
            out.update(stage=self.stage, reason=f"{self.stage}: {type(error).__name__}: {first}"[:500])
        if out["reason"]:
            out["reason"] = _in_run(out["reason"], self.run_dir)
        out["rejections"] = [_in_run(str(why), self.run_dir) for why in out["rejections"]]
        if out["stage"] is not None and out["stage"] not in out["timings"]:
            self.lap(out["stage"])
        out["seconds"] = round(time.perf_counter() - start, 3)
        try:
            self.conversion.mkdir(parents=True, exist_ok=True)
            _write(self.conversion / "report.json", json.dumps({**out, **self.details}, indent=2, default=str) + "\n")
        except OSError:
            pass
        return out

    def _input(self) -> None:
        self.stage = "input"
        self.source_failure = dict(self.record.get("failure") or {})
        k, threshold = self.settings.k, self.settings.threshold
        if not self.source_failure.get("type"):
            raise _Rejected("input", "the record holds no failure (record['failure'] is empty)")
        if int(k) < 1 or not 0.0 <= float(threshold) <= 1.0:
            raise _Rejected("input", f"the reproduction check needs k >= 1 and 0 <= threshold <= 1, not k={k}, "
                                     f"threshold={threshold}")
        if isinstance(self.bank, (str, os.PathLike)):
            self.bank = Bank(self.bank)
        if (self.settings.bank_dir is None and getattr(self.bank, "root", None) is not None
                and self.record.get("scenario") in self.bank):
            self.settings = self.settings.replace(bank_dir=self.bank.root)
        self.conversion.mkdir(parents=True, exist_ok=True)

    def _video(self) -> None:
        self.stage = "video"

        self.video = self.folder / "failure.webm"
        self.settings = self.settings.replace(monitor=_monitor_options(self.run_dir, self.settings.monitor))
        try:
            self.written = write_failure_video(self.record, self.video, _video_settings(self.settings))
        except SETUP_ERRORS:
            raise
        except Exception as error:  # no video, no conversion; the exact replay does not need one
            self.lap("video")
            _replay_without_video(self.out, _stage_error("video", error), self.record, self.bank, self.details,
                                  self.settings, _ReplaySource(self.source_failure, self.cluster, self.run_dir))
            self.lap("replay")
            raise _Rejected("video", self.out["rejections"][0].split(": ", 1)[1])
        self.out["video"] = _rel(self.video, self.run_dir)
        self.source_trace = self.written.trace
        detected = _detect(self.written.result, self.source_trace, self.settings.monitor)
        self.details["source_failure_detected"] = detected
        if detected and detected.get("type") == self.source_failure["type"]:
            for key, value in detected.items():  # fill what a minimal failure record leaves out
                if self.source_failure.get(key) is None:
                    self.source_failure[key] = value
        self.lap("video")

    def _interaction(self) -> None:
        self.stage = "interaction"

        self.interaction = failure_interaction(self.source_trace, self.source_failure)
        self.out["interaction"] = self.interaction.to_dict()  # the conversion's record (report.json, conversions.jsonl)
        self.lap("interaction")

    def _replay(self) -> None:
        self.stage = "replay"
        source = _ReplaySource(self.source_failure, self.cluster, self.run_dir, source_trace=self.source_trace,
                               interaction=self.interaction,
                               files={ENTRY_VIDEO: self.video, ENTRY_TRACE: self.written.trace_path})
        self.replay = _add_replay(self.record, self.bank, self.settings, source)
        self.out["replay_entry"] = self.replay["entry"]
        self.out["replay_not_narrowed"] = dict(self.replay.get("not_narrowed") or {})
        self.details["replay"] = self.replay
        self.lap("replay")

    def _describe(self) -> None:
        self.stage = "describe"

        s = self.settings
        description = stages.describe(self.video, backend=s.dra, llm_config=s.llm_config)
        self.details["dra_description"] = description.text
        events = interaction_sentence(self.interaction, known=description.elements) if s.describe_events else ""
        if events:  # what the trace says caused the failure, even where the clip does not show it
            description.text = f"{description.text.strip()} {events}"
            description.elements = elements_from_text(description.text)
        self.out["description"] = description.text
        _write(self.conversion / "description.txt", description.text.strip() + "\n")
        _write(self.conversion / "elements.json", json.dumps(description.elements, indent=2) + "\n")
        self.details["description"] = description.as_dict()
        self.description = description
        self.lap("describe")

    def _generate(self) -> None:
        self.stage = "generate"

        s = self.settings
        self.generation = stages.generate(self.description.text, backend=s.sg, seed=s.seed, llm_config=s.llm_config)
        self.script_path = self.conversion / "scenario.scenic"
        _write(self.script_path, self.generation.script)
        self.out["script"] = _rel(self.script_path, self.run_dir)
        self.details["generation"] = self.generation.as_dict()
        self.lap("generate")

    def _check(self) -> None:
        self.stage = "check"


        check = check_scenario(self.generation.script, seed=self.settings.seed,
                               name=f"mined failure {self.record.get('index')}", in_process=False)
        self.details["check"] = {**asdict(check), "ok": check.ok}
        self.lap("check")
        if not check.ok:
            failed = next(s for s in ("safety", "compile", "sample", "run")
                          if not {"safety": check.safe, "compile": check.compiled, "sample": check.sampled,
                                  "run": check.ran}[s])
            raise _Rejected("check", f"{failed} failed: {check.error}")

    def _reproduction(self) -> None:
        self.stage = "reproduction"

        episodes, self.traces = _reproduce(self.script_path, self.settings.policy, self.settings,
                                           int(self.record["seed"]), self.source_failure, self.interaction)
        self.reproduced = sum(e["reproduced"] for e in episodes)
        self.shown = sum(bool(e["interaction"]) for e in episodes)
        low, high = wilson_interval(self.reproduced, len(episodes))
        self.out["reproduction"] = {"k": len(episodes), "reproduced": self.reproduced,
                                    "rate": self.reproduced / len(episodes), "interval": [low, high],
                                    "threshold": float(self.settings.threshold), "interaction_shown": self.shown,
                                    "actor_kind": self.interaction.kind}
        self.details["reproduction_episodes"] = episodes
        self.lap("reproduction")

    def _avoidability(self) -> None:
        self.stage = "avoidability"
        reference = self.settings.reference
        if reference:
            reference_episodes, _ = _reproduce(self.script_path, reference, self.settings, int(self.record["seed"]),
                                               self.source_failure)
            self.out["avoidability"] = reference_outcome(self.source_failure, reference_episodes,
                                                         _policy_name(reference))
            self.details["reference_episodes"] = reference_episodes
        self.lap("avoidability")

    def _e2e_sc(self) -> None:
        self.stage = "e2e_sc"

        truth = elements_from_trace(self.source_trace)
        scores = [e2e_sc(truth, elements_from_trace(trace)) for trace in self.traces]
        self.out["e2e_sc"] = float(np.mean(scores))
        self.details["source_elements"] = truth
        self.lap("e2e_sc")

    def _judge(self) -> None:
        # what the judge compares beyond the runs: the actors of the failure's scene and of the new scenario's
        # runs, and the failing parameter values against the new script's ranges
        out, record = self.out, self.record
        out["actors"] = compare_actors(actor_census(self.source_trace), [actor_census(t) for t in self.traces],
                                       self.interaction.kind)
        out["parameters"] = compare_parameters((record.get("result") or {}).get("params") or record.get("params")
                                               or {}, self.generation.script,
                                               parent=_parent_script(record, self.settings.bank_dir),
                                               interaction=self.interaction)
        # the judge: every check that failed is recorded; the first one is the rejection's stage
        rejections = _judge(out, self.interaction, self.source_failure, self.settings.threshold)
        out["rejections"] = [_in_run(str(r), self.run_dir) for r in rejections]
        if self.replay["entry"]:
            _link(self.bank, self.replay["entry"], {"converted_e2e_sc": out["e2e_sc"],
                                                    "converted_rejections": out["rejections"]})
        if rejections:
            raise rejections[0]

    def _clip(self) -> None:
        """One reproduction episode of the converted script (:func:`clip_episode`: one that failed the same way
        when there is one) filmed as the failure was, so a reader sees whether the script plays the failure. The
        clip is extra: when it cannot be made, the record says why and the conversion goes on without it."""
        self.stage = "clip"

        episodes = self.details.get("reproduction_episodes") or []
        self.clip_path: Optional[Path] = None
        if not episodes:
            return
        episode, chosen = clip_episode(episodes)
        failure = episode.get("failure") or None
        clip = {"seed": int(episode["seed"]), "failed": bool(failure), "reproduced": bool(episode.get("reproduced")),
                "failure": ({key: failure.get(key) for key in ("type", "collision_type", "with_kind")
                             if failure.get(key) is not None} if failure else None),
                "chosen": chosen, "file": ENTRY_CONVERTED_VIDEO}
        path = self.conversion / ENTRY_CONVERTED_VIDEO
        try:
            write_script_episode_video(self.script_path, episode, path, _video_settings(self.settings),
                                       centre=self.written.failure_frame)
        except SETUP_ERRORS:
            raise
        except Exception as error:  # the clip is extra: the conversion goes on without it
            clip = {**clip, "file": None, "error": _in_run(_stage_error("clip", error), self.run_dir)}
        else:
            self.clip_path = path
            self.out["converted_video"] = _rel(path, self.run_dir)
        self.out["reproduction"]["clip"] = clip
        self.lap("clip")

    def _add_to_bank(self) -> None:
        self.stage = "bank"
        out, record = self.out, self.record
        files = {ENTRY_VIDEO: self.video, ENTRY_TRACE: self.written.trace_path}
        if self.clip_path is not None:
            files[ENTRY_CONVERTED_VIDEO] = self.clip_path
        fields = Sidecar(description=self.description.text,
                         name=_mined_name(record["scenario"], self.source_failure["type"]),
                         elements=self.description.elements, tags=("mined", self.source_failure["type"]),
                         source=self._provenance())
        outcome = self.bank.add(self.generation.script, fields, files=files, on_duplicate="merge",
                                near_copy_of=_family(record["scenario"], self.source_failure["type"]))
        if outcome.status == "added":
            out.update(status="kept", bank_entry=outcome.entry.name)
        else:
            out.update(status="merged", merged_into=outcome.entry.name, merge_reason=outcome.how)
        if self.replay["entry"]:
            _link(self.bank, self.replay["entry"], {"converted": outcome.entry.name})
        self.lap("bank")

    def _provenance(self) -> Provenance:
        """The kept script's ``mined`` provenance."""
        out, record, s = self.out, self.record, self.settings
        result = record.get("result") or {}
        return Provenance(
            kind="mined", parent=record["scenario"], seed=int(record["seed"]),
            params=_portable_params(result.get("params") or record.get("params") or {}),
            video=ENTRY_VIDEO, trace=ENTRY_TRACE,
            **conversion_provenance(s.dra, s.sg, self.generation, self.description),
            backends={"dra": s.dra, "sg": s.sg},
            policy=_policy_name(s.policy), failure=self.source_failure, cluster=self.cluster,
            reproduction=out["reproduction"], e2e_sc=out["e2e_sc"], run=str(self.run_dir.resolve()),
            index=record.get("index"),
            interaction=self.interaction.to_dict(), judge={"avoidability": out.get("avoidability"),
                                                 "interaction_shown": self.shown, "reproduced": self.reproduced,
                                                 "parameters_not_compared": dict(
                                                     (out.get("parameters") or {}).get("not_comparable") or {})},
            replay_entry=self.replay["entry"],
            converted_video=ENTRY_CONVERTED_VIDEO if self.clip_path is not None else None,
        )
