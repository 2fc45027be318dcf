"""The regression report as one self-contained HTML page.

:func:`write_html` turns a report (a :class:`~dv2s_gym.regress.records.RegressReport`, or the JSON object of
the ``dv2s-regress`` schema written by the runner, read at the door) into a single file with no external
resources: inline CSS, plots drawn as
inline SVG by the small functions below (per-scenario failure and collision rates
with their intervals, the paired difference per scenario against the margin,
distributions of minimum time-to-collision and return), a verdict banner, tables with
the scenarios worst first, and the newly failing episodes grouped by scenario (regressed
scenarios first), each as two embedded ``data:video/webm`` clips side by side: the
candidate's failure, replayed from its trace
(:func:`~dv2s_gym.regress.clips.render_episode_video`), and the baseline's run of the same
scene (from its trace, or re-run: :func:`~dv2s_gym.regress.clips.render_policy_video`).

The CSS, plot primitives and self-check script are shared with the mining report
(:mod:`dv2s_gym.report_page`). Every string taken from the report is escaped. A small inline script records, on
load, how many plots have a non-empty box (``data-plots-rendered`` on ``<body>``);
opened as ``report.html#selftest`` it also plays the first clip and both sides of the first
pair and records whether they played (``data-video-played``, ``data-pair-played``) — the
browser test reads these attributes.
"""

from __future__ import annotations

import math
import os
import sys
import tempfile
from pathlib import Path
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union

from tqdm import tqdm

from dv2s_gym.regress.clips import (DEFAULT_CLIP_CONFIG, ClipError, clip_window, render_episode_video,
                                    render_policy_video)
from dv2s_gym.regress.records import (BankInfo, PairedComparison, PairedEpisode, RegressReport, ReportSettings,
                                      ScenarioResult, Summary)
from dv2s_gym.regress.report import scenarios_by_severity, warnings as report_warnings
from dv2s_gym.report_page import (BOTTOM, CSS, RIGHT, ROW, SELFTEST, TOP, WIDTH, VideoSource,
                                  axis as _axis, escape as _e, finite as _num, fmt as _fmt,
                                  fmt_interval as _interval, interval_mark as _interval_mark, legend as _legend,
                                  row_label as _row_label, svg as _svg, video_bytes as _video_bytes, video_tag,
                                  x_scale as _x_scale)
from scenario_bank.atomic import atomic_write_text
from scenario_bank.failure_types import FAILURE_TABLE, FailureType
from scenario_bank.records import RegressEpisode, recorded

__all__ = ["write_html", "render_html", "render_episode_video", "MAX_VIDEOS"]

MAX_VIDEOS = 12
"""Newly failing episodes shown as clips; the rest are listed."""

COLOURS = {"candidate": "#0b63c5", "baseline": "#8a8f98", "PASS": "#1a7f37", "FAIL": "#cf222e",
           "INCONCLUSIVE": "#b07800", "ERROR": "#8250df", None: "#57606a"}


# --------------------------------------------------------------------------- SVG plots
def rate_plot(report: RegressReport, metric: str, title: str) -> str:
    """Forest plot: ``metric`` (a rate) per scenario and overall, with intervals, for both policies."""
    rows = _scenario_rows(report)
    has_baseline = report.baseline is not None
    height = TOP + ROW * len(rows) + BOTTOM
    x = _x_scale(0.0, 1.0)[2]
    body = _axis(x, 0.0, 1.0, height, title)
    legend = [("candidate", COLOURS["candidate"], "circle")]
    if has_baseline:
        legend.append(("baseline", COLOURS["baseline"], "square"))
    body.append(_legend(legend))
    for i, (name, entry, overall) in enumerate(rows):
        y = TOP + ROW * i + ROW / 2
        body.append(_row_label(y, name, bold=overall))
        for role, offset, shape in (("candidate", -4 if has_baseline else 0, "circle"), ("baseline", 4, "square")):
            summary = entry.candidate if role == "candidate" else entry.baseline
            stat = summary.rates.get(metric) if summary is not None else None
            if isinstance(stat, Mapping):
                tip = f"{name}, {role}: {metric.replace('_', ' ')} {_interval(stat)}"
                body.append(_interval_mark(x, y + offset, stat, COLOURS[role], shape, tip))
    return _svg(height, title, body)


