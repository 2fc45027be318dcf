"""The mining and loop reports read from records: a merged failure's clip captions, error-message counts of
every record generation, a worker's give-up messages counted by kind, and rejection reasons free of this
machine's paths. Fast: no episode is run."""

from __future__ import annotations

import json
from pathlib import Path

from dv2s_gym.mining.conversion.settings import ConversionSettings
from dv2s_gym.mining.html import _cards, _Videos
from dv2s_gym.mining.report_record import ClusterEntry
from dv2s_gym.loop.record import ErroredEpisodes, LoopReportBody, MiningSummary, RoundRecord
from dv2s_gym.loop.report import _entry_clips
from loop_helpers import written_report
from scenario_bank.records import HeldOutEpisode, RegressEpisode

KEEP_LANE = ConversionSettings(policy="keep_lane")
"""The conversion settings of the tests: the deterministic policy that fails."""

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
    page = _cards([ClusterEntry.from_dict(cluster)], _Videos(tmp_path, tmp_path, False, 0), tmp_path,
                  {"policy": "keep_lane"})
    assert "generated scenario s_mined_collision (the converted script)" not in page
    assert "the script converted from a failure merged into s_mined_collision" in page
    kept = {**cluster, "status": "kept", "bank_entry": "s_mined_collision", "merged_into": None}
    page = _cards([ClusterEntry.from_dict(kept)], _Videos(tmp_path, tmp_path, False, 0), tmp_path,
                  {"policy": "keep_lane"})
    assert "generated scenario s_mined_collision (the converted script) driven by keep_lane" in page


def test_a_workers_give_up_messages_count_by_kind_with_a_seed_as_example():
    from dv2s_gym.loop.errored import errored_episodes, merged_messages, messages_text
    from dv2s_gym.loop.report_text import _errored_lines
    from dv2s_gym.workers.tasks import gave_up_result

    hung = ["the worker hung (no result after 60 s)"] * 2
    records = [RegressEpisode.from_dict(gave_up_result({"scenario": "s", "seed": seed, "role": "eval",
                                                        "policy": "keep_lane"}, hung, 2))
               for seed in (17, 4, 99)]
    records.append(HeldOutEpisode(role="eval", scenario="s", seed=0, error="scene not sampled"))
    found = errored_episodes(records)
    kind = ("the worker hung (no result after 60 s); then the worker hung (no result after 60 s) running eval "
            "'keep_lane' on s seed <seed> (2 attempts)")
    assert found.to_dict()["messages"]["s"] == [{"message": kind, "count": 3, "example": records[0].error},
                                      {"message": "scene not sampled", "count": 1}]
    assert messages_text(found.to_dict()["messages"], "s") == f"{kind} (3 episodes, e.g. seed 17); scene not sampled (1 episode)"
    # a step recorded with one message per seed adds up with a new one by kind
    old = {"episodes": 2, "scenarios": {"s": 2},
           "messages": {"s": [{"message": records[1].error, "count": 1}, {"message": records[2].error, "count": 1}]}}
    merged = merged_messages([ErroredEpisodes.from_dict(old), found])
    assert merged["s"][0]["message"] == kind and merged["s"][0]["count"] == 5
    lines = _errored_lines(RoundRecord.from_dict({"round": 1, "steps": {"mine": {"errored": old},
                                                                       "regress": {"errored": {"fine_tuned": found}}}}))
    assert lines[-1] == f"  - `s`: {kind} (5 episodes, e.g. seed 4); scene not sampled (1 episode)"


def test_rejection_reasons_name_files_in_the_run_folder_by_their_relative_path(tmp_path):
    from dv2s_gym.mining.conversion.replay import replay_failure_entry
    from dv2s_gym.mining.conversion.convert import convert_failure

    run = tmp_path / "run"
    run.mkdir()
    (run / "failures").write_text("not a folder")  # the conversion cannot make its folder there
    record = {"scenario": "urban_lead_vehicle_stopped", "seed": 0, "index": 3, "params": {},
              "failure": {"type": "collision"}, "result": {"trajectory_hash": "0" * 16}}
    out = convert_failure(record, run, KEEP_LANE.replace(k=1), bank=tmp_path / "bank")
    assert out.to_dict()["status"] == "rejected" and out.to_dict()["stage"] == "input"
    assert "failures/episode-000003/conversion" in out.to_dict()["reason"] and str(tmp_path) not in out.to_dict()["reason"]
    (run / "settings.json").mkdir()  # nor read the run's settings
    out = replay_failure_entry(record, run, KEEP_LANE, bank=tmp_path / "bank")
    assert out.status == "rejected" and out.reason.startswith("replay: ")
    assert str(tmp_path) not in out.reason and "failures/" in out.reason


def test_the_loop_html_shows_a_kind_with_its_seed_mark_escaped():
    from dv2s_gym.loop.errored import errored_episodes
    from dv2s_gym.loop.html import _markdown_to_html
    from dv2s_gym.loop.report_text import _errored_lines
    from dv2s_gym.workers.tasks import gave_up_result

    found = errored_episodes([RegressEpisode.from_dict(gave_up_result(
        {"scenario": "s", "seed": seed, "role": "eval", "policy": "p"}, ["the worker hung (no result after 5 s)"], 1))
        for seed in (3, 8)])
    page = _markdown_to_html(_errored_lines(RoundRecord.from_dict({"round": 1, "steps": {"mine": {"errored": found}}})))
    assert "on s seed &lt;seed&gt; (1 attempts) (2 episodes, e.g. seed 3)" in page


