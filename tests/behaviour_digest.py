"""Digests of the product's outputs with what changes from run to run taken out: the recorded behaviour's normaliser.

``tests/test_behaviour_traces.py`` and ``tests/test_behaviour_reports.py`` record SHA-256 digests of episode traces
and of the files ``dv2s regress`` and ``dv2s mine`` write; a refactor must leave every digest as it is. What a run
writes that is not behaviour is taken out first, by these rules and no others:

JSON (``.json``, every line of ``.jsonl``, the JSON inside ``.json.gz``):
  - the keys in :data:`VOLATILE_KEYS` are dropped wherever they are: when a file or an entry was written
    (``created``, ``date``), how long something took (``timing``, ``timings``, ``seconds``, ``conversion_seconds``,
    ``conversion_stage_seconds``), the machine (``hostname``) and the installed version (``dv2s_version``,
    ``dv2s_gym_version``); ``duration`` is dropped at a file's top level only (a regression run's wall time; the
    env config's ``duration`` is behaviour and stays);
  - keys naming a digest of the code itself are dropped (:data:`CODE_IDENTITY`: ``dv2s version``,
    ``dv2s sources (SHA-256)``, ``dv2s_sources_sha256``, ``module ... source (SHA-256)``, ``module file ...
    (SHA-256)``): a regression run and an exact replay record them so that they resume or replay only on the same
    code, and a refactor changes them by definition;
  - keys naming a digest of a trained model's files (:data:`MODEL_FILE_IDENTITY`: ``... checkpoint <path>
    (SHA-256)``, ``... model card <path> (SHA-256)``): the model zip's members carry their writing date and the
    card a wall time, so these change from run to run with the same weights;
  - every string goes through the text rules below.

Text (every string above, Markdown, JUnit XML, HTML, the command's standard output):
  - the run's own absolute folders become placeholders: the output folder ``<out>``, the bank folder ``<bank>``,
    the checkout ``<repo>`` (:func:`normalise_text`'s ``places``);
  - ISO-8601 date-times become ``<time>``, dates alone ``<date>``;
  - JUnit's ``time``, ``timestamp`` and ``hostname`` attributes become ``<masked>``;
  - the mining report's sentence of conversion times (``Conversion time: ...``) becomes ``Conversion time: <masked>``;
  - the installed version after ``dv2s version`` becomes ``<version>``;
  - the episodes line's wall time (``N errors, T s``) becomes ``N errors, <seconds>``;
  - a model card's training time (``wall time: T s (R env steps/s)``) becomes ``wall time: <seconds>``;
  - a loop report's stage times (``timings: mine T s, split T s, ...``) become ``timings: <masked>``.

A record may name further JSON keys to drop (``drop`` of :func:`normalise` and :func:`file_digests`); its module
docstring then says which and why.

Videos (``.webm`` files, and the ``data:video/webm;base64,...`` clips a report page embeds): the container holds a
random segment id and its writing date, so a video's digest is that of its decoded frames (count, shape, pixels).

A mining run's sampler checkpoint (``sampler.pkl``) is sealed with a MAC keyed by the user's own secret: its
digest is that of the pickle behind the seal. The runs set ``PYTHONHASHSEED=0``, so that the sets a checkpoint
pickles are written in one order.

Anything else is digested as it is.
"""

from __future__ import annotations

import base64
import gzip
import hashlib
import json
import re
import tempfile
from pathlib import Path
from typing import AbstractSet, Any, Callable, Dict, Mapping

import cv2
import pytest

from scenario_bank.jail import jail_status

VOLATILE_KEYS = frozenset({"created", "date", "timing", "timings", "seconds", "conversion_seconds",
                           "conversion_stage_seconds", "hostname", "dv2s_version", "dv2s_gym_version"})
"""Keys dropped from JSON wherever they occur: when, how long, on which machine, which installed version."""

VOLATILE_TOP_KEYS = frozenset({"duration"})
"""Keys dropped from a file's top-level object only (a run's wall time; deeper, ``duration`` is the env's)."""