def difference_plot(report: RegressReport) -> str:
    """Paired difference (candidate − baseline failure rate) per scenario, with the margin line."""
    rows = [(n, e, o) for n, e, o in _scenario_rows(report) if e.comparison is not None]
    margin = _num(report.settings.margin if report.settings is not None else None) or 0.0
    values = [margin, 0.0]
    for _, entry, _ in rows:
        diff = entry.comparison.difference or {}
        values += [v for v in (_num(diff.get(k)) for k in ("value", "low", "high")) if v is not None]
    bound = min(1.0, max(0.1, max(abs(v) for v in values) * 1.1))
    low, high = -bound, bound
    height = TOP + ROW * len(rows) + BOTTOM
    x = _x_scale(low, high)[2]
    title = "Paired difference in failure rate (candidate − baseline)"
    body = _axis(x, low, high, height, title, signed=True)
    body.append(f'<line class="zero" x1="{x(0):.1f}" y1="{TOP - 6}" x2="{x(0):.1f}" y2="{height - BOTTOM}"/>')
    body.append(f'<line class="margin" x1="{x(margin):.1f}" y1="{TOP - 6}" x2="{x(margin):.1f}" '
                f'y2="{height - BOTTOM}"/><text class="margin-label" x="{x(margin) + 3:.1f}" y="{TOP - 12}">'
                f'margin {margin:+.2f}</text>')
    body.append(_legend([(v.lower(), COLOURS[v], "circle") for v in ("PASS", "FAIL", "INCONCLUSIVE")]))
    for i, (name, entry, overall) in enumerate(rows):
        y = TOP + ROW * i + ROW / 2
        comparison = entry.comparison
        verdict = comparison.verdict
        colour = COLOURS.get(verdict, COLOURS[None])
        body.append(_row_label(y, name, bold=overall))
        tip = f"{name}: difference {_interval(comparison.difference)}, {verdict or 'no verdict'}"
        if comparison.reason:
            tip += f" ({comparison.reason})"
        body.append(_interval_mark(x, y, comparison.difference or {}, colour, "circle", tip))
    return _svg(height, title, body)


def histogram_plot(groups: Mapping[str, Sequence[float]], title: str, bins: Sequence[float],
                   extra: Optional[Mapping[str, int]] = None, extra_label: str = "") -> str:
    """Grouped histogram of per-episode values for each policy (``extra``: a last bar of counts)."""
    roles = list(groups)
    counts = {role: [0] * (len(bins) - 1) for role in roles}
    for role in roles:
        for value in groups[role]:
            index = next((i for i in range(len(bins) - 1) if value < bins[i + 1]), len(bins) - 2)
            counts[role][max(0, index) if value >= bins[0] else 0] += 1
    labels = [_bin_label(bins[i], bins[i + 1]) for i in range(len(bins) - 1)]
    if extra is not None:
        labels.append(extra_label)
        for role in roles:
            counts[role].append(int(extra.get(role, 0)))
    top = max([1] + [c for role in roles for c in counts[role]])
    height, plot_top, plot_bottom, left = 230, 26, 190, 50
    slot = (WIDTH - left - RIGHT) / len(labels)
    bar = slot * 0.8 / max(1, len(roles))
    body = [f'<line class="axis" x1="{left}" y1="{plot_bottom}" x2="{WIDTH - RIGHT}" y2="{plot_bottom}"/>',
            f'<line class="axis" x1="{left}" y1="{plot_top}" x2="{left}" y2="{plot_bottom}"/>',
            f'<text class="tick" x="{left - 6}" y="{plot_top + 4}" text-anchor="end">{top}</text>',
            f'<text class="tick" x="{left - 6}" y="{plot_bottom + 4}" text-anchor="end">0</text>',
            f'<text class="axis-title" x="{(left + WIDTH - RIGHT) / 2:.1f}" y="{height - 6}">{_e(title)}</text>',
            _legend([(role, COLOURS.get(role, "#444"), "square") for role in roles])]
    for i, label in enumerate(labels):
        x0 = left + slot * i + slot * 0.1
        body.append(f'<text class="tick" x="{left + slot * (i + 0.5):.1f}" y="{plot_bottom + 14}">{_e(label)}</text>')
        for j, role in enumerate(roles):
            count = counts[role][i]
            h = (plot_bottom - plot_top) * count / top
            body.append(f'<rect class="mark" x="{x0 + bar * j:.1f}" y="{plot_bottom - h:.1f}" width="{bar:.1f}" '
                        f'height="{h:.1f}" fill="{COLOURS.get(role, "#444")}"><title>{_e(role)}, {_e(label)}: '
                        f'{count} episodes</title></rect>')
    return _svg(height, title, body)


