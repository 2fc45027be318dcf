"""``dv2s convert`` of a folder: which videos, each into its own folder, and what a converted bank entry records."""

from __future__ import annotations

import datetime
import json
import shutil
from pathlib import Path

import pytest

from dv2s_gym.cli import main
from dv2s_gym.pipeline.batch_convert import videos_to_convert
from dv2s_gym.pipeline.convert import (ConversionReport, ConvertSettings, ScenarioCheck, add_converted, checks_passed,
                                       conversion_provenance, convert_video)
from dv2s_gym.pipeline.stages import Description, Generation
from scenario_bank.elements import Elements
import scenario_bank.atomic as atomic
from scenario_bank.bank import Bank

ROOT = Path(__file__).resolve().parents[1]
CLIP = ROOT / "dv2s_gym" / "evalset" / "highway_cut_in_from_left_seed0.webm"


def test_a_folder_converts_every_video_in_it_sorted_each_into_a_folder_of_its_name(tmp_path):
    source = tmp_path / "videos"
    source.mkdir()
    for name in ("b.webm", "a.MP4", "notes.txt", "c.gif"):
        (source / name).write_bytes(b"")
    assert videos_to_convert(source, tmp_path / "out") == [
        (source / "a.MP4", tmp_path / "out" / "a"), (source / "b.webm", tmp_path / "out" / "b"),
        (source / "c.gif", tmp_path / "out" / "c")]
    assert videos_to_convert(source / "b.webm", tmp_path / "out") == [(source / "b.webm", tmp_path / "out")]


def test_a_folder_without_videos_is_refused_naming_the_suffixes(tmp_path):
    (tmp_path / "notes.txt").write_text("no video here")
    with pytest.raises(FileNotFoundError, match=r"no videos \(\.mp4, \.webm, .*\) in "):
        videos_to_convert(tmp_path, tmp_path / "out")


def test_conversion_provenance_reads_the_same_from_the_stages_and_from_their_report():
    description = Description("A car cuts in.", Elements(participants=("car", "ego")), backend="openai", model="vlm-1",
                              prompt_hash="p123")
    with_model = Generation("param map = 1", backend="openai", model="llm-2", context_hash="c456")
    without = Generation("param map = 1", backend="rules")
    today = datetime.date.today().isoformat()
    assert conversion_provenance("openai", "openai", with_model, description) == {
        "generator": "dra=openai,sg=openai", "model": "llm-2", "context_hash": "c456", "date": today}
    # a rule-based script has no model of its own: the description's is recorded
    assert conversion_provenance("bev", "rules", without, description) == {
        "generator": "dra=bev,sg=rules", "model": "vlm-1", "context_hash": "p123", "date": today}
    # read back from a conversion's report, the same
    assert conversion_provenance("bev", "rules", Generation.from_dict(without.as_dict()),
                                 Description.from_dict(description.as_dict())) == \
        conversion_provenance("bev", "rules", without, description)


def test_a_conversion_whose_checks_failed_is_not_added_and_the_bank_is_not_touched(tmp_path):
    report = ConversionReport(description=Description("x", Elements(), backend="bev"),
                              generation=Generation("param map = 1", backend="rules"), check=ScenarioCheck(safe=True))
    note = add_converted(tmp_path / "bank", "clip.webm", tmp_path / "out", report, seed=0, dra="bev", sg="rules")
    assert note == "(not added: clip.webm failed validation)"
    assert not (tmp_path / "bank").exists()


@pytest.mark.slow
def test_converting_a_folder_into_a_bank_adds_each_checked_scenario_with_its_provenance(tmp_path, capsys):
    source = tmp_path / "videos"
    source.mkdir()
    shutil.copy(CLIP, source / CLIP.name)
    code = main(["convert", str(source), "--out", str(tmp_path / "out"), "--add-to-bank",
                 "--bank", str(tmp_path / "bank"), "--seed", "3", "--json"])
    printed = json.loads(capsys.readouterr().out)
    report = printed["reports"][0]
    assert code == 0 and report["check"]["ok"]
    assert (tmp_path / "out" / CLIP.stem / "scenario.scenic").is_file()
    [name] = printed["added"]
    entry = Bank(tmp_path / "bank").get(name)
    assert entry.script == (tmp_path / "out" / CLIP.stem / "scenario.scenic").read_text(encoding="utf-8")
    expected = {"kind": "generated", "video": str(source / CLIP.name), "seed": 3, "generator": "dra=bev,sg=rules",
                "model": report["generation"]["model"] or report["description"]["model"],
                "context_hash": report["generation"]["context_hash"], "date": datetime.date.today().isoformat()}
    assert {key: entry.source.to_dict().get(key) for key in expected} == expected
    assert "generated" in entry.tags


def test_a_video_conversion_writes_its_whole_report_in_one_atomic_step(tmp_path, monkeypatch):
    written = []
    real = atomic.atomic_write_text
    monkeypatch.setattr("dv2s_gym.pipeline.convert.atomic_write_text",
                        lambda path, *a, **k: (written.append(Path(path).name), real(path, *a, **k))[1])
    report = convert_video(CLIP, tmp_path / "out", ConvertSettings(seconds=2))
    assert written.count("report.json") == 1  # inside the staged folder, moved into out with the other files
    text = (tmp_path / "out" / "report.json").read_text()
    assert text == json.dumps(report.to_json(), indent=2, default=str) + "\n"
    on_disk = json.loads(text)
    assert on_disk["seconds_total"] >= on_disk["seconds"] and report.seconds_total == on_disk["seconds_total"]
    assert list(on_disk)[:3] == ["description", "generation", "check"] and on_disk["check"]["ok"] == checks_passed(report)
    # read back, the same report and the same file
    again = ConversionReport.from_json(on_disk)
    assert json.dumps(again.to_json(), indent=2, default=str) + "\n" == text
