"""Pieces shared by the self-contained HTML report pages (``dv2s regress``, ``dv2s mine``).

A report page is one file with no external resources: inline CSS (:data:`CSS`), plots
drawn as inline SVG by the small functions below (an x axis, interval marks, row labels,
a legend), clips embedded as ``data:video/webm`` URIs (:func:`video_tag`), and the
browser self-check script (:data:`SELFTEST`): on load it records on ``<body>`` how many
plots have a non-empty box (``data-plots``, ``data-plots-rendered``, ``data-plot-marks``)
and how many videos there are (``data-videos``); opened as ``page.html#selftest`` it also
plays the first video and records whether it played (``data-video-played``,
``data-video-size``, ``data-video-contrast``, ``data-video-error``) and plays every clip of
the first side-by-side pair (``.pair``), recording which sides played (``data-pair-played``,
e.g. ``baseline,candidate``). The browser tests read these attributes.

Every string taken from a report goes through :func:`escape`.
"""

from __future__ import annotations

import base64
import html
import math
import os
from pathlib import Path
from typing import Any, Callable, Iterable, List, Mapping, Optional, Sequence, Tuple, Union

__all__ = [
    "VideoSource", "ROW", "TOP", "BOTTOM", "LABEL", "RIGHT", "WIDTH", "CSS", "SELFTEST",
    "escape", "finite", "fmt", "fmt_interval", "x_scale", "ticks", "axis", "svg", "legend",
    "interval_mark", "row_label", "video_bytes", "video_tag",
]

VideoSource = Union[str, os.PathLike, bytes]
"""A clip to embed: a ``.webm`` path or its bytes."""


def escape(value: Any) -> str:
    """Escape anything for HTML text or a double-quoted attribute (``None`` becomes "")."""
    return html.escape("" if value is None else str(value), quote=True)


def finite(value: Any) -> Optional[float]:
    """A finite float, or ``None`` (for ``None``, booleans, non-numbers, NaN and infinities)."""
    if isinstance(value, bool) or value is None:
        return None
    try:
        number = float(value)
    except (TypeError, ValueError):
        return None
    return number if math.isfinite(number) else None


def fmt(value: Any, digits: int = 2) -> str:
    """``value`` with ``digits`` decimals, or an en dash when it is not a finite number."""
    number = finite(value)
    return "–" if number is None else f"{number:.{digits}f}"


def fmt_interval(stat: Optional[Mapping[str, Any]], digits: int = 2) -> str:
    """``{"value", "low", "high"}`` as ``"v [low, high]"`` (``"v"`` without bounds, "–" without a value)."""
    if not isinstance(stat, Mapping):
        return "–"
    text = fmt(stat.get("value"), digits)
    low, high = finite(stat.get("low")), finite(stat.get("high"))
    if low is not None and high is not None:
        text += f" [{low:.{digits}f}, {high:.{digits}f}]"
    return text


# --------------------------------------------------------------------------- SVG plots
ROW, TOP, BOTTOM, LABEL, RIGHT, WIDTH = 22, 44, 34, 240, 24, 760
"""Forest-plot geometry [px]: row height, top and bottom margins, label column, right margin, width."""


def x_scale(low: float, high: float) -> Tuple[float, float, Callable[[float], float]]:
    """``(low, high, x)`` where ``x`` maps a value (clamped to the range) to a pixel column of the plot."""
    span = (high - low) or 1.0
    plot = WIDTH - LABEL - RIGHT
    return low, high, (lambda v: LABEL + (min(max(v, low), high) - low) / span * plot)


def ticks(low: float, high: float, count: int = 5) -> List[float]:
    """``count`` evenly spaced tick values from ``low`` to ``high``."""
    step = (high - low) / (count - 1)
    return [low + i * step for i in range(count)]


def axis(x: Callable[[float], float], low: float, high: float, height: float, title: str, signed: bool = False,
         digits: int = 2) -> List[str]:
    """The x axis at the bottom of a forest plot: line, grid, tick labels (``digits`` decimals) and title."""
    parts = [f'<line class="axis" x1="{LABEL}" y1="{height - BOTTOM}" x2="{WIDTH - RIGHT}" y2="{height - BOTTOM}"/>']
    for tick in ticks(low, high):
        px = x(tick)
        label = f"{tick:+.{digits}f}" if signed and abs(tick) > 1e-12 else f"{tick:.{digits}f}"
        parts.append(f'<line class="grid" x1="{px:.1f}" y1="{TOP - 6}" x2="{px:.1f}" y2="{height - BOTTOM}"/>'
                     f'<text class="tick" x="{px:.1f}" y="{height - BOTTOM + 14}">{escape(label)}</text>')
    parts.append(f'<text class="axis-title" x="{(LABEL + WIDTH - RIGHT) / 2:.1f}" y="{height - 6}">'
                 f'{escape(title)}</text>')
    return parts