def _bin_label(low: float, high: float) -> str:
    if math.isinf(high):
        return f"≥{low:g}"
    return f"{low:.3g}–{high:.3g}"


def _scenario_rows(report: RegressReport) -> List[Tuple[str, ScenarioResult, bool]]:
    """Scenarios worst first (:func:`~dv2s_gym.regress.report.scenarios_by_severity`), then overall."""
    scenarios = dict(report.scenarios or {})
    try:
        order = scenarios_by_severity(report)
    except (TypeError, ValueError, AttributeError):  # a hand-edited report: fall back to names
        order = sorted(scenarios)
    rows = [(str(name), scenarios[name], False) for name in order]
    if report.overall is not None:
        rows.append(("overall", report.overall, True))
    return rows


def _episode_values(report: RegressReport, role: str, measure: Callable[[RegressEpisode], Any]
                    ) -> List[Optional[float]]:
    values = []
    for episode in report.episodes or ():
        result = episode.result(role)
        if result is not None and not result.error:
            values.append(_num(measure(result)))
    return values


def distribution_plots(report: RegressReport) -> List[str]:
    """Histograms of minimum time-to-collision and episode return per policy."""
    roles = ["candidate"] + (["baseline"] if report.baseline is not None else [])
    ttc = {role: _episode_values(report, role, lambda result: result.min_ttc) for role in roles}
    finite = {role: [v for v in ttc[role] if v is not None] for role in roles}
    no_conflict = {role: sum(v is None for v in ttc[role]) for role in roles}
    plots = [histogram_plot(finite, "Minimum time-to-collision per episode [s]",
                            [0, 1, 2, 3, 4, 5, 6, 8, 10, math.inf], no_conflict, "none")]
    returns = {role: [v for v in _episode_values(report, role, lambda result: result.episode_return) if v is not None]
               for role in roles}
    every = [v for values in returns.values() for v in values]
    if every:
        low, high = min(every), max(every)
        if high - low < 1e-9:
            low, high = low - 0.5, high + 0.5
        step = (high - low) / 8
        bins = [low + i * step for i in range(8)] + [high + 1e-9]
        plots.append(histogram_plot(returns, "Episode return", bins))
    return plots


