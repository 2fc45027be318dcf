"""The mining report (``dv2s_gym.mining.report`` / ``.html``) on a run folder written by hand per the mining
contract: counts, per-sampler rates with Wilson intervals, clusters (from the mining core's clustering),
conversions and rejections, Markdown tables, the JSON schema, and the HTML page in a headless Chromium
(plots drawn, a real failure video plays)."""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from dv2s_gym.mining.html import write_html
from dv2s_gym.mining.report_record import MineReport
from dv2s_gym.mining.report import (SCHEMA, SCHEMA_VERSION, MiningReportError, build_report, format_summary,
                                    markdown, write_reports)
from envs.errors import DV2SError
from scenario_bank.records import EpisodeRecord
from dv2s_gym.mining.errors import MiningError
from browser_helpers import body_attributes, table_widths

POLICY = "rule?action_noise=0.3"
# (sampler, scenario, u, failure type, avoidable, error); u is the one unit-box coordinate of the scene; each
# failure's behaviour follows its type (BEHAVIOURS), so the clusters are (scenario, type) here
EPISODES = [
    ("cross-entropy", "A", 0.10, "collision", True, None),   # 0  A/collision:rear_end/r0
    ("cross-entropy", "A", 0.15, "collision", True, None),   # 1  A/collision:rear_end/r0
    ("cross-entropy", "A", 0.50, None, None, None),          # 2
    ("cross-entropy", "B", 0.20, "off_road", False, None),   # 3  B/off_road/r0 (unavoidable)
    ("cross-entropy", "B", 0.80, "collision", True, None),   # 4  B/collision:rear_end/r2
    ("cross-entropy", "A", 0.55, None, None, None),          # 5
    ("cross-entropy", "A", 0.90, "low_ttc", None, None),     # 6  A/low_ttc/r2 (avoidability unknown)
    ("cross-entropy", "B", 0.40, None, None, "worker crashed (exit code -9); restarted"),  # 7
    ("cross-entropy", "B", 0.85, "stall", True, None),       # 8  B/stall/r2
    ("cross-entropy", "A", 0.30, "collision", True, None),   # 9  A/collision:rear_end/r0
    ("cross-entropy", "B", 0.25, "off_road", False, None),   # 10 B/off_road/r0 (unavoidable)
    ("cross-entropy", "A", 0.60, None, None, None),          # 11
    ("random", "A", 0.62, None, None, None),                 # 12
    ("random", "A", 0.05, "collision", True, None),          # 13 A/collision:rear_end/r0
    ("random", "B", 0.45, None, None, None),                 # 14
    ("random", "B", 0.50, None, None, None),                 # 15
    ("random", "A", 0.40, None, None, None),                 # 16
    ("random", "B", 0.01, "off_road", False, None),          # 17 B/off_road/r0 (unavoidable)
    ("random", "A", 0.64, None, None, None),                 # 18
    ("random", "B", 0.66, None, None, None),                 # 19
]
BEHAVIOURS = {"collision": ("car", "braking", "keeping_lane"), "off_road": ("none", "none", "lane_change"),
              "low_ttc": ("truck", "steady", "keeping_lane"), "stall": ("none", "none", "stopped")}
A_COLLISION, B_COLLISION = "A/collision:rear_end/car-braking/ego-keeping_lane", "B/collision:rear_end/car-braking/ego-keeping_lane"
A_TTC, B_STALL = "A/low_ttc/truck-steady/ego-keeping_lane", "B/stall/none-none/ego-stopped"
B_OFF_ROAD = "B/off_road/none-none/ego-lane_change"
DESCRIPTION = "The ego drives in the right lane; a car ahead brakes hard and the ego <hits> it from behind."


def wilson(k: int, n: int, z: float = 1.959963984540054):
    """The Wilson score interval, written out here to check the report's."""
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return centre - half, centre + half


def _failure(kind: str, time: float) -> dict:
    collision_type = "rear_end" if kind == "collision" else None
    return {"type": kind, "time": time, "step": int(time * 5), "with": "car1" if collision_type else None,
            "with_kind": "car" if collision_type else None, "collision_type": collision_type,
            "min_ttc": 0.4 if kind == "low_ttc" else None, "speed": 20.0,
            "kind": f"{kind}:{collision_type}" if collision_type else kind}


def _record(index: int, sampler: str, scenario: str, u: float, kind, avoidable, error) -> dict:
    failure = _failure(kind, 3.0 + index / 10) if kind else None
    result = None if error else {"scenario": scenario, "seed": 1000 + index, "collided": kind == "collision",
                                 "off_road": kind == "off_road", "min_ttc": None, "steps": 40,
                                 "trajectory_hash": f"h{index}", "failed": kind in ("collision", "off_road")}
    reference = None
    if kind and avoidable is not None:
        reference = {"policy": "rule", "failure": _failure(kind, 3.5) if avoidable is False else None,
                     "trajectory_hash": f"r{index}"}
    return {"index": index, "sampler": sampler, "policy": POLICY, "scenario": scenario, "family": scenario,
            "seed": 1000 + index,
            "params": {"ego_speed": 20.0 + 15.0 * u}, "point": [u], "result": result, "failure": failure,
            "rho": (-1.0 - index / 100) if kind else 1.0, "reference": reference,
            "avoidable": avoidable if kind else None, "trace": f"traces/{index:06d}.json.gz" if kind else None,
            "error": error, **({"behaviour": dict(zip(("actor", "actor_manoeuvre", "ego_manoeuvre"), BEHAVIOURS[kind]))}
                               if kind else {})}


