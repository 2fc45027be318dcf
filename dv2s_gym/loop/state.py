"""A loop's record and the loop being run: ``loop.json`` (:class:`LoopState`: settings, starting scenarios, every
round's finished steps, written atomically), its paths inside the loop folder (written relative to it, so a moved
folder resumes where it is), the checks a resumed loop's record must pass, the working bank, and which earlier
rounds a policy descends from (:func:`lineage`)."""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path
from typing import Any, Callable, Dict, Iterable, List, Mapping, Optional, Sequence

from dv2s_gym.loop.measures import REFERENCE_DRIVER
from dv2s_gym.loop.record import LoopStart, RecordedLoopSettings, RoundRecord, SplitRecord
from dv2s_gym.loop.settings import LoopError, LoopSettings
from scenario_bank.atomic import atomic_write_json
from scenario_bank.bank import Bank
from scenario_bank.records import RecordError
from scenario_bank.run_identity import check_format, check_identity, check_run_kind, record_format
from policies.registry import SB3_ALGORITHMS
from policies.run_identity import (CODE_IDENTITY, check_code_unchanged, check_policy_unchanged, code_identity,
                                   resume_fingerprint, run_read_facts, with_recorded_reads)
from scenario_bank.read_files import ReadFile

__all__ = ["IDENTITY", "HOLDOUT_BY", "REFERENCE_FINGERPRINT", "STATE_SCHEMA", "STATE_VERSION", "IN_FOLDER",
           "STAGE_NAMES", "LoopState", "round_spec", "working_bank", "RunningLoop", "earlier_round_spec", "lineage",
           "earlier_sides"]


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


STAGE_NAMES = {"mine": "mining failures", "split": "splitting by family",
                "reference": "held-out: reference driver", "before": "held-out: starting policy",
                "fine_tune": "fine-tuning with the mined scenarios", "control": "control: fine-tuning without them",
                "after": "held-out: fine-tuned and control", "untouched": "untouched scenario set",
                "regress": "regression test on the starting bank"}


