"""``dv2s mine``: sample scenes, run a policy on them, keep and cluster its failures.

The run is a folder (``out``)::

    settings.json     what the run mines (policy, sampler, seed, scenarios, bank, env config, monitors)
    episodes.jsonl    one record per finished episode (:class:`~scenario_bank.records.EpisodeRecord`), appended and
                      fsynced as it arrives
    sampler.pkl       the sampler's state: after the last chunk whose outcomes it was fed (chunk schedule),
                      or the window schedule with its drawn, not yet fed scenes (window schedule)
    traces/           the trace of every failed episode
    failures/         per converted cluster: failure video, trace and the D-V2S conversion
    conversions.jsonl one record per converted cluster
    report.json/.md/.html

An adaptive sampler (cross-entropy, bandit, split, novelty-bandit) runs on the sliding-window schedule
(``settings.json`` ``"schedule": "window"``, :mod:`dv2s_gym.mining.sampling.window`): ``batch`` scenes
are drawn ahead, each outcome is fed back in index order as soon as every earlier one has
been, and each outcome fed lets the sampler draw one more scene, which goes straight to a
worker (a backend with ``streams = True``, the local pool; a backend that does not stream,
such as Ray, runs the window's outstanding scenes call after call: the same records, with
an idle tail per call). Every draw and record depends on the seed and ``batch`` only, not
on the number of workers or the timing.

Non-adaptive samplers (random, halton) run on the chunk schedule (``"schedule": "chunks"``), in chunks
of ``batch`` scenes: the sampler draws a chunk, the backend runs it, and the outcomes are
fed back in index order before the next chunk is drawn (a non-adaptive sampler sends up
to :data:`LOOKAHEAD_CHUNKS` chunks at once: its draws do not depend on outcomes).

A run killed at any point and started again with the same ``out`` loses no finished
episode and produces the same records as an uninterrupted run: the sampler is restored
from its checkpoint (or rebuilt by replaying the draws and feeding it the recorded
outcomes in the schedule's order), and only the missing episodes run.
"""

from __future__ import annotations

import fcntl
import importlib.util
import json
import os
import shutil
import time
from collections import Counter
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Dict, Iterator, List, Mapping, Optional, Sequence

import numpy as np
from tqdm.auto import tqdm

from dv2s_gym.mining.sampling import space as space_module
from dv2s_gym.mining.cluster import cell_id, cluster_failures, cluster_id, group
from dv2s_gym.mining.conversion.settings import ConversionSettings
from dv2s_gym.mining.conversion.episodes import reference_passed
from dv2s_gym.mining.conversion.files import cluster_slug, CONVERSION_DIR, provenance_run_path
from dv2s_gym.mining.conversion.rejection import SETUP_ERRORS
from dv2s_gym.mining.conversion.convert import convert_failure
from dv2s_gym.mining.conversion.record import ConversionRecord, ConversionStatus, read_conversions
from dv2s_gym.mining.errors import MiningError
from dv2s_gym.mining.failure_state import is_novel
from dv2s_gym.mining.family import record_family, scenario_family
from dv2s_gym.mining.jsonl import JsonlAppender
from dv2s_gym.mining.monitors import kind_label, types_without_detector
from dv2s_gym.mining.report import write_reports
from dv2s_gym.mining.report_text import error_warning, replaced_text
from dv2s_gym.mining.sampling.samplers import SceneSampler, is_adaptive, make_sampler, sampler_params, scene_proposal
from dv2s_gym.mining.settings import (DEFAULT_BATCH, FEEDBACKS, MineSettings, read_run_settings, RunOrigin,
                                      RunSettings, SETTINGS_FILE)
from dv2s_gym.mining.tasks import MineTask
from dv2s_gym.mining.sampling.window import SCHEDULES, WindowSchedule
from dv2s_gym.mining.write_errors import from_os_error, is_write_failure, run_write_error
from dv2s_gym.workers import backends
from dv2s_gym.workers.errors import WorkerError
from dv2s_gym.workers.pool import default_workers
from dv2s_gym.workers.settings import WorkerSettings
from scenario_bank.atomic import atomic_write_bytes, atomic_write_json
from scenario_bank.bank import Bank, BankError
from scenario_bank.named_registry import replaced_built_ins
from scenario_bank.extras import missing_extra_message
from scenario_bank.records import EpisodeRecord, JsonRecord, RecordError
from scenario_bank.failure_types import failure_table
from scenario_bank.jail import JailUnavailableError, require_jail
from scenario_bank.run_paths import as_read, loop_folder, record_paths, resume_fix
from scenario_bank.run_identity import (BANK_IDENTITY, bank_identity, check_bank_unchanged, check_format,
                                       check_identity, check_run_kind, record_format)
from policies.registry import load_policy
from policies.run_identity import (CODE_IDENTITY, RESUME_FINGERPRINT, check_code_unchanged, check_policy_unchanged,
                                   code_identity, resume_fingerprint, ReadsRecorder, with_recorded_reads)

__all__ = ["MineRun", "MineSettings", "RunOrigin", "WorkerSettings", "FEEDBACKS", "mine", "read_records",
           "episode_seed", "SETTINGS_VERSION", "progress_bar"]

SETTINGS_SCHEMA = "dv2s-mine"
SETTINGS_VERSION = 3
"""The format of a mining run's ``settings.json`` (bumped when its fields change; a run folder of another format is
refused on resume)."""
LOOKAHEAD_CHUNKS = 16
"""Whole chunks a non-adaptive sampler (random, halton) sends to the workers at once."""
REFERENCE_FINGERPRINT = "reference_fingerprint"
"""The key under which ``settings.json`` records the reference driver's
:func:`~policies.run_identity.resume_fingerprint`."""
_RESUME_KEYS = ("policy",) + MineSettings.resume_keys()
"""The keys of ``settings.json`` a resumed run must share with the recorded ones."""
_SPACE_KEYS = ("scenarios",)
"""Identity keys known only once the scene space is built (the scenario names it resolved); the others are compared
before building it, which takes minutes on a loaded machine."""


