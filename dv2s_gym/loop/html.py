"""The loop report as a self-contained HTML page (:func:`render_html`): the rounds' table, each round's section
of the Markdown form with its failure-rate figures and the clips of its kept mined scenarios."""

from __future__ import annotations

import re
from html import escape
from typing import Any, List, Mapping, Optional

from dv2s_gym.loop.record import HeldOutComparison, LoopReportBody, RoundRecord
from dv2s_gym.loop.report_text import (_final_line, _floor_lines, _recommendation, _replays_text, _round_row,
                                       _weights, render_markdown, report_rounds)

__all__ = ["render_html"]


_CSS = ("body{font-family:system-ui,sans-serif;margin:2em;max-width:1100px}table{border-collapse:collapse;margin:1em 0}"
        "td,th{border:1px solid #ccc;padding:4px 8px;text-align:left}th{background:#f3f3f3}"
        ".PASS,.ACCEPTED{color:#186a1f;font-weight:bold}.FAIL,.REJECTED{color:#a11;font-weight:bold}"
        ".INCONCLUSIVE,.NOT_ACCEPTED{color:#a60}"
        "code{background:#f5f5f5;padding:1px 3px}.row{display:flex;flex-wrap:wrap;gap:8px}"
        "figure{margin:0}figcaption{font-size:small}")


def _markdown_to_html(lines: List[str]) -> str:
    """The few Markdown forms the round details use (headings, bullets, tables, bold) as HTML."""
    def inline(text: str) -> str:
        text = escape(text)
        text = re.sub(r"\*\*(.+?)\*\*", r"<strong>\1</strong>", text)
        return re.sub(r"`([^`]+)`", r"<code>\1</code>", text)

    html: List[str] = []
    table: List[List[str]] = []
    bullets: List[str] = []

    def flush() -> None:
        if bullets:
            html.append("<ul>" + "".join(f"<li>{b}</li>" for b in bullets) + "</ul>")
            bullets.clear()
        if table:
            head, *body = table
            html.append("<table><tr>" + "".join(f"<th>{inline(c)}</th>" for c in head) + "</tr>"
                        + "".join("<tr>" + "".join(f"<td>{inline(c)}</td>" for c in row) + "</tr>" for row in body)
                        + "</table>")
            table.clear()

    for line in lines:
        if line.startswith("|"):
            if bullets:
                flush()
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if not all(set(c) <= set("-") for c in cells):
                table.append(cells)
            continue
        if table:
            flush()
        if line.startswith("## "):
            flush()
            html.append(f"<h2>{inline(line[3:])}</h2>")
        elif line.startswith("- "):
            bullets.append(inline(line[2:]))
        elif line.startswith("  - ") and bullets:
            bullets[-1] += "<br>" + inline(line[4:])
        elif line.strip():
            flush()
            html.append(f"<p>{inline(line)}</p>")
    flush()
    return "".join(html)


def _clips_html(clips: Mapping[str, Any]) -> str:
    """Each kept mined scenario's videos (paths relative to the loop folder): a failure's clip beside the clip of
    its converted script (the videos of one ``group`` in one row)."""
    parts = []
    for scenario, videos in clips.items():
        if not videos:
            continue
        rows: List[List[Mapping[str, Any]]] = []
        for video in videos:
            if not video.get("path"):  # no clip: only the reason
                rows.append([video])
                continue
            if rows and video.get("group") is not None and rows[-1][0].get("group") == video.get("group"):
                rows[-1].append(video)
            else:
                rows.append([video])
        cells = "".join(
            "<div class=\"row\">" + "".join(
                f"<figure><video src=\"{escape(v['path'])}\" controls muted loop preload=\"metadata\" "
                f"width=\"320\"></video><figcaption>{escape(v['label'])}</figcaption></figure>" for v in row
                if v.get("path"))
            + "".join(f"<p class=\"note\">{escape(note)}</p>"
                      for note in dict.fromkeys(v.get("note") for v in row) if note)
            + "</div>" for row in rows)
        parts.append(f"<div class=\"clips\"><h3>{escape(scenario)}</h3>{cells}</div>")
    return "".join(parts)


