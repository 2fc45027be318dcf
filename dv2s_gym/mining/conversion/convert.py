"""From a mined failure to validated bank entries: the failing scene kept exactly, and its D-V2S conversion judged.

:func:`convert_failure` takes one failure record of the miner (an episode record of
``episodes.jsonl`` whose ``failure`` is set) through these stages, each timed, and returns the
conversion record of ``conversions.jsonl``:

1. ``video``: re-run the episode and write its bird's-eye video and trace
   (:func:`dv2s_gym.mining.conversion.failure_video.record_failure_video`; a diverging replay is a rejection);
2. ``interaction``: the failure's interaction read from its own trace
   (:func:`dv2s_gym.mining.conversion.interaction.failure_interaction`): the actor involved (the collision partner, or
   the actor the ego slowed down for, however far ahead), its kind and its manoeuvres;
3. ``replay``: the exact replay of the failing scene goes into the bank whatever becomes of the conversion
   (:mod:`dv2s_gym.mining.conversion.exact_replay`): the parent script narrowed around the failing parameters, tagged
   ``replay``, its provenance ``replay`` holding the parameters, seed and trajectory hash that pin the
   scene; it is checked to replay the recorded episode step for step first (else a ``replay`` rejection);
4. ``describe``: the Driving Record Analyzer turns the video into a description; what it says of a collision the
   trace does not record is taken out (:func:`~dv2s_gym.mining.conversion.traced_collisions.keep_traced_collisions`:
   a red, crashed obstacle read as a crashed car is no car collision), and the trace's account of
   the interaction is added to it (:func:`~dv2s_gym.mining.conversion.interaction.interaction_sentence`), so the
   description names what caused the failure even when the clip does not show it;
5. ``generate``: the Scenario Generator turns the description into a Scenic script;
6. ``check``: safety allowlist, then compile, sample and run in the sandbox
   (:func:`dv2s_gym.pipeline.convert.check_scenario`);
7. ``reproduction``: the same policy drives the new scenario over ``k`` scenes whose seeds derive
   from the record's seed (``numpy.random.SeedSequence([seed, record seed])``); an episode reproduces the
   failure when it fails in the *same failure class* with the *same kind of actor*; each episode also says
   whether its trace shows the failure's interaction (an actor of the key actor's kind doing one of its
   manoeuvres and, for a collision, the ego colliding with that actor: :func:`~dv2s_gym.mining.conversion.interaction.trace_shows_interaction`);
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
    by name, else by the quantity of the same actor it sets, :mod:`dv2s_gym.mining.conversion.param_meaning`; the failing
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

import json
import os
import re
import time
from pathlib import Path
from typing import Any, Dict, Mapping, Optional, Union

import numpy as np

from dv2s_gym.mining.conversion.episodes import (actor_census, clip_episode, compare_actors, detected_failure,
                                                 monitor_options, policy_name, reference_outcome, reproduce,
                                                 video_settings)
from dv2s_gym.mining.conversion.files import (cluster_slug, CONVERSION_DIR, ENTRY_CONVERTED_VIDEO, ENTRY_TRACE,
                                              ENTRY_VIDEO, provenance_run, relative_to_run, run_relative,
                                              write_run_file)
from dv2s_gym.mining.conversion.judge import judge_conversion
from dv2s_gym.mining.conversion.parameters import compare_parameters, parent_script
from dv2s_gym.mining.conversion.record import ConversionRecord, ConversionStatus
from dv2s_gym.mining.conversion.rejection import check_settings, ConversionRejected, SETUP_ERRORS, stage_error
from dv2s_gym.mining.conversion.replay import (add_replay, link_entries, replay_failure_entry, replay_without_video,
                                               ReplaySource)
from dv2s_gym.mining.conversion.settings import ConversionSettings
from dv2s_gym.mining.conversion.failure_video import write_failure_video, write_script_episode_video
from dv2s_gym.mining.conversion.interaction import failure_interaction
from dv2s_gym.mining.conversion.traced_collisions import failure_description
from dv2s_gym.pipeline import stages
from dv2s_gym.pipeline.convert import check_scenario, conversion_provenance
from dv2s_gym.pipeline.metrics import e2e_sc
from dv2s_gym.pipeline.semantics.text import elements_from_text
from dv2s_gym.pipeline.semantics.trace import elements_from_trace
from dv2s_gym.regress.stats import wilson_interval
from scenario_bank.bank import Bank
from scenario_bank.records import EpisodeRecord, Failure, Provenance, Sidecar

__all__ = ["convert_failure", "replay_failure_entry"]


PathLike = Union[str, os.PathLike]


def _family(parent: str, failure_type: str):
    """Whether a bank entry is a converted (not replay) mined entry from ``parent`` with a ``failure_type`` failure."""
    def same(entry) -> bool:
        source = entry.source
        return (source.mined and not source.is_replay and source.parent == parent
                and source.failure_type == failure_type)
    return same


def _failing_params(record: EpisodeRecord) -> Mapping[str, Any]:
    """The failing episode's sampled parameters: its result's (as the env reported them), else the record's."""
    reported = record.result.params if record.result is not None else None
    return reported or record.params or {}


