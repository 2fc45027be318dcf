"""The run's output folder as a resumable log: settings in ``run.json``, episodes in ``results.jsonl``.

Every finished episode (a :class:`~scenario_bank.records.RegressEpisode`) is appended to ``results.jsonl`` as
one JSON line (flushed and synced before the next one), so a run that is interrupted - Ctrl-C, a killed
process, a lost machine - keeps every episode that finished. Rerunning with the same output folder
and settings reads the log and runs only what is missing; an episode is never run twice
and never counted twice (a line cut short by the interruption is dropped and rewritten).
Episodes that ended in an error are run again on resume (the error may have been
transient); the newer line replaces the older one.

``run.json`` holds the settings that decide which episodes the run has and what they
produce (policies, bank version, scenarios, episodes, seed, env config, ...). A folder
holding another run's settings is refused, naming what differs. Beside them it records, under their own keys, what
every resumable run kind records and checks the same way: the policies' fingerprints
(:data:`~policies.run_identity.RESUME_FINGERPRINT` for the candidate, :data:`BASELINE_FINGERPRINT`;
:func:`~policies.run_identity.check_policy_unchanged`), the scenarios' scripts
(:data:`~scenario_bank.run_identity.BANK_IDENTITY`; :func:`~scenario_bank.run_identity.check_bank_unchanged`) and the
code (:data:`~policies.run_identity.CODE_IDENTITY`; :func:`~policies.run_identity.check_code_unchanged`).
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Dict, Mapping, Optional, Tuple, Union

from dv2s_gym.regress.errors import RegressError, ResumeMismatchError
from scenario_bank.atomic import atomic_write_json
from scenario_bank.records import RecordError, RegressEpisode
from policies.run_identity import CODE_IDENTITY, RESUME_FINGERPRINT, check_code_unchanged, check_policy_unchanged
from scenario_bank.run_paths import as_read, read_paths, record_paths, resume_fix
from scenario_bank.run_identity import (BANK_IDENTITY, check_bank_unchanged, check_format, check_identity,
                                        check_run_kind, record_format)

__all__ = ["RunStore", "RUN_FILE", "RESULTS_FILE", "TRACES_DIR", "BASELINE_FINGERPRINT", "describe_differences"]

RUN_FILE = "run.json"
RESULTS_FILE = "results.jsonl"
TRACES_DIR = "traces"
_RUN_SCHEMA = "dv2s-regress-run"
_RUN_VERSION = 4
"""The format of ``run.json`` (bumped when its fields change; a run folder of another format is refused)."""
BASELINE_FINGERPRINT = "baseline_fingerprint"
"""The key under which ``run.json`` holds the baseline policy's :func:`~policies.run_identity.resume_fingerprint`
(``None`` without a baseline policy)."""
_CHECKED_APART = (RESUME_FINGERPRINT, BASELINE_FINGERPRINT, BANK_IDENTITY, CODE_IDENTITY)
"""The keys of the run's identity checked by their own checks, not compared as settings."""

Key = Tuple[str, str]  # (episode id, role)


def describe_differences(here: Dict[str, Any], there: Dict[str, Any], limit: int = 4) -> str:
    """``"episodes: 20 here, 10 there; seed: ..."`` for the keys whose values differ."""
    parts = []
    for key in sorted(set(here) | set(there)):
        if here.get(key) != there.get(key):
            parts.append(f"{key}: {_short(here.get(key))} here, {_short(there.get(key))} there")
    more = f"; and {len(parts) - limit} more" if len(parts) > limit else ""
    return "; ".join(parts[:limit]) + more


def _short(value: Any) -> str:
    text = json.dumps(value, sort_keys=True, default=str)
    return text if len(text) <= 80 else text[:77] + "..."