CODE_IDENTITY = re.compile(r"dv2s version$|dv2s sources \(SHA-256\)$|^dv2s_sources_sha256$|"
                           r"^(?:\w+ )?module .*\(SHA-256\)$")
"""Keys naming a digest of the code (or its version): a regression run's resume identity, changed by any edit."""

MODEL_FILE_IDENTITY = re.compile(r"^(?:\w+ )?(?:checkpoint|model card) .*\(SHA-256\)$")
"""Keys naming a digest of a trained model's files (a regression run's identity of a checkpoint policy): the model
file is a zip whose members carry their writing date, its card a wall time; the weights themselves are recorded
by ``tests/test_behaviour_runs.py``."""

_TEXT_RULES = (
    (re.compile(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d(?:\.\d+)?(?:[+-]\d\d:\d\d|Z)?"), "<time>"),
    (re.compile(r"\b\d{4}-\d\d-\d\d\b"), "<date>"),
    (re.compile(r'\b(time|timestamp|hostname)="[^"]*"'), r'\1="<masked>"'),
    (re.compile(r"Conversion time: [^<\n]*"), "Conversion time: <masked>"),
    (re.compile(r"(dv2s version(?:</th><td>|\W)*)\d[\w.+-]*"), r"\1<version>"),
    (re.compile(r"(\d+ errors?), \d+(?:\.\d+)? ?s\b"), r"\1, <seconds>"),
    (re.compile(r"wall time: \d+(?:\.\d+)? ?s \(\d+(?:\.\d+)? env steps/s\)"), "wall time: <seconds>"),
    (re.compile(r"timings: mine \d+(?:\.\d+)? ?s(?:, \w+ \d+(?:\.\d+)? ?s)*"), "timings: <masked>"),
)


_EMBEDDED_VIDEO = re.compile(r"data:video/webm;base64,([A-Za-z0-9+/=]+)")
_SEAL = len(b"DV2S-HMAC-SHA256\n") + 32


def video_digest(raw: bytes) -> str:
    """``frames:N:SHA-256`` of a video's decoded frames (shape and pixels of each)."""
    with tempfile.NamedTemporaryFile(suffix=".webm") as handle:
        handle.write(raw)
        handle.flush()
        capture = cv2.VideoCapture(handle.name)
        frames, hasher = 0, hashlib.sha256()
        try:
            while True:
                ok, frame = capture.read()
                if not ok:
                    break
                frames += 1
                hasher.update(repr(frame.shape).encode() + frame.tobytes())
        finally:
            capture.release()
    return f"frames:{frames}:{hasher.hexdigest()}"


def normalise_text(text: str, places: Mapping[str, str]) -> str:
    """``text`` with the folders in ``places`` (``{absolute path: placeholder}``, longest first), embedded videos
    (by their frames) and the volatile spans of the module docstring's text rules replaced."""
    text = _EMBEDDED_VIDEO.sub(lambda found: "data:video/webm;" + video_digest(base64.b64decode(found.group(1))),
                               text)
    for path in sorted(places, key=len, reverse=True):
        text = text.replace(path, places[path])
    for pattern, replacement in _TEXT_RULES:
        text = pattern.sub(replacement, text)
    return text


def normalise_document(value: Any, places: Mapping[str, str], drop: AbstractSet[str] = frozenset()) -> Any:
    """A whole file's JSON value normalised: :func:`normalise`, and its top-level volatile keys dropped."""
    if isinstance(value, dict):
        value = {key: item for key, item in value.items() if key not in VOLATILE_TOP_KEYS}
    return normalise(value, places, drop)


def normalise(value: Any, places: Mapping[str, str], drop: AbstractSet[str] = frozenset()) -> Any:
    """A JSON value with the volatile keys (and the keys in ``drop``, which a record that needs more names
    itself) dropped and every string (keys included) normalised as text."""
    if isinstance(value, dict):
        return {normalise_text(str(key), places): normalise(item, places, drop) for key, item in value.items()
                if key not in VOLATILE_KEYS and key not in drop and not CODE_IDENTITY.search(str(key))
                and not MODEL_FILE_IDENTITY.search(str(key))}
    if isinstance(value, list):
        return [normalise(item, places, drop) for item in value]
    if isinstance(value, str):
        return normalise_text(value, places)
    return value


def digest(value: Any) -> str:
    """SHA-256 of a JSON value (keys sorted) or of bytes."""
    if isinstance(value, bytes):
        return hashlib.sha256(value).hexdigest()
    return hashlib.sha256(json.dumps(value, sort_keys=True, default=str).encode("utf-8")).hexdigest()


def file_digests(path: Path, places: Mapping[str, str], drop: AbstractSet[str] = frozenset()) -> Any:
    """The digest of one written file, normalised by its kind: a JSON object's top-level keys one digest each
    (so a difference names the field), a JSON-lines file one digest per line, any other text one digest, bytes
    as they are; ``drop`` names further JSON keys to drop (see :func:`normalise`)."""
    raw = path.read_bytes()
    name = path.name
    if name.endswith(".webm"):
        return video_digest(raw)
    if name == "sampler.pkl" and raw.startswith(b"DV2S-HMAC-SHA256\n"):
        return digest(raw[_SEAL:])
    if name.endswith(".gz"):
        raw, name = gzip.decompress(raw), name[:-3]
    if name.endswith(".jsonl"):
        return [digest(normalise_document(json.loads(line), places, drop))
                for line in raw.decode("utf-8").splitlines() if line]
    if name.endswith(".json"):
        data = normalise_document(json.loads(raw.decode("utf-8")), places, drop)
        if isinstance(data, dict):
            return {key: digest(item) for key, item in sorted(data.items())}
        return digest(data)
    if name.endswith((".md", ".xml", ".html", ".txt", ".scenic", ".log")):
        return digest(normalise_text(raw.decode("utf-8"), places).encode("utf-8"))
    return digest(raw)


def folder_digests(folder: Path, places: Mapping[str, str]) -> Dict[str, Any]:
    """``{relative path: file_digests}`` of every file under ``folder``."""
    return {str(path.relative_to(folder)): file_digests(path, places)
            for path in sorted(folder.rglob("*")) if path.is_file()}


def differences(recorded: Any, now: Any, where: str = "") -> list:
    """The paths (``a/b/c``) at which two nested records differ: a key only one of them has, or another digest."""
    if isinstance(recorded, dict) and isinstance(now, dict):
        found = []
        for key in sorted(set(recorded) | set(now)):
            here = f"{where}/{key}" if where else str(key)
            if key not in recorded:
                found.append(f"{here} (new)")
            elif key not in now:
                found.append(f"{here} (gone)")
            else:
                found.extend(differences(recorded[key], now[key], here))
        return found
    if isinstance(recorded, list) and isinstance(now, list) and len(recorded) == len(now):
        return [path for index, (old, new) in enumerate(zip(recorded, now))
                for path in differences(old, new, f"{where}[{index}]")]
    return [] if recorded == now else [where or "(all)"]


def write_record(record_file: Path, behaviour: Callable[[], Any]) -> None:
    """Write a behaviour record again (``python tests/test_behaviour_<kind>.py --write``): what ``behaviour()``
    gives now becomes the record the test compares with."""
    record_file.parent.mkdir(parents=True, exist_ok=True)
    record_file.write_text(json.dumps(behaviour(), indent=1, sort_keys=True) + "\n", encoding="utf-8")
    print(f"wrote {record_file}")


def require_the_jail(runs: str) -> None:
    """Fail at once, naming the cause and its fix, when the jail cannot start here: ``runs`` convert failures in
    it (their exact replays and generated scripts), and without it every conversion would be rejected, showing
    only as digests that differ (e.g. a checkout copied under /tmp, which the jail hides)."""
    ok, why = jail_status()
    if not ok:
        pytest.fail(f"{runs} convert failures, whose scripts run only in the jail, and the jail cannot start here: "
                    f"{why}", pytrace=False)