def test_every_kept_entry_of_the_loop_report_shows_its_clip_or_why_it_has_none(tmp_path):
    from dv2s_gym.loop.report import render_html, round_clips

    bank = tmp_path / "bank"
    rejected = bank / "replay_s_collision"
    rejected.mkdir(parents=True)
    (rejected / "failure.webm").write_bytes(b"webm")
    reason = ("parameters: the new scenario's ranges do not contain the failing values: ego_speed = 9.4 outside "
              "6..9")
    (rejected / "meta.json").write_text(json.dumps({"name": rejected.name, "source": {
        "kind": "mined", "replay": {"seed": 1}, "cluster": "s/collision/0", "video": "failure.webm",
        "converted_rejections": [reason]}}))
    extra = bank / "replay_t_stall"
    extra.mkdir()
    (extra / "meta.json").write_text(json.dumps({"name": extra.name, "source": {
        "kind": "mined", "replay": {"seed": 2}, "cluster": "t/stall/0", "video": None}}))
    kept = [{"scenario": rejected.name, "cluster": "s/collision/0", "replay": True},
            {"scenario": extra.name, "cluster": "t/stall/0", "replay": True}]
    report = LoopReportBody.from_dict({
        "settings": {"bank_dir": str(bank), "policy": "p"}, "policy": "p",
        "rounds": [{"round": 1, "steps": {"mine": {"kept": kept}, "split": {"held_out": [extra.name]}}}]})
    clips = round_clips(report, tmp_path)[1]
    assert len(clips) == 2
    (video,) = clips[f"{rejected.name} (fine-tuned on)"]
    assert video["path"] == "bank/replay_s_collision/failure.webm"
    assert "has no converted script" not in video["note"]
    assert ("a script was converted from this failure and rejected (parameters: the new scenario's ranges do not "
            "contain the failing values)") in video["note"]
    assert "ego_speed" not in video["note"]  # the reason in short
    (none,) = clips[f"{extra.name} (held out)"]
    assert none["path"] is None and "no clip recorded" in none["note"] and "extra exact replay" in none["note"]
    page = render_html(written_report(report), {1: clips})
    assert page.count("<video") == 1
    assert "an extra exact replay of a cluster no conversion tried: no clip recorded" in page
    assert "rejected (parameters: the new scenario&#x27;s ranges do not contain the failing values)" in page


def test_the_loop_report_lists_an_exact_replays_parameters_left_at_the_parents_distribution(tmp_path):
    from dv2s_gym.loop.report_text import _mining_lines
    from dv2s_gym.loop.replays import replay_entries

    why = "its distribution Normal(0, 1) is not read as an interval or a set of numbers, so it keeps the parent's"
    rows = [{"cluster": "p/stall/0", "scenario": "p", "status": "kept", "replay_entry": "replay_p_stall",
             "replay_not_narrowed": {"noise": why}},
            {"cluster": "q/stall/0", "scenario": "q", "status": "kept", "replay_entry": "replay_q_stall",
             "replay_not_narrowed": {}}]
    (tmp_path / "replays.jsonl").write_text("".join(json.dumps(row) + "\n" for row in rows))
    kept = replay_entries(tmp_path)
    assert kept[0].to_dict()["not_narrowed"] == {"noise": why} and "not_narrowed" not in kept[1].to_dict()
    lines = _mining_lines(MiningSummary.from_dict({"folder": str(tmp_path), "kept": kept}), {})
    assert (f"  - exact replay replay_p_stall is the failing scene at its own seed only; at another seed these keep "
            f"the parent's draw: noise ({why})" in lines)
    assert not any("replay_q_stall" in line for line in lines)


def test_the_loop_s_mining_counts_fail_loudly_on_a_line_that_is_no_episode_record(tmp_path):
    """The loop reads a mining run's episodes.jsonl as the miner does: a line that is no episode record stops the
    counts with the file, the episode and the bad field named (it is not skipped, which would count it as 0), and so
    does a replays.jsonl row that is no replay row."""
    import pytest

    from dv2s_gym.loop.mined import mining_summary
    from dv2s_gym.mining.errors import MiningError
    from scenario_bank.records import RecordError

    good = {"index": 0, "scenario": "s", "family": "s", "seed": 1, "error": "worker hung", "failure": None}
    (tmp_path / "episodes.jsonl").write_text(json.dumps(good) + "\n")
    summary = mining_summary(tmp_path)
    assert (summary.episodes, summary.errors, summary.failures, summary.clusters) == (1, 1, 0, 0)
    assert summary.errored.to_dict()["scenarios"] == {"s": 1} and summary.replays == {}
    (tmp_path / "replays.jsonl").write_text(json.dumps({"cluster": "c", "index": 0, "status": "kept"}) + "\n"
                                            + json.dumps({"cluster": "d", "index": 1, "status": "rejected"}) + "\n")
    assert mining_summary(tmp_path).replays == {"kept": 1, "rejected": 1}
    (tmp_path / "replays.jsonl").write_text(json.dumps({"cluster": "c", "index": 0, "status": "lost"}) + "\n")
    with pytest.raises(RecordError, match=r"replays.jsonl, record 1: exact replay row field 'status' must be one of"):
        mining_summary(tmp_path)
    (tmp_path / "replays.jsonl").unlink()
    (tmp_path / "episodes.jsonl").write_text(json.dumps({**good, "seed": "one"}) + "\n"
                                             + json.dumps({**good, "index": 1}) + "\n")
    with pytest.raises(MiningError, match=r"episodes.jsonl, episode 0: episode record field 'seed' must be an integer"):
        mining_summary(tmp_path)
    (tmp_path / "episodes.jsonl").write_text(json.dumps({**good, "index": "zero"}) + "\n"
                                             + json.dumps({**good, "index": 1}) + "\n")
    with pytest.raises(MiningError, match=r"line 1 is not an episode record \(no integer 'index'\)"):
        mining_summary(tmp_path)