@dataclass
class MineRun:
    """What a mining run found (the run folder holds everything, this is a summary): the ``policy`` mined, the
    run's ``settings`` (its batch, scenarios and bank as the run resolved them), its ``records``
    (:class:`~scenario_bank.records.EpisodeRecord`, given as records or their JSON objects), the behaviour
    cluster of each failure by index, the conversions and the reports written."""

    out: Path
    policy: str
    settings: MineSettings
    records: List[EpisodeRecord]
    clusters: Dict[int, str]
    conversions: List[ConversionRecord] = field(default_factory=list)
    reports: Dict[str, Path] = field(default_factory=dict)
    seconds: float = 0.0

    def __post_init__(self) -> None:
        self.records = [EpisodeRecord.from_dict(r) for r in self.records]  # records given as their JSON objects

    @property
    def failures(self) -> List[EpisodeRecord]:
        """Records of failed episodes."""
        return [r for r in self.records if r.failed]

    @property
    def avoidable(self) -> List[EpisodeRecord]:
        """Failures the reference driver avoided in the same scene (they count against the policy)."""
        return [r for r in self.failures if r.avoidable is not False]

    @property
    def distinct_clusters(self) -> int:
        """Distinct failure clusters (behaviours, :mod:`dv2s_gym.mining.cluster`)."""
        return len(set(self.clusters.values()))

    @property
    def errors(self) -> List[EpisodeRecord]:
        """The episode records that ended in an error (they count in no failure figure)."""
        return [r for r in self.records if r.error]

    @property
    def all_errored(self) -> bool:
        """Whether every episode ended in an error, so the run measured nothing (a command should fail)."""
        return bool(self.records) and len(self.errors) == len(self.records)

    def _errored_scenarios(self) -> str:
        """`` (scenario A 2, scenario B 1)``: where the errored episodes were; empty when none errored."""
        counts = Counter(str(r.scenario) for r in self.errors)
        return f" ({', '.join(f'{name} {n}' for name, n in sorted(counts.items()))})" if counts else ""

    def summary(self) -> str:
        """A few lines for the terminal: episodes, failures, clusters, conversions, and a WARNING line when
        episodes ended in an error."""
        errors = len(self.errors)
        restarted = sum(1 for r in self.records if r.worker_restarts)
        failures = self.failures
        kinds = Counter(r.failure.kind for r in failures)
        kinds_by_type = Counter(r.failure.type for r in failures)
        avoidable_clusters = {self.clusters[int(r.index)] for r in self.avoidable}
        status = Counter(c.status for c in self.conversions)
        lines = [
            f"{len(self.records)} episodes of {self.policy} ({self.settings.sampler} sampler), "
            f"{errors} error{'s' if errors != 1 else ''}{self._errored_scenarios()}, "
            + (f"{restarted} finished after their worker crashed or hung and was replaced, " if restarted else "")
            + f"{self.seconds:.0f} s",
            f"{len(failures)} failures "
            f"({', '.join(f'{kind_label(k)} {n}' for k, n in kinds.most_common()) or 'none'}); "
            + (f"{len(self.avoidable)} avoidable by {self.settings.reference}" if self.settings.reference
             else "avoidability not checked (no reference driver)"),
            f"{self.distinct_clusters} distinct behaviours"
            # without a reference driver no failure is known to be avoidable: no count of them
            + (f", {len(avoidable_clusters)} with avoidable failures" if self.settings.reference else "") + "; "
            f"{len({(record_family(r), r.failure.kind) for r in failures})} (scenario family, failure type) "
            f"pairs, {len({record_family(r) for r in failures})} scenario families with a failure; "
            f"{kinds_by_type.get('collision', 0)} collisions, {kinds_by_type.get('stall', 0)} stalls",
        ]
        if replaced_built_ins():  # what the counts above count under a replaced name is a plug-in's
            lines.append(replaced_text(replaced_built_ins()))
        if self.conversions:
            lines.append(f"converted {len(self.conversions)}: kept {status[ConversionStatus.KEPT]}, merged "
                         f"{status[ConversionStatus.MERGED]}, rejected {status[ConversionStatus.REJECTED]}")
        if errors:
            first = str(self.errors[0].error).strip().splitlines()
            lines.append(error_warning(errors, len(self.records), first[-1] if first else ""))
        return "\n".join(lines)


def episode_seed(seed: int, index: int) -> int:
    """The env seed of episode ``index`` of a run seeded ``seed`` (distinct per index, below 2**31)."""
    return int(np.random.SeedSequence([int(seed), int(index), 0x6D696E65]).generate_state(1)[0] % (2**31 - 1))


def read_records(path: Path) -> List[EpisodeRecord]:
    """The records of an ``episodes.jsonl`` (a torn last line, left by a kill mid-write, is dropped), in index
    order; a line that is not an episode record is a :class:`MiningError` naming it and its bad field."""
    rows: Dict[int, Dict[str, Any]] = {}
    if not path.is_file():
        return []
    lines = path.read_bytes().split(b"\n")
    for number, line in enumerate(lines):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except json.JSONDecodeError:
            if number >= len(lines) - 2:  # the last line: an interrupted append
                continue
            raise MiningError(f"{path}, line {number + 1} is corrupt; remove that line to resume the run") from None
        if not isinstance(row, dict) or not isinstance(row.get("index"), int):
            raise MiningError(f"{path}, line {number + 1} is not an episode record (no integer 'index'); "
                              "remove that line to resume the run")
        rows[int(row["index"])] = row
    ordered = [rows[i] for i in sorted(rows)]
    records = []
    for row in ordered:
        try:
            records.append(EpisodeRecord.from_dict(row))
        except RecordError as error:
            raise MiningError(f"{path}, episode {row['index']}: {error}; remove that line to resume the run") from None
    return records


