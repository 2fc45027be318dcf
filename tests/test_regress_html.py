"""The HTML regression report: one self-contained file, escaped, and checked in a real headless
Chromium (it loads, the SVG plots have boxes, the first clip decodes and plays; a corrupt clip does
not). Chromium comes from the system packages: scripts/setup.sh installs it; without it these tests
fail and say how to install it."""

from __future__ import annotations

import copy
import json
import re
from pathlib import Path

import pytest

from dv2s_gym.regress.clips import ClipError, render_episode_video
from dv2s_gym.regress.html import write_html
from dv2s_gym.regress.records import RegressReport

from regress_report_data import make_report
from browser_helpers import body_attributes

@pytest.fixture(scope="module")
def report_dir(tmp_path_factory) -> Path:
    """A real report: rule?action_noise=0.3 against rule on two scenarios x 4 seeds, traces on disk."""
    out = tmp_path_factory.mktemp("report")
    report = make_report(out)
    (out / "report.json").write_text(json.dumps(report))
    return out


@pytest.fixture()
def report(report_dir) -> dict:
    return json.loads((report_dir / "report.json").read_text())


@pytest.mark.slow
def test_the_page_is_one_file_with_no_external_resource(report_dir, report, tmp_path):
    page = write_html(RegressReport.from_json(report), report_dir / "report.html").read_text()
    assert page.startswith("<!DOCTYPE html>")
    assert not re.search(r"<(link|iframe|img|object|embed)\b", page)
    assert not re.search(r"""\b(src|href)\s*=\s*["'](?!data:|#)""", page), "a resource loaded from outside the page"
    assert "url(" not in page and "@import" not in page
    assert page.count('<svg class="plot"') == 5  # two rate plots, the differences, two distributions
    # each newly failing episode: the candidate's clip beside the baseline's run of the same scene
    assert page.count("<video ") == 2 * len(report["newly_failing"]) > 0
    assert page.count('src="data:video/webm;base64,') == 2 * len(report["newly_failing"])
    assert page.count('class="clip pair"') == len(report["newly_failing"])
    for scenario in report["scenarios"]:
        assert scenario in page


@pytest.mark.slow
def test_clips_are_grouped_by_scenario_regressed_first_and_rows_sorted_by_severity(report, tmp_path):
    report = copy.deepcopy(report)
    names = list(report["scenarios"])
    worse, other = names[1], names[0]  # the second scenario (by name) is made the regressed one
    report["regressed"] = [worse]
    report["scenarios"][worse]["comparison"]["verdict"] = "FAIL"
    report["scenarios"][other]["comparison"]["verdict"] = "PASS"
    newly = [f"{worse}/{k}" for k in range(2)] + [f"{other}/{k}" for k in range(2)]
    for episode in report["episodes"]:
        if episode["id"] in newly:
            episode["candidate"]["failed"], episode["baseline"]["failed"] = True, False
    report["newly_failing"] = [i for i in newly if i.startswith(other)] + [i for i in newly if i.startswith(worse)]
    page = write_html(RegressReport.from_json(report), tmp_path / "r.html", render_videos=False).read_text()
    sections = re.findall(r'<section class="scenario-clips" data-scenario="([^"]+)">', page)
    assert sections == [worse, other]  # every clip goes to its own scenario, the regressed one first
    first, second = page.split('data-scenario="')[1:3]
    assert first.count('class="clip pair"') == 2 and all(f"{worse}/" in first for _ in range(1))
    assert f"{other}/0" not in first and f"{other}/0" in second
    table = page.split("<h2>Scenarios</h2>")[1]
    assert table.index(f"<td>{worse}</td>") < table.index(f"<td>{other}</td>")


@pytest.mark.slow
def test_the_baseline_clip_is_a_rerun_when_its_run_kept_no_trace(report_dir, report):
    from dv2s_gym.regress.runner import bank_info

    report = copy.deepcopy(report)
    report["bank"] = bank_info(list(report["scenarios"]))  # the scripts the episodes ran
    first = report["newly_failing"][0]
    for episode in report["episodes"]:
        episode["baseline"]["trace"] = None  # as in a real run: only failed episodes keep a trace
    page = write_html(RegressReport.from_json(report), report_dir / "rerun.html", max_videos=1).read_text()
    pair = page.split('class="clip pair"')[1]
    assert first in pair and pair.count("<video ") == 2
    # a run that does not reproduce the report's trajectory is not shown as if it were the same scene
    episode = next(e for e in report["episodes"] if e["id"] == first)
    episode["baseline"]["trajectory_hash"] = "0" * 64
    page = write_html(RegressReport.from_json(report), report_dir / "rerun2.html", max_videos=1).read_text()
    pair = page.split('class="clip pair"')[1]
    assert pair.count("<video ") == 1 and "did not reproduce" in pair