def svg(height: float, title: str, body: Iterable[str]) -> str:
    """An ``<svg class="plot">`` of the page's width holding ``body``, titled for screen readers and tooltips."""
    return (f'<svg class="plot" xmlns="http://www.w3.org/2000/svg" width="{WIDTH}" height="{height:.0f}" '
            f'viewBox="0 0 {WIDTH} {height:.0f}" role="img" aria-label="{escape(title)}"><title>{escape(title)}</title>'
            + "".join(body) + "</svg>")


def legend(entries: Sequence[Tuple[str, str, str]]) -> str:
    """``(label, colour, shape)`` entries (shape ``"square"`` or ``"circle"``) in the top right corner."""
    parts, x = [], WIDTH - RIGHT
    for label, colour, shape in reversed(entries):
        x -= 8 + 7 * len(label) + 16
        mark = (f'<rect x="{x}" y="6" width="9" height="9" fill="{colour}"/>' if shape == "square"
                else f'<circle cx="{x + 4.5}" cy="10.5" r="4.5" fill="{colour}"/>')
        parts.append(f'{mark}<text class="legend" x="{x + 13}" y="14">{escape(label)}</text>')
    return "".join(parts)


def interval_mark(x: Callable[[float], float], y: float, stat: Mapping[str, Any], colour: str, shape: str,
                  tooltip: str) -> str:
    """A point at ``stat["value"]`` with a bar from ``low`` to ``high`` (when given), class ``mark``."""
    value, low, high = finite(stat.get("value")), finite(stat.get("low")), finite(stat.get("high"))
    if value is None:
        return ""
    parts = [f'<g class="mark"><title>{escape(tooltip)}</title>']
    if low is not None and high is not None:
        parts.append(f'<line x1="{x(low):.1f}" y1="{y:.1f}" x2="{x(high):.1f}" y2="{y:.1f}" stroke="{colour}" '
                     f'stroke-width="2"/>')
    if shape == "square":
        parts.append(f'<rect x="{x(value) - 4:.1f}" y="{y - 4:.1f}" width="8" height="8" fill="{colour}"/>')
    else:
        parts.append(f'<circle cx="{x(value):.1f}" cy="{y:.1f}" r="4.5" fill="{colour}"/>')
    return "".join(parts) + "</g>"


def row_label(y: float, label: str, bold: bool = False) -> str:
    """A row's label, right-aligned in the label column (shortened, the full text as its tooltip)."""
    weight = ' font-weight="bold"' if bold else ""
    short = label if len(label) <= 36 else label[:34] + "…"
    return (f'<text class="row-label" x="{LABEL - 8}" y="{y + 4:.1f}"{weight}>{escape(short)}'
            f'<title>{escape(label)}</title></text>')


# --------------------------------------------------------------------------- videos
def video_bytes(source: VideoSource) -> bytes:
    """The bytes of a clip given as bytes or as a path."""
    if isinstance(source, (bytes, bytearray)):
        return bytes(source)
    return Path(source).read_bytes()


def video_tag(data: bytes) -> str:
    """A looping, muted ``<video>`` playing ``data`` (a ``.webm``) embedded as a data URI."""
    return (f'<video controls loop muted playsinline preload="auto" '
            f'src="data:video/webm;base64,{base64.b64encode(data).decode("ascii")}"></video>')