@contextmanager
def _run_lock(out: Path) -> Iterator[None]:
    handle = open(out / ".lock", "a+")
    try:
        try:
            fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise MiningError(f"another miner is running in {out}; wait for it or pass another --out") from None
        yield
    finally:
        handle.close()


class _Recorder:
    """Turns finished results into records: appended to ``episodes.jsonl``, kept in ``done``, counted on
    the progress bar (failures and distinct clusters)."""

    def __init__(self, appender: JsonlAppender, done: Dict[int, EpisodeRecord], sampler: str, out: Path, bar,
                 reads: Optional[ReadsRecorder] = None) -> None:
        self.appender, self.done, self.sampler, self.out, self.bar = appender, done, sampler, out, bar
        self.reads = reads
        counted = [r for r in done.values() if r.failed]
        self.found = {cluster_id(r) for r in counted}
        self.failed = len(counted)

    def add(self, result: Dict[str, Any], task: MineTask, spec) -> None:
        problem = result.get("write_error")
        if problem:  # the episode's trace could not be written: stop before recording it, a resume reruns it
            raise run_write_error(problem.get("path"), problem.get("errno"), problem.get("strerror"))
        record = _complete(result, task, spec, self.sampler, self.out)
        if self.reads is not None:  # the files the episode's worker read are recorded before the episode is
            self.reads.record()
        self.appender.append(record)
        self.done[record.index] = record
        if record.failed:
            self.found.add(cluster_id(record))
            self.failed += 1
        if self.bar is not None:
            self.bar.update(1)
            self.bar.set_postfix(failures=self.failed, clusters=len(self.found))


def _recorded(policy: str, settings: MineSettings, scenarios: Sequence[str],
              space_description: Dict[str, Any], out: Optional[Path] = None) -> Dict[str, Any]:
    """The run's ``settings.json``: :meth:`MineSettings.recorded` (with the run's resolved batch and bank) with the
    policy, the ``scenarios`` (the keys :data:`_RESUME_KEYS` name are its identity), the fingerprints of the policy
    and of the reference driver (:func:`~policies.run_identity.resume_fingerprint`: a resume with a changed checkpoint
    or module is refused), the scenarios' scripts (:func:`~scenario_bank.run_identity.bank_identity`) and the code
    (:func:`~policies.run_identity.code_identity`: dv2s's sources, plug-ins, detectors, replaced built-ins, the user's
    files read so far but those in ``out`` and the bank)."""
    reference = settings.reference
    return {**record_format(SETTINGS_SCHEMA, SETTINGS_VERSION), "policy": policy, **settings.recorded(),
            "batch": int(settings.batch), "scenarios": list(scenarios), SELECTION: _selection(settings),
            "space": space_description,
            RESUME_FINGERPRINT: resume_fingerprint(policy),
            REFERENCE_FINGERPRINT: resume_fingerprint(reference) if reference else None,
            BANK_IDENTITY: bank_identity(Bank(settings.bank_dir), scenarios),
            CODE_IDENTITY: code_identity(exclude=_own_folders(out, settings))}


def _own_folders(out: Optional[Path], settings: MineSettings) -> List[Any]:
    """The folders whose files are the run's own, not code it runs: the run folder (and the ``dv2s loop`` folder
    holding it: the policy a round fine-tuned is fingerprinted as the policy) and the bank."""
    return [folder for folder in (out, loop_folder(out) if out else None, settings.bank_dir) if folder]


SELECTION = "selection"
"""The ``settings.json`` key of the scenario selection as asked when the run began (``["tag:mined"]``; ``None`` for
the whole bank; a resume never rewrites it): a resume asking the same terms, in any order, mines the scenarios
they resolved to when the run began, though the bank has grown since (by this run's own conversions, say)."""


def _selection(settings: MineSettings) -> Optional[List[str]]:
    return list(settings.scenarios) if settings.scenarios is not None else None


def _same_terms(asked: Sequence[str], recorded: Optional[Sequence[str]]) -> bool:
    """Whether the ``asked`` selection names the bank names and tags of the ``recorded`` one, whatever their order
    or repetition (a recorded whole bank, ``None``, is no selection of terms)."""
    return recorded is not None and set(asked) == set(recorded)


@dataclass(frozen=True)
class _Mining:
    """A run being mined: its folder, policy, settings (batch, scenarios and bank as resolved), schedule
    (:data:`~dv2s_gym.mining.sampling.window.SCHEDULES`) and scene space."""

    out: Path
    policy: str
    settings: MineSettings
    schedule: str
    space: Any

    def new_sampler(self) -> SceneSampler:
        """A fresh sampler of the run (nothing drawn or fed)."""
        options = self.settings.sampler_options
        return make_sampler(self.settings.sampler, self.space, self.settings.seed, dict(options) if options else None)

    def task(self, index: int, spec) -> MineTask:
        """The worker's task of episode ``index`` on the scene ``spec``."""
        settings = self.settings
        seed = episode_seed(settings.seed, index)
        return MineTask(index=index, policy=self.policy, scenario=spec.scenario, seed=seed, params=spec.params,
                        reference=settings.reference, family=scenario_family(str(spec.scenario), settings.bank_dir),
                        env_config=settings.env_config, bank_dir=settings.bank_dir,
                        trace_dir=str(self.out / "traces"), monitor=settings.monitor,
                        failure_types=tuple(row.name for row in failure_table()))


