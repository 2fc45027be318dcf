"""The exact replay of a failing scene in the bank (:mod:`dv2s_gym.mining.conversion.exact_replay`), kept whatever becomes of
the failure's conversion: during a conversion (:func:`add_replay`; :func:`replay_without_video` when no video could
be made) or on its own (:func:`replay_failure_entry`). The two entries of one failure link each other
(:func:`link_entries`).
"""

from __future__ import annotations

import dataclasses
import datetime
import os
import time
import warnings
from pathlib import Path
from typing import Any, Dict, Mapping, Optional, Union

from dv2s_gym.mining.conversion.episodes import monitor_options, policy_name, reference_passed
from dv2s_gym.mining.conversion.files import (cluster_slug, CONVERSION_DIR, ENTRY_TRACE, ENTRY_VIDEO, provenance_run,
                                              relative_to_run, write_run_file)
from dv2s_gym.mining.conversion.record import ConversionStatus, ReplayRow
from dv2s_gym.mining.conversion.rejection import check_settings, ConversionRejected, SETUP_ERRORS, stage_error
from dv2s_gym.mining.conversion.settings import ConversionSettings
from dv2s_gym.mining.conversion.exact_replay import (conditioned_params, narrowed_script, replay_name, REPLAY_TAG,
                                                     replay_versions, run_replay)
from dv2s_gym.mining.conversion.interaction import failure_interaction, FailureInteraction, interaction_sentence
from dv2s_gym.pipeline.metrics import e2e_sc
from dv2s_gym.pipeline.semantics.trace import elements_from_trace
from scenario_bank.bank import Bank, DuplicateScenarioError
from scenario_bank.errors import NearDuplicateWarning
from scenario_bank.records import EpisodeRecord, Failure, Provenance, Sidecar

__all__ = ["replay_failure_entry", "add_replay", "replay_without_video", "ReplaySource", "link_entries"]


PathLike = Union[str, os.PathLike]


def link_entries(bank, name: str, fields: Mapping[str, Any]) -> None:
    bank.update_source(name, dict(fields))


@dataclasses.dataclass
class ReplaySource:
    """The failure an exact replay keeps: its failure, cluster, the mining run folder, and what the conversion
    read from it so far (its trace, interaction and files: ``None`` when no video was made)."""

    source_failure: Failure
    cluster: Optional[str]
    run_dir: Path
    source_trace: Any = None
    interaction: Optional[FailureInteraction] = None
    files: Optional[Mapping[str, Path]] = None


def add_replay(record: EpisodeRecord, bank, settings: ConversionSettings, source: ReplaySource) -> Dict[str, Any]:
    """Add the exact replay of the failing scene to ``bank`` (:mod:`dv2s_gym.mining.conversion.exact_replay`): the parent
    script (in the settings' ``bank_dir``) narrowed around the failing parameters, checked to replay the recorded
    episode step for step with the settings' ``policy``, ``env_config`` and ``monitor``.
    Returns ``{"entry", "params", "intervals", "not_narrowed", "seed", "trajectory_hash", "e2e_sc", "note"}``
    (``not_narrowed``: ``{parameter: why}`` of those left at the parent's distribution; ``entry`` None,
    with a ``note``, when the narrowed script is the parent itself and the parent is in ``bank``).

    Without a ``source_trace`` (no failure video was made), the replay's own trace stands for it once its
    trajectory hash matches the record's, and is what the entry keeps (``files``: the trace only, no video);
    without an ``interaction`` it is read from that trace. A scene the reference driver failed too
    (:func:`~dv2s_gym.mining.conversion.episodes.reference_passed`) is not replayed: ``{"entry": None, "note",
    "not_narrowed": {}}``."""
    if not reference_passed(record):
        reference_failure = record.reference.failure if record.reference is not None else None
        failed = reference_failure.type if reference_failure is not None else "not avoided"
        return {"entry": None, "not_narrowed": {}, "note": f"no replay entry: the reference driver failed this scene "
                                                          f"too ({failed}), so it is no failure the policy could have "
                                                          "avoided"}
    parent = (Bank(settings.bank_dir) if settings.bank_dir else Bank()).get(record.scenario)
    params = dict(record.params or {})
    script, intervals, not_narrowed, trace, failure, source = _run_narrowed(record, parent, params, settings, source)
    replay = {"params": params, "intervals": intervals, "not_narrowed": not_narrowed, "seed": int(record.seed),
              "trajectory_hash": record.result.trajectory_hash,
              "policy": policy_name(settings.policy), **replay_versions(settings.policy)}
    out = {"entry": None, **replay, "failure": failure.to_dict() if failure is not None else None, "note": None,
           "e2e_sc": e2e_sc(elements_from_trace(source.source_trace), elements_from_trace(trace))}
    _bank_replay(out, record, bank, parent, script, replay, settings, source)
    return out