# --------------------------------------------------------------------------- page
CSS = """
body{font:14px/1.45 system-ui,-apple-system,"Segoe UI",sans-serif;margin:0 auto;max-width:1100px;padding:16px 24px;color:#1f2328}
h1{font-size:22px;margin:8px 0}h2{font-size:18px;margin:28px 0 8px;border-bottom:1px solid #d0d7de;padding-bottom:4px}
.banner{padding:14px 18px;border-radius:6px;color:#fff;font-size:18px;margin:12px 0}
.banner small{display:block;font-size:13px;opacity:.95;margin-top:4px}
.PASS{background:#1a7f37}.FAIL{background:#cf222e}.INCONCLUSIVE{background:#b07800}.ERROR{background:#8250df}.NONE{background:#57606a}
table{border-collapse:collapse;margin:6px 0;font-size:13px}th,td{border:1px solid #d0d7de;padding:3px 8px;text-align:left;vertical-align:top}
th{background:#f6f8fa}td.num{text-align:right;font-variant-numeric:tabular-nums}
.v-PASS{color:#1a7f37;font-weight:600}.v-FAIL{color:#cf222e;font-weight:600}.v-INCONCLUSIVE{color:#b07800;font-weight:600}.v-ERROR{color:#8250df;font-weight:600}
figure{margin:10px 0}figcaption{font-size:12px;color:#57606a}
svg.plot{display:block;background:#fff}
svg .axis{stroke:#57606a}svg .grid{stroke:#eaeef2}svg .zero{stroke:#57606a}
svg .margin{stroke:#cf222e;stroke-dasharray:5 4}svg text{font:11px system-ui,sans-serif;fill:#1f2328}
svg .tick,svg .axis-title{text-anchor:middle}svg .row-label{text-anchor:end}svg .margin-label{fill:#cf222e}
.clips{display:flex;flex-wrap:wrap;gap:14px}.clip{border:1px solid #d0d7de;border-radius:6px;padding:8px;width:360px}.clip.pair{width:auto}.sides{display:flex;gap:10px;flex-wrap:wrap}.side{margin:0;width:360px}.side figcaption{font-size:13px}
.clip video{width:360px;height:360px;background:#000;display:block}.clip p{margin:6px 0 0;font-size:12px}
.muted{color:#57606a}code{font-size:12px}
"""
"""The pages' style sheet (inline in ``<style>``)."""

SELFTEST = """
(function () {
  function check() {
    var body = document.body, plots = document.querySelectorAll("svg.plot"), rendered = 0, marks = 0;
    plots.forEach(function (svg) {
      var box = svg.getBoundingClientRect();
      if (box.width > 0 && box.height > 0) { rendered += 1; }
      svg.querySelectorAll(".mark").forEach(function (mark) {
        var b = mark.getBBox(); if (b.width > 0 || b.height > 0) { marks += 1; }
      });
    });
    body.setAttribute("data-plots", String(plots.length));
    body.setAttribute("data-plots-rendered", String(rendered));
    body.setAttribute("data-plot-marks", String(marks));
    var videos = document.querySelectorAll("video");
    body.setAttribute("data-videos", String(videos.length));
    if (!videos.length || location.hash !== "#selftest") { return; }
    var pair = document.querySelector(".pair"), playedInPair = {};
    if (pair) {  // every clip of the first side-by-side pair plays too
      body.setAttribute("data-pair-played", "");
      pair.querySelectorAll("video").forEach(function (clip, index) {
        var side = clip.closest(".side"), role = side ? (side.classList.contains("baseline") ? "baseline" : "candidate") : String(index);
        clip.addEventListener("timeupdate", function () {
          if (clip.currentTime <= 0 || clip.videoWidth <= 0 || playedInPair[role]) { return; }
          playedInPair[role] = true;
          body.setAttribute("data-pair-played", Object.keys(playedInPair).sort().join(","));
        });
        if (index > 0) { clip.muted = true; var p = clip.play(); if (p && p.catch) { p.catch(function () {}); } }
      });
    }
    var video = videos[0];
    body.setAttribute("data-video-played", "false");
    video.addEventListener("error", function () {
      body.setAttribute("data-video-error", "media error " + (video.error ? video.error.code : "?"));
    });
    video.addEventListener("timeupdate", function () {
      if (video.currentTime <= 0 || video.videoWidth <= 0) { return; }
      body.setAttribute("data-video-played", "true");
      body.setAttribute("data-video-size", video.videoWidth + "x" + video.videoHeight);
      try {
        var canvas = document.createElement("canvas"); canvas.width = 32; canvas.height = 32;
        var ctx = canvas.getContext("2d"); ctx.drawImage(video, 0, 0, 32, 32);
        var px = ctx.getImageData(0, 0, 32, 32).data, lo = 255, hi = 0;
        for (var i = 0; i < px.length; i += 4) { var g = (px[i] + px[i + 1] + px[i + 2]) / 3; lo = Math.min(lo, g); hi = Math.max(hi, g); }
        body.setAttribute("data-video-contrast", String(Math.round(hi - lo)));
      } catch (e) { body.setAttribute("data-video-contrast", "unreadable: " + e.name); }
    });
    video.muted = true;
    var played = video.play();
    if (played && played.catch) {
      played.catch(function (e) { body.setAttribute("data-video-error", e.name + ": " + e.message); });
    }
  }
  window.addEventListener("load", check);
})();
"""
"""The browser self-check (inline in the page's one ``<script>``; see the module docstring)."""