def _read_settings(out: Path) -> Optional[RunSettings]:
    """The run folder's ``settings.json`` (``None`` when there is none); a damaged one, or one of another format
    (:data:`SETTINGS_VERSION`), is refused in one line naming the file and the fix."""
    check_run_kind(out, SETTINGS_SCHEMA, error=MiningError)
    saved = read_run_settings(out)
    if saved is not None:
        check_format(saved.values, SETTINGS_SCHEMA, SETTINGS_VERSION, folder=out, what="a mining run",
                     file=SETTINGS_FILE, error=MiningError)
    if saved is not None and saved.scenarios is None:
        raise MiningError(f"{saved.path} is not a mining run's settings (no list of scenarios); restore it, or choose "
                          "another --out (or delete the run folder) to start the run over")
    return saved


def _check_resume(saved: Mapping[str, Any], settings: Dict[str, Any], out: Path,
                  keys: Sequence[str] = _RESUME_KEYS) -> None:
    check_identity(saved, settings, keys, run=f"{out} holds a mining run",
                   fix=resume_fix(out, "resume it with the same settings or pass another --out"))


def _restore_sampler(mining: _Mining, records: Dict[int, EpisodeRecord]) -> SceneSampler:
    """The sampler after every complete chunk already in ``records``: from its checkpoint when that is
    current, else rebuilt by drawing the chunks again and feeding their recorded outcomes."""
    out, space, batch = mining.out, mining.space, mining.settings.batch
    complete = 0
    while all(i in records for i in range(complete * batch, (complete + 1) * batch)):
        complete += 1
    checkpoint = out / "sampler.pkl"
    if checkpoint.is_file():
        try:
            sampler = SceneSampler.loads(checkpoint.read_bytes())
        except Exception:
            sampler = None
        if sampler is not None and sampler.fed == complete * batch:
            return sampler
    sampler = mining.new_sampler()
    seen: set = set()
    for chunk in range(complete):
        drawn = sampler.draw(batch)
        for offset, (point, info) in enumerate(drawn):
            index = chunk * batch + offset
            spec = space.decode(point)
            if spec.scenario != records[index].scenario or spec.params != records[index].params:
                raise MiningError(f"{out}: episode {index} in episodes.jsonl does not match the sampler's draw "
                                  "(the run was made by another version); pass another --out")
            sampler.feed(point, info, _feedback(records[index], seen, mining.settings.feedback))
    return sampler


def _schedule(saved: Optional[RunSettings], sampler: str, out: Path) -> str:
    """The run's schedule: an adaptive sampler streams with a sliding window, a non-adaptive one runs in chunks;
    a run folder recorded with another schedule is refused."""
    schedule = "window" if is_adaptive(sampler) else "chunks"
    if saved is not None and saved.schedule != schedule:
        raise MiningError(f"{out}/settings.json records the schedule {saved.schedule!r}, not {schedule!r} "
                          f"(the {', '.join(SCHEDULES)} schedules are those of the adaptive and the non-adaptive "
                          "samplers); it was not written by this dv2s-gym: pass another --out")
    return schedule


def _restore_window(mining: _Mining, records: Dict[int, EpisodeRecord]) -> WindowSchedule:
    """The window schedule after feeding every recorded outcome it can: from its checkpoint when that is
    usable, else from a fresh sampler; either way the remaining recorded outcomes are fed in the schedule's
    order, so the state is the one an uninterrupted run had at that point."""
    out, batch, budget = mining.out, mining.settings.batch, mining.settings.budget
    window = None
    checkpoint = out / "sampler.pkl"
    if checkpoint.is_file():
        try:
            window = WindowSchedule.loads(checkpoint.read_bytes())
        except MiningError:
            window = None
        if window is not None and (window.window != batch or any(i not in records for i in range(window.fed))):
            window = None  # another window, or ahead of the records: rebuild
    if window is None:
        window = WindowSchedule(mining.new_sampler(), batch)
    mode = mining.settings.feedback
    window.advance(records, budget, lambda record, seen: _feedback(record, seen, mode), _matcher(out, mining.space))
    return window


def _matcher(out: Path, space) -> Any:
    def check(index: int, point: Any, record: EpisodeRecord) -> None:
        spec = space.decode(point)
        if spec.scenario != record.scenario or spec.params != record.params:
            raise MiningError(f"{out}: episode {index} in episodes.jsonl does not match the sampler's draw "
                              "(the run was made by another version); pass another --out")
    return check