class RunStore:
    """The output folder of one regression run.

    Args:
        out_dir: the folder (created when missing).
        settings: the run's identity (JSON-safe dict); compared with ``run.json`` when the
            folder already holds a run (of this format, :data:`_RUN_VERSION`).
        fsync: sync every appended line to disk (default), so not even a power loss loses
            a finished episode.
    """

    def __init__(self, out_dir: Union[str, os.PathLike], settings: Dict[str, Any], fsync: bool = True) -> None:
        self.root = Path(out_dir)
        self.settings = json.loads(json.dumps(settings, sort_keys=True, default=str))
        self.fsync = fsync
        self.results_path = self.root / RESULTS_FILE
        self.traces_dir = self.root / TRACES_DIR
        self._handle = None

    # ------------------------------------------------------------------ open
    def open(self) -> Dict[Key, RegressEpisode]:
        """Check or write ``run.json`` and return the episodes already finished, by (id, role)."""
        if self.root.exists() and not self.root.is_dir():
            raise RegressError(f"--out {self.root} is a file; give a folder for the run's reports")
        self.root.mkdir(parents=True, exist_ok=True)
        run_file = self.root / RUN_FILE
        check_run_kind(self.root, _RUN_SCHEMA, error=RegressError)
        if run_file.is_file():
            try:
                stored = json.loads(run_file.read_text(encoding="utf-8"))
            except ValueError as error:
                raise RegressError(f"{run_file} is not readable JSON ({error}); delete the folder {self.root} "
                                   "or choose another --out") from None
            there = stored.get("settings") if isinstance(stored, dict) else None
            if not isinstance(there, dict) or stored.get("schema") != _RUN_SCHEMA:
                raise RegressError(f"{run_file} was not written by dv2s regress; choose another --out")
            check_format(stored, _RUN_SCHEMA, _RUN_VERSION, folder=self.root, what="a regression run",
                         file=RUN_FILE, error=ResumeMismatchError)
            # paths in the run folder or the loop folder holding it, where they are now (a moved folder resumes)
            self._check_same_run(read_paths(there, self.root), as_read(self.settings, self.root))
        elif self.results_path.exists():
            raise RegressError(f"{self.results_path} exists without {RUN_FILE}; choose another --out or delete it")
        else:
            atomic_write_json(run_file, {**record_format(_RUN_SCHEMA, _RUN_VERSION),
                                         "settings": record_paths(self.settings, self.root)})
        return self._read()

    def _check_same_run(self, there: Dict[str, Any], asked: Dict[str, Any]) -> None:
        """Refuse a folder whose ``run.json`` holds other settings than ``asked``, naming each difference and the
        fix; then other policies, scenario scripts or code than the run's, as every resumable run kind does (each
        check for a key of :data:`_CHECKED_APART` this run's identity holds)."""
        if there == asked:
            return
        stale = [n for n in ("junit.xml", "report.html", "report.md", "report.json") if (self.root / n).is_file()]
        warning = (f"its reports ({', '.join(stale)}) are that run's, not this one's: nothing was written, so do "
                   "not read them as this run's verdict" if stale else "")
        check_identity(there, asked, sorted((set(there) | set(asked)) - set(_CHECKED_APART)),
                       run=f"{self.root} holds a regression run", error=ResumeMismatchError,
                       fix=f"{warning + '; ' if warning else ''}" + resume_fix(
                           self.root, f"rerun with the same settings to resume it, or choose another --out (or delete "
                                      f"{self.root}) for a new run"))
        try:
            self._check_what_the_run_ran(there, asked)
        except ResumeMismatchError as error:
            if not warning:
                raise
            raise ResumeMismatchError(f"{error} ({warning})", error.differences) from None

    def _check_what_the_run_ran(self, there: Dict[str, Any], asked: Dict[str, Any]) -> None:
        """The policies, scenario scripts and code of the run in the folder, checked (:data:`_CHECKED_APART`)."""
        for key, role in ((RESUME_FINGERPRINT, "policy"), (BASELINE_FINGERPRINT, "baseline")):
            spec = asked.get("candidate" if role == "policy" else "baseline")
            if key in asked and spec is not None:
                check_policy_unchanged(there, spec, folder=self.root, run="regression run",
                                       error=ResumeMismatchError, key=key, role=role)
        if CODE_IDENTITY in asked:
            check_code_unchanged(there, run=f"{self.root} holds a regression run", error=ResumeMismatchError)
        if BANK_IDENTITY in asked:
            check_bank_unchanged(there.get(BANK_IDENTITY), asked[BANK_IDENTITY],
                                 run=f"{self.root} holds a regression run", error=ResumeMismatchError)

    def _read(self) -> Dict[Key, RegressEpisode]:
        done: Dict[Key, RegressEpisode] = {}
        if not self.results_path.is_file():
            return done
        raw = self.results_path.read_bytes()
        good = 0  # bytes of whole, parseable lines
        lines = raw.split(b"\n")
        for number, line in enumerate(lines, 1):
            last = number == len(lines)
            if not line.strip():
                if not last:
                    good += len(line) + 1
                continue
            try:
                record = json.loads(line)
                key = (record["id"], record["role"])
            except (ValueError, KeyError, TypeError):
                if last:
                    break  # the line being written when the run was interrupted
                raise RegressError(f"{self.results_path} line {number} is not a result record; the file is "
                                   f"damaged: delete {self.root} and run again") from None
            if last:
                break  # no newline yet: the write was cut short
            done[key] = self._record(record, number)
            good += len(line) + 1
        if good < len(raw):
            with open(self.results_path, "r+b") as handle:  # drop the cut-short tail before appending
                handle.truncate(good)
        return done

    def _record(self, data: Dict[str, Any], number: int) -> RegressEpisode:
        try:
            return RegressEpisode.from_dict(data)
        except RecordError as error:
            raise RegressError(f"{self.results_path} line {number} is not a result record ({error}); the file is "
                               f"damaged: delete {self.root} and run again") from None

    # ---------------------------------------------------------------- append
    def append(self, result: RegressEpisode) -> None:
        """Append one finished episode's record (one JSON line, flushed and synced)."""
        if self._handle is None:
            self._handle = open(self.results_path, "a", encoding="utf-8")
        self._handle.write(json.dumps(result.to_dict(), sort_keys=True, default=str) + "\n")
        self._handle.flush()
        if self.fsync:
            os.fsync(self._handle.fileno())

    def close(self) -> None:
        """Close the log."""
        if self._handle is not None:
            self._handle.close()
            self._handle = None

    def __enter__(self) -> "RunStore":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # ----------------------------------------------------------------- paths
    def relative(self, path: Optional[str]) -> Optional[str]:
        """``path`` relative to the folder when inside it (reports stay valid when the folder moves)."""
        if not path:
            return None
        try:
            return Path(path).resolve().relative_to(self.root.resolve()).as_posix()
        except ValueError:
            return str(path)