# --------------------------------------------------------------------------- page
def _banner(report: RegressReport) -> str:
    verdict = report.verdict
    candidate = report.candidate.spec if report.candidate is not None else None
    baseline = report.baseline.spec if report.baseline is not None else None
    css = verdict if verdict in ("PASS", "FAIL", "INCONCLUSIVE", "ERROR") else "NONE"
    if verdict == "ERROR" and report.baseline is None:
        head = f"ERROR: {_e(candidate)} (measures only): {_e(report.error_reason)}"
    elif verdict is None:
        head = f"No verdict: {_e(candidate)} was run without a baseline"
    else:
        head = f"{_e(verdict)}: {_e(candidate)} against {_e(baseline)}"
    detail = []
    regressed = report.regressed or ()
    if regressed:
        detail.append(f"regressed on {len(regressed)} scenario(s): {_e(', '.join(map(str, regressed)))}")
    comparison = report.overall.comparison if report.overall is not None else None
    if comparison is not None and comparison.reason:
        detail.append(f"overall: {_e(comparison.reason)}")
    if report.newly_failing:
        detail.append(f"{len(report.newly_failing)} newly failing episode(s)")
    if report.errors:
        detail.append(f"{len(report.errors)} error(s)")
    if report.stopped_early:
        detail.append("stopped early (sequential test)")
    small = f"<small>{'; '.join(detail)}</small>" if detail else ""
    banner = f'<div class="banner {css}" id="verdict">{head}{small}</div>'
    for number, warning in enumerate(report_warnings(report)):  # before the verdict is trusted: as prominent as it
        banner += f'<div class="banner INCONCLUSIVE" id="warning-{number}">warning: {_e(warning)}</div>'
    return banner


def _settings_table(report: RegressReport) -> str:
    settings = report.settings if recorded(report.settings) else ReportSettings()
    bank = report.bank if recorded(report.bank) else BankInfo()
    written = settings.to_dict()  # the settings the run recorded (a null one included)
    rows = [("candidate", report.candidate.spec if report.candidate is not None else None),
            ("baseline", report.baseline.spec if report.baseline is not None else "none")]
    rows += [(key, getattr(settings, key)) for key in ("episodes", "seed", "margin", "alpha", "sequential", "backend",
                                                       "workers") if key in written]
    version = "?" if bank.version is None else bank.version
    rows += [("bank", f"{'' if bank.path is None else bank.path} (version {version})"),
             ("created", report.created), ("dv2s version", report.dv2s_version)]
    return "<table>" + "".join(f"<tr><th>{_e(k)}</th><td>{_e(v)}</td></tr>" for k, v in rows) + "</table>"


def _scenario_table(report: RegressReport) -> str:
    has_baseline = report.baseline is not None
    head = ["scenario", "episodes", "candidate failure rate"]
    if has_baseline:
        head += ["baseline failure rate", "both fail / cand. only / base. only / neither", "difference",
                 "p", "p (adjusted)", "verdict", "reason"]
    out = ["<table><tr>" + "".join(f"<th>{_e(h)}</th>" for h in head) + "</tr>"]
    for name, entry, overall in _scenario_rows(report):
        candidate = entry.candidate if recorded(entry.candidate) else Summary()
        cells = [f"<td>{'<b>' if overall else ''}{_e(name)}{'</b>' if overall else ''}</td>",
                 f'<td class="num">{_e(candidate.episodes)}</td>',
                 f'<td class="num">{_e(_interval(candidate.failure_rate))}</td>']
        if has_baseline:
            baseline = entry.baseline if recorded(entry.baseline) else Summary()
            comparison = entry.comparison if recorded(entry.comparison) else PairedComparison()
            table = comparison.table or {}
            counts = " / ".join(str(table.get(k, "–")) for k in ("both_fail", "candidate_only", "baseline_only",
                                                                  "neither"))
            verdict = comparison.verdict
            cells += [f'<td class="num">{_e(_interval(baseline.failure_rate))}</td>',
                      f'<td class="num">{_e(counts)}</td>',
                      f'<td class="num">{_e(_interval(comparison.difference, 3))}</td>',
                      f'<td class="num">{_e(_fmt(comparison.p_value, 4))}</td>',
                      f'<td class="num">{_e(_fmt(comparison.p_adjusted, 4))}</td>',
                      f'<td class="v-{_e(verdict)}">{_e(verdict or "–")}</td>',
                      f"<td>{_e(comparison.reason)}</td>"]
        out.append("<tr>" + "".join(cells) + "</tr>")
    return "".join(out) + "</table>"


