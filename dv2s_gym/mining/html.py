"""The mining report as one self-contained HTML page.

:func:`write_html` turns a ``dv2s-mine`` report (a :class:`~dv2s_gym.mining.report_record.MineReport`,
:mod:`dv2s_gym.mining.report`) into a
single file: a summary banner, the settings, plots drawn as inline SVG (failures per 100
episodes per sampler with their Wilson intervals, distinct clusters found over the run per
sampler, the failure rate per scenario with its interval), the per-sampler, per-scenario
and cluster tables, then each converted cluster's failure video beside the description the
pipeline generated from it (the generated Scenic script collapsed below; a kept conversion's clip of the converted
script driven by the same policy below the failure's), the rejected
conversions with their reasons, the unavoidable failures apart, and the errors.

Videos are embedded as ``data:video/webm`` URIs (up to ``max_videos``; the rest, or all
with ``embed_videos=False``, are linked relative to the page, so the page then works in
its run folder). The page shares its CSS, plot primitives and browser self-check with the
regression report (:mod:`dv2s_gym.report_page`); every string from the report is escaped.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any, Mapping, Optional, Sequence, Tuple, Union

from dv2s_gym.mining.behaviour import Behaviour
from dv2s_gym.mining.conversion.record import ConversionStatus
from dv2s_gym.mining.report_record import ClusterEntry, FailureEntry, mine_report, MineReport
from dv2s_gym.mining.report_text import (breadth, by_type_text, clip_caption, parameter_check_text, rate_text,
                                         replaced_in, replaced_text, seed_text)
from dv2s_gym.report_page import (BOTTOM, CSS, RIGHT, ROW, SELFTEST, TOP, WIDTH, axis, escape, finite,
                                  fmt, fmt_interval, interval_mark, legend, row_label, svg, video_tag, x_scale)
from scenario_bank.atomic import atomic_write_text
from scenario_bank.records import recorded

__all__ = ["write_html", "render_html", "MAX_VIDEOS", "MAX_SCRIPT_CHARS"]

MAX_VIDEOS = 24
"""Failure videos embedded in the page; further ones are linked relative to the page."""
MAX_SCRIPT_CHARS = 40_000
"""Longest generated script shown (longer ones are cut, saying so)."""

COLOURS = {"failures": "#cf222e", "avoidable": "#0b63c5", "rate": "#cf222e"}
SAMPLER_COLOURS = ("#0b63c5", "#cf222e", "#1a7f37", "#b07800", "#8250df", "#57606a", "#bc4c00", "#1b7c83")

EXTRA_CSS = """
.cards{display:flex;flex-direction:column;gap:14px}.card{border:1px solid #d0d7de;border-radius:6px;padding:10px;display:flex;gap:16px}
.card video{width:360px;height:360px;background:#000;display:block;flex:none}.card .novideo{width:360px;flex:none}
.card .text{flex:1;min-width:0}.card .media{display:flex;flex-direction:column;gap:8px;flex:none}
.card figure{margin:0}.card figcaption{font-size:12px;width:360px}
.card h3{font-size:15px;margin:0 0 6px}.card blockquote{margin:6px 0;padding:6px 10px;
border-left:4px solid #0b63c5;background:#f6f8fa;white-space:pre-wrap}
pre{background:#f6f8fa;padding:8px;overflow:auto;max-height:420px;font-size:12px}
.s-kept{color:#1a7f37;font-weight:600}.s-merged{color:#8250df;font-weight:600}.s-rejected{color:#cf222e;font-weight:600}
svg .line{fill:none;stroke-width:2}.wide{overflow-x:auto;max-width:100%}
span.region{font-size:12px;display:inline-block;min-width:110px}
"""


# --------------------------------------------------------------------------- plots
def _forest(rows: Sequence[Tuple[str, Sequence[Tuple[Mapping[str, Any], str, str, str]]]], low: float, high: float,
            title: str, marks: Sequence[Tuple[str, str, str]], digits: int) -> str:
    """Rows of ``(label, [(stat, colour, shape, tooltip)])`` on one x axis from ``low`` to ``high``."""
    height = TOP + ROW * max(1, len(rows)) + BOTTOM
    x = x_scale(low, high)[2]
    body = axis(x, low, high, height, title, digits=digits)
    body.append(legend(marks))
    for i, (label, stats) in enumerate(rows):
        y = TOP + ROW * i + ROW / 2
        body.append(row_label(y, label))
        offsets = [0.0] if len(stats) == 1 else [-4.0 + 8.0 * j / (len(stats) - 1) for j in range(len(stats))]
        for (stat, colour, shape, tooltip), offset in zip(stats, offsets):
            body.append(interval_mark(x, y + offset, stat, colour, shape, tooltip))
    return svg(height, title, body)


def sampler_plot(report: MineReport) -> str:
    """Failures (and avoidable failures) per 100 episodes per sampler, with Wilson 95 % intervals."""
    report = mine_report(report, "sampler_plot")
    samplers = report.samplers
    highs = [finite((getattr(s, key) or {}).get("high")) for s in samplers.values()
             for key in ("failures_per_100", "avoidable_failures_per_100")]
    widest = max([10.0] + [h * 1.05 for h in highs if h is not None])
    top = min(100.0, 20.0 * math.ceil(widest / 20.0))  # quarter ticks at whole numbers
    rows = []
    for name, s in samplers.items():
        every, avoidable = s.failures_per_100 or {}, s.avoidable_failures_per_100 or {}
        rows.append((str(name), [
            (every, COLOURS["failures"], "circle",
             f"{name}: {every.get('count', 0)} failures in {every.get('n', 0)} episodes, "
             f"{fmt_interval(every, 1)} per 100"),
            (avoidable, COLOURS["avoidable"], "square",
             f"{name}: {avoidable.get('count', 0)} avoidable failures, {fmt_interval(avoidable, 1)} per 100")]))
    return _forest(rows, 0.0, top, "Failures per 100 episodes (95% interval)",
                   [("all failures", COLOURS["failures"], "circle"), ("avoidable", COLOURS["avoidable"], "square")], 0)


def scenario_plot(report: MineReport) -> str:
    """The failure rate of each scenario with its Wilson 95 % interval."""
    report = mine_report(report, "scenario_plot")
    rows = []
    for name, s in report.scenarios.items():
        rate = s.failure_rate or {}
        rows.append((str(name), [(rate, COLOURS["rate"], "circle",
                                  f"{name}: {_or_zero(s.failures)} failures ({_or_zero(s.avoidable)} avoidable) in "
                                  f"{_or_zero(s.episodes)} episodes, rate {fmt_interval(rate)}")]))
    return _forest(rows, 0.0, 1.0, "Failure rate per scenario (95% interval)",
                   [("failure rate", COLOURS["rate"], "circle")], 2)


def discovery_plot(report: MineReport) -> str:
    """Distinct clusters found against episodes run, one step line per sampler."""
    report = mine_report(report, "discovery_plot")
    samplers = report.samplers
    curves = {name: [(int(p[0]), int(p[1])) for p in (s.discovery or [])] for name, s in samplers.items()}
    max_x = max([1] + [p[0] for c in curves.values() for p in c])
    max_y = max([1] + [p[1] for c in curves.values() for p in c])
    height, plot_top, plot_bottom, left = 250, 26, 210, 50
    title = "Distinct failure clusters found over the run"

    def px(episodes: float) -> float:
        return left + episodes / max_x * (WIDTH - left - RIGHT)

    def py(clusters: float) -> float:
        return plot_bottom - clusters / max_y * (plot_bottom - plot_top)

    body = [f'<line class="axis" x1="{left}" y1="{plot_bottom}" x2="{WIDTH - RIGHT}" y2="{plot_bottom}"/>',
            f'<line class="axis" x1="{left}" y1="{plot_top}" x2="{left}" y2="{plot_bottom}"/>',
            f'<text class="tick" x="{left - 6}" y="{plot_top + 4}" text-anchor="end">{max_y}</text>',
            f'<text class="tick" x="{left - 6}" y="{plot_bottom + 4}" text-anchor="end">0</text>',
            f'<text class="tick" x="{left}" y="{plot_bottom + 14}">0</text>',
            f'<text class="tick" x="{WIDTH - RIGHT}" y="{plot_bottom + 14}">{max_x}</text>',
            f'<text class="axis-title" x="{(left + WIDTH - RIGHT) / 2:.1f}" y="{height - 6}">'
            f'{escape(title)}: clusters (up) against episodes (across)</text>']
    entries = []
    for i, (name, points) in enumerate(curves.items()):
        colour = SAMPLER_COLOURS[i % len(SAMPLER_COLOURS)]
        entries.append((str(name), colour, "square"))
        if not points:
            continue
        coords, level = [(px(0), py(0))], 0
        for episodes, clusters in points:
            coords += [(px(episodes), py(level)), (px(episodes), py(clusters))]
            level = clusters
        path = " ".join(f"{a:.1f},{b:.1f}" for a, b in coords)
        body.append(f'<g class="mark"><title>{escape(name)}: {points[-1][1]} distinct clusters in '
                    f'{points[-1][0]} episodes</title><polyline class="line" stroke="{colour}" points="{path}"/></g>')
    body.append(legend(entries))
    return svg(height, title, body)


def _or_zero(count: Optional[int]) -> int:
    """A scenario's count, 0 when the report does not hold it."""
    return 0 if count is None else count


# --------------------------------------------------------------------------- sections
def _banner(report: MineReport) -> str:
    counts = report.counts
    episodes, avoidable = counts.episodes, counts.avoidable_clusters
    css = "NONE" if not episodes else "FAIL" if avoidable else "PASS"
    head = (f"{counts.failures} failure(s) in {episodes} episode(s): {counts.clusters} distinct "
            f"behaviour(s), {avoidable} avoidable")
    settings = report.settings
    detail = [f"policy {settings.get('policy')}, sampler {settings.get('sampler')}, {seed_text(settings)}",
              breadth(counts), f"{counts.avoidable} avoidable, {counts.unavoidable} unavoidable, "
              f"{counts.avoidability_unknown} unknown failure(s)",
              f"converted {counts.converted}: kept {counts.kept}, merged {counts.merged}, "
              f"rejected {counts.rejected}"]
    if counts.errors:
        detail.append(f"{counts.errors} error(s)")
    if replaced_in(settings):
        detail.append(replaced_text(replaced_in(settings)))
    return f'<div class="banner {css}" id="summary">{escape(head)}<small>{escape("; ".join(detail))}</small></div>'


def _breakable(value: Any) -> str:
    """``value`` escaped, with a line-break opportunity after each ``/``, ``_`` and ``:``, so long identifiers
    (cluster ids, scenario and entry names) wrap inside their column instead of widening the table."""
    text = escape(value)
    for mark in ("/", "_", ":"):
        text = text.replace(mark, mark + "<wbr>")
    return text


def _table(head: Sequence[str], rows: Sequence[Sequence[Tuple[str, bool]]]) -> str:
    """A table; each cell is ``(escaped html, numeric)``."""
    out = ['<div class="wide"><table><tr>' + "".join(f"<th>{escape(h)}</th>" for h in head) + "</tr>"]
    for row in rows:
        out.append("<tr>" + "".join(f'<td class="num">{cell}</td>' if numeric else f"<td>{cell}</td>"
                                    for cell, numeric in row) + "</tr>")
    return "".join(out) + "</table></div>"


def _settings_table(report: MineReport) -> str:
    settings = report.settings
    keys = [k for k in ("policy", "sampler", "seed", "budget", "scenarios", "bank_dir", "reference", "backend",
                        "workers", "convert") if k in settings]
    rows = [(k, ", ".join(map(str, settings[k])) if isinstance(settings[k], list) else
             seed_text(settings).removeprefix("seed ") if k == "seed" else settings[k]) for k in keys]
    rows += [("run folder", report.run_dir), ("created", report.created),
             ("dv2s version", report.dv2s_version)]
    return "<table>" + "".join(f"<tr><th>{escape(k)}</th><td>{escape(v)}</td></tr>" for k, v in rows) + "</table>"


def _counts_table(report: MineReport) -> str:
    c = report.counts
    head = ["episodes", "errors", "failures", "distinct behaviours", "(scenario family, failure type) pairs",
            "scenario families with a failure", "avoidable", "unavoidable", "unknown",
            "avoidable behaviours", "converted", "kept", "merged", "rejected"]
    keys = ["episodes", "errors", "failures", "behaviours", "scenario_failure_types", "scenarios_failing",
            "avoidable", "unavoidable", "avoidability_unknown", "avoidable_clusters", "converted", "kept",
            "merged", "rejected"]
    half = len(head) // 2  # two tables of seven columns: one of fourteen is wider than the page
    table = "".join(_table(head[part], [[(escape(getattr(c, k)), True) for k in keys[part]]])
                    for part in (slice(0, half), slice(half, None)))
    by_type = c.failures_by_type
    seconds = c.conversion_seconds
    notes = []
    if by_type:
        notes.append("Failures by type: " + escape(by_type_text(by_type)))
    if seconds.get("n"):
        stages = c.conversion_stage_seconds
        notes.append(f"Conversion time: median {fmt(seconds.get('median'))} s, max {fmt(seconds.get('max'))} s over "
                     f"{escape(seconds['n'])} conversion(s)" + ("; median per stage: " + ", ".join(
                         f"{escape(stage)} {fmt(value)} s" for stage, value in stages.items()) if stages else ""))
    if c.parameters_compared or c.parameters_not_compared:
        notes.append(escape(parameter_check_text(c)))
    return table + "".join(f"<p>{n}.</p>" for n in notes)


def _sampler_table(report: MineReport) -> str:
    rows = []
    for name, s in report.samplers.items():
        rows.append([(escape(name), False), (escape(s.episodes), True), (escape(s.failures), True),
                     (escape(fmt_interval(s.failures_per_100, 1)), True),
                     (escape(fmt_interval(s.avoidable_failures_per_100, 1)), True),
                     (escape(s.clusters), True), (escape(fmt(s.clusters_per_100, 1)), True),
                     (escape(s.avoidable_clusters), True),
                     (escape(s.episodes_to_first_failure or "–"), True)])
    return _table(["sampler", "episodes", "failures", "failures per 100 [95%]", "avoidable per 100 [95%]",
                   "clusters", "clusters per 100", "avoidable clusters", "first failure at episode"], rows)


def _scenario_table(report: MineReport) -> str:
    rows = []
    for name, s in report.scenarios.items():
        types = by_type_text(s.failures_by_type) if s.failures_by_type else ""
        rows.append([(_breakable(name), False), (escape(s.episodes), True), (escape(s.failures), True),
                     (escape(fmt_interval(s.failure_rate)), True),
                     (escape(_estimate(s.estimated_rate)), True), (escape(s.avoidable), True),
                     (escape(s.unavoidable), True), (escape(types or "–"), False),
                     (escape(s.clusters), True), (escape(s.converted), True),
                     (escape(s.kept), True)])
    return _table(["scenario", "episodes", "failures", "sampled failure rate [95%]",
                   "estimated rate under its own distribution [95%] (ESS)", "avoidable", "unavoidable", "by type",
                   "behaviours", "converted", "kept"], rows)


def _estimate(estimate: Any) -> str:
    if not isinstance(estimate, Mapping) or estimate.get("value") is None:
        return "–"
    return (f"{100 * estimate['value']:.1f}% [{100 * estimate['low']:.1f}, {100 * estimate['high']:.1f}] "
            f"({fmt(estimate.get('ess'))})")


def _region(params: Mapping[str, Any]) -> str:
    parts = []
    for name, region in params.items():
        if isinstance(region, Mapping) and "min" in region:
            low, high = finite(region.get("min")), finite(region.get("max"))
            if low is None or high is None:
                continue
            parts.append(f"{name} {low:.3g}" if low == high else f"{name} {low:.3g}–{high:.3g}")
        elif isinstance(region, Mapping):
            parts.append(f"{name} ∈ {{{', '.join(map(str, region.get('values') or []))}}}")
    return "; ".join(parts) or "–"


def _reproduction(cluster: ClusterEntry) -> str:
    reproduction = cluster.reproduction
    if not isinstance(reproduction, Mapping) or finite(reproduction.get("rate")) is None:
        return "–"
    text = f"{reproduction['rate']:.2f}"
    if reproduction.get("k") is not None:
        text += f" ({reproduction.get('reproduced', '?')}/{reproduction['k']})"
    interval = reproduction.get("interval")
    if isinstance(interval, (list, tuple)) and len(interval) == 2 and all(finite(v) is not None for v in interval):
        text += f" [{interval[0]:.2f}, {interval[1]:.2f}]"
    if finite(reproduction.get("threshold")) is not None:
        text += f", threshold {reproduction['threshold']:.2f}"
    return text


def _status(cluster: ClusterEntry) -> str:
    status = str(cluster.status or "")
    text = f'<span class="s-{escape(status)}">{escape(status)}</span>'
    if cluster.merged_into:
        text += f" into {_breakable(cluster.merged_into)}"
    return text


def _representative(cluster: ClusterEntry) -> FailureEntry:
    """The cluster's representative failure (an empty one when the report does not hold it)."""
    return cluster.representative if cluster.representative is not None else FailureEntry()


def _cluster_table(clusters: Sequence[ClusterEntry]) -> str:
    if not clusters:
        return '<p class="muted">None.</p>'
    rows = []
    for c in clusters:
        rep = _representative(c)
        link = f' <a href="#card-{escape(c.id)}">video</a>' if c.conversion is not None else ""
        short = str(c.id or "").split("/", 1)[-1]  # the scenario has its own column
        rows.append([(f'<code class="id" title="{escape(c.id)}">{_breakable(short)}</code>', False),
                     (_breakable(c.scenario), False),
                     (escape(c.type), False), (escape(c.size), True), (escape(c.avoidable), True),
                     ('<span class="region">' + escape(_region(c.params or {})) + "</span>", False),
                     (f"#{escape(rep.index)} seed {escape(rep.seed)}{link}", False),
                     (_status(c), False), (_breakable(c.bank_entry or "–"), False),
                     (escape(_reproduction(c)), True), (escape(fmt(c.e2e_sc, 3)), True)])
    return _table(["cluster (class/actor/ego)", "scenario", "type", "failures", "avoidable", "parameter region",
                   "representative",
                   "conversion", "bank entry", "reproduction", "E2E-SC"], rows)


class _Videos:
    """Turns a cluster's video path into a ``<video>``: embedded up to a count, then linked."""

    def __init__(self, base: Path, page_dir: Path, embed: bool, limit: int) -> None:
        self.base, self.page_dir, self.embed, self.left = base, page_dir, embed, limit

    def tag(self, video: Any) -> str:
        if not video:
            return '<p class="muted novideo">No video was recorded for this failure.</p>'
        path = Path(str(video))
        path = path if path.is_absolute() else self.base / path
        if not path.is_file():
            return f'<p class="muted novideo">Video {escape(video)} is missing from the run folder.</p>'
        if self.embed and self.left > 0:
            self.left -= 1
            return video_tag(path.read_bytes())
        link = Path(os.path.relpath(path.resolve(), self.page_dir.resolve())).as_posix()
        return f'<video controls loop muted playsinline preload="metadata" src="{escape(link)}"></video>'


def _script(base: Path, script: Any) -> str:
    if not script:
        return '<p class="muted">No script was generated.</p>'
    path = Path(str(script))
    path = path if path.is_absolute() else base / path
    try:
        text = path.read_text(encoding="utf-8", errors="replace")
    except OSError:
        return f'<p class="muted">Script {escape(script)} is missing from the run folder.</p>'
    cut = ""
    if len(text) > MAX_SCRIPT_CHARS:
        text, cut = text[:MAX_SCRIPT_CHARS], f" (first {MAX_SCRIPT_CHARS} characters)"
    return (f"<details><summary>Generated Scenic script <code>{escape(script)}</code>{cut}</summary>"
            f"<pre><code>{escape(text)}</code></pre></details>")


def _behaviour_text(behaviour: Optional[Behaviour]) -> str:
    if behaviour is None:
        return "unknown unknown; ego unknown"
    actor = behaviour.actor or "unknown"
    other = "no other actor" if actor == "none" else f"{actor} {behaviour.actor_manoeuvre or 'unknown'}"
    return f"{other}; ego {behaviour.ego_manoeuvre or 'unknown'}"


def _cards(clusters: Sequence[ClusterEntry], videos: _Videos, base: Path,
           report_settings: Optional[Mapping[str, Any]] = None) -> str:
    if not clusters:
        return '<p class="muted">None.</p>'
    out = ['<div class="cards">']
    for c in clusters:
        rep = _representative(c)
        facts = [f"{escape(c.type)} in <code>{escape(c.scenario)}</code>, {escape(c.size)} "
                 f"failure(s), {escape(c.avoidable)} avoidable",
                 f"representative: episode #{escape(rep.index)}, seed {escape(rep.seed)}"
                 + (f", {escape(rep.collision_type)}" if rep.collision_type else "")
                 + (f" with {escape(rep.with_actor)}" if rep.with_actor else ""),
                 f"parameters of its failures: {escape(_region(c.params or {}))}",
                 f"behaviour: {escape(_behaviour_text(c.behaviour))}",
                 f"conversion: {_status(c)}" + (f", bank entry <code>{escape(c.bank_entry)}</code>"
                                                if c.bank_entry else ""),
                 f"reproduction: {escape(_reproduction(c))}; E2E-SC {escape(fmt(c.e2e_sc, 3))}"]
        if c.replay_entry:
            missed = c.replay_not_narrowed or {}
            facts.append(f"exact replay entry <code>{escape(c.replay_entry)}</code>: " + (
                "every parameter narrowed around the failing values" if not missed else
                "not narrowed (drawn as in the parent): " + "; ".join(
                    f"<code>{escape(name)}</code> ({escape(why)})" for name, why in sorted(missed.items()))))
        if c.reason:
            facts.append(f"reason: {escape(c.reason)}")
        if c.status in (ConversionStatus.KEPT, ConversionStatus.MERGED) and not c.converted_video:
            facts.append(f"converted script's clip: none ({escape(_missing_clip_reason(c))})")
        merge_reason = c.conversion.merge_reason if c.conversion is not None else None
        if merge_reason:
            facts.append(f"merged because: {escape(merge_reason)}")
        text = (f"<blockquote>{escape(c.description)}</blockquote>" if c.description
                else '<p class="muted">No description was generated.</p>')
        media = videos.tag(c.video)
        if c.converted_video:  # the failure beside its converted script driven by the same policy
            caption = clip_caption(str(c.bank_entry or c.merged_into or "-"),
                                   {"policy": (report_settings or {}).get("policy"),
                                    "reproduction": c.reproduction or {}},
                                   merged=not c.bank_entry and bool(c.merged_into))
            media = (f'<div class="media"><figure>{media}<figcaption>the failure ({escape(c.scenario)}, seed '
                     f'{escape(rep.seed)})</figcaption></figure><figure>{videos.tag(c.converted_video)}'
                     f'<figcaption>{escape(caption)}</figcaption></figure></div>')
        out.append(f'<div class="card" id="card-{escape(c.id)}">{media}'
                   f'<div class="text"><h3><code>{escape(c.id)}</code></h3>'
                   f'<p>{"<br>".join(facts)}</p><p><b>Generated description</b></p>{text}'
                   f'{_script(base, c.script)}</div></div>')
    return "".join(out) + "</div>"


def _missing_clip_reason(cluster: ClusterEntry) -> str:
    """Why a kept or merged conversion shows no clip of its converted script: the error recorded when it could not
    be made, else that none was recorded (a run from before clips were made, or no reproduction episode)."""
    reproduction = cluster.reproduction
    clip = reproduction.get("clip") if isinstance(reproduction, Mapping) else None
    if isinstance(clip, Mapping) and clip.get("error"):
        return f"it could not be made: {clip['error']}"
    return "none was recorded for this conversion"


def _rejected(report: MineReport) -> str:
    rejected = report.rejected
    if not rejected:
        return '<p class="muted">None.</p>'
    by_stage = report.counts.rejected_by_stage or {}
    summary = "<p>By stage: " + ", ".join(f"{escape(s)} {escape(n)}" for s, n in by_stage.items()) + ".</p>"
    rows = [[(f"<code>{_breakable(r.cluster)}</code>", False), (escape(r.index), True),
             (escape(r.stage), False), (escape(r.reason), False)] for r in rejected]
    return summary + _table(["cluster", "episode", "stage", "reason"], rows)


def _failure_rows(failures: Sequence[FailureEntry], limit: int = 200) -> str:
    if not failures:
        return '<p class="muted">None.</p>'
    rows = []
    for f in failures[:limit]:
        reference = f.reference
        ref_text = (f"{reference.policy if reference.policy is not None else '?'}: "
                    + (reference.failure_type or "no failure") if recorded(reference) else "–")
        rows.append([(escape(f.index), True), (_breakable(f.scenario), False),
                     (escape(f.seed), True), (escape(f.type), False), (escape(ref_text), False),
                     (f"<code>{_breakable(f.cluster)}</code>", False), (_breakable(f.trace or "–"), False)])
    more = (f'<p class="muted">{len(failures) - limit} more in report.json.</p>' if len(failures) > limit else "")
    return _table(["episode", "scenario", "seed", "failure", "reference driver", "cluster", "trace"], rows) + more


def _errors(report: MineReport) -> str:
    errors = report.errors
    if not errors and not report.worker_restarts:
        return '<p class="muted">None.</p>'
    items = [f"<li><b>#{escape(e.index)} {escape(e.scenario)} seed {escape(e.seed)}</b>: "
             f"{escape(e.error)}</li>" for e in errors[:100]]
    items += [f"<li><b>#{escape(r.index)} {escape(r.scenario)} seed {escape(r.seed)}</b>: "
              f"{escape('; then '.join(r.problems or []))}; finished by a new worker</li>"
              for r in report.worker_restarts[:100]]
    return "<ul>" + "".join(items) + "</ul>"


def render_html(report: MineReport, *, base: Union[str, os.PathLike] = ".",
                page_dir: Optional[Union[str, os.PathLike]] = None, embed_videos: bool = True,
                max_videos: int = MAX_VIDEOS) -> str:
    """The page as a string; relative video and script paths resolve against ``base`` (the run folder)."""
    report = mine_report(report, "render_html")
    base = Path(base)
    videos = _Videos(base, Path(page_dir) if page_dir is not None else base, embed_videos, max_videos)
    title = f"dv2s mine: {report.settings.get('policy', '?')}"
    plots = [("Failures per 100 episodes for each sampler: every failure (circle) and the avoidable ones (square), "
              "with Wilson 95% intervals", sampler_plot(report)),
             ("Distinct failure clusters found as episodes ran, per sampler", discovery_plot(report)),
             ("Failure rate of each scenario with its Wilson 95% interval", scenario_plot(report))]
    figures = "".join(f"<figure>{plot}<figcaption>{escape(caption)}</figcaption></figure>" for caption, plot in plots)
    clusters = list(report.clusters)
    unavoidable = list(report.unavoidable_clusters)
    order = {status: rank for rank, status in enumerate(ConversionStatus)}  # kept, merged, rejected
    converted = sorted((c for c in clusters if c.conversion is not None), key=lambda c: order.get(c.status, 3))
    unavoidable_converted = [c for c in unavoidable if c.conversion is not None]
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{escape(title)}</title><style>{CSS}{EXTRA_CSS}</style></head><body>",
        f"<h1>{escape(title)}</h1>",
        _banner(report),
        "<h2>Settings</h2>", _settings_table(report),
        "<h2>Summary</h2>", _counts_table(report), f"<p>{escape(rate_text(report.failure_rate))}</p>",
        "<h2>Samplers</h2>", _sampler_table(report),
        "<h2>Plots</h2>", figures,
        "<h2>Scenarios</h2>", _scenario_table(report),
        f"<h2>Failure clusters ({len(clusters)})</h2>",
        '<p class="muted">Clusters with at least one failure the reference driver avoided (or not checked); '
        "unavoidable clusters are listed apart below.</p>", _cluster_table(clusters),
        f"<h2>Converted failures ({len(converted)})</h2>",
        '<p class="muted">Each converted cluster\'s failure video (bird\'s-eye, the seconds before and through the '
        "failure) beside the description the pipeline generated from it; below it, where the conversion was kept, "
        "the converted script driven by the same policy on one of its reproduction episodes.</p>",
        _cards(converted, videos, base, report.settings),
        f"<h2>Rejected conversions ({len(report.rejected)})</h2>", _rejected(report),
        f"<h2>Unavoidable failures ({len(report.unavoidable)})</h2>",
        '<p class="muted">The reference driver failed in the same scene too; these do not count against the '
        "policy.</p>", _cluster_table(unavoidable),
        _cards(unavoidable_converted, videos, base, report.settings) if unavoidable_converted else "",
        _failure_rows(report.unavoidable),
        "<h2>Errors and worker restarts</h2>", _errors(report),
        f"<script>{SELFTEST}</script></body></html>",
    ]
    return "\n".join(parts)


def write_html(report: MineReport, path: Union[str, os.PathLike], *,
               base: Optional[Union[str, os.PathLike]] = None, embed_videos: bool = True,
               max_videos: int = MAX_VIDEOS) -> Path:
    """Write the page to ``path`` (atomically) and return ``path``.

    Args:
        report: a ``dv2s-mine`` report (:class:`~dv2s_gym.mining.report_record.MineReport`).
        path: the ``.html`` file.
        base: the run folder the report's relative paths (videos, scripts) start from
            (default: the report's ``run_dir``, else the page's folder).
        embed_videos: embed up to ``max_videos`` failure videos as data URIs; the others are
            linked relative to the page.
    """
    report = mine_report(report, "write_html")
    path = Path(path)
    base = Path(base) if base is not None else Path(report.run_dir or path.parent)
    page = render_html(report, base=base, page_dir=path.parent, embed_videos=embed_videos, max_videos=max_videos)
    path.parent.mkdir(parents=True, exist_ok=True)
    return atomic_write_text(path, page)
