"""Writing a regression report in every format at once: JSON, JUnit XML, Markdown and HTML."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Dict, Union

from dv2s_gym.regress.html import write_html
from dv2s_gym.regress.junit import write_junit
from dv2s_gym.regress.records import RegressReport
from dv2s_gym.regress.report import write_json, write_markdown

__all__ = ["write_reports"]


def write_reports(report: RegressReport, out_dir: Union[str, os.PathLike],
                  progress: bool = False, *, clips: bool = True) -> Dict[str, Path]:
    """Write ``report.json``, ``junit.xml``, ``report.md`` and ``report.html`` into ``out_dir``;
    returns format -> path. ``progress``: a bar on stderr while the HTML's clips render; ``clips=False``: the
    HTML lists the newly failing episodes without rendering their clips (each takes seconds)."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = {"json": write_json(report, out_dir / "report.json"),
             "junit": write_junit(report, out_dir / "junit.xml"),
             "markdown": write_markdown(report, out_dir / "report.md", "report.json")}
    written = write_html(report, out_dir / "report.html", render_videos=clips, progress=progress)
    paths["html"] = Path(written) if written is not None else out_dir / "report.html"
    return paths