def _collided_detail(result: RegressEpisode) -> str:
    return f" with {', '.join(map(str, result.collisions))}" if result.collisions else ""


def _stalled_detail(result: RegressEpisode) -> str:
    stall = _num(result.stall_time)
    return f" from {stall:.1f} s" if stall is not None else ""


_DETAILS: Dict[str, Callable[[RegressEpisode], str]] = {"collided": _collided_detail, "stalled": _stalled_detail}
"""What an episode's outcome says after a failure kind's label, by the kind's result field: the result records whom
the ego collided with (``collisions``) and when it began to stall (``stall_time``) beside those two fields."""


def _outcome_detail(row: FailureType, result: RegressEpisode) -> str:
    """What an episode's outcome says after the label of failure type ``row``: whom it collided with, when it
    stalled (:data:`_DETAILS`)."""
    detail = _DETAILS.get(row.result_field or "")
    return detail(result) if detail is not None else ""


def _outcome(result: Optional[RegressEpisode]) -> str:
    if result is None:
        return "not run"
    if result.error:
        return f"error: {result.error}"
    # a failure kind's result field is one of the record's attributes (collided, off_road, stalled)
    parts = [row.label + _outcome_detail(row, result) for row in FAILURE_TABLE
             if row.label and row.result_field and getattr(result, row.result_field)]
    if not parts:
        parts.append("success" if result.success else "no failure")
    ttc = _num(result.min_ttc)
    parts.append(f"min TTC {'none' if ttc is None else f'{ttc:.2f} s'}")
    parts.append(f"{'?' if result.steps is None else result.steps} steps")
    return ", ".join(parts)


def _resolve_trace(trace: Any, base: Path) -> Optional[Path]:
    if not trace:
        return None
    path = Path(str(trace))
    for candidate in ([path] if path.is_absolute() else [base / path, Path.cwd() / path]):
        if candidate.is_file():
            return candidate
    return None


def _clip(report: RegressReport, episode: PairedEpisode, role: str, base: Path, scratch: Path,
          given: Optional[VideoSource], render_videos: bool, end_step: Optional[int] = None
          ) -> Tuple[Optional[bytes], str]:
    """One side of a pair: the given clip, the trace's replay, or (no trace) a re-run of the policy; rendered
    ones cover the clip's seconds up to ``end_step`` (default: the episode's end)."""
    result = episode.result(role)
    if given is not None:
        return _video_bytes(given), ""
    if not render_videos:
        return None, "clips were not rendered"
    if result is None or result.error:
        return None, f"the {role} has no run of this scene to show"
    out = scratch / f"{role}-{abs(hash(str(episode.id)))}.webm"
    try:
        trace = _resolve_trace(result.trace, base)
        if trace is not None:
            return render_episode_video(trace, out, end_step=end_step).read_bytes(), ""
        if role == "candidate":
            return None, "no trace was recorded for this episode"
        return render_policy_video(report, result, role, out, end_step=end_step).read_bytes(), ""
    except (ClipError, OSError, AssertionError, ValueError) as error:
        return None, f"clip not available: {error}"


def _pair_window(report: RegressReport, episode: PairedEpisode) -> Tuple[Optional[int], str]:
    """``(end step, the caption's words)`` of a pair of clips: both sides show the same seconds of the scene,
    those up to the candidate's failure (its last step)."""
    steps = _num(episode.candidate.steps) if episode.candidate is not None else None
    if steps is None:
        return None, ""
    config = (report.settings.env_config if report.settings is not None else None) or {}
    frequency = float(_num(config.get("policy_frequency")) or 5)
    first, last = clip_window(int(steps), DEFAULT_CLIP_CONFIG["seconds"], frequency)
    return int(steps), (f", both from {first / frequency:.1f} s to {last / frequency:.1f} s of the episode "
                        "(the seconds up to the candidate's failure)")