def _run_narrowed(record: EpisodeRecord, parent: Any, params: Dict[str, Any], settings: ConversionSettings,
                  source: ReplaySource) -> tuple:
    """Write the parent narrowed around the failing ``params`` and replay the recorded episode on it:
    ``(script, intervals, not_narrowed, trace, failure, source)``, ``source`` completed from the replay when it had no
    trace. A replay that diverges is a ``replay`` rejection."""
    script, intervals, not_narrowed = narrowed_script(parent.script, params)
    seed = int(record.seed)
    expected = record.result.trajectory_hash
    folder = source.run_dir / "failures" / cluster_slug(source.cluster, record.index) / CONVERSION_DIR
    path = folder / "replay.scenic"
    write_run_file(path, script)
    result, trace, failure = run_replay(path, policy=settings.policy, seed=seed,
                                        params=conditioned_params(params, intervals),
                                        env_config=settings.env_config, monitor=settings.monitor)
    if result.trajectory_hash != expected:
        raise ConversionRejected("replay", f"the parent {record.scenario!r} narrowed around the failing parameters "
                                           f"does not replay the failing episode (trajectory hash "
                                           f"{result.trajectory_hash[:12]} != recorded {expected[:12]})")
    if source.source_trace is None:  # the same episode step for step: its trace is the failure's own
        trace.save(folder / ENTRY_TRACE)
        source_failure = source.source_failure
        if failure is not None and failure.type == source_failure.type:
            source_failure = source_failure.completed_by(failure)
        interaction = source.interaction
        if interaction is None:
            interaction = failure_interaction(trace, source_failure)
        source = dataclasses.replace(source, source_trace=trace, files={ENTRY_TRACE: folder / ENTRY_TRACE},
                                     source_failure=source_failure, interaction=interaction)
    return script, intervals, not_narrowed, trace, failure, source


def _bank_replay(out: Dict[str, Any], record: EpisodeRecord, bank, parent: Any, script: str,
                 replay: Mapping[str, Any], settings: ConversionSettings, source: ReplaySource) -> None:
    """Add the narrowed script to ``bank`` as the failure's exact replay entry (``out["entry"]``), or say in
    ``out["note"]`` why there is none."""
    files = dict(source.files or {})
    seed, params, policy = replay["seed"], replay["params"], settings.policy
    source_failure = source.source_failure
    events = interaction_sentence(source.interaction)
    description = (f"{parent.description.strip()} Exact replay of a failure of {policy_name(policy)}: seed {seed}, "
                   f"parameters narrowed around the failing values"
                   + (f" (not narrowed, drawn as in the parent: {', '.join(sorted(replay.get('not_narrowed') or {}))})"
                      if replay.get("not_narrowed") else "") + "." + (f" {events}" if events else ""))
    provenance = Provenance(kind="mined", parent=record.scenario, seed=seed, params=params,
                            video=ENTRY_VIDEO if ENTRY_VIDEO in files else None,
                            trace=ENTRY_TRACE if ENTRY_TRACE in files else None, generator="exact replay",
                            policy=policy_name(policy), failure=source_failure.to_dict(), cluster=source.cluster,
                            run=provenance_run(source.run_dir, bank), index=record.index,
                            interaction=FailureInteraction.from_dict(source.interaction).to_dict(),
                            replay=dict(replay), e2e_sc=out["e2e_sc"],
                            date=datetime.date.today().isoformat())
    base = replay_name(record.scenario, source_failure.type)
    name, n = base, 2
    while name in bank:
        name, n = f"{base}_{n}", n + 1
    try:
        fields = Sidecar(description=description, name=name, elements=parent.elements, map=parent.map,
                         tags=("mined", REPLAY_TAG, source_failure.type), source=provenance)
        with warnings.catch_warnings():  # a replay is by construction a near-duplicate of its parent
            warnings.simplefilter("ignore", NearDuplicateWarning)
            entry = bank.add(script, fields, files=files)
        out["entry"] = entry.name
    except DuplicateScenarioError as error:
        existing = bank.get(error.existing).source.replay or {}
        if existing.get("seed") == seed and existing.get("params") == params:
            out["entry"] = error.existing  # this failing scene is in the bank already (a resumed run)
        elif error.existing == record.scenario:
            out["note"] = (f"no replay entry: {record.scenario!r} has no free parameters to narrow, so the failing "
                           f"scene is that scenario itself with seed {seed}")
        else:
            out["note"] = f"no replay entry: {error}"


