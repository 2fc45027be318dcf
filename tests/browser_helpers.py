"""Loading a self-contained HTML report in headless Chromium and reading what its self-check found."""

from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
from pathlib import Path

import pytest

INSTALL_HINT = ("Chromium is needed for the HTML report's browser test: run scripts/setup.sh as root, or "
                "`sudo apt-get update && sudo apt-get install -y --no-install-recommends chromium`")


def chromium() -> str:
    """Path of a Chromium binary; fails the test (never skips) with the install command when there is none."""
    for name in ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable"):
        found = shutil.which(name)
        if found:
            return found
    pytest.fail(INSTALL_HINT, pytrace=False)


def body_attributes(page: Path, fragment: str = "#selftest") -> dict:
    """Load ``page`` in headless Chromium, let it run 8 s of virtual time, and read <body>'s data- attributes."""
    with tempfile.TemporaryDirectory(prefix="dv2s-chromium-") as profile:
        out = subprocess.run(
            [chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", f"--user-data-dir={profile}",
             "--autoplay-policy=no-user-gesture-required", "--virtual-time-budget=8000", "--dump-dom",
             page.resolve().as_uri() + fragment],
            capture_output=True, text=True, timeout=180)
    match = re.search(r"<body([^>]*)>", out.stdout)
    assert match, f"Chromium dumped no page (exit {out.returncode}): {out.stderr[-2000:]}"
    return dict(re.findall(r'(data-[\w-]+)="([^"]*)"', match.group(1)))


_MEASURE_TABLES = """<script>window.addEventListener("load", function () {
  var out = [];
  document.querySelectorAll("table").forEach(function (table, index) {
    var box = table.parentElement;
    out.push([index, Math.ceil(table.getBoundingClientRect().width), box.clientWidth, window.innerWidth].join(","));
  });
  document.body.setAttribute("data-table-widths", out.join(";"));
});</script>"""


def table_widths(page: Path, window_width: int) -> list:
    """Each table's index on the page, its width, the width of the box it sits in, and the window's, from a copy of ``page`` loaded in
    headless Chromium in a window ``window_width`` pixels wide."""
    copy = page.with_name(page.stem + "-measured.html")
    copy.write_text(page.read_text().replace("</body>", _MEASURE_TABLES + "</body>"))
    with tempfile.TemporaryDirectory(prefix="dv2s-chromium-") as profile:
        out = subprocess.run(
            [chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", f"--user-data-dir={profile}",
             f"--window-size={window_width},900", "--virtual-time-budget=2000", "--dump-dom", copy.resolve().as_uri()],
            capture_output=True, text=True, timeout=180)
    match = re.search(r'<body[^>]*data-table-widths="([^"]*)"', out.stdout)
    assert match, f"Chromium measured no table (exit {out.returncode}): {out.stderr[-2000:]}"
    return [dict(zip(("index", "table", "box", "window"), map(int, item.split(","))))
            for item in match.group(1).split(";") if item]