def _portable_params(params: Mapping[str, Any]) -> Dict[str, Any]:
    """The sampled parameters as the bank keeps them: a map given by a path becomes its file name (the
    entry's ``map`` names it; shipped maps are found by name), so no path into this machine is kept."""
    out = dict(params)
    if isinstance(out.get("map"), str) and ("/" in out["map"] or os.sep in out["map"]):
        out["map"] = Path(out["map"]).name
    return out


def _clip_failure(failure: Optional[Failure]) -> Optional[Dict[str, Any]]:
    """What the clip's record says of the filmed episode's failure: its type, collision type and the other actor's
    kind, those it has."""
    if failure is None:
        return None
    parts = {"type": failure.type, "collision_type": failure.collision_type, "with_kind": failure.with_kind}
    return {key: value for key, value in parts.items() if value is not None}


def _mined_name(parent: str, failure_type: str) -> str:
    base = re.sub(r"[^a-z0-9_\-]+", "_", f"mined_{parent}_{failure_type}".lower()).strip("_-")
    return base[:90] or "mined"


def convert_failure(record: EpisodeRecord, run_dir: PathLike, settings: ConversionSettings, *,
                    bank: Any, cluster: Optional[str] = None) -> ConversionRecord:
    """Turn one failure record into a bank entry; returns the conversion record (never raises for a bad failure).

    Args:
        record: an episode record of the miner with a ``failure`` (see the mining contract): an
            :class:`~scenario_bank.records.EpisodeRecord`, or its JSON object as ``episodes.jsonl`` holds it.
        run_dir: the mining run folder; files go to ``failures/<cluster slug>/`` (``failure.webm``,
            ``trace.json.gz``, ``conversion/{description.txt, elements.json, scenario.scenic, report.json}``).
        settings: the :class:`ConversionSettings` (the policy that failed, the backends, the reproduction check,
            the video window, the reference driver...). The video covers ``before`` seconds before the failure
            and ``after`` after it (a stall's clip covers the stall, up to the monitor's ``stall_seconds``, between
            them: :func:`~dv2s_gym.mining.conversion.failure_video.write_failure_video`).
        bank: the bank to add to (a :class:`~scenario_bank.bank.Bank` or its folder).
        cluster: the failure's cluster id, which the miner passes (default the record's ``cluster`` key).

    Raises the model backends' setup errors (:data:`~dv2s_gym.mining.conversion.rejection.SETUP_ERRORS`), and
    ``WrongTypeError`` (a ``TypeError``) for settings that are not a :class:`ConversionSettings` or name no policy,
    and :class:`~scenario_bank.records.RecordError` for a record that is no episode record (a field of the wrong kind,
    or no ``index``, ``scenario`` or ``seed``); every other problem is a rejection.

    Returns the :class:`~dv2s_gym.mining.conversion.record.ConversionRecord` whose JSON object is ``{"cluster",
    "index", "status": "kept"|"merged"|"rejected" (a :class:`~dv2s_gym.mining.conversion.record.ConversionStatus`),
    "reason", "stage", "video",
    "description", "script", "reproduction", "e2e_sc", "bank_entry", "merged_into", "seconds",
    "timings", "interaction", "replay_entry", "avoidability", "rejections", "actors", "parameters"}`` (paths
    relative to ``run_dir``; ``actors`` and ``parameters``: the judge's comparisons of the failure with the new
    script, :func:`~dv2s_gym.mining.conversion.episodes.compare_actors` and
    :func:`~dv2s_gym.mining.conversion.parameters.compare_parameters`; ``timings``: seconds per stage; ``status`` is the
    converted script's; ``replay_entry``: the exact replay's bank entry, kept whatever the script's fate, and
    ``replay_not_narrowed`` (once the replay is made) the parameters it leaves at the parent's distribution, with why;
    ``rejections``: every judge check that failed, the first one is ``reason``).
    """
    check_settings(settings, "convert_failure")
    return ConversionRecord.from_dict(
        _Conversion(EpisodeRecord.from_dict(record), Path(run_dir), settings, bank, cluster).run())