def _clips(report: RegressReport, base: Path, videos: Optional[Mapping[str, VideoSource]],
           render_videos: bool, max_videos: int, progress: bool = False) -> str:
    """The newly failing episodes, grouped by scenario (worst first): the candidate's clip beside the
    baseline's run of the same scene; ``progress``: a bar on stderr over the clips rendered."""
    newly = [str(i) for i in report.newly_failing or ()]
    if not newly:
        return '<p class="muted">No episode fails for the candidate that the baseline passes.</p>'
    episodes = {str(e.id): e for e in report.episodes or ()}
    videos = dict(videos or {})
    order = [name for name, _, overall in _scenario_rows(report) if not overall]
    by_scenario: dict = {}
    for episode_id in newly:
        known = episodes.get(episode_id)
        scenario = str((known.scenario if known is not None else None) or episode_id.rsplit("/", 1)[0])
        by_scenario.setdefault(scenario, []).append(episode_id)
    regressed = set(map(str, report.regressed or ()))
    out, shown, left = [], 0, []
    bar = None
    if progress and render_videos:
        pairs = min(len(newly), max_videos)
        bar = tqdm(total=2 * pairs - sum(1 for i in newly[:pairs] for key in (i, f"{i}#baseline") if key in videos),
                   desc="report clips", unit="clip", file=sys.stderr, dynamic_ncols=True)
    with tempfile.TemporaryDirectory(prefix="dv2s-clips-") as scratch:
        for scenario in sorted(by_scenario, key=lambda n: (n not in regressed, order.index(n) if n in order else 10**6)):
            ids = by_scenario[scenario]
            label = "regressed" if scenario in regressed else "not significant alone"
            out.append(f'<section class="scenario-clips" data-scenario="{_e(scenario)}"><h3>{_e(scenario)} '
                       f'<small>({_e(label)}; {len(ids)} newly failing)</small></h3><div class="clips">')
            for episode_id in ids:
                if shown >= max_videos:
                    left.append(episode_id)
                    continue
                episode = episodes.get(episode_id)
                episode = episode if recorded(episode) else PairedEpisode()
                end_step, window = _pair_window(report, episode)
                sides = []
                for role in ("candidate", "baseline"):
                    given = videos.get(episode_id) if role == "candidate" else videos.get(f"{episode_id}#baseline")
                    data, note = _clip(report, episode, role, Path(base), Path(scratch), given, render_videos,
                                       end_step)
                    if bar is not None and given is None:
                        bar.update(1)
                    media = video_tag(data) if data is not None else f'<p class="muted">{_e(note)}</p>'
                    sides.append(f'<figure class="side {role}">{media}<figcaption><b>{role}</b>: '
                                 f"{_e(_outcome(episode.result(role)))}</figcaption></figure>")
                out.append(f'<div class="clip pair" id="clip-{shown}"><p><b>{_e(episode_id)}</b> (seed '
                           f'{_e(episode.seed)}): the same scene, candidate beside baseline'
                           f'{_e(window)}</p><div class="sides">{"".join(sides)}</div></div>')
                shown += 1
            out.append("</div></section>")
    if bar is not None:
        bar.close()
    if left:
        out.append(f'<p class="muted">{len(left)} more not shown as clips: {_e(", ".join(left))}</p>')
    return "".join(out)


def _aggregates(report: RegressReport) -> str:
    """The return aggregates (interquartile mean, probability of improvement) as context, not the verdict."""
    aggregates = report.aggregates
    if not isinstance(aggregates, Mapping):
        return ""
    iqm = aggregates.get("return_iqm") or {}
    rows = [("interquartile mean of the return, candidate", iqm.get("candidate")),
            ("interquartile mean of the return, baseline", iqm.get("baseline")),
            ("probability of improvement (return)", aggregates.get("probability_of_improvement"))]
    body = "".join(f'<tr><th>{_e(label)}</th><td class="num">{_e(_interval(value, 3))}</td></tr>'
                   for label, value in rows)
    return ('<h2>Context: aggregates of the return</h2><p class="muted">Stratified bootstrap intervals (episodes '
            'resampled within each scenario). Context only: the verdict is the paired failure test.</p>'
            f'<table id="aggregates">{body}</table>')