def write_clip(path: Path, frames: int = 12, size: int = 96) -> Path:
    """A real VP8 clip of a bright square crossing a dark road, written with the project's VideoWriter."""
    from envs.recording import VideoWriter

    path.parent.mkdir(parents=True, exist_ok=True)
    with VideoWriter(path, fps=5) as video:
        for i in range(frames):
            frame = np.full((size, size, 3), 40, dtype=np.uint8)
            x = 4 + i * (size - 24) // frames
            frame[size // 2 - 10: size // 2 + 10, x: x + 20] = (240, 200, 60)
            video.write(frame)
    return path


def make_run(out: Path, *, clips: bool = True) -> Path:
    """A run folder per the mining contract: 20 episodes of two samplers, four conversions, a torn last line."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "settings.json").write_text(json.dumps({
        "schema": "dv2s-mine", "version": 1, "policy": POLICY, "sampler": "cross-entropy", "seed": 7, "batch": 4,
        "scenarios": ["A", "B", "C"], "bank_dir": None, "env_config": {}, "reference": "rule",
        "ttc_threshold": 1.0, "stall_seconds": 3.0, "budget": 20,
        "space": {name: {"ego_speed": {"kind": "continuous", "low": 20.0, "high": 35.0}} for name in "ABC"}}))
    lines = [json.dumps(_record(i, *row)) for i, row in enumerate(EPISODES)]
    lines[2] = lines[2].replace('"rho": 1.0', '"rho": NaN')  # a non-finite number must not reach report.json
    (out / "episodes.jsonl").write_text("\n".join(lines) + '\n{"index": 20, "sampler": "cross-ent')
    a_dir, merged_dir = "failures/A__collision-rear_end__r0", "failures/A__low_ttc__r2"
    conversions = [
        {"cluster": A_COLLISION, "index": 0, "status": "kept", "reason": None, "video": f"{a_dir}/failure.webm",
         "description": DESCRIPTION, "script": f"{a_dir}/conversion/scenario.scenic",
         "reproduction": {"k": 10, "reproduced": 6, "rate": 0.6, "interval": [0.31, 0.83], "threshold": 0.3},
         "e2e_sc": 0.712, "bank_entry": "mined_a_rear_end", "merged_into": None, "seconds": 2.5,
         "timings": {"video": 0.75, "describe": 0.25, "generate": 0.25, "check": 0.5, "reproduction": 0.5}},
        {"cluster": B_COLLISION, "index": 4, "status": "rejected",
         "reason": "reproduction: reproduced 1 of 10 (0.10 < threshold 0.30)", "video": None,
         "description": "A car cuts in.", "script": None,
         "reproduction": {"k": 10, "reproduced": 1, "rate": 0.1, "interval": [0.02, 0.4], "threshold": 0.3},
         "e2e_sc": 0.4, "bank_entry": None, "merged_into": None, "seconds": 4.5},
        {"cluster": B_STALL, "index": 8, "status": "rejected", "reason": "check: compile failed: unknown name 'Lanee'",
         "stage": "check", "timings": {"video": 0.5, "describe": 0.25, "generate": 0.25, "check": 0.5},
         "video": "failures/B__stall__r2/failure.webm", "description": None, "script": None, "reproduction": None,
         "e2e_sc": None, "bank_entry": None, "merged_into": None, "seconds": 1.5},
        {"cluster": A_TTC, "index": 6, "status": "merged", "reason": None, "video": f"{merged_dir}/failure.webm",
         "description": "The ego closes in on a slow truck.", "script": f"{merged_dir}/conversion/scenario.scenic",
         "reproduction": {"k": 10, "reproduced": 5, "rate": 0.5, "interval": [0.24, 0.76], "threshold": 0.3},
         "e2e_sc": 0.65, "bank_entry": None, "merged_into": "mined_a_rear_end", "seconds": 3.0},
    ]
    (out / "conversions.jsonl").write_text("".join(json.dumps(c) + "\n" for c in conversions))
    script = out / a_dir / "conversion" / "scenario.scenic"
    script.parent.mkdir(parents=True)
    script.write_text("param ego_speed = Range(20, 25)\nego = new Car with behavior FollowLaneBehavior()\n")
    if clips:
        write_clip(out / a_dir / "failure.webm")
        write_clip(out / merged_dir / "failure.webm")
    return out


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    return make_run(tmp_path_factory.mktemp("mine"))


@pytest.fixture(scope="module")
def report(run_dir) -> dict:
    return build_report(run_dir)


def test_counts(report):
    counts = report.to_dict()["counts"]
    assert counts["episodes"] == 19 and counts["errors"] == 1  # the torn 21st line is left out
    assert report.to_dict()["skipped_lines"] == {"episodes.jsonl": 1}
    assert counts["failures"] == 10
    assert counts["failures_by_type"] == {"collision": 5, "off_road": 3, "low_ttc": 1, "stall": 1}
    assert (counts["avoidable"], counts["unavoidable"], counts["avoidability_unknown"]) == (6, 3, 1)
    assert counts["clusters"] == 5 and counts["avoidable_clusters"] == 3 and counts["unavoidable_clusters"] == 1
    assert (counts["converted"], counts["kept"], counts["merged"], counts["rejected"]) == (4, 1, 1, 2)
    assert counts["rejected_by_stage"] == {"check": 1, "reproduction": 1}  # the record's stage, else the reason's
    assert counts["conversion_stage_seconds"] == {"video": 0.625, "describe": 0.25, "generate": 0.25, "check": 0.5,
                                                  "reproduction": 0.5}
    assert counts["conversion_seconds"] == {"n": 4, "median": 2.75, "max": 4.5, "total": 11.5}


def test_per_sampler_rates_have_wilson_intervals(report):
    ce, rnd = report.to_dict()["samplers"]["cross-entropy"], report.to_dict()["samplers"]["random"]
    assert (ce["episodes"], ce["errors"], ce["failures"], ce["avoidable_failures"]) == (11, 1, 8, 5)
    assert (rnd["episodes"], rnd["errors"], rnd["failures"], rnd["avoidable_failures"]) == (8, 0, 2, 1)
    for entry, k, n in ((ce["failures_per_100"], 8, 11), (ce["avoidable_failures_per_100"], 5, 11),
                        (rnd["failures_per_100"], 2, 8), (rnd["avoidable_failures_per_100"], 1, 8)):
        low, high = wilson(k, n)
        assert entry["value"] == pytest.approx(100 * k / n)
        assert entry["low"] == pytest.approx(100 * low) and entry["high"] == pytest.approx(100 * high)
        assert (entry["count"], entry["n"]) == (k, n)
    assert ce["clusters"] == 5 and ce["avoidable_clusters"] == 3
    assert ce["clusters_per_100"] == pytest.approx(500 / 11)
    assert rnd["clusters"] == 2 and rnd["avoidable_clusters"] == 1 and rnd["clusters_per_100"] == 25.0
    assert ce["episodes_to_first_failure"] == 1 and rnd["episodes_to_first_failure"] == 2
    # cross-entropy found new clusters at its 1st, 4th, 5th, 7th and 8th episode (index 7 errored); 11 ran
    assert ce["discovery"] == [[1, 1], [4, 2], [5, 3], [7, 4], [8, 5], [11, 5]]
    assert rnd["discovery"] == [[2, 1], [6, 2], [8, 2]]


def test_per_scenario_table(report):
    a, b, c = (report.to_dict()["scenarios"][name] for name in "ABC")
    assert (a["episodes"], a["failures"], a["avoidable"], a["unknown"], a["clusters"]) == (11, 5, 4, 1, 2)
    assert (b["episodes"], b["errors"], b["failures"], b["unavoidable"], b["clusters"]) == (8, 1, 5, 3, 3)
    assert c["episodes"] == 0 and c["failure_rate"]["value"] is None  # selected but never sampled
    low, high = wilson(5, 11)
    assert a["failure_rate"]["value"] == pytest.approx(5 / 11)
    assert (a["failure_rate"]["low"], a["failure_rate"]["high"]) == (pytest.approx(low), pytest.approx(high))
    assert a["converted"] == 2 and a["kept"] == 1 and b["converted"] == 2 and b["kept"] == 0


def test_clusters_carry_their_conversion(report):
    clusters = {c["id"]: c for c in report.to_dict()["clusters"]}
    assert list(clusters) == [A_COLLISION, B_COLLISION, B_STALL, A_TTC]  # most avoidable failures first
    a = clusters[A_COLLISION]
    assert (a["scenario"], a["type"], a["kind"], a["region"], a["size"], a["avoidable"]) == (
        "A", "collision", "collision:rear_end", "car-braking/ego-keeping_lane", 4, 4)
    assert a["samplers"] == {"cross-entropy": 3, "random": 1}
    assert a["params"]["ego_speed"]["min"] == pytest.approx(20.75) and a["params"]["ego_speed"]["max"] == pytest.approx(24.5)
    assert a["behaviour"] == {"actor": "car", "actor_manoeuvre": "braking", "ego_manoeuvre": "keeping_lane"}
    assert clusters[B_STALL]["behaviour"] == {"actor": "none", "actor_manoeuvre": "none", "ego_manoeuvre": "stopped"}
    assert a["collision_types"] == {"rear_end": 4} and a["with_kinds"] == {"car": 4}
    assert a["representative"]["index"] == 0 and a["representative"]["seed"] == 1000
    assert (a["status"], a["bank_entry"], a["reproduction_rate"], a["e2e_sc"]) == ("kept", "mined_a_rear_end", 0.6, 0.712)
    assert a["video"].endswith("failure.webm") and a["description"] == DESCRIPTION
    assert clusters[A_TTC]["status"] == "merged" and clusters[A_TTC]["merged_into"] == "mined_a_rear_end"
    assert clusters[A_TTC]["unknown"] == 1
    assert clusters[B_STALL]["status"] == "rejected" and clusters[B_STALL]["reason"].startswith("check: compile")
    [off_road] = report.to_dict()["unavoidable_clusters"]
    assert (off_road["id"], off_road["size"], off_road["unavoidable"], off_road["status"]) == (
        B_OFF_ROAD, 3, 3, "not converted")
    assert off_road["representative"]["index"] == 17  # all unavoidable, so among all: the lowest rho (-1.17)


def test_failures_and_unavoidable_are_listed_apart(report):
    assert sorted(f["index"] for f in report.to_dict()["failures"]) == [0, 1, 4, 6, 8, 9, 13]
    assert [f["index"] for f in report.to_dict()["unavoidable"]] == [3, 10, 17]
    assert all(f["reference"]["failure"]["type"] == "off_road" for f in report.to_dict()["unavoidable"])
    assert report.to_dict()["errors"] == [{"index": 7, "sampler": "cross-entropy", "scenario": "B", "seed": 1007,
                                 "error": "worker crashed (exit code -9); restarted"}]
    assert {(r["cluster"], r["stage"]) for r in report.to_dict()["rejected"]} == {(B_COLLISION, "reproduction"),
                                                                        (B_STALL, "check")}


def test_report_json_is_strict_schema_json(run_dir, tmp_path):
    run = make_run(tmp_path / "run", clips=False)
    paths = write_reports(run)
    assert set(paths) == {"json", "markdown", "html"} and all(p.is_file() for p in paths.values())

    def no_constants(name):
        raise AssertionError(f"report.json holds {name}")

    data = json.loads(paths["json"].read_text(), parse_constant=no_constants)
    assert (data["schema"], data["schema_version"]) == (SCHEMA, SCHEMA_VERSION) == ("dv2s-mine-report", 3)
    for key in ("created", "dv2s_version", "run_dir", "settings", "counts", "samplers", "scenarios", "clusters",
                "unavoidable_clusters", "failures", "unavoidable", "rejected", "errors", "skipped_lines"):
        assert key in data, key
    assert data["settings"]["policy"] == POLICY and data["settings"]["budget"] == 20
    assert data["counts"]["clusters"] == 5
    assert not list(run.glob("*.tmp*"))  # atomic writes leave no temporary files


def test_markdown_has_the_tables(report):
    text = markdown(report)
    assert "| sampler | episodes | failures | failures per 100 |" in text
    ce = report.to_dict()["samplers"]["cross-entropy"]["failures_per_100"]
    assert f"| cross-entropy | 11 | 8 | {ce['value']:.1f} [{ce['low']:.1f}, {ce['high']:.1f}] |" in text
    assert "| `A` | 11 | 5 | 45.5% [" in text
    assert f"| `{A_COLLISION}` | `A` | collision (rear_end, with car) | 4 | 4 |" in text  # how and with whom
    assert "ego_speed 20.8..24.5" in text and "mined_a_rear_end" in text and "0.60 (6/10) [0.31, 0.83]" in text
    assert f"| `{B_STALL}` | 8 | check | check: compile failed: unknown name 'Lanee' |" in text
    assert "### Unavoidable failures (3)" in text and f"| `{B_OFF_ROAD}` | `B` | off_road | 3 | 0 |" in text
    assert "By stage: check 1, reproduction 1" in text
    assert "median per stage: video 0.62 s" in text
    assert "worker crashed (exit code -9)" in text
    assert DESCRIPTION.replace("|", "\\|") in text
    converted = text[text.index("### Converted failures"):text.index("### Rejected conversions")]
    assert converted.index("bank entry `mined_a_rear_end`") < converted.index("merged into `mined_a_rear_end`")
    summary = format_summary(report)
    assert "cross-entropy" in summary and "random" in summary and "10 failure(s) in 19 episode(s)" in summary


def test_a_run_without_failures_reports_zeros(tmp_path):
    out = tmp_path / "quiet"
    out.mkdir()
    (out / "settings.json").write_text(json.dumps({"policy": "rule", "sampler": "halton", "seed": 0}))
    (out / "episodes.jsonl").write_text(json.dumps(_record(0, "halton", "A", 0.5, None, None, None)) + "\n")
    report = build_report(out)
    assert report.to_dict()["counts"]["failures"] == 0 and report.to_dict()["counts"]["clusters"] == 0
    halton = report.to_dict()["samplers"]["halton"]["failures_per_100"]
    assert halton["value"] == 0.0 and halton["high"] == pytest.approx(100 * wilson(0, 1)[1])
    page = write_html(report, out / "report.html").read_text()
    assert "0 failure(s) in 1 episode(s)" in page and "<video" not in page


@pytest.mark.parametrize("damage, message", [
    ("missing", "does not exist"),
    ("no settings", "no settings.json"),
    ("bad settings", "settings.json is not readable JSON"),
    ("torn middle", "episodes.jsonl:2 is not a JSON record"),
    ("no index", "has no integer 'index'"),
])
def test_bad_run_folders_get_one_line_errors(tmp_path, damage, message):
    out = make_run(tmp_path / "run", clips=False)
    if damage == "missing":
        out = tmp_path / "nowhere"
    elif damage == "no settings":
        (out / "settings.json").unlink()
    elif damage == "bad settings":
        (out / "settings.json").write_text("{not json")
    else:
        lines = (out / "episodes.jsonl").read_text().splitlines()
        lines[1] = lines[1][:30] if damage == "torn middle" else json.dumps({"sampler": "random"})
        (out / "episodes.jsonl").write_text("\n".join(lines) + "\n")
    with pytest.raises(MiningReportError, match=re.escape(message)) as caught:
        build_report(out)
    assert isinstance(caught.value, DV2SError) and "\n" not in str(caught.value)


@pytest.mark.slow
def test_the_report_loads_neither_scenic_nor_highway_env(run_dir):
    code = ("import sys; from dv2s_gym.mining.report import write_reports; import tempfile, shutil; "
            f"d = tempfile.mkdtemp(); shutil.copytree({str(run_dir)!r}, d, dirs_exist_ok=True); write_reports(d); "
            "print(sorted({m.split('.')[0] for m in sys.modules} & {'scenic', 'highway_env', 'verifai', 'torch'}))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                         cwd=Path(__file__).resolve().parents[1])
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "[]"


# ------------------------------------------------------------------------------ HTML
def test_a_kept_conversion_without_its_converted_clip_says_why(run_dir, report, tmp_path):
    """A kept or merged conversion whose converted script's clip is missing says why on its card: the error
    recorded when it could not be made, else that none was recorded."""
    page = write_html(report, tmp_path / "report.html", base=run_dir).read_text()
    assert page.count("converted script's clip: none (none was recorded for this conversion)") == 2  # kept, merged
    damaged = report.to_dict()
    kept = next(c for c in damaged["clusters"] if c.get("status") == "kept")
    kept["reproduction"] = {**(kept.get("reproduction") or {}),
                            "clip": {"file": None, "error": "clip: OSError: [Errno 28] No space left on device"}}
    page = write_html(MineReport.from_dict(damaged), tmp_path / "damaged.html", base=run_dir).read_text()
    assert "converted script's clip: none (it could not be made: clip: OSError: [Errno 28] No space left" in page
    assert page.count("converted script's clip: none") == 2


def test_the_page_embeds_videos_descriptions_and_scripts(run_dir, report, tmp_path):
    page = write_html(report, tmp_path / "report.html", base=run_dir).read_text()
    assert page.startswith("<!DOCTYPE html>")
    assert not re.search(r"<(link|iframe|img|object|embed)\b", page)
    assert not re.search(r"""\b(src|href)\s*=\s*["'](?!data:|#)""", page), "a resource loaded from outside the page"
    assert page.count('<svg class="plot"') == 3
    assert page.count('src="data:video/webm;base64,') == 2  # the kept and the merged cluster's clips
    assert "is missing from the run folder" in page  # the rejected stall cluster's clip was never written
    assert "The ego drives in the right lane; a car ahead brakes hard and the ego &lt;hits&gt; it from behind." in page
    assert "behaviour: car braking; ego keeping_lane" in page
    assert "<details><summary>Generated Scenic script" in page and "FollowLaneBehavior()" in page
    assert "check: compile failed: unknown name &#x27;Lanee&#x27;" in page
    kept, rejected = page.index('id="card-' + A_COLLISION), page.index('id="card-' + B_STALL)
    assert kept < rejected  # kept before rejected
    unavoidable = page.index("<h2>Unavoidable failures (3)</h2>")
    assert page.index(B_OFF_ROAD) > unavoidable  # listed apart, after the avoidable ones
    for scenario in ("A", "B", "C"):
        assert f"<td>{scenario}</td>" in page


def test_videos_beyond_the_cap_are_linked_relative_to_the_page(run_dir, report):
    page = write_html(report, run_dir / "linked.html", max_videos=1).read_text()
    assert page.count('src="data:video/webm;base64,') == 1
    assert 'src="failures/A__low_ttc__r2/failure.webm"' in page


def test_strings_from_records_are_escaped(run_dir, tmp_path):
    hostile = '<script>alert("x")</script><img src=x onerror=alert(1)>'
    run = make_run(tmp_path / "run", clips=False)
    lines = (run / "conversions.jsonl").read_text().splitlines()
    first = json.loads(lines[0])
    first.update(description=hostile, reason=hostile, bank_entry=hostile)
    lines[0] = json.dumps(first)
    (run / "conversions.jsonl").write_text("\n".join(lines) + "\n")
    settings = json.loads((run / "settings.json").read_text())
    settings["policy"] = hostile
    (run / "settings.json").write_text(json.dumps(settings))
    page = write_reports(run)["html"].read_text()
    assert "<script>alert" not in page and "<img" not in page
    assert "&lt;script&gt;alert(&quot;x&quot;)&lt;/script&gt;" in page
    assert page.count("<script>") == 1


@pytest.mark.slow
def test_chromium_renders_the_plots_and_plays_the_failure_video(run_dir):
    page = write_reports(run_dir)["html"]
    attributes = body_attributes(page)
    assert attributes.get("data-plots") == "3", attributes
    assert attributes.get("data-plots-rendered") == "3", attributes
    # 2 samplers x 2 marks, 2 discovery lines, 3 scenario rates minus C (never sampled): 8 marks with a box
    assert attributes.get("data-plot-marks") == "8", attributes
    assert attributes.get("data-videos") == "2", attributes
    assert attributes.get("data-video-played") == "true", attributes
    assert attributes.get("data-video-size") == "96x96", attributes
    assert int(attributes.get("data-video-contrast", "0")) >= 100, attributes


def test_chromium_reports_a_corrupt_failure_video_as_not_played(tmp_path):
    run = make_run(tmp_path / "run")
    clip = run / "failures/A__collision-rear_end__r0/failure.webm"
    clip.write_bytes(b"\x1a\x45\xdf\xa3" + bytes(range(256)) * 40)  # an EBML magic number, then garbage
    attributes = body_attributes(write_reports(run)["html"])
    assert attributes.get("data-plots-rendered") == "3", attributes
    assert attributes.get("data-video-played") == "false", attributes
    assert attributes.get("data-video-error"), attributes


@pytest.mark.slow
def test_the_report_of_a_real_mining_run_matches_its_records(tmp_path):
    """``mine`` writes the three reports at its end; their numbers are those of its episodes.jsonl."""
    from dv2s_gym.mining.cluster import cluster_failures
    from dv2s_gym.mining.miner import read_records
    from mining_helpers import mine

    out = tmp_path / "mine"
    run = mine("rule?action_noise=0.5", out=out, budget=8, sampler="random", workers=1, progress=False,
               scenarios=["highway_lead_vehicle_brakes"])
    assert set(run.reports) == {"json", "markdown", "html"}
    report = json.loads((out / "report.json").read_text())
    records = read_records(out / "episodes.jsonl")
    rows = [r.to_dict() for r in records]  # each line's JSON object
    failed = [r for r in rows if r["failure"] and not r["error"]]
    clusters = cluster_failures(records)
    assert report["counts"]["episodes"] == sum(not r["error"] for r in rows) == 8 - report["counts"]["errors"]
    assert report["counts"]["failures"] == len(failed)
    assert report["counts"]["avoidable"] == sum(r["avoidable"] is True for r in failed)
    assert report["counts"]["clusters"] == len(set(clusters.values()))
    entry = report["samplers"]["random"]["failures_per_100"]
    assert (entry["count"], entry["n"]) == (len(failed), report["counts"]["episodes"])
    page = (out / "report.html").read_text()
    for cluster in set(clusters.values()):
        assert cluster in page
    for name, params in report["scenarios"].items():
        assert name == "highway_lead_vehicle_brakes" and params["failures"] == len(failed)


def test_breadth_counts_and_their_text(report):
    counts = report.to_dict()["counts"]
    assert counts["behaviours"] == counts["clusters"] == 5
    # A: collision, low_ttc; B: off_road, collision, stall
    assert counts["scenario_failure_types"] == 5 and counts["scenarios_failing"] == 2
    assert report.to_dict()["scenarios"]["A"]["failure_types"] == 2 and report.to_dict()["scenarios"]["B"]["failure_types"] == 3
    assert (counts["collisions"], counts["stalls"]) == (5, 1)
    line = ("10 failure(s): 5 distinct behaviour(s), 5 (scenario family, failure type) pair(s), 2 scenario "
            "famil(ies) with a failure; by type: collision 5, off road 3, low_ttc 1, stall 1; collisions 5, stalls 1")
    assert line in format_summary(report) and line in markdown(report)


def test_a_report_without_stalls_says_zero_stalls_apart_from_collisions(tmp_path):
    """A reader of the saved report tells "0 stalls" from "not counted": the counts and every form say it."""
    run = make_run(tmp_path / "run", clips=False)
    lines = (run / "episodes.jsonl").read_text().splitlines()
    kept = [line for line in lines if '"stall"' not in line]
    assert len(kept) < len(lines)
    (run / "episodes.jsonl").write_text("".join(line + "\n" for line in kept))
    report = build_report(run)
    assert (report.to_dict()["counts"]["collisions"], report.to_dict()["counts"]["stalls"]) == (5, 0)
    assert "collisions 5, stalls 0" in markdown(report) and "collisions 5, stalls 0" in format_summary(report)


def test_the_rate_estimate_needs_every_proposal_density(report):
    rate = report.to_dict()["failure_rate"]  # the cross-entropy records of this run were written without their densities
    assert rate["available"] is False and "no proposal density" in rate["reason"]
    assert "not estimated" in format_summary(report)


def test_a_uniform_run_estimates_its_plain_failure_rate(tmp_path):
    run = make_run(tmp_path / "run", clips=False)
    lines = (run / "episodes.jsonl").read_text().splitlines()[:-1]
    records = [json.loads(line.replace("NaN", "1.0")) for line in lines]
    for record in records:
        record["sampler"] = "random"
    (run / "episodes.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    report = build_report(run)
    rate = report.to_dict()["failure_rate"]
    assert rate["available"] is True
    a = rate["scenarios"]["A"]
    assert (a["value"], a["n"], a["ess"]) == (pytest.approx(5 / 11), 11, pytest.approx(11))
    low, high = wilson(5, 11)
    assert (a["low"], a["high"]) == (pytest.approx(low), pytest.approx(high))
    # random draws every scenario as often as the overall target weighs it: every weight is 1
    assert (rate["overall"]["value"], rate["overall"]["ess"]) == (pytest.approx(10 / 19), pytest.approx(19))
    assert "importance-weighted" in markdown(report)


def _mine_settings(run_dir) -> tuple:
    """``(policy, MineSettings)`` of the miner's run in ``run_dir``, as its ``settings.json`` records them."""
    from dv2s_gym.mining.miner import MineSettings

    recorded = json.loads((Path(run_dir) / "settings.json").read_text())
    return recorded["policy"], MineSettings(sampler=recorded["sampler"], seed=recorded["seed"],
                                            scenarios=tuple(recorded["scenarios"]), batch=recorded["batch"],
                                            reference=recorded["reference"])


def test_the_miner_s_summary_states_the_breadth(run_dir):
    from pathlib import Path as _Path

    from dv2s_gym.mining.cluster import cluster_failures
    from dv2s_gym.mining.miner import MineRun, read_records

    records = read_records(_Path(run_dir) / "episodes.jsonl")
    policy, settings = _mine_settings(run_dir)
    run = MineRun(out=_Path(run_dir), policy=policy, settings=settings, records=records,
                  clusters=cluster_failures([EpisodeRecord.from_dict(r) for r in records]))
    # the miner counts a failure of unknown avoidability (the low TTC) as avoidable
    assert ("5 distinct behaviours, 4 with avoidable failures; 5 (scenario family, failure type) pairs, 2 scenario "
            "families with a failure; 5 collisions, 1 stalls") in run.summary()


def test_the_miner_s_summary_calls_failure_kinds_by_their_labels(run_dir):
    from pathlib import Path as _Path

    from dv2s_gym.mining.cluster import cluster_failures
    from dv2s_gym.mining.miner import MineRun, read_records

    records = read_records(_Path(run_dir) / "episodes.jsonl")
    policy, settings = _mine_settings(run_dir)
    run = MineRun(out=_Path(run_dir), policy=policy, settings=settings, records=records,
                  clusters=cluster_failures([EpisodeRecord.from_dict(r) for r in records]))
    failures_line = run.summary().splitlines()[1]
    assert failures_line.startswith("10 failures (rear-end collision 5, off road 3, ")
    assert "low_ttc 1" in failures_line and "stall 1" in failures_line
    assert "collision:" not in failures_line and "off_road" not in failures_line


def test_without_a_reference_driver_the_summary_counts_no_behaviour_with_avoidable_failures(run_dir):
    from pathlib import Path as _Path

    from dv2s_gym.mining.cluster import cluster_failures
    from dv2s_gym.mining.miner import MineRun, read_records

    records = [{**r.to_dict(), "avoidable": None, "reference": None}
               for r in read_records(_Path(run_dir) / "episodes.jsonl")]
    policy, settings = _mine_settings(run_dir)
    run = MineRun(out=_Path(run_dir), policy=policy, settings=settings.replace(reference=None), records=records,
                  clusters=cluster_failures([EpisodeRecord.from_dict(r) for r in records]))
    summary = run.summary()
    assert "avoidability not checked (no reference driver)" in summary
    assert "5 distinct behaviours; 5 (scenario family, failure type) pairs" in summary
    assert "avoidable failures" not in summary


def test_a_plain_run_states_its_seed(report):
    assert "sampler cross-entropy, seed 7: " in format_summary(report)
    assert "derived" not in markdown(report)


def test_a_loop_round_s_report_names_the_loop_seed_beside_its_own(tmp_path):
    """`dv2s loop` mines round R of a loop with seed S with seed 1000 S + R; every form of the report says both."""
    run = make_run(tmp_path / "run", clips=False)
    settings = json.loads((run / "settings.json").read_text())
    settings.update(seed=1, origin={"command": "dv2s loop", "seed": 0, "round": 1})
    (run / "settings.json").write_text(json.dumps(settings))
    paths = write_reports(run)
    said = "seed 1 (derived by dv2s loop from its seed 0, round 1)"
    assert said in format_summary(MineReport.from_dict(json.loads(paths["json"].read_text())))
    assert said in paths["markdown"].read_text()
    page = paths["html"].read_text()
    start = page.index('id="summary"')
    assert said in page[start:page.index("</div>", start)]  # the banner
    assert "<th>seed</th><td>1 (derived by dv2s loop from its seed 0, round 1)</td>" in page


LONG_NAMES = {"A": "urban_t_junction_left_turn_oncoming", "B": "highway_simultaneous_merge_middle",
              "mined_a_rear_end": "mined_urban_t_junction_left_turn_oncoming_collision_rear_end_3"}


def test_the_page_s_tables_fit_a_1400_pixel_window(tmp_path):
    """With the bank's longest scenario names and real cluster ids, no table is wider than the page's column
    (a wider one would scroll inside its box, its scroll bar below a table of 60 clusters)."""
    run = make_run(tmp_path / "run", clips=False)
    for name in ("settings.json", "episodes.jsonl", "conversions.jsonl"):
        text = (run / name).read_text()
        for short, long in LONG_NAMES.items():
            text = text.replace(f'"{short}"', f'"{long}"').replace(f'"{short}/', f'"{long}/')
        (run / name).write_text(text)
    page = write_reports(run)["html"]
    assert LONG_NAMES["A"] + "/collision:rear_end/car-braking/ego-keeping_lane" in page.read_text()
    widths = table_widths(page, window_width=1400)
    assert len(widths) >= 6, widths
    too_wide = [w for w in widths if w["table"] > w["box"] + 1 or w["box"] > w["window"]]
    assert not too_wide, too_wide


def test_the_rate_sentence_says_how_many_episodes_and_which_scenarios_were_never_drawn():
    from dv2s_gym.mining.report_text import rate_text

    drawn = {"value": 0.2, "raw": 0.2, "low": 0.04, "high": 0.6, "ess": 9.4, "n": 6, "failures": 1}
    empty = {"value": None, "raw": None, "low": None, "high": None, "ess": 0.0, "n": 0, "failures": 0}
    rate = {"available": True, "reason": None, "collapsed": False, "overall": drawn,
            "scenarios": {"a": drawn, "b": drawn, "c": empty}}
    text = rate_text(rate)
    assert "from 6 episodes, as precise as 9.4 draws" in text
    assert "1 of 3 scenarios were never drawn" in text and "--budget" in text
    assert "never drawn" not in rate_text({**rate, "scenarios": {"a": drawn}})


def test_a_run_whose_every_episode_errored_says_so_and_counts_them_as_drawn(tmp_path):
    from dv2s_gym.mining.cluster import cluster_failures
    from dv2s_gym.mining.miner import MineRun, MineSettings

    out = tmp_path / "broken"
    out.mkdir()
    settings = {"policy": "boom", "sampler": "random", "seed": 0, "scenarios": ["A", "B"], "reference": None}
    (out / "settings.json").write_text(json.dumps(settings))
    records = [_record(i, "random", "A", 0.5, None, None, "Traceback ...\nRuntimeError: boom") for i in range(2)]
    (out / "episodes.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    report = build_report(out)
    assert report.to_dict()["counts"]["errors"] == 2 and report.to_dict()["counts"]["episodes"] == 0
    text = markdown(report)
    assert "WARNING: all 2 episodes ended in an error: the run measured nothing (e.g. RuntimeError: boom)" in text
    assert "1 of 2 scenarios were drawn (2 episode(s)) but every episode of them ended in an error" in text
    assert "1 of 2 scenarios were never drawn" in text  # B
    mined = MineSettings(sampler="random", seed=0, scenarios=("A", "B"), reference=None)
    run = MineRun(out=out, policy="boom", settings=mined, records=records,
                  clusters=cluster_failures([EpisodeRecord.from_dict(r) for r in records]))
    assert run.all_errored and "WARNING: all 2 episodes ended in an error" in run.summary()
    partial = MineRun(out=out, policy="boom", settings=mined, clusters={},
                      records=records[:1] + [_record(1, "random", "A", 0.5, None, None, None)])
    assert not partial.all_errored and "WARNING: 1 of 2 episodes ended in an error" in partial.summary()
    assert partial.summary().startswith("2 episodes of boom (random sampler), 1 error (A 1), ")
    assert run.summary().startswith("2 episodes of boom (random sampler), 2 errors (A 2), ")


def test_one_behaviour_in_two_entries_of_one_family_is_one_behaviour(tmp_path):
    """Clusters and breadth counts are per scenario family; the cluster still lists the entries."""
    from dv2s_gym.mining.cluster import cluster_failures

    out = tmp_path / "family"
    out.mkdir()
    (out / "settings.json").write_text(json.dumps({"policy": "rule", "sampler": "random", "seed": 0,
                                                   "scenarios": ["mined_a", "replay_a"]}))
    records = [{**_record(i, "random", name, 0.5, "collision", True, None), "family": "A"}
               for i, name in enumerate(["mined_a", "replay_a", "mined_a"])]
    (out / "episodes.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    report = build_report(out)
    counts = report.to_dict()["counts"]
    assert counts["failures"] == 3 and counts["behaviours"] == 1
    assert counts["scenario_failure_types"] == 1 and counts["scenarios_failing"] == 1
    (cluster,) = report.to_dict()["clusters"]
    assert cluster["id"].startswith("A/collision:rear_end/") and cluster["family"] == "A"
    assert cluster["scenarios"] == ["mined_a", "replay_a"] and cluster["size"] == 3
    assert report.to_dict()["scenarios"]["replay_a"]["clusters"] == report.to_dict()["scenarios"]["mined_a"]["clusters"] == 1
    assert "`mined_a`, `replay_a`" in markdown(report)
    without = [{k: v for k, v in r.items() if k != "family"} for r in records]  # no family: not a record of a run
    with pytest.raises(MiningError, match="episode 0 of mined_a records no scenario family"):
        cluster_failures([EpisodeRecord.from_dict(r) for r in without])


def test_a_scenario_s_family_follows_the_provenance_to_its_first_scenario(tmp_path):
    from dv2s_gym.mining.family import scenario_family
    from loop_helpers import add_mined_copy

    bank = tmp_path / "bank"
    bank.mkdir()
    add_mined_copy(str(bank), "highway_cut_in_from_right", "mined_x", "c")
    add_mined_copy(str(bank), "highway_cut_in_from_right", "replay_of_mined_x", "c", parent="mined_x")
    assert scenario_family("replay_of_mined_x", str(bank)) == "highway_cut_in_from_right"
    assert scenario_family("mined_x", str(bank)) == "highway_cut_in_from_right"
    assert scenario_family("highway_cut_in_from_right") == "highway_cut_in_from_right"  # shipped: no parent
    assert scenario_family("not_an_entry", str(bank)) == "not_an_entry"


def test_a_family_asked_before_its_entry_was_added_is_read_again_after(tmp_path):
    from dv2s_gym.mining.family import scenario_family
    from loop_helpers import add_mined_copy

    bank = tmp_path / "bank"
    bank.mkdir()
    assert scenario_family("mined_y", str(bank)) == "mined_y"  # not an entry yet: its own family
    add_mined_copy(str(bank), "highway_cut_in_from_left", "mined_y", "c")
    assert scenario_family("mined_y", str(bank)) == "highway_cut_in_from_left"


def test_every_reason_the_judge_rejected_a_conversion_for_is_in_the_reports(tmp_path):
    """A conversion the judge rejected for three reasons (its first is ``reason``) shows all three, in the report's
    JSON, Markdown and HTML."""
    import html

    run = make_run(tmp_path / "run", clips=False)
    rows = [json.loads(line) for line in (run / "conversions.jsonl").read_text().splitlines()]
    reasons = [rows[1]["reason"],
               "actors: the failure's scene has 2 actors (car 1, pedestrian 1), the new scenario's 1 actor (car 1): "
               "1 pedestrian fewer",
               "parameters: the new scenario's ranges do not contain the failing values: ego_speed = 31.5 outside 20..25"]
    rows[1]["rejections"] = reasons
    (run / "conversions.jsonl").write_text("".join(json.dumps(row) + "\n" for row in rows))
    paths = write_reports(run)
    rejected = {r["cluster"]: r for r in json.loads(paths["json"].read_text())["rejected"]}
    assert rejected[B_COLLISION]["rejections"] == reasons and rejected[B_COLLISION]["stage"] == "reproduction"
    assert rejected[B_STALL]["rejections"] == [rows[2]["reason"]]  # a failed check before the judge: its one reason
    markdown, page = paths["markdown"].read_text(), paths["html"].read_text()
    for reason in reasons:
        assert reason in markdown and html.escape(reason, quote=True) in page, reason


def test_each_kept_replay_entry_lists_the_parameters_its_replay_could_not_narrow(tmp_path):
    run_dir = make_run(tmp_path / "run", clips=False)
    lines = (run_dir / "conversions.jsonl").read_text().splitlines()
    conversions = [json.loads(line) for line in lines]
    why = "its distribution is not an interval the replay can narrow"
    conversions[0].update(replay_entry="A_replay_1000", replay_not_narrowed={"weather": why, "lane": "a <choice>"})
    conversions[1].update(replay_entry="B_replay_1004", replay_not_narrowed={})  # kept although its script was not
    (run_dir / "conversions.jsonl").write_text("".join(json.dumps(c) + "\n" for c in conversions))
    report = build_report(run_dir)
    clusters = {c["id"]: c for c in report.to_dict()["clusters"]}
    assert clusters[A_COLLISION]["replay_entry"] == "A_replay_1000"
    assert clusters[A_COLLISION]["replay_not_narrowed"] == {"weather": why, "lane": "a <choice>"}
    assert clusters[B_COLLISION]["replay_not_narrowed"] == {} and clusters[B_STALL]["replay_entry"] is None
    saved = json.loads(json.dumps(report.to_dict()))  # what report.json holds
    assert saved["clusters"][0]["replay_not_narrowed"]["weather"] == why
    text = markdown(report)
    section = text[text.index("### Exact replay entries"):]
    assert (f"- `A_replay_1000` (cluster `{A_COLLISION}`): not narrowed: lane (a <choice>); weather ({why})"
            in section)
    assert f"- `B_replay_1004` (cluster `{B_COLLISION}`): every parameter narrowed" in section
    page = write_html(report, tmp_path / "report.html", base=run_dir).read_text()
    assert ("exact replay entry <code>A_replay_1000</code>: not narrowed (drawn as in the parent): "
            "<code>lane</code> (a &lt;choice&gt;); <code>weather</code> (" + why + ")") in page
    assert "exact replay entry <code>B_replay_1004</code>: every parameter narrowed" in page