def _rates_svg(title: str, bars: List[tuple]) -> str:
    """An inline SVG bar chart of failure rates with their 95 % intervals: ``bars`` = ``[(label, rate, low,
    high)]`` (``rate`` ``None``: no bar)."""
    bars = [b for b in bars if b[1] is not None]
    if not bars:
        return ""
    width, height, left, top = 120 * len(bars) + 60, 190, 40, 24
    plot = height - top - 36
    parts = [f'<svg width="{width}" height="{height}" role="img">'
             f'<title>{escape(title)}</title><text x="4" y="14" font-size="12">{escape(title)}</text>']
    for tick in (0.0, 0.5, 1.0):
        y = top + plot * (1 - tick)
        parts.append(f'<line x1="{left - 4}" x2="{width - 8}" y1="{y:.1f}" y2="{y:.1f}" stroke="#ddd"/>'
                     f'<text x="4" y="{y + 4:.1f}" font-size="10">{tick:.1f}</text>')
    for index, (label, rate, low, high) in enumerate(bars):
        x = left + 20 + index * 120
        y = top + plot * (1 - float(rate))
        parts.append(f'<rect x="{x}" y="{y:.1f}" width="60" height="{top + plot - y:.1f}" fill="#7a9cc6"/>')
        if low is not None and high is not None:
            y_low, y_high = top + plot * (1 - float(low)), top + plot * (1 - float(high))
            parts.append(f'<line x1="{x + 30}" x2="{x + 30}" y1="{y_low:.1f}" y2="{y_high:.1f}" stroke="#222"/>'
                         f'<line x1="{x + 22}" x2="{x + 38}" y1="{y_low:.1f}" y2="{y_low:.1f}" stroke="#222"/>'
                         f'<line x1="{x + 22}" x2="{x + 38}" y1="{y_high:.1f}" y2="{y_high:.1f}" stroke="#222"/>')
        parts.append(f'<text x="{x + 30}" y="{height - 18}" font-size="11" text-anchor="middle">{escape(label)}</text>'
                     f'<text x="{x + 30}" y="{height - 5}" font-size="10" text-anchor="middle">{float(rate):.2f}</text>')
    return "".join(parts) + "</svg>"


def _round_figures(record: RoundRecord) -> str:
    """The round's failure rates as charts: held-out (start, control, fine-tuned) and untouched."""
    steps = record.steps
    after = steps.after if steps.after is not None else HeldOutComparison()
    held = [(label, rate.rate, rate.low, rate.high) if rate is not None else (label, None, None, None)
            for label, rate in (("start", after.before), ("control", after.control), ("fine-tuned", after.after))]
    policies = (steps.untouched.policies if steps.untouched is not None else None) or {}
    untouched = [(label, ((policies.get(key) or {}).get("failure_rate") or {}).get("value"),
                  ((policies.get(key) or {}).get("failure_rate") or {}).get("low"),
                  ((policies.get(key) or {}).get("failure_rate") or {}).get("high"))
                 for label, key in (("start", "start"), ("control", "control"), ("fine-tuned", "fine_tuned"))]
    charts = [_rates_svg("held-out failure rate (95 % Wilson)", held),
              _rates_svg("untouched set failure rate (95 % Wilson)", untouched)]
    charts = [chart for chart in charts if chart]
    return f'<div class="row">{"".join(charts)}</div>' if charts else ""