class LoopState:
    """``loop.json``: its settings (:attr:`settings`, a :class:`~dv2s_gym.loop.record.RecordedLoopSettings`),
    the starting bank and scenarios (:attr:`start`, a :class:`~dv2s_gym.loop.record.LoopStart` once chosen)
    and every round (:attr:`rounds`, each a :class:`~dv2s_gym.loop.record.RoundRecord` replaced as its steps
    finish); atomic writes."""

    def __init__(self, path: Path, settings: Dict[str, Any]) -> None:
        self.path = path
        self.exclude = [path.parent, settings.get("bank_dir")]  # the loop's own files are no code it runs
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
                    CODE_IDENTITY: code_identity(exclude=self.exclude)}
        self.rounds: List[RoundRecord] = _read_rounds(data.pop("rounds"), path)
        self.settings: RecordedLoopSettings = _read_part(RecordedLoopSettings, data.pop("settings"), path)
        start = data.pop("start", None)
        self.start: Optional[LoopStart] = None if start is None else _read_part(LoopStart, start, path)
        self.extra = data  # the record's format and any top-level keys, written back as read

    def save(self) -> None:
        """Write ``loop.json`` atomically, each path inside the loop folder relative to it."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        folder = self.path.parent
        start = None if self.start is None else _in_folder(self.start.to_dict(), folder, write=True)
        rounds = [_in_folder(record.to_dict(), folder, write=True) for record in self.rounds]
        atomic_write_json(self.path, {**self.extra, "settings": self.settings.to_dict(), "start": start,
                                      "rounds": rounds}, indent=1)

    def add_reads(self, reads: Iterable[ReadFile] = (), records: Iterable[Path] = ()) -> bool:
        """Add to the loop's code identity the user's files the code read (checked unchanged when the loop resumes):
        those this process read, ``reads`` (read by a pool's workers) and those a run of a step recorded in its
        own record (``records``: a mining run's ``settings.json``, a regression run's ``run.json``), but the loop's
        own files; ``True`` when one was new (written by the next :meth:`save`)."""
        identity = dict(self.extra.get(CODE_IDENTITY) or {})
        merged = {**identity, **{key: value for key, value in run_read_facts(self.exclude, reads,
                                                                             covered=identity).items()
                                 if key not in identity}}
        for record in records:
            merged = with_recorded_reads(_recorded_code(Path(record)), merged)
        self.extra[CODE_IDENTITY] = merged
        return merged != identity

    def record_reads(self, reads: Iterable[ReadFile] = ()) -> None:
        """:meth:`add_reads` of this process and of ``reads``, written to ``loop.json`` at once when one is new
        (before the episode whose workers read it is saved)."""
        if self.add_reads(reads):
            self.save()

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


def _recorded_code(record: Path) -> Dict[str, Any]:
    """The code identity a run's record holds (a mining run's ``settings.json`` at its top, a regression run's
    ``run.json`` in its settings); empty when there is no such file (a step that ran no such run)."""
    if not record.is_file():
        return {}
    data = json.loads(record.read_text(encoding="utf-8"))
    holder = data if CODE_IDENTITY in data else data.get("settings") or {}
    return dict(holder.get(CODE_IDENTITY) or {})


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
            elif step in STAGE_NAMES and not isinstance(value, dict):
                return f"round {number}'s {step!r} step is not an object"
        for key in _ROUND_TEXTS:
            if record.get(key) is not None and not isinstance(record[key], str):
                return f"round {number}'s {key!r} is not text"
        if any(isinstance(t, bool) or not isinstance(t, (int, float)) for t in record.get("timings", {}).values()):
            return f"round {number} has a timing that is not a number"
    return None


def round_spec(spec: Any, folder: Path, out: Path) -> str:
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


def working_bank(out: Path, bank_dir: Optional[str]) -> str:
    """The bank the loop adds to: ``bank_dir`` itself, or a copy of the shipped bank in ``out/bank``."""
    if bank_dir is not None:
        return str(Path(bank_dir).resolve())

    target = out / "bank"
    if not target.is_dir() or not any(target.iterdir()):
        Bank().copy_to(target)  # atomic: a killed copy leaves no half bank behind
    return str(target.resolve())


@dataclasses.dataclass
class RunningLoop:
    """A loop being run: its settings, record, working bank and the env configs its steps use."""

    settings: LoopSettings
    state: "LoopState"
    out: Path
    bank: str
    start_names: List[str]
    env_config: Dict[str, Any]
    fine_tune_config: Dict[str, Any]
    workers: int
    progress: bool
    log: Callable[[str], None]


def earlier_round_spec(spec: Any, loop: RunningLoop, number: int) -> str:
    """``spec`` read back from ``loop.json`` as the starting policy or the fine-tuned checkpoint of a round
    before ``number`` (anything else is refused, as :func:`round_spec` does)."""
    if spec == loop.state.settings.policy:
        return spec
    for earlier in range(number - 1, 0, -1):
        try:
            return round_spec(spec, loop.out / f"round_{earlier}" / "policy", loop.out)
        except LoopError:
            continue
    return round_spec(spec, loop.out / f"round_{max(number - 1, 1)}" / "policy", loop.out)  # raises, naming it


def lineage(loop: RunningLoop, rounds: Sequence[RoundRecord], current: str) -> List[RoundRecord]:
    """The earlier ``rounds`` whose fine-tuned policy ``current`` descends from, latest first: a round whose
    policy was not adopted (REJECTED, NOT ACCEPTED) trained nothing the next rounds start from."""
    chain: List[RoundRecord] = []
    for number in range(len(rounds), 0, -1):
        record = rounds[number - 1]
        if record.new_policy is None:
            continue
        try:
            spec = earlier_round_spec(record.new_policy, loop, number + 1)
        except LoopError:
            continue
        if spec == current:
            chain.append(record)
            current = record.policy
    return chain


def earlier_sides(rounds: Sequence[RoundRecord]) -> tuple:
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