class _Conversion:
    """One run of :func:`convert_failure`: its stages in order (each a method, timed), the record being built
    (``out``) and what goes only into ``report.json`` (``details``)."""

    def __init__(self, record: EpisodeRecord, run_dir: Path, settings: ConversionSettings, bank: Any,
                 cluster: Optional[str]) -> None:
        self.record, self.run_dir, self.settings, self.bank = record, run_dir, settings, bank
        self.cluster = cluster if cluster is not None else record.extra.get("cluster")
        self.folder = run_dir / "failures" / cluster_slug(self.cluster, record.index)
        self.conversion = self.folder / CONVERSION_DIR
        self.out: Dict[str, Any] = {
            "cluster": self.cluster, "index": record.index, "status": ConversionStatus.REJECTED.value, "reason": None,
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
        except ConversionRejected as rejection:
            out.update(stage=rejection.stage, reason=str(rejection))
        except SETUP_ERRORS:
            raise  # the endpoint's or its configuration's fault, not the failure's: not a rejection
        except Exception as error:  # a bad failure is a rejection with its stage, never an exception
            first = (str(error).strip().splitlines() or [""])[0]
            out.update(stage=self.stage, reason=f"{self.stage}: {type(error).__name__}: {first}"[:500])
        if out["reason"]:
            out["reason"] = relative_to_run(out["reason"], self.run_dir)
        out["rejections"] = [relative_to_run(str(why), self.run_dir) for why in out["rejections"]]
        if out["stage"] is not None and out["stage"] not in out["timings"]:
            self.lap(out["stage"])
        out["seconds"] = round(time.perf_counter() - start, 3)
        try:
            self.conversion.mkdir(parents=True, exist_ok=True)
            write_run_file(self.conversion / "report.json",
                           json.dumps({**out, **self.details}, indent=2, default=str) + "\n")
        except OSError:
            pass
        return out

    def _input(self) -> None:
        self.stage = "input"
        self.source_failure = self.record.failure
        k, threshold = self.settings.k, self.settings.threshold
        if self.source_failure is None or not self.source_failure.type:
            raise ConversionRejected("input", "the record holds no failure (its 'failure' is empty)")
        if int(k) < 1 or not 0.0 <= float(threshold) <= 1.0:
            raise ConversionRejected("input", f"the reproduction check needs k >= 1 and 0 <= threshold <= 1, not "
                                              f"k={k}, threshold={threshold}")
        if isinstance(self.bank, (str, os.PathLike)):
            self.bank = Bank(self.bank)
        if (self.settings.bank_dir is None and getattr(self.bank, "root", None) is not None
                and self.record.scenario in self.bank):
            self.settings = self.settings.replace(bank_dir=self.bank.root)
        self.conversion.mkdir(parents=True, exist_ok=True)

    def _video(self) -> None:
        self.stage = "video"

        self.video = self.folder / "failure.webm"
        self.settings = self.settings.replace(monitor=monitor_options(self.run_dir, self.settings.monitor))
        try:
            self.written = write_failure_video(self.record, self.video, video_settings(self.settings))
        except SETUP_ERRORS:
            raise
        except Exception as error:  # no video, no conversion; the exact replay does not need one
            self.lap("video")
            replay_without_video(self.out, stage_error("video", error), self.record, self.bank, self.details,
                                 self.settings, ReplaySource(self.source_failure, self.cluster, self.run_dir))
            self.lap("replay")
            raise ConversionRejected("video", self.out["rejections"][0].split(": ", 1)[1])
        self.out["video"] = run_relative(self.video, self.run_dir)
        self.source_trace = self.written.trace
        detected = detected_failure(self.written.result, self.source_trace, self.settings.monitor)
        self.details["source_failure_detected"] = detected.to_dict() if detected is not None else None
        if detected is not None and detected.type == self.source_failure.type:
            self.source_failure = self.source_failure.completed_by(detected)  # what a minimal record leaves out
        self.lap("video")

    def _interaction(self) -> None:
        self.stage = "interaction"

        self.interaction = failure_interaction(self.source_trace, self.source_failure)
        self.out["interaction"] = self.interaction.to_dict()  # the conversion's record (report.json, conversions.jsonl)
        self.lap("interaction")

    def _replay(self) -> None:
        self.stage = "replay"
        source = ReplaySource(self.source_failure, self.cluster, self.run_dir, source_trace=self.source_trace,
                              interaction=self.interaction,
                              files={ENTRY_VIDEO: self.video, ENTRY_TRACE: self.written.trace_path})
        self.replay = add_replay(self.record, self.bank, self.settings, source)
        self.out["replay_entry"] = self.replay["entry"]
        self.out["replay_not_narrowed"] = dict(self.replay.get("not_narrowed") or {})
        self.details["replay"] = self.replay
        self.lap("replay")

    def _describe(self) -> None:
        self.stage = "describe"

        s = self.settings
        description = stages.describe(self.video, backend=s.dra, llm_config=s.llm_config)
        self.details["dra_description"] = description.text
        # held to the trace: no collision it does not record; what it says caused the failure added, even where
        # the clip does not show it
        traced = failure_description(description.text, self.source_trace,
                                     self.interaction if s.describe_events else None)
        if traced.removed:
            self.details["untraced_collisions"] = traced.removed
        if traced.text != description.text:
            description.text = traced.text
            description.elements = elements_from_text(description.text)
        self.out["description"] = description.text
        write_run_file(self.conversion / "description.txt", description.text.strip() + "\n")
        write_run_file(self.conversion / "elements.json", json.dumps(description.elements.to_dict(), indent=2) + "\n")
        self.details["description"] = description.as_dict()
        self.description = description
        self.lap("describe")

    def _generate(self) -> None:
        self.stage = "generate"

        s = self.settings
        self.generation = stages.generate(self.description.text, backend=s.sg, seed=s.seed, llm_config=s.llm_config)
        self.script_path = self.conversion / "scenario.scenic"
        write_run_file(self.script_path, self.generation.script)
        self.out["script"] = run_relative(self.script_path, self.run_dir)
        self.details["generation"] = self.generation.as_dict()
        self.lap("generate")

    def _check(self) -> None:
        self.stage = "check"


        check = check_scenario(self.generation.script, seed=self.settings.seed,
                               name=f"mined failure {self.record.index}", in_process=False)
        self.details["check"] = check.to_json()
        self.lap("check")
        if not check.ok:
            failed = next(s for s in ("safety", "compile", "sample", "run")
                          if not {"safety": check.safe, "compile": check.compiled, "sample": check.sampled,
                                  "run": check.ran}[s])
            raise ConversionRejected("check", f"{failed} failed: {check.error}")

    def _reproduction(self) -> None:
        self.stage = "reproduction"

        episodes, self.traces = reproduce(self.script_path, self.settings.policy, self.settings,
                                          int(self.record.seed), self.source_failure, self.interaction)
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
            reference_episodes, _ = reproduce(self.script_path, reference, self.settings, int(self.record.seed),
                                              self.source_failure)
            self.out["avoidability"] = reference_outcome(self.source_failure, reference_episodes,
                                                         policy_name(reference))
            self.details["reference_episodes"] = reference_episodes
        self.lap("avoidability")

    def _e2e_sc(self) -> None:
        self.stage = "e2e_sc"

        truth = elements_from_trace(self.source_trace)
        scores = [e2e_sc(truth, elements_from_trace(trace)) for trace in self.traces]
        self.out["e2e_sc"] = float(np.mean(scores))
        self.details["source_elements"] = truth.to_dict()
        self.lap("e2e_sc")

    def _judge(self) -> None:
        # what the judge compares beyond the runs: the actors of the failure's scene and of the new scenario's
        # runs, and the failing parameter values against the new script's ranges
        out, record = self.out, self.record
        out["actors"] = compare_actors(actor_census(self.source_trace), [actor_census(t) for t in self.traces],
                                       self.interaction.kind)
        out["parameters"] = compare_parameters(_failing_params(record), self.generation.script,
                                               parent=parent_script(record.scenario, self.settings.bank_dir),
                                               interaction=self.interaction)
        # the judge: every check that failed is recorded; the first one is the rejection's stage
        rejections = judge_conversion(out, self.interaction, self.source_failure, self.settings.threshold)
        out["rejections"] = [relative_to_run(str(r), self.run_dir) for r in rejections]
        if self.replay["entry"]:
            link_entries(self.bank, self.replay["entry"], {"converted_e2e_sc": out["e2e_sc"],
                                                    "converted_rejections": out["rejections"]})
        if rejections:
            raise rejections[0]

    def _clip(self) -> None:
        """One reproduction episode of the converted script (:func:`~dv2s_gym.mining.conversion.episodes.clip_episode`:
        one that failed the same way when there is one) filmed as the failure was, so a reader sees whether the script
        plays the failure. The clip is extra: when it cannot be made, the record says why and the conversion goes on
        without it."""
        self.stage = "clip"

        episodes = self.details.get("reproduction_episodes") or []
        self.clip_path: Optional[Path] = None
        if not episodes:
            return
        episode, chosen = clip_episode(episodes)
        failure = Failure.of(episode.get("failure"))
        clip = {"seed": int(episode["seed"]), "failed": failure is not None,
                "reproduced": bool(episode.get("reproduced")), "failure": _clip_failure(failure),
                "chosen": chosen, "file": ENTRY_CONVERTED_VIDEO}
        path = self.conversion / ENTRY_CONVERTED_VIDEO
        try:
            write_script_episode_video(self.script_path, episode, path, video_settings(self.settings),
                                       centre=self.written.failure_frame)
        except SETUP_ERRORS:
            raise
        except Exception as error:  # the clip is extra: the conversion goes on without it
            clip = {**clip, "file": None, "error": relative_to_run(stage_error("clip", error), self.run_dir)}
        else:
            self.clip_path = path
            self.out["converted_video"] = run_relative(path, self.run_dir)
        self.out["reproduction"]["clip"] = clip
        self.lap("clip")

    def _add_to_bank(self) -> None:
        self.stage = "bank"
        out, record = self.out, self.record
        files = {ENTRY_VIDEO: self.video, ENTRY_TRACE: self.written.trace_path}
        if self.clip_path is not None:
            files[ENTRY_CONVERTED_VIDEO] = self.clip_path
        fields = Sidecar(description=self.description.text,
                         name=_mined_name(record.scenario, self.source_failure.type),
                         elements=self.description.elements, tags=("mined", self.source_failure.type),
                         source=self._provenance())
        outcome = self.bank.add(self.generation.script, fields, files=files, on_duplicate="merge",
                                near_copy_of=_family(record.scenario, self.source_failure.type))
        if outcome.status == "added":
            out.update(status=ConversionStatus.KEPT.value, bank_entry=outcome.entry.name)
        else:
            out.update(status=ConversionStatus.MERGED.value, merged_into=outcome.entry.name, merge_reason=outcome.how)
        if self.replay["entry"]:
            link_entries(self.bank, self.replay["entry"], {"converted": outcome.entry.name})
        self.lap("bank")

    def _provenance(self) -> Provenance:
        """The kept script's ``mined`` provenance."""
        out, record, s = self.out, self.record, self.settings
        return Provenance(
            kind="mined", parent=record.scenario, seed=int(record.seed),
            params=_portable_params(_failing_params(record)),
            video=ENTRY_VIDEO, trace=ENTRY_TRACE,
            **conversion_provenance(s.dra, s.sg, self.generation, self.description),
            backends={"dra": s.dra, "sg": s.sg},
            policy=policy_name(s.policy), failure=self.source_failure.to_dict(), cluster=self.cluster,
            reproduction=out["reproduction"], e2e_sc=out["e2e_sc"], run=provenance_run(self.run_dir, self.bank),
            index=record.index,
            interaction=self.interaction.to_dict(), judge={"avoidability": out.get("avoidability"),
                                                 "interaction_shown": self.shown, "reproduced": self.reproduced,
                                                 "parameters_not_compared": dict(
                                                     (out.get("parameters") or {}).get("not_comparable") or {})},
            replay_entry=self.replay["entry"],
            converted_video=ENTRY_CONVERTED_VIDEO if self.clip_path is not None else None,
        )