def _errors(report: RegressReport) -> str:
    errors = report.errors or ()
    if not errors:
        return '<p class="muted">None.</p>'
    items = []
    for error in errors:
        label = " ".join(str(value) for value in (error.role, error.id) if value)
        items.append(f"<li><b>{_e(label)}</b>: {_e(error.error if 'error' in error.to_dict() else error.to_dict())}"
                     "</li>")
    return "<ul>" + "".join(items) + "</ul>"


def render_html(report: RegressReport, *, base: Union[str, os.PathLike] = ".",
                videos: Optional[Mapping[str, VideoSource]] = None, render_videos: bool = True,
                max_videos: int = MAX_VIDEOS, progress: bool = False) -> str:
    """The report page as a string (see :func:`write_html`); relative trace paths resolve against ``base``."""
    spec = report.candidate.spec if report.candidate is not None else None
    title = f"dv2s regress: {'?' if spec is None else spec}"
    has_baseline = report.baseline is not None
    failure = ", ".join(report.settings.failure)
    plots = [(f"Failure ({failure}) rate per scenario, 95% intervals",
              rate_plot(report, "failure_rate", "Failure rate")),
             ("Collision rate per scenario, 95% intervals", rate_plot(report, "collision_rate", "Collision rate"))]
    if has_baseline:
        plots.append(("Paired difference per scenario with its interval; the dashed line is the non-inferiority "
                      "margin, colours are the verdicts", difference_plot(report)))
    captions = ["Minimum time-to-collision over each episode (none: no vehicle ever on a collision course)",
                "Return of each episode"]
    for caption, plot in zip(captions, distribution_plots(report)):
        plots.append((caption, plot))
    figures = "".join(f"<figure>{svg}<figcaption>{_e(caption)}</figcaption></figure>" for caption, svg in plots)
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{_e(title)}</title><style>{CSS}</style></head><body>",
        f"<h1>{_e(title)}</h1>",
        _banner(report),
        "<h2>Settings</h2>", _settings_table(report),
        "<h2>Scenarios</h2>", _scenario_table(report),
        "<h2>Plots</h2>", figures,
        _aggregates(report),
        f"<h2>Newly failing episodes ({len(report.newly_failing or ())})</h2>",
        _clips(report, Path(base), videos, render_videos, max_videos, progress),
        "<h2>Errors</h2>", _errors(report),
        f"<script>{SELFTEST}</script></body></html>",
    ]
    return "\n".join(parts)


def write_html(report: RegressReport, path: Union[str, os.PathLike], *,
               videos: Optional[Mapping[str, VideoSource]] = None, render_videos: bool = True,
               max_videos: int = MAX_VIDEOS, progress: bool = False) -> Path:
    """Write the report as one self-contained HTML file at ``path`` (atomically); returns the path.

    Args:
        report: a ``dv2s-regress`` report (:class:`~dv2s_gym.regress.records.RegressReport`).
        path: the ``.html`` file to write; relative trace paths in the report resolve against its folder.
        videos: clips to embed, by episode id (``"<scenario>/<seed>"``; ``"<scenario>/<seed>#baseline"`` for the
            baseline's run of the same scene): a ``.webm`` path or its bytes.
        render_videos: render the clips ``videos`` lacks: from the traces, or by re-running the baseline
            policy on the scene when its run kept no trace (it must reproduce the report's trajectory hash).
        max_videos: at most this many clips; the other newly failing episodes are listed.
        progress: a progress bar on stderr while the clips render (they take seconds each).
    """
    path = Path(path)
    page = render_html(report, base=path.parent, videos=videos, render_videos=render_videos,
                       max_videos=max_videos, progress=progress)
    path.parent.mkdir(parents=True, exist_ok=True)
    return atomic_write_text(path, page)