def replay_failure_entry(record: EpisodeRecord, run_dir: PathLike, settings: ConversionSettings, *, bank: Any,
                         cluster: Optional[str] = None) -> ReplayRow:
    """Keep one failure exactly, without converting it: only the exact replay entry of the failing scene
    (stage 3 of :func:`~dv2s_gym.mining.conversion.convert.convert_failure`, with no video, description or script; the entry keeps
    the replay's trace). Never raises for a bad failure; raises ``WrongTypeError`` when ``settings`` is not a
    :class:`ConversionSettings` with a policy, and :class:`~scenario_bank.records.RecordError` when ``record`` (an
    :class:`~scenario_bank.records.EpisodeRecord`, or its JSON object as ``episodes.jsonl`` holds it) is no episode
    record.

    Of ``settings`` the replay reads the ``policy`` that failed, the run's ``env_config``, the ``bank_dir`` holding
    the record's scenario (default the ``bank`` when it holds it, else the shipped bank) and the ``monitor``
    (default the run's ``settings.json``'s).

    Returns the :class:`~dv2s_gym.mining.conversion.record.ReplayRow` of the cluster (a line of ``replays.jsonl``):
    ``kept`` with the entry's name (and ``replay_not_narrowed``: ``{parameter: why}`` of the parameters the replay
    leaves at the parent's distribution), or ``rejected`` with the reason (a replay that diverges from the recorded
    episode, a bad record); ``kept`` with no entry and a ``note`` when the bank holds the scene already under another
    name."""
    check_settings(settings, "replay_failure_entry")
    start = time.perf_counter()
    run_dir = Path(run_dir)
    record = EpisodeRecord.from_dict(record)
    cluster = cluster if cluster is not None else record.extra.get("cluster")
    row = ReplayRow(cluster=cluster, index=record.index, scenario=record.scenario, status=ConversionStatus.REJECTED)
    try:
        failure = record.failure
        if failure is None or not failure.type:
            raise ConversionRejected("input", "the record holds no failure (its 'failure' is empty)")
        if record.result is None or not record.result.trajectory_hash:
            raise ConversionRejected("input", "the record holds no trajectory hash to check the replay against")
        if isinstance(bank, (str, os.PathLike)):
            bank = Bank(bank)
        if settings.bank_dir is None and getattr(bank, "root", None) is not None and record.scenario in bank:
            settings = settings.replace(bank_dir=bank.root)
        settings = settings.replace(monitor=monitor_options(run_dir, settings.monitor))
        replay = add_replay(record, bank, settings, ReplaySource(failure, cluster, run_dir))
        row = row.replace(status=ConversionStatus.KEPT, replay_entry=replay["entry"], note=replay["note"],
                          replay_not_narrowed=dict(replay.get("not_narrowed") or {}))
    except ConversionRejected as rejection:
        row = row.replace(reason=str(rejection))
    except SETUP_ERRORS:
        raise
    except Exception as error:  # a bad failure is a rejection, never an exception
        first = (str(error).strip().splitlines() or [""])[0]
        row = row.replace(reason=f"replay: {type(error).__name__}: {first}"[:500])
    if row.reason:
        row = row.replace(reason=relative_to_run(row.reason, run_dir))
    return row.replace(seconds=round(time.perf_counter() - start, 3))


def replay_without_video(out: Dict[str, Any], video_error: str, record: EpisodeRecord, bank,
                         details: Dict[str, Any], settings: ConversionSettings, source: ReplaySource) -> None:
    """After the video stage failed: keep the exact replay all the same (its own trace stands for the failure's)
    and record both outcomes in ``out``: ``rejections`` holds the video's reason, then the replay's if it
    failed too."""
    out["rejections"] = [relative_to_run(video_error, source.run_dir)]
    try:
        replay = add_replay(record, bank, settings, source)
    except SETUP_ERRORS:
        raise
    except Exception as error:
        out["rejections"].append(relative_to_run(stage_error("replay", error), source.run_dir))
        return
    out["replay_entry"] = replay["entry"]
    out["replay_not_narrowed"] = dict(replay.get("not_narrowed") or {})
    details["replay"] = replay
    if replay["entry"]:
        link_entries(bank, replay["entry"], {"converted_rejections": list(out["rejections"])})
