"""The files of a failure's conversion: where they go in a mining run folder and in a kept bank entry, and how
the conversion's records name them.

A failure of cluster ``c`` keeps its files in ``failures/<cluster_slug(c)>/`` of the run folder (the failure video
and trace), the conversion's own in its :data:`CONVERSION_DIR` (description, elements, script, ``report.json``, the
exact replay's script and the clip of the converted script); a kept bank entry carries the failure video, trace and
clip under the names :data:`ENTRY_VIDEO`, :data:`ENTRY_TRACE` and :data:`ENTRY_CONVERTED_VIDEO`. A record names a
file of the run by its path relative to the run folder (:func:`run_relative`, :func:`relative_to_run`), so it
travels with the folder.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any, Optional

from scenario_bank.atomic import atomic_write_text
from scenario_bank.run_paths import read_paths, record_paths

__all__ = ["CONVERSION_DIR", "ENTRY_VIDEO", "ENTRY_TRACE", "ENTRY_CONVERTED_VIDEO", "cluster_slug", "write_run_file",
           "run_relative", "relative_to_run", "provenance_run", "provenance_run_path"]


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


def cluster_slug(cluster: Optional[str], index: Any) -> str:
    """A folder name for a failure cluster (``"<scenario>/<type>/<actor>-<manoeuvre>/ego-<manoeuvre>"`` -> its
    parts joined by ``__``, other characters replaced)."""
    if not cluster:
        return f"episode-{int(index):06d}" if isinstance(index, int) else "failure"
    return re.sub(r"[^A-Za-z0-9_.\-]+", "_", str(cluster).replace("/", "__")).strip("._")[:120] or "failure"


def write_run_file(path: Path, text: str) -> None:
    atomic_write_text(path, text, fsync=False)


def run_relative(path: Path, root: Path) -> str:
    try:
        return str(path.resolve().relative_to(root.resolve()))
    except ValueError:
        return str(path)


def relative_to_run(text: str, run_dir: Path) -> str:
    """``text`` (a rejection reason, a clip's error) naming files inside the run folder ``run_dir`` by their path
    relative to it, not by this machine's absolute path (the record travels with the run folder)."""
    for where in dict.fromkeys((str(run_dir), str(run_dir.absolute()), str(run_dir.resolve()))):
        text = text.replace(where.rstrip(os.sep) + os.sep, "")
    return text


def provenance_run(run_dir: Path, bank: Any) -> str:
    """The ``run`` a bank entry's provenance names for the mining run in ``run_dir``: its absolute path, or, when
    one loop folder holds the run and ``bank``, its path in that folder (``<loop>/round_1/mine``,
    :mod:`scenario_bank.run_paths`), so the entry still names its run after the loop folder has moved."""
    run = str(Path(run_dir).resolve())
    root = getattr(bank, "root", None)
    return record_paths(run, root) if root is not None else run


def provenance_run_path(run: Any, bank: Any) -> Optional[Path]:
    """The mining run folder a provenance's ``run`` names (:func:`provenance_run`) where it is now, resolved
    (``None`` when it names none)."""
    if not isinstance(run, str) or not run:
        return None
    root = getattr(bank, "root", None)
    return Path(read_paths(run, root) if root is not None else run).resolve()
