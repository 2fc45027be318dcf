"""Mined bank entries carry their failure video and trace in their own folder: no path into the run folder.

A failure record of the ``keep_lane`` policy (the miner's worker runs it) is converted into a fresh bank,
merged a second time from another run, then every run folder is deleted: the entry still holds its
video and trace, the merged failure its own, the bank validates, and export/import carries the files.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
from pathlib import Path

import pytest

from dv2s_gym.bank_validate import validate_entry
from dv2s_gym.mining.conversion.settings import ConversionSettings
from dv2s_gym.mining.conversion.convert import convert_failure
from dv2s_gym.pipeline.video import read_video
from envs.trace import EpisodeTrace
from policies.evaluation import trajectory_hash
from scenario_bank.bank import Bank, BankError, Sidecar, entry_files

sys.path.insert(0, str(Path(__file__).parent))
from test_mining_convert import SCENARIO, make_record, midpoint  # noqa: E402

KEEP_LANE = ConversionSettings(policy="keep_lane")
"""The conversion settings of the tests: the deterministic policy that fails."""


@pytest.fixture(scope="module")
def record() -> dict:
    return make_record(SCENARIO, 0, midpoint(SCENARIO))


@pytest.mark.slow
def test_a_kept_and_a_merged_entry_keep_their_videos_once_the_runs_are_deleted(record, tmp_path):
    bank = Bank(tmp_path / "bank")
    out = convert_failure(record, tmp_path / "run", KEEP_LANE.replace(k=3), bank=bank, cluster=f"{SCENARIO}/collision/0")
    assert out.to_dict()["status"] == "kept", out.to_dict()["reason"]
    again = convert_failure({**record, "index": 5}, tmp_path / "run2", KEEP_LANE.replace(k=3), bank=bank)
    assert again.to_dict()["status"] == "merged" and again.to_dict()["merged_into"] == out.to_dict()["bank_entry"], again.to_dict()["reason"]
    frames = len(read_video(tmp_path / "run" / out.to_dict()["video"], fps=None, max_frames=1000, max_pixels=10**7).frames)
    shutil.rmtree(tmp_path / "run")
    shutil.rmtree(tmp_path / "run2")

    entry = Bank(tmp_path / "bank").get(out.to_dict()["bank_entry"])
    source = entry.source.to_dict()
    assert source["video"] == "failure.webm" and source["trace"] == "trace.json.gz"
    assert source["merged"][0]["video"] == "merged/1/failure.webm"
    assert source["merged"][0]["trace"] == "merged/1/trace.json.gz"
    # and the clip of the converted script driven by the policy (one reproduction episode)
    assert source["files"] == ["failure.webm", "trace.json.gz", "converted.webm"]
    assert source["converted_video"] == "converted.webm"
    assert source["merged"][0]["files"] == ["merged/1/failure.webm", "merged/1/trace.json.gz",
                                            "merged/1/converted.webm"]
    assert source["merged"][0]["converted_video"] == "merged/1/converted.webm"
    assert entry_files(entry.source) == ["failure.webm", "trace.json.gz", "converted.webm", "merged/1/failure.webm",
                                         "merged/1/trace.json.gz", "merged/1/converted.webm"]
    assert (entry.folder / "converted.webm").stat().st_size > 0
    assert entry.missing_files() == []
    clip = read_video(entry.folder / "failure.webm", fps=None, max_frames=1000, max_pixels=10**7)
    assert len(clip.frames) == frames > 0
    trace = EpisodeTrace.load(entry.folder / "trace.json.gz")
    assert trajectory_hash(trace) == record["result"]["trajectory_hash"]
    assert (entry.folder / "merged" / "1" / "failure.webm").stat().st_size > 0
    # no path into this machine in the provenance (the run's own path is history, not a file it needs)
    assert source["params"]["map"] == "urban_two_way.xodr"
    flat = json.dumps({k: v for k, v in source.items() if k != "run"})
    assert str(tmp_path) not in flat.replace(str(tmp_path / "run"), "")

    report = validate_entry(str(tmp_path / "bank"), entry.name, samples=1, seconds=0.5)
    assert report.ok and report.sidecar == [], report.error
    os.remove(entry.folder / "merged" / "1" / "failure.webm")
    report = validate_entry(str(tmp_path / "bank"), entry.name, samples=1, seconds=0.5)
    assert not report.ok and "merged/1/failure.webm" in report.error

    # export/import carries the files that exist
    archive = Bank(tmp_path / "bank").export(tmp_path / "bank.tar.gz", names=[entry.name])
    imported = Bank(tmp_path / "other")
    assert imported.import_archive(archive)["added"] == [entry.name]
    copy = imported.get(entry.name)
    assert (copy.folder / "failure.webm").read_bytes() == (entry.folder / "failure.webm").read_bytes()
    assert copy.missing_files() == ["merged/1/failure.webm"]


# over 1 s of CPU, kept in the quick run: the entry files' one check there
def test_entry_file_names_are_checked(tmp_path):
    script = Bank().get(SCENARIO).script
    video = tmp_path / "v.webm"
    video.write_bytes(b"x")
    bank = Bank(tmp_path / "bank")
    for bad in ("../v.webm", "/abs/v.webm", ".hidden", "meta.json", "a/../b"):
        with pytest.raises(BankError, match="invalid entry file name"):
            bank.add(script, Sidecar(description="a test scenario", source={"kind": "mined", "video": bad}),
                     files={bad: video})
    with pytest.raises(BankError, match="does not exist"):
        bank.add(script, "a test scenario", files={"v.webm": tmp_path / "nope.webm"})
    assert bank.names() == []
    # a video given by a path of the user's (not carried) is not taken for a missing entry file
    entry = bank.add(script, Sidecar(description="a test scenario", source={"kind": "generated",
                                                                            "video": "clips/a.mp4"}))
    assert entry.files == [] and entry.missing_files() == []
