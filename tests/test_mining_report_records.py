"""The mining and loop reports read from records: a merged failure's clip captions, error-message counts of
every record generation, a worker's give-up messages counted by kind, and rejection reasons free of this
machine's paths. Fast: no episode is run."""

from __future__ import annotations

import json
from pathlib import Path

from dv2s_gym.mining.html import _cards, _Videos
from dv2s_gym.mining.loop_report import _entry_clips

CLIP = {"seed": 7, "failed": True, "reproduced": True, "failure": {"type": "collision"}, "chosen": "reproduced",
        "file": "converted.webm"}


def _entry_folder(root: Path) -> Path:
    """A bank entry holding its own failure and converted clip, and a failure merged into it with its own two."""
    folder = root / "urban_lead_vehicle_stopped_mined_collision"
    (folder / "merged" / "1").mkdir(parents=True)
    for name in ("failure.webm", "converted.webm", "merged/1/failure.webm", "merged/1/converted.webm"):
        (folder / name).write_bytes(b"webm")
    merged = {"kind": "mined", "parent": "urban_lead_vehicle_stopped", "seed": 11, "cluster": "c/1",
              "video": "merged/1/failure.webm", "converted_video": "merged/1/converted.webm", "policy": "keep_lane",
              "reproduction": {"clip": {**CLIP, "seed": 9}}}
    source = {"kind": "mined", "parent": "urban_lead_vehicle_stopped", "seed": 3, "cluster": "c/0",
              "video": "failure.webm", "converted_video": "converted.webm", "policy": "keep_lane",
              "reproduction": {"clip": CLIP}, "merged": [merged]}
    (folder / "meta.json").write_text(json.dumps({"name": folder.name, "source": source}))
    return folder


def test_a_merged_failures_clip_is_captioned_as_that_failures_script_in_the_loop_report(tmp_path):
    folder = _entry_folder(tmp_path)
    clips = _entry_clips({"scenario": folder.name, "cluster": "c/0"}, folder, {}, "keep_lane")
    captions = {str(video.relative_to(folder)): label for video, label, _, _ in clips}
    assert captions["converted.webm"].startswith(f"generated scenario {folder.name} (the converted script) "
                                                 "driven by keep_lane, seed 7")
    merged = captions["merged/1/converted.webm"]
    assert "(the converted script)" not in merged
    assert merged.startswith(f"the script converted from a failure merged into {folder.name}")
    assert "the bank keeps the entry's own script, not this one" in merged and ", seed 9" in merged


def test_a_merged_clusters_clip_is_captioned_as_its_own_script_in_the_mining_report(tmp_path):
    (tmp_path / "failures").mkdir()
    for name in ("failure.webm", "converted.webm"):
        (tmp_path / "failures" / name).write_bytes(b"webm")
    cluster = {"id": "s/collision/0", "type": "collision", "scenario": "s", "size": 1, "avoidable": 1,
               "representative": {"index": 0, "seed": 4}, "status": "merged", "merged_into": "s_mined_collision",
               "bank_entry": None, "video": "failures/failure.webm", "converted_video": "failures/converted.webm",
               "reproduction": {"clip": CLIP}, "conversion": {"merge_reason": "a near-copy"}}
    page = _cards([cluster], _Videos(tmp_path, tmp_path, False, 0), tmp_path, {"policy": "keep_lane"})
    assert "generated scenario s_mined_collision (the converted script)" not in page
    assert "the script converted from a failure merged into s_mined_collision" in page
    kept = {**cluster, "status": "kept", "bank_entry": "s_mined_collision", "merged_into": None}
    page = _cards([kept], _Videos(tmp_path, tmp_path, False, 0), tmp_path, {"policy": "keep_lane"})
    assert "generated scenario s_mined_collision (the converted script) driven by keep_lane" in page