def test_a_report_without_baseline_has_no_difference_plot(report, tmp_path):
    report = copy.deepcopy(report)
    report.update(baseline=None, verdict=None, regressed=[], newly_failing=[])
    for episode in report["episodes"]:
        episode["baseline"] = None
    for entry in [*report["scenarios"].values(), report["overall"]]:
        entry.update(baseline=None, comparison=None)
    page = write_html(RegressReport.from_json(report), tmp_path / "r.html").read_text()
    assert page.count('<svg class="plot"') == 4
    assert "No verdict" in page and "<video" not in page


def test_strings_from_the_report_are_escaped(report, tmp_path):
    hostile = '<script>alert("x")</script>&<img src=x onerror=alert(1)>'
    report = copy.deepcopy(report)
    name = next(iter(report["scenarios"]))
    report["scenarios"][hostile] = report["scenarios"].pop(name)
    report["scenarios"][hostile]["comparison"]["reason"] = hostile
    report["candidate"]["spec"] = hostile
    report["regressed"] = [hostile]
    report["errors"] = [{"id": hostile, "role": "candidate", "error": hostile}]
    page = write_html(RegressReport.from_json(report), tmp_path / "r.html", render_videos=False).read_text()
    assert "<script>alert" not in page
    assert "<img" not in page
    assert "&lt;script&gt;alert(&quot;x&quot;)&lt;/script&gt;&amp;&lt;img src=x onerror=alert(1)&gt;" in page
    assert page.count("<script>") == 1  # only the page's own self-check


@pytest.mark.slow
def test_chromium_loads_the_page_renders_the_plots_and_plays_a_clip(report_dir, report):
    page = write_html(RegressReport.from_json(report), report_dir / "report.html")
    attributes = body_attributes(page)
    assert attributes.get("data-plots") == "5", attributes
    assert attributes.get("data-plots-rendered") == "5", attributes  # every SVG has a non-empty box
    assert int(attributes.get("data-plot-marks", 0)) >= 10, attributes  # points, intervals and bars drawn
    assert attributes.get("data-videos") == str(2 * len(report["newly_failing"]))
    assert attributes.get("data-video-played") == "true", attributes  # currentTime advanced past 0
    assert attributes.get("data-video-size") == "360x360", attributes
    assert int(attributes.get("data-video-contrast", "0")) >= 10, attributes  # a decoded picture, not a blank
    assert attributes.get("data-pair-played") == "baseline,candidate", attributes  # both sides of the pair play


@pytest.mark.slow
def test_chromium_reports_a_corrupt_clip_as_not_played(report, tmp_path):
    first = report["newly_failing"][0]
    corrupt = b"\x1a\x45\xdf\xa3" + bytes(range(256)) * 40  # an EBML magic number, then garbage
    page = write_html(RegressReport.from_json(report), tmp_path / "r.html", videos={first: corrupt}, render_videos=False, max_videos=1)
    attributes = body_attributes(page)
    assert attributes.get("data-plots-rendered") == "5", attributes
    assert attributes.get("data-video-played") == "false", attributes
    assert attributes.get("data-video-error"), attributes


def test_given_clips_are_embedded_as_they_are(report, tmp_path):
    clip = tmp_path / "given.webm"
    clip.write_bytes(b"not really a video, embedded as given")
    first = report["newly_failing"][0]
    page = write_html(RegressReport.from_json(report), tmp_path / "r.html", videos={first: clip, f"{first}#baseline": clip},
                      render_videos=False).read_text()
    assert page.count("<video ") == 2
    assert "bm90IHJlYWxseSBhIHZpZGVv" in page  # base64 of the bytes
    assert "clips were not rendered" in page


