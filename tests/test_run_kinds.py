"""A run folder holds one kind of run: every run kind refuses an ``--out`` that holds another kind's run (its
reports would be written over the other's). A D-V2S conversion's folder (``dv2s generate``, ``dv2s convert``) is
one kind too, known by its ``report.json``."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from cli_helpers import one_line_error, run
from dv2s_gym.pipeline import batch_convert
from dv2s_gym.pipeline import convert as convert_module
from dv2s_gym.pipeline.batch_convert import convert_videos, videos_to_convert
from dv2s_gym.pipeline.convert import OUTPUT_FILES, ConversionReport, convert_video
from dv2s_gym.pipeline.errors import ConversionFolderError
from dv2s_gym.pipeline.stages import Description
from scenario_bank.elements import Elements
from scenario_bank.run_identity import CONVERSION_KIND, RUN_KINDS, check_run_kind, record_format

CLIP = Path(__file__).resolve().parents[1] / "dv2s_gym" / "evalset" / "highway_cut_in_from_left_seed0.webm"


def _write(folder, schema):
    """``folder`` as a run folder of ``schema``: its record and a ``report.json`` (a conversion's record is one)."""
    file, _ = RUN_KINDS[schema]
    folder.mkdir(parents=True, exist_ok=True)
    if schema == CONVERSION_KIND:
        report = ConversionReport(description=Description("A car ahead brakes hard.", Elements(), backend="user"),
                                  seconds=1.0, files=["description.txt", "report.json"])
        (folder / file).write_text(json.dumps(report.to_json(), indent=2), encoding="utf-8")
        return
    (folder / file).write_text(json.dumps({**record_format(schema, 1), "settings": {}}), encoding="utf-8")
    (folder / "report.json").write_text('{"kept": true}', encoding="utf-8")


def _files(folder):
    return {path.name: path.read_bytes() for path in folder.iterdir() if path.is_file()}


@pytest.mark.parametrize("held", sorted(RUN_KINDS))
@pytest.mark.parametrize("asked", sorted(RUN_KINDS))
def test_a_folder_of_one_kind_refuses_a_run_of_another(tmp_path, held, asked):
    _write(tmp_path / "out", held)
    if held == asked:
        check_run_kind(tmp_path / "out", asked, error=ValueError)  # its own kind: the kind's own checks follow
        return
    with pytest.raises(ValueError, match=rf"holds {RUN_KINDS[held][1]} \(its {RUN_KINDS[held][0]}\), not "
                                         rf"{RUN_KINDS[asked][1]}: pass another --out"):
        check_run_kind(tmp_path / "out", asked, error=ValueError)


def test_each_run_kind_names_its_record_in_the_table():
    from dv2s_gym.loop.state import STATE_SCHEMA
    from dv2s_gym.mining.miner import SETTINGS_FILE, SETTINGS_SCHEMA
    from dv2s_gym.regress import store
    from policies.training import run_record

    assert RUN_KINDS[SETTINGS_SCHEMA][0] == SETTINGS_FILE and RUN_KINDS[STATE_SCHEMA][0] == "loop.json"
    assert RUN_KINDS[store._RUN_SCHEMA][0] == store.RUN_FILE and RUN_KINDS[run_record._RUN_SCHEMA][0] == "run.json"
    assert RUN_KINDS[CONVERSION_KIND][0] == "report.json" and "report.json" in OUTPUT_FILES


def test_a_conversion_folder_is_known_by_its_report_and_no_other_report_is_taken_for_one(tmp_path):
    _write(tmp_path / "gen", CONVERSION_KIND)
    with pytest.raises(ValueError, match="holds a D-V2S conversion"):
        check_run_kind(tmp_path / "gen", "dv2s-mine", error=ValueError)
    for report in ({"kept": True}, {"schema": "dv2s-mine", "description": {}, "seconds": 1, "files": []},
                   {"description": "text", "seconds": 1, "files": []}, ["description", "seconds", "files"]):
        (tmp_path / "other").mkdir(exist_ok=True)
        (tmp_path / "other" / "report.json").write_text(json.dumps(report), encoding="utf-8")
        check_run_kind(tmp_path / "other", "dv2s-mine", error=ValueError)  # another run's report, or none


@pytest.mark.parametrize("held, command", [
    ("dv2s-loop-state", ["mine", "--policy", "rule", "--scenarios", "highway_lead_vehicle_brakes", "--budget", "1",
                         "--workers", "1", "--no-convert", "--no-progress"]),
    ("dv2s-mine", ["regress", "--policy", "rule", "--baseline", "idm", "--scenarios", "highway_lead_vehicle_brakes",
                   "--episodes", "1", "--workers", "1", "--no-progress"]),
    ("dv2s-regress-run", ["loop", "--budget", "4", "--no-progress"]),
    ("dv2s-regress-run", ["train", "--algo", "ppo", "--scenarios", "highway_lead_vehicle_brakes", "--steps", "64",
                          "--resume"]),
    (CONVERSION_KIND, ["mine", "--policy", "rule", "--scenarios", "highway_lead_vehicle_brakes", "--budget", "1",
                       "--workers", "1", "--no-convert", "--no-progress"]),
    (CONVERSION_KIND, ["regress", "--policy", "rule", "--baseline", "idm", "--scenarios",
                       "highway_lead_vehicle_brakes", "--episodes", "1", "--workers", "1", "--no-progress"]),
    (CONVERSION_KIND, ["loop", "--budget", "4", "--no-progress"]),
    (CONVERSION_KIND, ["train", "--algo", "ppo", "--scenarios", "highway_lead_vehicle_brakes", "--steps", "64",
                       "--resume"]),
    (CONVERSION_KIND, ["train", "--algo", "ppo", "--scenarios", "highway_lead_vehicle_brakes", "--steps", "64"]),
    ("dv2s-regress-run", ["generate", "a car ahead brakes hard", "--seconds", "2"]),
    ("dv2s-mine", ["generate", "a car ahead brakes hard", "--seconds", "2"]),
    ("dv2s-loop-state", ["convert", CLIP, "--seconds", "2"]),
    ("dv2s-train-run", ["convert", CLIP, "--seconds", "2"]),
])
def test_the_commands_refuse_another_kinds_folder_and_keep_its_reports(capsys, tmp_path, held, command):
    _write(tmp_path / "out", held)
    before = _files(tmp_path / "out")
    code, _, err = run(capsys, *command, "--out", tmp_path / "out")
    line = one_line_error(err)
    assert code == 2 and f"{tmp_path / 'out'} holds {RUN_KINDS[held][1]} (its {RUN_KINDS[held][0]})" in line, err
    assert "pass another --out" in line
    assert {name: data for name, data in _files(tmp_path / "out").items() if name in before} == before


def test_a_conversion_writes_over_an_earlier_conversion_as_before(capsys, tmp_path):
    _write(tmp_path / "gen", CONVERSION_KIND)
    code, out, err = run(capsys, "generate", "xyzzy plugh", "--out", tmp_path / "gen", "--seconds", "2")
    assert code == 1 and "nothing of the description could be placed" in out and not err  # generated, nothing placed
    assert json.loads((tmp_path / "gen" / "report.json").read_text())["description"]["text"] == "xyzzy plugh"


def test_a_video_conversion_is_refused_before_the_video_is_read(tmp_path, monkeypatch):
    _write(tmp_path / "out", "dv2s-regress-run")
    monkeypatch.setattr(convert_module, "describe", lambda *a, **k: pytest.fail("the video was described"))
    with pytest.raises(ConversionFolderError, match=r"holds a regression run \(its run.json\), not a D-V2S "
                                                    r"conversion: pass another --out"):
        convert_video(CLIP, tmp_path / "out")


def test_a_batch_is_refused_before_any_video_is_converted(tmp_path, monkeypatch):
    converted = []
    monkeypatch.setattr(batch_convert, "convert_video", lambda video, out, settings: converted.append(video))
    _write(tmp_path / "out" / "b", "dv2s-mine")
    with pytest.raises(ConversionFolderError, match=r"out/b holds a mining run"):
        convert_videos([(tmp_path / "a.webm", tmp_path / "out" / "a"), (tmp_path / "b.webm", tmp_path / "out" / "b")])
    assert converted == []
    (tmp_path / "videos").mkdir()
    (tmp_path / "videos" / "a.webm").write_bytes(b"")
    with pytest.raises(ConversionFolderError, match=r"holds a mining run \(its settings.json\)"):
        videos_to_convert(tmp_path / "videos", tmp_path / "out" / "b")  # the batch's own folder too