def _run_chunks(mining: _Mining, scene_sampler: SceneSampler, pool, recorder: "_Recorder") -> None:
    """Run the episodes of a chunk-scheduled run: draw ``batch`` scenes, run them, feed their outcomes in
    index order, draw the next chunk. An adaptive sampler draws a chunk only once it has been fed the last
    one's outcomes; a non-adaptive one learns nothing from them, so several whole chunks go to the workers
    at once (the same draws, without idle workers at the end of every chunk)."""
    done, out, space = recorder.done, mining.out, mining.space
    budget, batch, mode = mining.settings.budget, mining.settings.batch, mining.settings.feedback
    seen: set = set()
    for i in range(scene_sampler.fed):  # what the feedback had seen when the sampler was last fed
        _feedback(done[i], seen, mode)
    lookahead = 1 if is_adaptive(mining.settings.sampler) else LOOKAHEAD_CHUNKS
    chunk = scene_sampler.fed // batch
    while chunk * batch < budget:
        count = max(1, min(lookahead, budget // batch - chunk))
        draws = [scene_sampler.draw(batch) for _ in range(count)]
        first = chunk * batch
        indices = range(first, first + count * batch)
        pairs = [pair for drawn in draws for pair in drawn]
        specs = {i: _with_proposal(space.decode(point), scene_sampler.proposal(i)) for i, (point, _) in zip(indices, pairs)}
        tasks = [mining.task(i, specs[i]) for i in indices if i not in done and i < budget]
        by_id = {t.id: t for t in tasks}

        def handle(result: Any) -> None:
            result = _worker_result(result)
            task = by_id[result["id"]]
            recorder.add(result, task, specs[task.index])

        pool.run([task.to_json() for task in tasks], handle)
        if all(i in done for i in indices):
            for i, (point, info) in zip(indices, pairs):
                scene_sampler.feed(point, info, _feedback(done[i], seen, mode))
            atomic_write_bytes(out / "sampler.pkl", scene_sampler.dumps())
        chunk += count


def _run_window(mining: _Mining, window: WindowSchedule, pool, recorder: "_Recorder") -> None:
    """Run the episodes of a window-scheduled run: a streaming backend gets each new draw as soon as the
    outcome that allows it has been fed (the workers never wait for a chunk's last episode); any other
    backend runs the window's outstanding scenes, call after call (the same draws and records, with an
    idle tail per call)."""
    mode, budget, out = mining.settings.feedback, mining.settings.budget, mining.out
    done = recorder.done
    check = _matcher(out, mining.space)
    specs: Dict[int, Any] = {}
    by_id: Dict[str, MineTask] = {}
    last_saved = [window.fed]

    def tasks_for(indices: Sequence[int]) -> List[Dict[str, Any]]:
        tasks = []
        for i in indices:
            if i >= budget or i in done:
                continue
            specs[i] = _with_proposal(mining.space.decode(window.pending[i][0]), window.sampler.proposal(i))
            task = mining.task(i, specs[i])
            by_id[task.id] = task
            tasks.append(task.to_json())
        return tasks

    def handle(result: Any) -> None:
        result = _worker_result(result)
        task = by_id.pop(result["id"])
        recorder.add(result, task, specs.pop(task.index))

    def more() -> List[Dict[str, Any]]:
        new = window.advance(done, budget, lambda record, seen: _feedback(record, seen, mode), check)
        if window.fed - last_saved[0] >= window.window or window.fed >= budget:
            atomic_write_bytes(out / "sampler.pkl", window.dumps())
            last_saved[0] = window.fed
        return tasks_for(new)

    streams = getattr(pool, "streams", False)
    while True:
        tasks = tasks_for(window.outstanding(done, budget))
        if not tasks:
            break
        before = len(done)
        if streams:
            pool.run(tasks, handle, more=more)
        else:
            pool.run(tasks, handle)
            more()
        if len(done) == before:
            raise MiningError(f"the {type(pool).__name__} backend returned no result for {len(tasks)} episodes; "
                              "see its log, then run the same command again to resume")
    more()  # the checkpoint of the finished run


_REPEAT = 9.0  # what a repeated failure is fed under "novelty": the robustness of a scene without a near miss


def _feedback(record: EpisodeRecord, seen: set, mode: str) -> float:
    """The value fed to the sampler for ``record``; ``seen`` holds the parameter cells (:func:`cell_id`) of the
    failures fed before it (in index order) and is updated."""
    rho = record.rho
    if rho is None or record.error:
        return 1.0
    if record.failure and mode == "cluster-novelty":
        cluster = ("cluster", cluster_id(record))
        repeat = cluster in seen
        seen.add(cluster)
        return _REPEAT if repeat else float(rho)
    if record.failure and mode == "state-novelty":
        state = record.failure_state
        scenario = str(record.scenario)
        archive = [entry[2:] for entry in seen if isinstance(entry, tuple) and entry[:2] == ("state", scenario)]
        if state is not None:
            seen.add(("state", scenario) + tuple(float(x) for x in state))
        return float(rho) if is_novel(state, archive) else _REPEAT
    if record.failure:
        cluster = cell_id(record) if mode != "scenario-novelty" else f"scenario:{record.scenario}"
        repeat = cluster in seen
        seen.add(cluster)
        if repeat and mode in ("novelty", "scenario-novelty"):
            return _REPEAT
    return float(rho)


def mine(policy: str, settings: MineSettings, *, out: os.PathLike | str, workers: Optional[WorkerSettings] = None,
         progress: bool = True, reports: bool = True, origin: Optional[RunOrigin] = None) -> MineRun:
    """Mine ``policy``'s failures over ``settings.budget`` episodes; resumable (same ``out``).

    Args:
        policy: the policy spec (:func:`policies.registry.load_policy`).
        settings: what the run mines (:class:`~dv2s_gym.mining.settings.MineSettings`: sampler, scenarios,
            bank, seed, monitors, conversion).
        out: the run folder (created; an existing run with the same settings is resumed
            and may be given a larger budget).
        workers: where episodes run (as ``dv2s regress``: a local process pool or Ray; default every core
            of this machine); a worker that crashes or hangs longer than its ``timeout`` on one episode is
            replaced and the episode retried once.
        progress: progress bars on stderr.
        reports: write report.json, report.md and report.html at the end.
        origin: what started this run (:class:`~dv2s_gym.mining.settings.RunOrigin`), shown beside the seed in its
            reports: ``dv2s loop`` passes ``RunOrigin("dv2s loop", seed=S, round=R)`` because it mines each round
            with a seed derived from its own. Not a setting: a resumed run may be given another.
    """
    started = time.perf_counter()
    if origin is not None and not isinstance(origin, RunOrigin):
        raise MiningError(f"origin must be a RunOrigin (the command, its seed and round), not {origin!r}")
    _check_can_mine(policy, settings)
    out = Path(out)
    for flag, folder in (("--out", out), ("--bank", Path(settings.bank_dir) if settings.bank_dir else None)):
        if folder is not None and folder.exists() and not folder.is_dir():
            raise MiningError(f"{flag} {folder} is a file, not a folder; pass a folder (a new one is created)")
    created = not out.exists()
    try:
        out.mkdir(parents=True, exist_ok=True)
        (out / "traces").mkdir(exist_ok=True)
    except OSError as error:
        raise MiningError(f"cannot create the run folder {out}: {error.strerror}; pass a writable --out") from None
    try:
        try:
            return _mine_in(out, started, policy, settings, workers or WorkerSettings(), progress, reports, origin)
        except OSError as error:
            if not is_write_failure(error):
                raise
            # a full disk, a quota, a read-only file system: the file, the problem and the fix in one line
            raise from_os_error(error) from None
    except BaseException:
        if created:
            _remove_if_empty(out)  # bad input found late (an unknown scenario) leaves no empty run folder behind
        raise


def _check_can_mine(policy: str, settings: MineSettings) -> None:
    """Refuse, before any work, a run that cannot start: no VerifAI, a failure type without a detector, bad sampler
    options, a misspelt env config key, an unknown policy, conversions without a jail to run them in."""
    if importlib.util.find_spec("verifai") is None:  # the core install has no mining extra
        raise MiningError(missing_extra_message("verifai", "failure mining"))
    undetected = types_without_detector()
    if undetected:  # else every episode would end in an error
        raise MiningError(f"failure type(s) {', '.join(undetected)} have no detector: register one for each with "
                          "dv2s_gym.mining.monitors.register_detector (in each process that detects) before mining")
    sampler_params(settings.sampler, dict(settings.sampler_options) if settings.sampler_options else None)
    from envs.dv2s_env import check_env_config

    check_env_config(settings.env_config)  # a misspelt key fails here, in one line, not in every episode
    # an unknown spec or broken checkpoint fails here, in one line, before any worker starts; so does a checkpoint
    # trained with another observation than the env config's
    load_policy(policy).check_env_config(settings.env_config)
    if settings.reference:
        load_policy(settings.reference)
    if settings.convert:
        _check_jail()


def _check_jail() -> None:
    """Refuse to convert where the jail cannot start: the exact replays and generated scripts run only there, so
    every conversion would be rejected with the same reason (e.g. a checkout under /tmp, which the jail hides)."""
    try:
        require_jail("a converted failure (its exact replay and its generated script)")
    except JailUnavailableError as error:
        raise MiningError(f"{' '.join(str(error).split())} Or mine without converting: --no-convert.") from None


def _remove_if_empty(out: Path) -> None:
    """Remove a run folder this call created when no episode reached it (settings, lock, sampler state, an empty
    episode log and trace folder only)."""
    traces, log = out / "traces", out / "episodes.jsonl"
    if (traces.is_dir() and any(traces.iterdir())) or (log.is_file() and log.stat().st_size) or any(
            p.name not in ("traces", "settings.json", ".lock", "episodes.jsonl", "sampler.pkl") for p in out.iterdir()):
        return
    with open(out / ".lock", "a+") as handle:
        try:
            fcntl.flock(handle.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            return  # another miner started on the same new folder at the same moment and runs in it
        shutil.rmtree(out, ignore_errors=True)


def _mine_in(out: Path, started: float, policy: str, settings: MineSettings, workers: WorkerSettings,
             progress: bool, reports: bool, origin: Optional[RunOrigin]) -> MineRun:
    """The body of :func:`mine` once the input is checked and the run folder exists."""
    bank_dir = str(Path(settings.bank_dir).resolve()) if settings.bank_dir else None
    if settings.convert:
        _own_bank(bank_dir)
    n_workers = int(workers.workers) if workers.workers else (
        1 if workers.backend == "local" and default_workers() < 2 else default_workers())
    with _run_lock(out):
        mining = _open_run(out, policy, settings.replace(bank_dir=bank_dir), origin)
        done = {int(r.index): r for r in read_records(out / "episodes.jsonl")}
        _run_episodes(mining, done, workers, n_workers, progress)
        records = [done[i] for i in sorted(done) if i < settings.budget]
        run = MineRun(out=out, policy=policy, settings=mining.settings, records=records,
                      clusters=cluster_failures(records))
        if settings.convert:
            run.conversions = convert_clusters(run, settings.conversion, bank_dir=bank_dir, progress=progress,
                                               max_conversions=settings.max_conversions)
        else:
            run.conversions = _conversions(out / "conversions.jsonl")
        run.seconds = time.perf_counter() - started
        if reports:
            run.reports = _write_reports(out)
    return run


def _open_run(out: Path, policy: str, settings: MineSettings, origin: Optional[RunOrigin]) -> _Mining:
    """The run in ``out`` (``settings.bank_dir`` resolved): a new run's settings, or a resumed run's checked against
    the ones asked (its own scenarios and batch when none are asked, or the same terms in any order); ``settings.json``
    written (back, with the selection the run began with)."""
    saved = _read_settings(out)
    batch = settings.batch or (saved.batch if saved else DEFAULT_BATCH)  # never the workers: the seed decides the run
    settings = settings.replace(batch=int(batch))
    if saved is not None and saved.scenarios:
        _check_still_in_bank(out, saved.scenarios, settings.bank_dir)
    if saved is not None:  # a changed seed, policy, ... is refused before the space is built, not minutes later
        before_space = as_read(_recorded(policy, settings, saved.scenarios, {}, out), out)
        _check_resume(saved.values, before_space, out, [key for key in _RESUME_KEYS if key not in _SPACE_KEYS])
        # the same spec naming a changed checkpoint or module is refused, naming what changed
        check_policy_unchanged(saved.values, as_read(policy, out), folder=out, run="mining run", error=MiningError)
        if settings.reference:
            check_policy_unchanged(saved.values, as_read(settings.reference, out), folder=out, run="mining run",
                                   error=MiningError, key=REFERENCE_FINGERPRINT, role="reference driver")
        check_code_unchanged(saved.values, run=f"{out} holds a mining run", error=MiningError)
    same_selection = saved is not None and (settings.scenarios is None
                                            or _same_terms(settings.scenarios, saved.values.get(SELECTION)))
    names = saved.scenarios if same_selection else None
    asked = list(settings.scenarios) if settings.scenarios is not None else None
    space = space_module.SceneSpace(names or asked, settings.bank_dir)
    recorded = _recorded(policy, settings, space.scenarios, space.describe(), out)
    if saved is not None:
        recorded[SELECTION] = saved.values.get(SELECTION)  # recorded once, when the run began: a resume keeps it
        # the files the workers of the run's earlier parts read (checked unchanged above) stay part of its identity
        recorded[CODE_IDENTITY] = with_recorded_reads(saved.values.get(CODE_IDENTITY) or {}, recorded[CODE_IDENTITY])
    if saved is not None:
        _check_resume(saved.values, as_read(recorded, out), out)
        check_bank_unchanged(saved.values.get(BANK_IDENTITY), recorded[BANK_IDENTITY],
                             run=f"{out} holds a mining run", error=MiningError)
    schedule = _schedule(saved, settings.sampler, out)
    recorded["schedule"] = schedule
    if origin is not None:
        recorded["origin"] = origin.to_json()
    atomic_write_json(out / SETTINGS_FILE, record_paths(recorded, out))
    return _Mining(out=out, policy=policy, settings=settings.replace(scenarios=tuple(space.scenarios)),
                   schedule=schedule, space=space)


def _check_still_in_bank(out: Path, names: Sequence[str], bank_dir: Optional[str]) -> None:
    """Refuse to resume the run in ``out`` over its recorded scenarios ``names`` when the bank no longer holds one
    (the names come from the run, not from the command line: no did-you-mean)."""
    bank = Bank(bank_dir)
    held = set(bank.names()) | set(bank.problems)
    gone = [name for name in names if name not in held]
    if gone:
        shown = ", ".join(repr(name) for name in gone[:3]) + (f" and {len(gone) - 3} more" if len(gone) > 3 else "")
        raise MiningError(f"{out} holds a mining run over {shown}, which the bank at {bank.root} no longer holds; "
                          "restore it (dv2s bank add or import), or start a new --out folder")


def _run_episodes(mining: _Mining, done: Dict[int, EpisodeRecord], workers: WorkerSettings, n_workers: int,
                  progress: bool) -> None:
    """Run the episodes of the run's budget not in ``done`` (recorded into it), on its schedule."""
    budget = mining.settings.budget
    window, scene_sampler = None, None
    if mining.schedule == "window":
        window = _restore_window(mining, done)
    else:
        scene_sampler = _restore_sampler(mining, done)
    appender = JsonlAppender(mining.out / "episodes.jsonl")
    bar = progress_bar(progress, budget, len([i for i in done if i < budget]))
    try:
        pool = backends.get_backend(workers.backend, workers=n_workers, address=workers.address,
                                    timeout=workers.timeout)
    except WorkerError as error:
        appender.close()
        raise MiningError(str(error)) from None
    try:
        with pool:
            recorder = _Recorder(appender, done, mining.settings.sampler, mining.out, bar,
                                 ReadsRecorder(mining.out / SETTINGS_FILE, pool,
                                               _own_folders(mining.out, mining.settings)))
            if window is not None:
                _run_window(mining, window, pool, recorder)
            else:
                _run_chunks(mining, scene_sampler, pool, recorder)
    finally:
        appender.close()
        if bar is not None:
            bar.close()


def _with_proposal(spec, proposal: Optional[Dict[str, Any]]):
    """``spec`` with the density its point was drawn with, over the scenario's own coordinates (importance
    weights of the failure-rate estimate, :mod:`dv2s_gym.mining.sampling.rate`)."""
    spec.proposal = scene_proposal(proposal, len(spec.point))
    return spec


def _worker_result(result: Any) -> Dict[str, Any]:
    """A worker's result as its JSON object: the episode record the task returned
    (:func:`~dv2s_gym.mining.tasks.run_mine_task`), or the error result a backend gives for a crashed or hung
    worker (a JSON object already)."""
    return result.to_dict() if isinstance(result, JsonRecord) else dict(result)


def _complete(result: Dict[str, Any], task: MineTask, spec, sampler: str, out: Path) -> EpisodeRecord:
    """The episode record from a worker's result (or a backend's error result for a crashed or hung worker)."""
    taken = {k: v for k, v in result.items()
             if k in ("policy", "scenario", "seed", "result", "failure", "rho", "reference", "avoidable", "trace",
                      "error", "family")}
    trace = taken.get("trace")
    return EpisodeRecord.from_dict({
        "index": task.index, "policy": task.policy, "scenario": task.scenario, "seed": task.seed,
        "params": task.params, "result": None, "failure": None, "rho": None, "reference": None,
        "avoidable": None, "trace": None, "error": None, "family": task.family or task.scenario,
        **taken,
        "behaviour": result.get("behaviour"), "failure_state": result.get("failure_state"),
        # a worker crashed or hung on this episode, then a new one finished it
        "worker_restarts": list(result["worker_restarts"]) if result.get("worker_restarts") else None,
        "sampler": sampler, "point": spec.point, "proposal": getattr(spec, "proposal", None),
    }).replace(trace=os.path.relpath(trace, out) if trace else trace,
               null_fields=None)


def _own_bank(bank_dir: os.PathLike | str) -> None:
    """Make ``bank_dir`` a writable bank: a new or empty folder becomes a copy of the shipped bank.

    Miners started at the same moment on one new folder all copy; the first copy lands (atomically) and
    the others, refused because the folder is no longer empty, use it.
    """
    if _has_entries(Path(bank_dir)):
        return
    try:
        Bank().copy_to(bank_dir)  # a bank of one's own starts as the shipped one
    except BankError:
        if not _has_entries(Path(bank_dir)):
            raise


def _has_entries(folder: Path) -> bool:
    return folder.is_dir() and any(not p.name.startswith(".") for p in folder.iterdir())


def convert_clusters(run: MineRun, conversion: ConversionSettings, *, bank_dir: Optional[str],
                     progress: bool = True, max_conversions: Optional[int] = None) -> List[ConversionRecord]:
    """Convert one representative failure per avoidable cluster not converted yet, with ``conversion`` (its policy
    and ``env_config`` replaced by the run's); the conversion records.

    The representative is the cluster's most severe failure (lowest robustness, then
    lowest index) among those whose scene the reference driver passed (:func:`~dv2s_gym.mining.conversion.episodes.reference_passed`;
    among all when there is none: the converted script is judged all the same, but no exact replay is kept). Clusters with more avoidable failures go first; at most
    ``max_conversions`` conversions are made in the run (``None``: every cluster). Each conversion is appended to ``conversions.jsonl`` when it ends, so a
    resumed run converts the remaining clusters only.
    """
    if bank_dir is None:
        raise MiningError("converting failures adds scenarios to a bank: pass a writable bank folder "
                          "(--bank DIR); the shipped bank is read-only")
    path = run.out / "conversions.jsonl"
    existing = _conversions(path)
    converted = {row.cluster for row in existing}
    converted_episodes = {row.index for row in existing}  # a run converted under older cluster ids
    candidates = []
    for cluster, members in sorted(group(run.records).items()):
        avoidable = [r for r in members if r.avoidable is not False]
        if cluster in converted or not avoidable or any(r.index in converted_episodes for r in members):
            continue
        # a failure whose scene the reference driver passed first: only such a scene gets an exact replay entry
        representative = min(avoidable, key=lambda r: (not reference_passed(r), float(r.rho or 0.0),
                                                       int(r.index)))
        candidates.append((-len(avoidable), cluster, representative))
    candidates.sort(key=lambda c: (c[0], c[1]))  # the clusters with most avoidable failures first
    room = None if max_conversions is None else max(0, int(max_conversions) - len(existing))
    todo = [(cluster, record) for _, cluster, record in candidates][:room]
    bank = Bank(bank_dir)
    conversion = conversion.replace(policy=run.policy, env_config=run.settings.env_config)
    appender = JsonlAppender(path)
    bar = progress_bar(progress, len(todo), 0, desc="converting")
    try:
        for cluster, record in todo:
            row = _reached_bank(bank, run.out, cluster)  # killed after the bank write, before its line
            if row is None:
                try:
                    row = convert_failure(record, run.out, conversion, bank=bank, cluster=cluster)
                except SETUP_ERRORS as error:
                    first = (str(error).strip().splitlines() or [type(error).__name__])[0]
                    raise MiningError(f"converting stopped at cluster {cluster} ({len(existing)} converted, the rest "
                                      f"not tried): {first} Rerun the same command when it works; finished "
                                      "episodes and conversions are kept") from None
            row = ConversionRecord.from_dict(row).replace(cluster=cluster)
            appender.append(row)
            existing.append(row)
            if bar is not None:
                bar.update(1)
    finally:
        appender.close()
        if bar is not None:
            bar.close()
    return existing


def _entry_video(entry, provenance: Mapping[str, Any]) -> Optional[str]:
    """The path of a provenance record's video: in the entry's folder when relative to it (as the converter
    writes it), else as recorded."""
    video = provenance.get("video")
    if isinstance(video, str) and video and not os.path.isabs(video):
        return str(entry.folder / video)
    return video


def _reached_bank(bank, out: Path, cluster: str) -> Optional[ConversionRecord]:
    """The conversion row of ``cluster`` when this run already added it to the bank (or merged it into an entry)
    but was killed before writing its ``conversions.jsonl`` line; rebuilt from the entry's provenance, so a
    resumed run neither converts the cluster again nor reports it merged into the entry it made itself."""
    run = Path(out).resolve()
    for entry in bank:
        source = entry.source
        if source.is_replay:
            continue  # the exact replay of a failure is written before its converted script is judged
        found = [(ConversionStatus.KEPT, source.to_dict())] + [(ConversionStatus.MERGED, merged)
                                                               for merged in source.merged or ()]
        for status, provenance in found:
            if provenance_run_path(provenance.get("run"), bank) != run or provenance.get("cluster") != cluster:
                continue

            folder = Path(out) / "failures" / cluster_slug(cluster, provenance.get("index"))
            video, script = folder / "failure.webm", folder / CONVERSION_DIR / "scenario.scenic"
            merged = status == ConversionStatus.MERGED
            return ConversionRecord.from_dict({
                "cluster": cluster, "index": provenance.get("index"), "status": status.value, "reason": None,
                "stage": None, "video": str(video.relative_to(out)) if video.is_file() else _entry_video(entry, provenance),
                "description": provenance.get("description") if merged else entry.description,
                "script": str(script.relative_to(out)) if script.is_file() else None,
                "reproduction": provenance.get("reproduction"), "e2e_sc": provenance.get("e2e_sc"),
                "bank_entry": None if merged else entry.name, "merged_into": entry.name if merged else None,
                **({"merge_reason": provenance.get("how")} if merged else {}),
                "seconds": None, "timings": {}, "recovered_from_bank": True})
    return None


def _conversions(path: Path) -> List[ConversionRecord]:
    """The conversion records of the run's ``conversions.jsonl``; a damaged line is a :class:`MiningError`."""
    try:
        return read_conversions(path)
    except RecordError as error:
        raise MiningError(str(error)) from None


def _write_reports(out: Path) -> Dict[str, Path]:
    return write_reports(out)


def progress_bar(enabled: bool, total: int, initial: int, desc: str = "mining"):
    """A progress bar on stderr counting ``total`` episodes from ``initial`` (``None`` when not ``enabled``)."""
    if not enabled:
        return None

    return tqdm(total=total, initial=initial, desc=desc, unit="ep", dynamic_ncols=True)