def test_a_missing_trace_is_noted_instead_of_a_clip(report, tmp_path):
    report = copy.deepcopy(report)
    for episode in report["episodes"]:
        episode["candidate"]["trace"] = None
    page = write_html(RegressReport.from_json(report), tmp_path / "r.html").read_text()
    assert "<video" not in page and "no trace was recorded" in page


def test_clips_are_capped(report, tmp_path):
    page = write_html(RegressReport.from_json(report), tmp_path / "r.html", render_videos=False, max_videos=1).read_text()
    more = len(report["newly_failing"]) - 1
    assert f"{more} more not shown as clips" in page


def test_render_episode_video_writes_the_last_seconds_of_the_replayed_episode(report_dir, report, tmp_path):
    from dv2s_gym.pipeline.video import read_video

    episode = next(e for e in report["episodes"] if e["id"] == report["newly_failing"][0])
    steps = episode["candidate"]["steps"]
    out = render_episode_video(report_dir / episode["candidate"]["trace"], tmp_path / "clip.webm", seconds=2.0,
                               size=160)
    frames = read_video(out, fps=None, max_frames=10**6, max_pixels=10**9).frames  # every frame, full size
    assert len(frames) == min(steps + 1, 10)  # 2 s at the policy frequency (5 Hz), reset frame included
    assert frames[0].shape == (160, 160, 3)
    assert frames[-1].std() > 5  # a picture of the road, not a blank


def test_render_episode_video_errors_name_the_trace(tmp_path):
    with pytest.raises(ClipError, match="does not exist"):
        render_episode_video(tmp_path / "missing.json.gz", tmp_path / "x.webm")
    broken = tmp_path / "broken.json.gz"
    broken.write_bytes(b"\x1f\x8bnot gzip")
    with pytest.raises(ClipError, match="broken.json.gz"):
        render_episode_video(broken, tmp_path / "x.webm")


@pytest.mark.slow
def test_both_clips_of_a_pair_show_the_same_seconds_of_the_scene(report_dir, report, tmp_path):
    """The baseline's clip covers the seconds up to the candidate's failure, not the end of its own episode."""
    import numpy as np

    from dv2s_gym.pipeline.video import read_video

    def frames(path):
        return read_video(path, fps=None, max_frames=10**6, max_pixels=10**9).frames

    # the pair whose baseline drives on longest after the candidate's failure: its last frame is farthest from
    # the failure's moment, so the window's end can be told from the episode's end
    episode = max((e for e in report["episodes"] if e["id"] in report["newly_failing"]
                   and e["baseline"]["steps"] > e["candidate"]["steps"] >= 10),
                  key=lambda e: e["baseline"]["steps"] - e["candidate"]["steps"])
    end = episode["candidate"]["steps"]
    trace = report_dir / episode["baseline"]["trace"]
    whole = frames(render_episode_video(trace, tmp_path / "whole.webm", seconds=1000, size=96))
    window = frames(render_episode_video(trace, tmp_path / "window.webm", seconds=2.0, size=96, end_step=end))
    assert len(window) == 10 and len(whole) == episode["baseline"]["steps"] + 1

    def gap(a, b):
        return float(np.abs(a.astype(float) - b.astype(float)).mean())

    assert gap(window[-1], whole[end]) < gap(window[-1], whole[-1])  # the moment of the failure, not the end
    assert gap(window[0], whole[end - 9]) < 3.0 and gap(window[-1], whole[end]) < 3.0
    page = write_html(RegressReport.from_json(report), tmp_path / "r.html", render_videos=False).read_text()
    pair = next(p for p in page.split('class="clip pair"')[1:] if f"<b>{episode['id']}</b>" in p)
    first = max(0, end - 35 + 1) / 5
    assert f"both from {first:.1f} s to {end / 5:.1f} s of the episode (the seconds up to the candidate" in pair


@pytest.mark.slow
def test_rendering_the_clips_shows_its_progress(report, report_dir, capsys):
    write_html(RegressReport.from_json(report), report_dir / "progress.html", max_videos=1, progress=True)
    err = capsys.readouterr().err.replace("\r", "\n")
    assert "report clips: 100%" in err and "2/2" in err
    write_html(RegressReport.from_json(report), report_dir / "quiet.html", max_videos=1)
    assert "report clips" not in capsys.readouterr().err