def render_html(report: LoopReportBody,
                clips: Optional[Mapping[int, Mapping[str, List[Mapping[str, Optional[str]]]]]] = None) -> str:
    """A self-contained HTML page (inline CSS, nothing fetched) of the loop report's body; ``clips``: round ->
    scenario -> ``[{"path", "label"}]`` videos shown per round (:func:`round_clips`)."""
    settings = report.settings.to_dict() if report.settings is not None else {}  # read by name
    advice = _recommendation(report)
    rounds = report_rounds(report)
    rows = []
    for record in rounds:
        row = _round_row(record)
        verdict = row["verdict"]
        cells = [row["round"], f"{row['failures']} / {row['episodes']}", row["clusters"], row["kept"], row["split"],
                 row["before"], row["control"], row["after"], row["drop"], row["p"], row["p_control"],
                 row["untouched"]]
        row = "".join(f"<td>{escape(str(c))}</td>" for c in cells)
        rows.append(f"<tr>{row}<td class=\"{escape(str(verdict))}\">{escape(str(verdict))}</td></tr>")
    final_line = _final_line(report.final_vs_start)
    final_html = f"<p>{escape(final_line).replace('**', '')}</p>" if final_line else ""
    head = ("<tr><th>round</th><th>failures / episodes mined</th><th>clusters</th><th>kept</th>"
            "<th>fine-tune / held-out</th><th>held-out failure rate: start</th><th>control</th><th>fine-tuned</th>"
            "<th>relative drop</th><th>two-sided McNemar p vs start</th><th>vs control</th>"
            "<th>untouched failure rate start / control / fine-tuned</th><th>rest of the bank</th></tr>")
    markdown = render_markdown(report).splitlines()
    details = []
    starts = [i for i, line in enumerate(markdown) if line.startswith("## Round ")]
    for position, begin in enumerate(starts):
        end = starts[position + 1] if position + 1 < len(starts) else len(markdown)
        number = rounds[position].round if position < len(rounds) else None
        details.append(_markdown_to_html(markdown[begin:end]))
        if position < len(rounds):
            details.append(_round_figures(rounds[position]))
        round_clips = (clips or {}).get(number) or {}
        if any(round_clips.values()):
            details.append("<h3>Clips of the kept mined scenarios: each failure beside its converted script driven "
                           "by the same policy (an entry without a clip says why)</h3>" + _clips_html(round_clips))
    return (f"<!DOCTYPE html><html><head><meta charset=\"utf-8\"><title>dv2s loop</title><style>{_CSS}</style>"
            f"</head><body><h1>dv2s loop</h1><p>Started from <code>{escape(str(report.start_policy))}</code>; "
            f"last fine-tuned policy <code>{escape(str(report.policy))}</code>.</p>"
            f"<p class=\"{escape(advice.verdict.replace(' ', '_'))}\"><b>"
            f"{escape(advice.sentence)}</b></p><p>Policy to use: <code>"
            f"{escape(str(advice.policy))}</code></p><p>Mining budget {settings.get('budget')} "
            f"episodes per round, at most {escape(str('every' if settings.get('max_conversions') is None else settings.get('max_conversions')))} cluster(s) "
            f"converted, {escape(_replays_text(settings))}, "
            f"fine-tuning ({escape(str(settings['fine_tune_method']))}) "
            f"{settings.get('fine_tune_steps')} steps (reward terms "
            f"{escape(_weights(settings.get('fine_tune_reward')))} overridden in training only), "
            f"{'with' if settings.get('control') else 'without'} a control arm, {settings.get('k_eval')} "
            f"evaluation seeds per held-out scenario (Wilson 95 % intervals; the drop's interval resamples "
            f"held-out families, the unit the split holds out; the McNemar p-values pair episodes, and pairs within "
            f"a family are not independent; no drop or test below {settings['min_heldout_episodes']} held-out episodes or "
            f"{settings['min_heldout_families']} held-out families).</p>"
            + "".join(f"<p><strong>{escape(line.strip('*'))}</strong></p>" for line in _floor_lines(settings)[:1]) +
            f"<table>{head}{''.join(rows)}</table>{final_html}{''.join(details)}</body></html>\n")
