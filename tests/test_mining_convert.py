"""From a mined failure to a bank entry: the failure video, the conversion, its rejections and merges.

Failure records come from the miner's worker (an episode of the ``keep_lane`` policy, which drives at
constant speed and runs into what stands in its lane, on a scene with fixed Scenic parameters).
"""

from __future__ import annotations

import inspect
import json

import numpy as np
import pytest

import dv2s_gym.mining.conversion.convert as convert_module
from dv2s_gym.loop.record import LoopReportBody
from dv2s_gym.mining.conversion.interaction import FailureInteraction
from dv2s_gym.mining.conversion.settings import ConversionSettings
from dv2s_gym.mining.conversion.episodes import reproduction_seeds, same_failure_class
from dv2s_gym.mining.conversion.ranges import exact_number
from dv2s_gym.mining.conversion.replay import replay_failure_entry
from dv2s_gym.mining.conversion.convert import convert_failure
from dv2s_gym.mining.errors import MiningError
from dv2s_gym.mining.settings import MineSettings
from dv2s_gym.mining.conversion.exact_replay import replay_failure
from dv2s_gym.mining.conversion.failure_video import FailureReplayError, record_failure_video, write_failure_video
from dv2s_gym.pipeline.video import read_video
from envs.trace import EpisodeTrace
from loop_helpers import written_report
from policies.evaluation import trajectory_hash
from scenario_bank.bank import Bank, Sidecar
from scenario_bank.errors import WrongTypeError
from scenario_bank.records import EpisodeRecord, Failure

KEEP_LANE = ConversionSettings(policy="keep_lane")
"""The conversion settings of the tests: the deterministic policy that fails."""

SCENARIO = "urban_lead_vehicle_stopped"




def midpoint(scenario: str) -> dict:
    """The centre of a scenario's mined parameter space (the miner's scene features)."""
    from dv2s_gym.mining.sampling.space import SceneSpace

    return {name: r.from_unit(0.5) for name, r in SceneSpace([scenario]).param_ranges(scenario).items()}


def make_record(scenario: str, seed: int, params: dict, policy: str = "keep_lane", index: int = 0,
                bank_dir: str | None = None) -> dict:
    """The miner's episode record of one scene (its worker runs the episode and the failure monitors)."""
    from dv2s_gym.mining.family import scenario_family
    from dv2s_gym.mining.monitors import MonitorSettings
    from dv2s_gym.mining.tasks import MineTask, run_mine_task

    record = run_mine_task(MineTask(index=index, policy=policy, scenario=scenario, seed=seed, params=params,
                                    bank_dir=bank_dir,
                                    monitor=MonitorSettings(ttc_threshold=1.0, stall_seconds=5.0)).to_json())
    assert record.error is None and record.failure.type == "collision", record
    return {**record.to_dict(), "family": scenario_family(scenario, bank_dir)}  # as episodes.jsonl holds it


@pytest.fixture(scope="module")
def record() -> dict:
    return make_record(SCENARIO, 0, midpoint(SCENARIO))


def _red_pixels(frame: np.ndarray) -> int:
    """Pixels of the red highway-env paints crashed vehicles with (tolerant of VP8's colour shifts)."""
    r, g, b = (frame[..., i].astype(int) for i in range(3))
    return int(((r > 160) & (g < 90) & (b < 90)).sum())


def test_failure_video_holds_the_window_before_and_through_the_failure(record, tmp_path):
    written = write_failure_video(record, tmp_path / "failure.webm", policy="keep_lane", before=2.0, after=1.0)
    fps = 5  # the env's default policy frequency
    k = record["failure"]["step"]
    assert abs(k / fps - record["failure"]["time"]) <= 0.5 / fps
    assert (written.first, written.failure_frame, written.last) == (k - 2 * fps, k, k + fps)
    # the episode ended at the collision: the last second was driven past its end
    assert written.last > record["result"]["steps"]
    clip = read_video(written.path, fps=None, max_frames=1000, max_pixels=10**7)
    assert len(clip.frames) == written.frames == 3 * fps + 1
    assert clip.frames[0].shape[:2] == (480, 480)
    # nothing crashed in the first frame; the crash (vehicles painted red) shows from the failure on
    assert _red_pixels(clip.frames[0]) == 0
    assert _red_pixels(clip.frames[-1]) > 20
    # the saved trace is the recorded episode (not the extra steps) and replays to the record's hash
    trace = EpisodeTrace.load(tmp_path / "trace.json.gz")
    assert len(trace.actions) == record["result"]["steps"]
    assert trajectory_hash(trace) == record["result"]["trajectory_hash"]


NOISY = "rule?action_noise=0.5"


def test_failure_video_from_a_saved_trace_replays_its_actions(tmp_path):
    # a driver whose whole behaviour is its actions: keep_lane also resets the ego's target speed outside its
    # action, which a replay of the recorded actions cannot reproduce
    noisy = make_record(SCENARIO, 0, midpoint(SCENARIO), policy=NOISY)
    write_failure_video(noisy, tmp_path / "a.webm", policy=NOISY, before=1.0, after=0.0)
    out = record_failure_video(tmp_path / "trace.json.gz", tmp_path / "b.webm", before=1.0, after=0.0,
                               trace_path=tmp_path / "b.json.gz")
    a = read_video(tmp_path / "a.webm", fps=None, max_frames=1000, max_pixels=10**7).frames
    b = read_video(out, fps=None, max_frames=1000, max_pixels=10**7).frames
    assert len(a) == len(b) == 6
    assert np.array_equal(np.asarray(a), np.asarray(b))


@pytest.mark.slow
def test_a_diverging_replay_raises(record, tmp_path):
    with pytest.raises(FailureReplayError, match="diverged"):
        record_failure_video(record, tmp_path / "x.webm", policy="idm")  # not the policy that failed
    tampered = {**record, "result": {**record["result"], "trajectory_hash": "0" * 64}}
    with pytest.raises(FailureReplayError, match="diverged.*recorded 000000000000"):
        record_failure_video(tampered, tmp_path / "x.webm", policy="keep_lane")
    assert not (tmp_path / "x.webm").exists()
    with pytest.raises(FailureReplayError, match="lacks result.trajectory_hash"):
        record_failure_video({"scenario": SCENARIO, "seed": 0}, tmp_path / "x.webm", policy="keep_lane")


def test_failure_class_rule():
    rear = Failure("collision", with_kind="car", collision_type="rear_end")
    assert same_failure_class(rear, Failure("collision", with_kind="car", collision_type="rear_end"))
    assert same_failure_class(rear, Failure("collision", with_kind="car", collision_type=None))
    assert not same_failure_class(rear, Failure("collision", with_kind="car", collision_type="side"))
    assert not same_failure_class(rear, Failure("collision", with_kind="pedestrian", collision_type="rear_end"))
    assert not same_failure_class(rear, Failure("off_road"))
    assert not same_failure_class(rear, None)
    assert same_failure_class(Failure("stall"), Failure("stall", 3.0))
    assert reproduction_seeds(7, 5) == reproduction_seeds(7, 5) != reproduction_seeds(8, 5)
    assert len(set(reproduction_seeds(7, 10))) == 10


@pytest.mark.slow
def test_a_reproducing_failure_is_kept_with_provenance_and_a_repeat_merges(record, tmp_path):
    bank = Bank(tmp_path / "bank")
    out = convert_failure(record, tmp_path / "run", KEEP_LANE, bank=bank, cluster=f"{SCENARIO}/collision/0")
    assert out.to_dict()["status"] == "kept", out.to_dict()["reason"]
    assert out.to_dict()["reason"] is None and out.to_dict()["merged_into"] is None
    repro = out.to_dict()["reproduction"]
    assert repro["k"] == 10 and repro["rate"] == repro["reproduced"] / 10 >= 0.3
    assert repro["interval"][0] <= repro["rate"] <= repro["interval"][1]
    assert 0.0 <= out.to_dict()["e2e_sc"] <= 1.0
    folder = tmp_path / "run" / "failures" / f"{SCENARIO}__collision__0"
    assert out.to_dict()["video"] == f"failures/{SCENARIO}__collision__0/failure.webm" and (folder / "failure.webm").is_file()
    for name in ("trace.json.gz", "conversion/description.txt", "conversion/elements.json",
                 "conversion/scenario.scenic", "conversion/report.json"):
        assert (folder / name).is_file(), name
    report = json.loads((folder / "conversion" / "report.json").read_text())
    assert report["status"] == "kept" and len(report["reproduction_episodes"]) == 10
    assert set(out.to_dict()["timings"]) == {"video", "interaction", "replay", "describe", "generate", "check", "reproduction",
                                   "avoidability", "e2e_sc", "clip", "bank"}
    # the converted script driven by the same policy, filmed on a reproduction episode that failed the same way
    clip = repro["clip"]
    chosen = next(e for e in report["reproduction_episodes"] if e["reproduced"])
    assert clip["seed"] == chosen["seed"] and clip["reproduced"] and clip["failed"]
    assert clip["failure"]["type"] == "collision" and clip["file"] == "converted.webm" and "error" not in clip
    assert out.to_dict()["converted_video"] == f"failures/{SCENARIO}__collision__0/conversion/converted.webm"
    frames = read_video(folder / "conversion" / "converted.webm", fps=None, max_frames=1000, max_pixels=10**7).frames
    # 4 s before the collision (or from the reset when it came sooner), 1 s after, at 5 Hz
    assert len(frames) == min(chosen["failure"]["step"], 4 * 5) + 5 + 1 and frames[0].shape[:2] == (480, 480)
    assert _red_pixels(frames[0]) == 0 and _red_pixels(frames[-1]) > 20  # the crash shows
    # the judge: the stopped car the ego ran into shows in the runs, the policy fails on it the same way, and
    # the reference driver avoids it
    assert out.to_dict()["interaction"]["kind"] == "car" and out.to_dict()["interaction"]["manoeuvres"] == ["stop"]
    assert out.to_dict()["interaction"]["gap_m"] == pytest.approx(record["params"]["stopped_gap"], abs=0.5)
    assert repro["interaction_shown"] >= 3 and out.to_dict()["rejections"] == []
    assert out.to_dict()["avoidability"]["reference"] == "rule" and out.to_dict()["avoidability"]["avoided_rate"] > 0.5

    fresh = Bank(tmp_path / "bank")  # as another process sees it
    assert fresh.names() == sorted([out.to_dict()["bank_entry"], out.to_dict()["replay_entry"]]) and not fresh.problems
    # the failing scene itself, kept exactly: running the replay entry is the recorded episode, step for step
    replay = fresh.get(out.to_dict()["replay_entry"])
    assert {"mined", "replay", "collision"} <= set(replay.tags)
    assert replay.source.replay["seed"] == 0 and replay.source.replay["params"] == record["params"]
    assert replay.source.converted == out.to_dict()["bank_entry"] and replay.source.extra["converted_e2e_sc"] == out.to_dict()["e2e_sc"]
    assert replay.source.e2e_sc == 1.0
    for name, (low, high) in replay.source.replay["intervals"].items():
        assert low <= record["params"][name] <= high
        assert f"Range({low!r}, {high!r})" in replay.script or (low == high and "fixed at the failing" in replay.script)
    assert isinstance(replay.source.replay["not_narrowed"], dict)
    rerun = replay_failure(fresh, out.to_dict()["replay_entry"])
    assert rerun["matches"] and rerun["trajectory_hash"] == record["result"]["trajectory_hash"]
    assert same_failure_class(Failure.of(record["failure"]), Failure.of(rerun["failure"]))
    entry = fresh.get(out.to_dict()["bank_entry"])
    source = entry.source.to_dict()
    assert source["kind"] == "mined" and source["parent"] == SCENARIO and source["seed"] == 0
    portable = {**record["result"]["params"], "map": "urban_two_way.xodr"}  # the map by name, not by path
    assert source["params"] == portable and source["params"]["ego_speed"] == record["params"]["ego_speed"]
    assert source["video"].endswith("failure.webm") and source["policy"] == "keep_lane"
    assert source["backends"] == {"dra": "bev", "sg": "rules"}
    assert source["reproduction"] == repro and source["e2e_sc"] == out.to_dict()["e2e_sc"]
    assert source["failure"] == record["failure"] and source["failure"]["collision_type"] == "rear_end"
    assert source["cluster"] == f"{SCENARIO}/collision/0"
    assert entry.description == out.to_dict()["description"] and "mined" in entry.tags
    assert entry.script == (folder / "conversion" / "scenario.scenic").read_text()
    assert source["replay_entry"] == out.to_dict()["replay_entry"] and source["interaction"] == out.to_dict()["interaction"]
    assert source["converted_video"] == "converted.webm" and "converted.webm" in source["files"]
    assert (entry.folder / "converted.webm").read_bytes() == (folder / "conversion" / "converted.webm").read_bytes()

    _the_reports_show_the_converted_clip_beside_the_failure(record, out, tmp_path)

    again = convert_failure({**record, "index": 5}, tmp_path / "run2", KEEP_LANE, bank=bank)
    assert again.to_dict()["status"] == "merged" and again.to_dict()["merged_into"] == out.to_dict()["bank_entry"], again.to_dict()["reason"]
    merged = Bank(tmp_path / "bank").get(out.to_dict()["bank_entry"]).source.merged
    assert len(merged) == 1 and merged[0]["index"] == 5 and merged[0]["parent"] == SCENARIO
    assert merged[0]["converted_video"] == "merged/1/converted.webm"
    assert (entry.folder / "merged" / "1" / "converted.webm").is_file()
    assert again.to_dict()["replay_entry"] == out.to_dict()["replay_entry"]  # the same failing scene: its replay is not added twice
    assert Bank(tmp_path / "bank").names() == sorted([out.to_dict()["bank_entry"], out.to_dict()["replay_entry"]])


def _the_reports_show_the_converted_clip_beside_the_failure(record, out, tmp_path):
    """The loop's report.html shows the kept entry's failure clip with its converted script's clip beside it (one
    row), captioned with the scenario, seed and outcome; the exact replay shows its failure clip alone, saying why;
    the mining report's card shows both clips too."""
    from dv2s_gym.mining.html import render_html
    from dv2s_gym.loop.report import render_html as loop_html
    from dv2s_gym.loop.report import round_clips
    from dv2s_gym.mining.report import build_report_from_records

    conversion, out = out, out.to_dict()  # the record for the product, its JSON object for the checks
    seed = out["reproduction"]["clip"]["seed"]
    loop = LoopReportBody.from_dict({
        "settings": {"bank_dir": str(tmp_path / "bank"), "policy": "keep_lane"}, "policy": "keep_lane",
        "rounds": [{"round": 1, "steps": {"mine": {"folder": str(tmp_path / "run"), "kept": [
            {"cluster": out["cluster"], "scenario": out["bank_entry"]},
            {"cluster": out["cluster"], "scenario": out["replay_entry"], "replay": True}]}}}]})
    clips = round_clips(loop, tmp_path)[1]
    converted = clips[f"{out['bank_entry']} (fine-tuned on)"]
    assert [c["path"] for c in converted] == [f"bank/{out['bank_entry']}/failure.webm",
                                              f"bank/{out['bank_entry']}/converted.webm"]
    assert converted[0]["group"] == converted[1]["group"]
    assert converted[1]["label"] == (f"generated scenario {out['bank_entry']} (the converted script) driven by "
                                     f"keep_lane, seed {seed}: it failed, collision (rear_end) with a car, the same "
                                     "way as the source failure")
    (replay,) = clips[f"{out['replay_entry']} (fine-tuned on)"]
    assert replay["path"] == f"bank/{out['replay_entry']}/failure.webm" and "no converted script" in replay["note"]
    page = loop_html(written_report(loop), {1: clips})
    row = page.split(f'<video src="bank/{out["bank_entry"]}/failure.webm"')[1].split("</div>")[0]
    assert f'<video src="bank/{out["bank_entry"]}/converted.webm"' in row and f"seed {seed}: it failed" in row
    assert "it has no converted script, so only the failure clip is shown" in page
    gone = loop.replace(settings=loop.settings.replace(bank_dir=str(tmp_path / "no_bank")))  # the mining run's copies
    from_run = round_clips(gone, tmp_path)[1][f"{out['bank_entry']} (fine-tuned on)"]
    assert [c["path"] for c in from_run] == [f"run/failures/{SCENARIO}__collision__0/failure.webm",
                                             f"run/failures/{SCENARIO}__collision__0/conversion/converted.webm"]
    assert f"driven by keep_lane, seed {seed}: it failed" in from_run[1]["label"]  # the round's policy, named

    mining = build_report_from_records({"policy": "keep_lane", "sampler": "uniform"},
                                       [EpisodeRecord.from_dict(record)], [conversion], {record["index"]: out["cluster"]})
    card = render_html(mining, base=tmp_path / "run", page_dir=tmp_path / "run", embed_videos=False)
    card = card.split(f'id="card-{out["cluster"]}"')[1].split('class="text"')[0]
    assert f'src="failures/{SCENARIO}__collision__0/failure.webm"' in card
    assert f'src="failures/{SCENARIO}__collision__0/conversion/converted.webm"' in card and f"seed {seed}" in card


@pytest.mark.slow
def test_a_reproduction_rate_below_the_threshold_is_rejected(record, tmp_path):
    # the collision was with a car; as a collision with a truck, the new scenario never reproduces it
    truck = {**record, "failure": {**record["failure"], "with_kind": "truck"}}
    out = convert_failure(truck, tmp_path / "run", KEEP_LANE, bank=tmp_path / "bank")
    assert out.to_dict()["status"] == "rejected" and out.to_dict()["stage"] == "reproduction"
    assert out.to_dict()["reproduction"]["reproduced"] == 0 and out.to_dict()["reproduction"]["rate"] == 0.0
    assert out.to_dict()["reason"].startswith("reproduction: ") and "0 of 10" in out.to_dict()["reason"]
    # the interaction is read from the trace, where the stopped actor is a car, and the new scenario shows it
    assert out.to_dict()["interaction"]["kind"] == "car" and out.to_dict()["rejections"] == [out.to_dict()["reason"]]
    assert out.to_dict()["e2e_sc"] is not None  # measured either way
    assert _converted(tmp_path / "bank") == []


def _converted(bank_dir) -> list:
    """The bank's mined entries that are converted scripts (not exact replays of a failing scene)."""
    return [e.name for e in Bank(bank_dir) if e.source.kind == "mined" and not e.source.replay]


def _generator_speeds_as_the_scenario(monkeypatch) -> None:
    """The rule-based generator draws the ego's speed on this scenario's map from its own range (8..12 m/s), the
    scenario from 8..13 m/s: a failure at over 12 m/s gives a script whose range leaves the failing speed out,
    which the judge rejects (``parameters``; :func:`test_the_miner_converts_a_cluster_into_the_bank`). Tests of
    what happens around a kept conversion give the generator the scenario's range."""
    from dv2s_gym.pipeline.sg.rules import lanes

    monkeypatch.setattr(lanes, "speed_ranges", lambda map_name: (8, 13))


def _patch_generator(monkeypatch, script: str) -> None:
    from dv2s_gym.pipeline import stages

    monkeypatch.setattr(stages, "generate", lambda *a, **k: stages.Generation(script, "rules"))


@pytest.mark.slow
def test_an_unsafe_script_is_rejected_at_the_check(record, tmp_path, monkeypatch):
    _patch_generator(monkeypatch, "param map = 'highway_straight'\nmodel scenic.domains.driving.model\n"
                                  "import os\nego = new Car\n")
    out = convert_failure(record, tmp_path / "run", KEEP_LANE, bank=tmp_path / "bank")
    assert out.to_dict()["status"] == "rejected" and out.to_dict()["stage"] == "check"
    assert out.to_dict()["reason"].startswith("check: safety failed") and "import" in out.to_dict()["reason"]
    assert out.to_dict()["reproduction"] is None and out.to_dict()["bank_entry"] is None
    assert _converted(tmp_path / "bank") == [] and out.to_dict()["replay_entry"] in Bank(tmp_path / "bank")


@pytest.mark.slow
def test_a_script_failing_in_the_sandbox_is_rejected_with_its_stage(record, tmp_path, monkeypatch):
    _patch_generator(monkeypatch, "param map = 'highway_straight'\nmodel scenic.domains.driving.model\n"
                                  "ego = new Car with behavior NoSuchBehavior()\n")
    out = convert_failure(record, tmp_path / "run", KEEP_LANE, bank=tmp_path / "bank")
    assert out.to_dict()["status"] == "rejected" and out.to_dict()["stage"] == "check", out
    assert "sandboxed check" in out.to_dict()["reason"] and "NoSuchBehavior" in out.to_dict()["reason"]
    assert _converted(tmp_path / "bank") == []


def test_the_conversion_entry_points_take_one_settings_record_and_no_loose_options(tmp_path):
    """The settings of a conversion travel as one checked record: no keyword options, no mapping in its place."""
    for function in (convert_failure, replay_failure_entry):
        parameters = inspect.signature(function).parameters
        assert not any(p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters.values()), function.__name__
        assert list(parameters)[:3] == ["record", "run_dir", "settings"]
        assert parameters["settings"].annotation == "ConversionSettings"
        with pytest.raises(WrongTypeError, match="one ConversionSettings, not dict"):
            function({}, tmp_path / "run", {"policy": "keep_lane"}, bank=tmp_path / "bank")
        with pytest.raises(WrongTypeError, match="needs the policy that failed"):
            function({}, tmp_path / "run", ConversionSettings(), bank=tmp_path / "bank")
    with pytest.raises(MiningError, match="conversion must be the conversion's settings"):
        MineSettings(conversion={"dra": "bev"})
    with pytest.raises(MiningError, match=r"conversion k must be an integer >= 0, not '3'"):
        MineSettings(conversion=ConversionSettings(k="3"))
    assert MineSettings().conversion == ConversionSettings()  # and none of it is recorded with the run
    assert "conversion" not in MineSettings().recorded()


def test_a_record_without_a_failure_is_rejected_not_raised(record, tmp_path):
    out = convert_failure({**record, "failure": None}, tmp_path / "run", KEEP_LANE, bank=tmp_path / "bank")
    assert out.to_dict()["status"] == "rejected" and out.to_dict()["stage"] == "input"
    out = convert_failure(record, tmp_path / "run", KEEP_LANE.replace(k=0), bank=tmp_path / "bank")
    assert out.to_dict()["status"] == "rejected" and out.to_dict()["stage"] == "input" and "k >= 1" in out.to_dict()["reason"]
    out = convert_failure({**record, "seed": 1}, tmp_path / "run", KEEP_LANE, bank=tmp_path / "bank")
    assert out.to_dict()["status"] == "rejected" and out.to_dict()["stage"] == "video" and "diverged" in out.to_dict()["reason"]
    out = convert_failure({**record, "params": {"no_such_param": 1}}, tmp_path / "run", KEEP_LANE,
                          bank=tmp_path / "bank")
    assert out.to_dict()["status"] == "rejected" and out.to_dict()["stage"] == "video"


@pytest.mark.slow
def test_a_minimal_failure_record_is_completed_from_the_monitors(record, tmp_path):
    minimal = {**record, "failure": {"type": "collision", "time": record["failure"]["time"]}}
    out = convert_failure(minimal, tmp_path / "run", KEEP_LANE, bank=tmp_path / "bank")
    assert out.to_dict()["status"] == "kept", out.to_dict()["reason"]
    failure = Bank(tmp_path / "bank").get(out.to_dict()["bank_entry"]).source.failure
    assert failure["with_kind"] == "car" and failure["collision_type"] == "rear_end"


CONTRACT_KEYS = {"cluster", "index", "status", "reason", "video", "description", "script", "reproduction", "e2e_sc",
                 "bank_entry", "merged_into", "seconds"}


@pytest.mark.slow
def test_the_miner_converts_a_cluster_into_the_bank(tmp_path):
    from mining_helpers import mine

    run = mine("keep_lane", out=tmp_path / "run", budget=4, sampler="random", scenarios=[SCENARIO],
               bank_dir=str(tmp_path / "bank"), workers=1, reference=None, progress=False, convert=True,
               max_conversions=1, reports=False)
    rows = [json.loads(line) for line in (tmp_path / "run" / "conversions.jsonl").read_text().splitlines()]
    assert len(rows) == 1 and rows[0] == run.conversions[0].to_dict()
    row = rows[0]
    assert CONTRACT_KEYS <= set(row), row
    assert (tmp_path / "run" / row["video"]).is_file() and (tmp_path / "run" / row["script"]).is_file()
    # the judge keeps the script only if its ranges hold the failing values of the parameters of the same name (the
    # rule-based generator draws the ego's speed from its own range for the map, which may leave the failing one out)
    from scenario_bank.dedup import param_ranges

    failing = next(json.loads(line) for line in (tmp_path / "run" / "episodes.jsonl").read_text().splitlines()
                   if json.loads(line)["index"] == row["index"])["result"]["params"]
    ranges = param_ranges((tmp_path / "run" / row["script"]).read_text())
    outside = sorted(name for name, value in failing.items() if name in ranges and isinstance(value, float)
                     and not ranges[name][0] <= value <= ranges[name][1])
    assert row["parameters"]["outside"] == outside
    if outside:
        assert row["status"] == "rejected" and row["bank_entry"] is None, row
        assert any(r.startswith("parameters: ") and all(f"{name} = {exact_number(failing[name])} outside" in r for name in outside)
                   for r in row["rejections"])
    else:
        assert row["status"] == "kept", row
    for name in filter(None, [row["bank_entry"], row["replay_entry"]]):  # the failing scene is kept either way
        entry = Bank(tmp_path / "bank").get(name)
        assert entry.source.cluster == row["cluster"] and entry.source.index == row["index"]
        assert entry.source.run == str((tmp_path / "run").resolve())
    assert row["replay_entry"]
    settings = json.loads((tmp_path / "run" / "settings.json").read_text())
    report = json.loads((tmp_path / "run" / row["script"]).with_name("report.json").read_text())
    assert report["reproduction"] == row["reproduction"] and settings["ttc_threshold"] == 1.0


@pytest.mark.slow
def test_a_run_killed_between_the_bank_write_and_its_record_resumes_without_a_self_merge(tmp_path, monkeypatch):
    # killed after Bank.add and before conversions.jsonl got the line: the resumed run used to convert the
    # cluster again and report it "merged" into the entry it had made itself (kept 0, merged 1)
    from dv2s_gym.mining.jsonl import JsonlAppender
    from mining_helpers import mine

    _generator_speeds_as_the_scenario(monkeypatch)
    run = dict(out=tmp_path / "run", budget=4, sampler="random", scenarios=[SCENARIO], bank_dir=str(tmp_path / "bank"),
               workers=1, reference=None, progress=False, convert=True, max_conversions=1, reports=False)
    original = JsonlAppender.append

    def killed(self, record):
        if self._path.name == "conversions.jsonl":
            raise KeyboardInterrupt
        original(self, record)

    monkeypatch.setattr(JsonlAppender, "append", killed)
    with pytest.raises(KeyboardInterrupt):
        mine("keep_lane", **run)
    monkeypatch.setattr(JsonlAppender, "append", original)
    mined = _converted(tmp_path / "bank")
    assert len(mined) == 1 and not (tmp_path / "run" / "conversions.jsonl").read_text().strip()
    replays = [e.name for e in Bank(tmp_path / "bank") if e.source.replay]
    assert len(replays) == 1 and Bank(tmp_path / "bank").get(replays[0]).source.converted == mined[0]

    resumed = mine("keep_lane", **run)
    row = resumed.conversions[0].to_dict()
    assert len(resumed.conversions) == 1 and row["status"] == "kept" and row["bank_entry"] == mined[0], row
    entry = Bank(tmp_path / "bank").get(mined[0])
    assert _converted(tmp_path / "bank") == mined
    assert [e.name for e in Bank(tmp_path / "bank") if e.source.replay] == replays
    assert not entry.source.merged and row["reproduction"] == entry.source.reproduction
    assert CONTRACT_KEYS <= set(row) and (tmp_path / "run" / row["video"]).is_file()
    assert (tmp_path / "run" / row["script"]).is_file()


@pytest.mark.slow
def test_an_unreachable_model_endpoint_stops_converting_and_the_rerun_converts(tmp_path, monkeypatch):
    # every cluster used to be recorded "rejected (describe: EndpointUnreachableError)", and a rerun after the
    # endpoint came back never tried them again
    from llm_server import closed_port_url

    from dv2s_gym.mining.errors import MiningError
    from mining_helpers import mine

    monkeypatch.setenv("DV2S_LLM_RETRIES", "0")
    _generator_speeds_as_the_scenario(monkeypatch)
    run = dict(out=tmp_path / "run", budget=4, sampler="random", scenarios=[SCENARIO], bank_dir=str(tmp_path / "bank"),
               workers=1, reference=None, progress=False, convert=True, max_conversions=1, reports=False)
    down = ConversionSettings(dra="openai", llm_config={"base_url": closed_port_url(), "model": "m"})
    with pytest.raises(MiningError, match="converting stopped at cluster .*could not connect.*Rerun the same command"):
        mine("keep_lane", conversion=down, **run)
    assert not (tmp_path / "run" / "conversions.jsonl").read_text().strip()
    assert len((tmp_path / "run" / "episodes.jsonl").read_text().splitlines()) == 4
    rows = [row.to_dict() for row in mine("keep_lane", conversion=ConversionSettings(dra="bev"), **run).conversions]
    assert len(rows) == 1 and rows[0]["stage"] != "describe" and rows[0]["status"] == "kept", rows


@pytest.mark.slow
def test_a_script_without_the_failures_interaction_is_rejected_though_the_policy_fails_on_it(record, tmp_path,
                                                                                            monkeypatch):
    # the failure: the ego ran into a car standing still in its lane. The script below has the ego run into a
    # car *driving* slowly in its lane: the same failure class (rear-end collision with a car), but not the
    # stopped car of the failure
    moving = Bank().get(SCENARIO).script.replace(
        "    with speed 0,\n    with behavior StayStopped()",
        "    with speed 3,\n    with behavior FollowLaneBehavior(target_speed=3)")
    assert moving != Bank().get(SCENARIO).script
    _patch_generator(monkeypatch, moving)
    out = convert_failure(record, tmp_path / "run", KEEP_LANE, bank=tmp_path / "bank")
    assert out.to_dict()["status"] == "rejected" and out.to_dict()["stage"] == "interaction", out
    assert out.to_dict()["reproduction"]["rate"] >= 0.3  # the policy does fail on it, the same way ...
    assert out.to_dict()["reproduction"]["interaction_shown"] == 0  # ... but never with a car that stops
    assert out.to_dict()["rejections"] == [out.to_dict()["reason"]] and out.to_dict()["reason"].startswith("interaction: ")
    assert "car (stop)" in out.to_dict()["reason"]
    assert _converted(tmp_path / "bank") == []
    # the failure itself is kept exactly all the same
    replay = Bank(tmp_path / "bank").get(out.to_dict()["replay_entry"])
    assert replay.source.to_dict()["converted"] is None
    assert replay.source.to_dict()["converted_rejections"] == [out.to_dict()["reason"]]


def test_each_failed_check_of_the_judge_is_its_own_reason():
    from dv2s_gym.mining.conversion.judge import judge_conversion

    interaction = FailureInteraction.from_dict({"kind": "car", "manoeuvres": ["brake", "stop"], "failure_type": "stall"})
    out = {"reproduction": {"k": 10, "reproduced": 2, "rate": 0.2, "interaction_shown": 1},
           "avoidability": {"reference": "rule", "k": 10, "failed": 6, "avoided_rate": 0.4}}
    reasons = [str(r) for r in judge_conversion(out, interaction, Failure("stall"), 0.3)]
    assert [r.split(":")[0] for r in reasons] == ["interaction", "reproduction", "avoidability"]
    assert "car (brake, stop) in 1 of 10" in reasons[0] and "stall failure with a car in 2 of 10" in reasons[1]
    assert "rule failed in 6 of 10" in reasons[2]
    passing = {"reproduction": {"k": 10, "reproduced": 3, "rate": 0.3, "interaction_shown": 3},
               "avoidability": {"reference": "rule", "k": 10, "failed": 4, "avoided_rate": 0.6}}
    assert judge_conversion(passing, interaction, Failure("stall"), 0.3) == []
    # the reference avoiding it in half of the episodes is not "most"
    half = {**passing, "avoidability": {"reference": "rule", "k": 10, "failed": 5, "avoided_rate": 0.5}}
    assert [str(r).split(":")[0] for r in judge_conversion(half, interaction, {"type": "stall"}, 0.3)] == ["avoidability"]


def test_the_judge_rejects_a_script_whose_actors_or_parameter_ranges_are_not_the_failures():
    """The failure: the ego ran into a car cutting in while a pedestrian crossed (two actors, the adversary a car).
    A script that reproduces it and that the reference avoids is still rejected, each problem its own reason,
    when its actors differ from the failure's or its ranges leave out the failing values."""
    from dv2s_gym.mining.conversion.episodes import compare_actors
    from dv2s_gym.mining.conversion.judge import judge_conversion
    from dv2s_gym.mining.conversion.parameters import compare_parameters

    interaction = FailureInteraction.from_dict({"kind": "car", "manoeuvres": ["cut_in"]})
    failure = {"type": "collision", "with_kind": "car"}
    passing = {"reproduction": {"k": 10, "reproduced": 6, "rate": 0.6, "interaction_shown": 6},
               "avoidability": {"reference": "rule", "k": 10, "failed": 0, "avoided_rate": 1.0}}
    source = {"car": 1, "pedestrian": 1}
    same = compare_actors(source, [{"car": 1, "pedestrian": 1}] * 3 + [{"car": 1}], "car")
    assert same["same"] and same["script"] == source  # the runs' most frequent census is the script's
    script = ("param ego_speed = Range(8, 12)\nparam cut_gap = Range(4.0, 9.0)\nparam weather = Uniform('a', 'b')\n"
              "param walking_speed = 1.5\n")
    inside = compare_parameters({"ego_speed": 11.2, "cut_gap": 4.0, "walking_speed": 1.5, "weather": "a",
                                 "kerb_offset": 2.9}, script)
    assert inside["outside"] == [] and inside["not_in_script"] == ["kerb_offset"]
    assert inside["compared"]["cut_gap"] == {"value": 4.0, "range": [4.0, 9.0]}
    assert judge_conversion({**passing, "actors": same, "parameters": inside}, interaction, failure, 0.3) == []

    no_adversary = compare_actors(source, [{"pedestrian": 1}], "car")
    fewer = compare_actors(source, [{"car": 1}], "car")
    more = compare_actors(source, [{"car": 2, "pedestrian": 1}], "car")
    outside = compare_parameters({"ego_speed": 12.5, "cut_gap": 3.2}, script)
    assert outside["outside"] == ["cut_gap", "ego_speed"]
    reasons = [str(r) for r in judge_conversion({**passing, "actors": no_adversary, "parameters": outside}, interaction,
                                                failure, 0.3)]
    assert reasons == ["actors: the failure's scene has 2 actors (car 1, pedestrian 1), the new scenario's 1 actor "
                       "(pedestrian 1): the failure's adversary, a car, is missing",
                       "parameters: the new scenario's ranges do not contain the failing values: cut_gap = 3.2 "
                       "outside 4..9, ego_speed = 12.5 outside 8..12"]
    assert [str(r) for r in judge_conversion({**passing, "actors": fewer}, interaction, failure, 0.3)] == [
        "actors: the failure's scene has 2 actors (car 1, pedestrian 1), the new scenario's 1 actor (car 1): "
        "1 pedestrian fewer"]
    assert [str(r) for r in judge_conversion({**passing, "actors": more}, interaction, failure, 0.3)] == [
        "actors: the failure's scene has 2 actors (car 1, pedestrian 1), the new scenario's 3 actors (car 2, "
        "pedestrian 1): 1 car more"]


def test_the_actor_census_of_a_trace_counts_every_actor_but_the_ego_by_kind():
    from dv2s_gym.mining.conversion.episodes import actor_census

    trace = EpisodeTrace(scenario="s", source="", seed=0, scene_seed=0, params={}, config={},
                         states=[{"ego": [0, 0], "lead": [1, 0]}, {"ego": [0, 0], "lead": [1, 0], "walker": [2, 2]}],
                         kinds={"lead": "truck", "walker": "pedestrian", "parked": "car"})
    assert actor_census(trace) == {"car": 1, "pedestrian": 1, "truck": 1}


def test_any_reference_failure_counts_against_the_new_scenario_whatever_its_class():
    from dv2s_gym.mining.conversion.episodes import reference_failed, reference_outcome
    from dv2s_gym.mining.conversion.judge import judge_conversion

    rear = Failure("collision", with_kind="car", collision_type="rear_end")
    behind = Failure("collision", with_kind="car", collision_type="struck_from_behind")
    stall, near_miss = Failure("stall"), Failure("low_ttc")
    assert not same_failure_class(rear, behind)  # another class than the source's ...
    assert reference_failed(rear, behind) and reference_failed(rear, stall)  # ... still a failure of the reference
    assert reference_failed(rear, Failure("off_road"))
    assert not reference_failed(rear, None) and not reference_failed(rear, near_miss)
    assert reference_failed(near_miss, near_miss)  # the miner calls such a near miss unavoidable too
    outcome = reference_outcome(rear, [{"failure": failure.to_dict() if failure else None}
                                       for failure in (behind, behind, stall, near_miss, None)], "rule")
    assert outcome == {"reference": "rule", "k": 5, "failed": 3, "avoided_rate": pytest.approx(0.4),
                       "failures": {"collision:struck_from_behind": 2, "stall": 1}}
    out = {"reproduction": {"k": 5, "reproduced": 5, "rate": 1.0, "interaction_shown": 5}, "avoidability": outcome}
    reasons = [str(r) for r in judge_conversion(out, FailureInteraction.from_dict({"kind": "car", "manoeuvres": ["stop"]}), rear, 0.3)]
    assert reasons == ["avoidability: the reference driver rule failed in 3 of 5 episodes of the new scenario "
                       "(collision:struck_from_behind 2, stall 1); it must drive most of them without any "
                       "collision, off-road or stall"]


@pytest.mark.slow
def test_a_script_on_which_the_reference_fails_another_way_is_rejected(record, tmp_path, monkeypatch):
    # the source failure: the ego ran into a car standing still ahead (rear end). The script adds a faster car
    # 40 m behind the ego in its lane: the policy (constant speed) still runs into the stopped car first, while
    # the reference driver, which stops behind it, is struck from behind: not the source's failure class, yet
    # a scenario its reference cannot drive
    chaser = Bank().get(SCENARIO).script + (
        'chaser = new Car at egoLane.centerline.pointAlongBy(egoS - 40),\n    with name "chaser",\n'
        "    with speed globalParameters.ego_speed + 5,\n"
        "    with behavior FollowLaneBehavior(target_speed=globalParameters.ego_speed + 5)\n")
    _patch_generator(monkeypatch, chaser)
    out = convert_failure(record, tmp_path / "run", KEEP_LANE.replace(k=4), bank=tmp_path / "bank")
    assert out.to_dict()["status"] == "rejected" and out.to_dict()["stage"] == "avoidability", out
    # the chaser is also a car the failure's scene did not have: the judge names that too
    assert out.to_dict()["reproduction"]["reproduced"] == 4 and out.to_dict()["rejections"] == [
        out.to_dict()["reason"], "actors: the failure's scene has 2 actors (car 2), the new scenario's 3 actors (car 3): "
                       "1 car more"]
    avoid = out.to_dict()["avoidability"]
    assert avoid["failed"] == 4 and avoid["avoided_rate"] == 0.0
    assert avoid["failures"] == {"collision:struck_from_behind": 4}
    assert "rule failed in 4 of 4" in out.to_dict()["reason"] and "collision:struck_from_behind 4" in out.to_dict()["reason"]
    assert _converted(tmp_path / "bank") == []
    report = json.loads((tmp_path / "run" / out.to_dict()["script"]).with_name("report.json").read_text())
    assert [e["failure"]["collision_type"] for e in report["reference_episodes"]] == ["struck_from_behind"] * 4
    replay = Bank(tmp_path / "bank").get(out.to_dict()["replay_entry"])  # the failing scene is kept exactly all the same
    assert replay.source.extra["converted_rejections"] == out.to_dict()["rejections"]


@pytest.mark.slow
def test_a_near_copy_of_a_mined_entry_of_the_same_family_is_merged(tmp_path):
    from dv2s_gym.mining.conversion.convert import _family
    from scenario_bank.bank import changed_code_lines

    script = Bank().get(SCENARIO).script
    one_line = script.replace("param stopped_gap = Range(30, 60)", "param stopped_gap = Range(61, 90)")
    three_lines = one_line.replace("param ego_speed = Range(8, 13)", "param ego_speed = Range(14, 16)").replace(
        "param oncoming_speed = Range(8, 12)", "param oncoming_speed = Range(13, 15)")
    assert changed_code_lines(script, one_line) == 1 and changed_code_lines(script, three_lines) == 3
    assert changed_code_lines(script, "# a comment\n" + script) == 0
    bank = Bank(tmp_path / "bank")
    source = {"kind": "mined", "parent": SCENARIO, "failure": {"type": "collision"}}
    first = bank.add(script, Sidecar(description="a car stands still ahead", elements={"participants": ["ego", "car"]},
                                     source=source, name="mined_a"),
                     near_copy_of=_family(SCENARIO, "collision"), on_duplicate="merge")
    assert first.status == "added"
    # other elements, no overlapping range: not a near-duplicate by elements, but one line of code apart
    other = {"participants": ["ego", "car", "car"], "actions": [["car", "stop"]]}
    elsewhere = script.replace("param oncoming_distance = Range(40, 90)", "param oncoming_distance = Range(91, 120)")
    stall = bank.add(elsewhere, Sidecar(description="another description", elements=other, name="mined_b",
                                        source={**source, "failure": {"type": "stall"}}),
                     near_copy_of=_family(SCENARIO, "stall"), on_duplicate="merge")
    assert stall.status == "added"  # another family (failure type): kept apart
    copy = bank.add(one_line, Sidecar(description="another description", elements=other, name="mined_c",
                                      source=source),
                    near_copy_of=_family(SCENARIO, "collision"), on_duplicate="merge")
    assert copy.status == "merged" and copy.entry.name == first.entry.name and "1 changed line" in copy.how
    apart = bank.add(three_lines, Sidecar(description="a third description", elements=other, name="mined_d",
                                          source=source),
                     near_copy_of=_family(SCENARIO, "collision"), on_duplicate="merge")
    assert apart.status == "added"
    assert sorted(Bank(tmp_path / "bank").names()) == ["mined_a", "mined_b", "mined_d"]


def test_the_replay_script_narrows_the_continuous_ranges_and_fixes_the_discrete_ones_at_the_failing_values():
    from dv2s_gym.mining.conversion.exact_replay import narrowed_script

    script = ("param map = 'highway_straight'\nparam gap = Range(20, 40)  # metres\nparam lanes = DiscreteRange(1, 3)\n"
              "param colour = Uniform('red', 'blue')\nparam other = Range(0, 10)\nego = new Car\n")
    narrowed, intervals, not_narrowed = narrowed_script(script, {"gap": 25.0, "lanes": 2, "colour": "red",
                                                                 "other": 0.0})
    assert intervals == {"gap": [24.6, 25.4], "lanes": [2.0, 2.0], "other": [0.0, 0.2]}  # 2 % of the width each side
    assert "param gap = Range(24.6, 25.4)" in narrowed and "param other = Range(0.0, 0.2)" in narrowed
    assert "param lanes = 2  # fixed at the failing value (the parent draws DiscreteRange(1, 3))" in narrowed
    assert not_narrowed == {"colour": "its failing value 'red' is not a number",  # and what the body draws:
                            "ego": "outside the params, its position is drawn at random (no specifier fixes it, so "
                                   "the model's default region places it)"}
    for kept in ("param colour = Uniform('red', 'blue')", "param map = 'highway_straight'", "ego = new Car"):
        assert kept in narrowed
    with pytest.raises(ValueError, match="outside its range"):
        narrowed_script(script, {"gap": 41.0})
    with pytest.raises(ValueError, match="outside its range"):
        narrowed_script(script, {"lanes": 4})


def test_the_replay_script_narrows_an_offset_range_fixes_a_two_valued_choice_and_lists_what_it_cannot_narrow():
    from dv2s_gym.mining.conversion.exact_replay import narrowed_script

    script = ("param map = 'highway_straight'\nparam ego_speed = Range(22, 30)\nparam lead_gap = Range(0, 10) + 12\n"
              "param brake_strength = Uniform(0.3, 1.0)\nparam drawn = Range(1, 2)\nparam noise = Normal(0, 1)\n"
              "param mix = Uniform(Range(1, 2), 5)\nego = new Car\n")
    params = {"ego_speed": 24.0, "lead_gap": 17.0, "brake_strength": 1.0, "noise": 0.3, "mix": 5.0}
    narrowed, intervals, not_narrowed = narrowed_script(script, params)
    assert intervals["lead_gap"] == [16.8, 17.2]  # 2 % of the width 10 of 12..22 on either side
    assert "param lead_gap = Range(16.8, 17.2)" in narrowed
    assert intervals["brake_strength"] == [1.0, 1.0]
    assert "param brake_strength = 1.0  # fixed at the failing value" in narrowed
    assert sorted(not_narrowed) == ["drawn", "ego", "mix", "noise"]
    assert "not among the failure's recorded parameters" in not_narrowed["drawn"]
    assert "Normal(0, 1)" in not_narrowed["noise"] and "mixes intervals and separate values" in not_narrowed["mix"]
    with pytest.raises(ValueError, match="outside its range"):
        narrowed_script(script, {"lead_gap": 5.0})
    with pytest.raises(ValueError, match="outside its range"):
        narrowed_script(script, {"brake_strength": 0.5})


def test_the_replay_lists_every_value_the_script_draws_outside_its_params():
    """A draw in the script's body is recorded by no mining run, so the replay keeps it as the parent draws it: the
    entry is the failing scene at its own seed only, and its provenance says which draws make other seeds differ."""
    from dv2s_gym.mining.conversion.exact_replay import narrowed_script

    script = ("param map = 'highway_straight'\nparam gap = Range(20, 40)\nlanes = [1, 2]\n"
              "lane = Uniform(*lanes)\nfixedLane = Uniform(lanes[0])\negoS = Range(50, 1200)  # Range(1, 2) in a note\n"
              "behavior Wobble():\n    while True:\n        take SetThrottleAction(Range(0.2, 0.4))\n"
              "ego = new Car at lane.centerline.pointAlongBy(egoS),\n    with speed Range(20, 27)\n"
              "lead = new Car ahead of ego by globalParameters.gap\n"
              "walker = new Pedestrian on lane.centerline\nmarker = new OrientedPoint\n"
              "new Car following roadDirection from ego for 30, with behavior FollowLaneBehavior(target_speed=Range(9, 11))\n"
              "recordedGap = Range(1, 3)\nrequire (distance to lead) > 5\n")
    narrowed, intervals, not_narrowed = narrowed_script(script, {"gap": 25.0})
    assert intervals == {"gap": [24.6, 25.4]}
    assert not_narrowed == {
        "lane": "outside the params, draws Uniform(*lanes)",
        "egoS": "outside the params, draws Range(50, 1200)",
        "behavior Wobble": "outside the params, draws Range(0.2, 0.4)",
        "ego": "outside the params, draws Range(20, 27)",
        "walker": "outside the params, its position is drawn at random (on lane.centerline)",
        "<Car 12>": "outside the params, draws Range(9, 11)",
        "recordedGap": "outside the params, draws Range(1, 3)"}  # a name that starts like a statement is a name
    assert "lead" not in not_narrowed and "marker" not in not_narrowed and "fixedLane" not in not_narrowed


def test_the_judge_compares_parameter_names_without_case_and_never_prints_an_outside_value_as_inside():
    from dv2s_gym.mining.conversion.judge import judge_conversion
    from dv2s_gym.mining.conversion.parameters import compare_parameters

    passing = {"reproduction": {"k": 10, "reproduced": 10, "rate": 1.0, "interaction_shown": 10},
               "avoidability": {"reference": "rule", "k": 10, "failed": 0, "avoided_rate": 1.0}}
    judged = compare_parameters({"lead_speed": 12.0}, "param Lead_Speed = Range(5, 10)\n")
    assert judged["outside"] == ["lead_speed"] and judged["not_in_script"] == []
    assert [str(r) for r in judge_conversion({**passing, "parameters": judged}, FailureInteraction(), {"type": "collision"}, 0.3)] == [
        "parameters: the new scenario's ranges do not contain the failing values: lead_speed (the script's "
        "Lead_Speed) = 12 outside 5..10"]
    just_past = compare_parameters({"lead_speed": 10.00001}, "param lead_speed = Range(5, 10)\n")
    assert [str(r) for r in judge_conversion({**passing, "parameters": just_past}, FailureInteraction(), {"type": "collision"}, 0.3)] == [
        "parameters: the new scenario's ranges do not contain the failing values: lead_speed = 10.00001 "
        "outside 5..10"]
    below = compare_parameters({"gap": 5.0000001}, "param gap = Range(5.0000002, 9)\n")
    assert "gap = 5.0000001 outside 5.0000002..9" in str(judge_conversion({**passing, "parameters": below},
                                                                          FailureInteraction(),
                                                                          {"type": "collision"}, 0.3)[0])


# --------------------------------------------------------------------------- the parameters, compared by meaning
_PARENT = '''param ego_speed = Range(18, 25)
param cutter_extra_speed = Range(4, 8)
param start_offset = Range(-12, -2)
param cut_in_gap = Range(5, 11)
param speed_after_cut_in = Range(-3, 1)
param crossing_distance = Range(35, 55)
param kerb_offset = Range(2.6, 3.0)

behavior CutIn(extraSpeed, gap, speedAfter):
    wait

ego = new Car at egoLane.centerline.pointAlongBy(egoS),
    with speed globalParameters.ego_speed
cutter = new Car at leftLane.centerline.pointAlongBy(egoS + globalParameters.start_offset),
    with speed globalParameters.ego_speed + globalParameters.cutter_extra_speed,
    with behavior CutIn(globalParameters.cutter_extra_speed, globalParameters.cut_in_gap,
                        globalParameters.speed_after_cut_in)
traffic = new Car at egoLane.centerline.pointAlongBy(egoS + 60), with speed globalParameters.ego_speed + 2
spot = new OrientedPoint following roadDirection from ego for globalParameters.crossing_distance
walker = new Pedestrian right of spot by globalParameters.kerb_offset
'''

_GENERATED = '''param ego_speed = Range(20, 26)
param car1_start = Range(7, 11)
param car1_extra_speed = Range(4, 7)
param car1_cut_gap = Range(10, 15)
param pedestrian1_distance = Range(30, 42)

behavior CutInWhenAhead(side, speed, gap, speedAfter):
    wait

ego = new Car at egoLane.centerline.pointAlongBy(egoS),
    with speed globalParameters.ego_speed
car1 = new Car at leftLane.centerline.pointAlongBy(egoS + globalParameters.car1_start),
    with speed globalParameters.ego_speed + globalParameters.car1_extra_speed,
    with behavior CutInWhenAhead(-1, globalParameters.ego_speed + globalParameters.car1_extra_speed,
                                 globalParameters.car1_cut_gap, globalParameters.ego_speed + Range(-1, 2))
pedestrian1Spot = new OrientedPoint at egoLane.centerline.pointAlongBy(egoS + globalParameters.pedestrian1_distance)
pedestrian1 = new Pedestrian left of pedestrian1Spot by Range(5.5, 6.2)
'''


def test_the_judge_compares_a_failing_parameter_with_the_generated_one_that_sets_the_same_quantity():
    """The generated script names its parameters anew: the cutter's gap is ``car1_cut_gap``, its start
    ``car1_start``, its extra speed ``car1_extra_speed``, the crossing's distance ``pedestrian1_distance``. Each is
    paired by the actor it feeds and the quantity it sets; what the new script sets with no parameter (the speed after
    the cut-in, the kerb offset) is listed as not compared, with why."""
    from dv2s_gym.mining.conversion.judge import judge_conversion
    from dv2s_gym.mining.conversion.parameters import compare_parameters

    failing = {"ego_speed": 21.0, "cutter_extra_speed": 5.0, "start_offset": -6.0, "cut_in_gap": 8.0,
               "speed_after_cut_in": 0.0, "crossing_distance": 40.0, "kerb_offset": 2.8, "weather": "a"}
    by_name = compare_parameters(failing, _GENERATED)
    assert list(by_name["compared"]) == ["ego_speed"] and len(by_name["not_in_script"]) == 6
    judged = compare_parameters(failing, _GENERATED, parent=_PARENT)
    paired = {name: c["script_name"] for name, c in judged["compared"].items() if c.get("by") == "meaning"}
    assert paired == {"cut_in_gap": "car1_cut_gap", "start_offset": "car1_start",
                      "cutter_extra_speed": "car1_extra_speed", "crossing_distance": "pedestrian1_distance"}
    assert judged["compared"]["cut_in_gap"]["basis"] == ("the Car car1's behaviour argument gap (cutter in the "
                                                         "parent)")
    assert set(judged["not_comparable"]) == {"speed_after_cut_in", "kerb_offset"}
    assert judged["not_in_script"] == ["kerb_offset", "speed_after_cut_in"]
    assert judged["outside"] == ["cut_in_gap", "start_offset"]  # 8 outside 10..15, -6 outside 7..11
    passing = {"reproduction": {"k": 10, "reproduced": 10, "rate": 1.0, "interaction_shown": 10},
               "avoidability": {"reference": "rule", "k": 10, "failed": 0, "avoided_rate": 1.0}}
    unread, reason = [str(r) for r in judge_conversion({**passing, "parameters": judged}, FailureInteraction(), {"type": "collision"}, 0.3)]
    # with no actor named, every actor's placement is key: the walker to the right of its spot, the new script's
    # pedestrian to the left of its own
    assert unread.startswith("parameters: a key quantity (of the failure's interaction) is placed by another quantity "
                             "or form") and "kerb_offset (the Pedestrian walker's lateral:right" in unread, unread
    assert "left of pedestrian1Spot by Range(5.5, 6.2), a distance to the left, the other side" in unread, unread
    assert reason.startswith("parameters: the new scenario's ranges do not contain the failing values: cut_in_gap "
                             "(the script's car1_cut_gap: the Car car1's behaviour argument gap (cutter in the "
                             "parent)) = 8 outside 10..15")
    assert "(not compared: kerb_offset, speed_after_cut_in with no counterpart in the new script)" in reason


def test_parameters_that_cannot_be_paired_one_to_one_are_not_compared_but_listed():
    """Two unnamed parameters that together place the lead car (``egoS + a + b``), and a generated script with two
    cars of the same behaviour the parent's car could be: nothing is guessed."""
    from dv2s_gym.mining.conversion.param_meaning import meaning_map

    parent = ("param a = Range(1, 2)\nparam b = Range(1, 2)\nparam s = Range(1, 2)\n"
              "lead = new Car at lane.centerline.pointAlongBy(egoS + globalParameters.a + globalParameters.b),\n"
              "    with speed globalParameters.s\n")
    generated = ("param g1 = Range(1, 2)\nparam v1 = Range(1, 2)\nparam v2 = Range(1, 2)\n"
                 "car1 = new Car at lane.centerline.pointAlongBy(egoS + globalParameters.g1),\n"
                 "    with speed globalParameters.v1\n"
                 "car2 = new Car at lane.centerline.pointAlongBy(egoS + globalParameters.g2), "
                 "with speed globalParameters.v2\n")
    mapped = meaning_map(parent, generated, ["a", "b", "s"], ["g1", "g2", "v1", "v2"])
    assert mapped["pairs"] == {}
    # car1 and car2 share as many of the lead's slots: neither is its counterpart
    assert all("no counterpart" in mapped["unpaired"][name] for name in ("a", "b", "s"))
    # with a single car of its kind the lead's speed pairs; the sum still does not
    single = meaning_map(parent, generated.split("car2 =")[0], ["a", "b", "s"], ["g1", "v1"])
    assert single["pairs"]["s"]["target"] == "v1" and set(single["unpaired"]) == {"a", "b"}
    assert "together with other parameters" in single["unpaired"]["a"]


def test_a_parameter_scaled_in_one_script_and_added_in_the_other_is_not_paired():
    from dv2s_gym.mining.conversion.param_meaning import meaning_map

    parent = "param share = Range(0.5, 0.8)\nlead = new Car ahead of ego by 20, with speed globalParameters.v * (globalParameters.share)\n"
    generated = "param low = Range(5, 10)\ncar1 = new Car ahead of ego by 20, with speed globalParameters.v - globalParameters.low\n"
    mapped = meaning_map(parent, generated, ["share"], ["low"])
    assert mapped["pairs"] == {} and "no parameter" in mapped["unpaired"]["share"]


_NO_COUNTERPART = "the new script defines no numeric parameter of that name"
"""The judge's reason for a failing parameter the new script has no counterpart of."""


def test_the_mining_report_counts_the_failing_parameters_the_judge_could_not_compare():
    from dv2s_gym.mining.report import build_report_from_records, markdown

    conversions = [{"cluster": "c1", "index": 0, "status": "rejected", "reason": "parameters: x", "stage": "parameters",
                    "parameters": {"compared": {"a": {}, "b": {}}, "outside": ["a"],
                                   "not_comparable": {"c": "why", "d": "why"}}},
                   {"cluster": "c2", "index": 1, "status": "kept",
                    "parameters": {"compared": {"a": {}}, "outside": [], "not_in_script": ["e"],
                                   "not_comparable": {"e": _NO_COUNTERPART}}}]
    report = build_report_from_records({"policy": "p", "sampler": "uniform"}, [], conversions, {})
    assert report.to_dict()["counts"]["parameters_compared"] == 3 and report.to_dict()["counts"]["parameters_not_compared"] == 3
    assert "3 failing parameter value(s) compared with the new scripts' ranges, 3 not compared" in markdown(report)


def test_the_reports_name_each_reason_a_parameter_was_not_compared_with_its_count(tmp_path):
    """The judge could not compare parameters for several reasons (no counterpart, a distribution that is not an
    interval, a name match that reaches no object, one actor for two); the judge's reason, report.md and report.html
    name each with its count instead of calling them all "no parameter means the same"."""
    from dv2s_gym.mining.conversion.judge import judge_conversion
    from dv2s_gym.mining.conversion.parameters import compare_parameters
    from dv2s_gym.mining.html import render_html
    from dv2s_gym.mining.report import build_report_from_records, markdown

    opaque = (_CUT_PARENT.replace("cut_in_gap = Range(5, 11)", "g = TruncatedNormal(30, 1, 25, 35)")
              .replace("globalParameters.cut_in_gap", "globalParameters.g")
              .replace("lane_change_duration = Range(1.8, 3.0)", "lane_change_duration = Range(8, 9)"))
    failing = {**_CUT_FAILING, "kerb_offset": 2.8}
    judged = compare_parameters(failing, opaque, parent=_CUT_PARENT + "param kerb_offset = Range(2, 3)\n")
    assert judged["outside"] == ["lane_change_duration"]
    key, reason = [str(r) for r in judge_conversion({**_PASSING, "parameters": judged}, FailureInteraction(), {"type": "collision"}, 0.3)]
    # the cutter's gap is a quantity of the failure's interaction the new script sets by its own g: a rejection too
    assert key.startswith("parameters: a key parameter") and "cut_in_gap (the Car cutter's behaviour argument" in key
    assert reason.endswith("(not compared: cut_in_gap whose counterpart's distribution is not an interval the judge "
                           "can read; kerb_offset feeding no object of the parent script)")
    decoy = _CUT_PARENT.replace("CutIn(globalParameters.cut_in_gap, globalParameters.lane_change_duration)",
                                "CutIn(40, 6.0)")
    conversions = [{"cluster": "c1", "index": 0, "status": "rejected", "stage": "parameters", "reason": reason,
                    "parameters": judged},
                   {"cluster": "c2", "index": 1, "status": "rejected", "stage": "parameters", "reason": "x",
                    "parameters": compare_parameters(_CUT_FAILING, decoy, parent=_CUT_PARENT)},
                   {"cluster": "c3", "index": 2, "status": "kept",
                    "parameters": {"compared": {"a": {}}, "outside": [], "not_in_script": ["e", "f"],
                                   "not_comparable": {"e": _NO_COUNTERPART, "f": _NO_COUNTERPART}}}]
    report = build_report_from_records({"policy": "p", "sampler": "uniform"}, [], conversions, {})
    counts = report.to_dict()["counts"]
    assert counts["parameters_not_compared"] == 6
    assert counts["parameters_not_compared_by_reason"] == {"no_counterpart": 2, "not_interval": 1,
                                                           "reaches_no_object": 2, "feeds_no_object": 1}
    expected = ("6 not compared: 2 with no counterpart in the new script, 1 whose counterpart's distribution is not "
                "an interval the judge can read, 2 named alike in the new script, where it reaches no object, 1 "
                "feeding no object of the parent script")
    assert expected in markdown(report) and "no parameter of the new script means the same" not in markdown(report)
    assert expected.replace("'", "&#x27;") in render_html(report, embed_videos=False)


# --------------------------------------------------------------------------- a name match must match in meaning
_CUT_PARENT = '''param ego_speed = Range(18, 25)
param cut_in_gap = Range(5, 11)
param lane_change_duration = Range(1.8, 3.0)

behavior CutIn(gap, duration):
    wait

ego = new Car at lane.centerline.pointAlongBy(egoS),
    with speed globalParameters.ego_speed
cutter = new Car at lane.centerline.pointAlongBy(egoS + 10),
    with speed 25,
    with behavior CutIn(globalParameters.cut_in_gap, globalParameters.lane_change_duration)
'''
_CUT_FAILING = {"ego_speed": 20.0, "cut_in_gap": 6.0, "lane_change_duration": 2.0}
_PASSING = {"reproduction": {"k": 10, "reproduced": 10, "rate": 1.0, "interaction_shown": 10}}


def _judged(generated, parent=_CUT_PARENT, failing=_CUT_FAILING):
    from dv2s_gym.mining.conversion.judge import judge_conversion
    from dv2s_gym.mining.conversion.parameters import compare_parameters

    compared = compare_parameters(failing, generated, parent=parent)
    return compared, [str(r) for r in judge_conversion({**_PASSING, "parameters": compared}, FailureInteraction(), {"type": "collision"}, 0.3)]


def test_parameters_named_alike_but_swapped_are_not_compared_and_the_judge_rejects():
    swapped = _CUT_PARENT.replace("Range(5, 11)", "Range(1.5, 8)").replace(
        "CutIn(globalParameters.cut_in_gap, globalParameters.lane_change_duration)",
        "CutIn(gap=globalParameters.lane_change_duration, duration=globalParameters.cut_in_gap)")
    compared, rejections = _judged(swapped)
    assert list(compared["compared"]) == ["ego_speed"]
    assert "named alike but not the same meaning" in compared["not_comparable"]["cut_in_gap"]
    key, reason = rejections  # the cutter's gap and duration, set by the new script's own (swapped) parameters
    assert key.startswith("parameters: a key parameter") and "cut_in_gap (" in key and "lane_change_duration (" in key
    assert reason.startswith("parameters: only 1 of the failure's 3 parameters could be compared") and "fewer than half" in reason


def test_parameters_named_alike_that_reach_no_object_are_not_compared():
    decoy = _CUT_PARENT.replace("with speed globalParameters.ego_speed", "with speed 30").replace(
        "CutIn(globalParameters.cut_in_gap, globalParameters.lane_change_duration)", "CutIn(40, 6.0)")
    compared, rejections = _judged(decoy)
    assert compared["compared"] == {}
    assert compared["not_comparable"]["cut_in_gap"] == "the new script's cut_in_gap reaches no object of the scene"
    assert len(rejections) == 2 and "only 0 of the failure's 3 parameters" in rejections[1]
    # and the key quantities it fixes instead (the ego's speed at 30, the gap at 40, the duration at 6) are not the
    # failure's
    assert sorted(compared["key_fixed_outside"]) == ["cut_in_gap", "ego_speed", "lane_change_duration"]
    assert rejections[0].startswith("parameters: a key quantity (of the failure's interaction) that the new script "
                                    "fixes must hold the failing value")


def test_a_constant_term_a_factor_or_another_direction_changes_the_meaning():
    from dv2s_gym.mining.conversion.param_meaning import meaning_map

    renamed = _CUT_PARENT.replace("cut_in_gap", "g").replace("lane_change_duration", "dur")
    # a constant term on a parameter that sets the quantity alone is read through (the tests below); beside
    # another sampled value it still changes the meaning
    offset = renamed.replace("CutIn(globalParameters.g,", "CutIn(globalParameters.g + egoS + 10,")
    compared, _ = _judged(offset)
    assert compared["compared"]["lane_change_duration"]["script_name"] == "dur"
    assert "cut_in_gap" in compared["not_comparable"]
    ahead = ("param lead_gap = Range(5, 11)\nparam ped_offset = Range(2, 4)\nego = new Car on lane.centerline\n"
             "lead = new Car ahead of ego by globalParameters.lead_gap\n"
             "ped = new Pedestrian right of lead by globalParameters.ped_offset\n")
    behind = ("param g = Range(5, 11)\nparam side = Range(2, 4)\nego = new Car on lane.centerline\n"
              "other = new Car behind ego by globalParameters.g\n"
              "walker = new Pedestrian left of other by globalParameters.side\n")
    assert meaning_map(ahead, behind, ["lead_gap", "ped_offset"], ["g", "side"])["pairs"] == {}
    same = behind.replace("behind ego", "ahead of ego").replace("left of other", "right of other")
    assert set(meaning_map(ahead, same, ["lead_gap", "ped_offset"], ["g", "side"])["pairs"]) == {"lead_gap",
                                                                                               "ped_offset"}


def test_a_counterpart_with_a_distribution_the_judge_cannot_read_is_not_comparable_with_that_reason():
    opaque = (_CUT_PARENT.replace("cut_in_gap = Range(5, 11)", "g = TruncatedNormal(30, 1, 25, 35)")
              .replace("lane_change_duration = Range(1.8, 3.0)", "dur = Range(8, 9) * 1")
              .replace("globalParameters.cut_in_gap", "globalParameters.g")
              .replace("globalParameters.lane_change_duration", "globalParameters.dur"))
    compared, rejections = _judged(opaque)
    assert "cannot read as an interval (TruncatedNormal(30, 1, 25, 35))" in compared["not_comparable"]["cut_in_gap"]
    assert "cannot read as an interval (Range(8, 9) + Range(0, 1))" in _judged(
        opaque.replace("Range(8, 9) * 1", "Range(8, 9) + Range(0, 1)"))[0]["not_comparable"]["lane_change_duration"]
    # Range(8, 9) * 1 is read as the interval 8..9, which does not contain the failing 2
    assert compared["compared"]["lane_change_duration"]["range"] == [8.0, 9.0]
    key, outside = rejections  # the gap, a quantity of the failure's interaction, is set by the new script's own g
    assert key.startswith("parameters: a key parameter") and "cut_in_gap (" in key and "TruncatedNormal(30, 1, 25, 35)" in key
    assert "lane_change_duration (the script's dur" in outside and "= 2 outside 8..9" in outside


def test_one_actor_of_the_new_script_cannot_stand_for_two_of_the_parent():
    parent = ("param lead_speed = Range(2, 6)\nparam oncoming_gap = Range(30, 60)\nego = new Car on lane.centerline\n"
              "lead = new Car ahead of ego by 20, with speed globalParameters.lead_speed\n"
              "oncoming = new Car ahead of ego by globalParameters.oncoming_gap, with speed 12\n")
    generated = ("param v = Range(2, 15)\nparam oncoming_gap = Range(30, 60)\nego = new Car on lane.centerline\n"
                 "car_a = new Car ahead of ego by 20, with speed 20\n"
                 "car_b = new Car ahead of ego by globalParameters.oncoming_gap, with speed globalParameters.v\n")
    compared, rejections = _judged(generated, parent, {"lead_speed": 3.0, "oncoming_gap": 40.0})
    assert compared["compared"] == {}
    assert "car_b would stand for the parent's lead and oncoming" in compared["not_comparable"]["lead_speed"]
    assert len(rejections) == 1 and "only 0 of the failure's 2 parameters" in rejections[0]


def test_the_failures_actors_must_be_the_scene_in_a_majority_of_the_runs():
    """Four of ten runs with the failure's one car, three with a pedestrian too, three with two cars: the most
    common set is the failure's, but not in most runs."""
    from dv2s_gym.mining.conversion.episodes import compare_actors
    from dv2s_gym.mining.conversion.judge import judge_conversion

    split = compare_actors({"car": 1}, [{"car": 1}] * 4 + [{"car": 1, "pedestrian": 1}] * 3 + [{"car": 2}] * 3, "car")
    assert split["script"] == {"car": 1} and split["runs_matching"] == 4 and not split["same"]
    (reason,) = [str(r) for r in judge_conversion({**_PASSING, "actors": split}, FailureInteraction(), {"type": "collision"}, 0.3)]
    assert reason.startswith("actors:") and "in only 4 of 10 runs (a majority needed)" in reason
    tie = compare_actors({"car": 1}, [{"car": 1}] * 5 + [{"car": 1, "pedestrian": 1}] * 5, "car")
    assert not tie["same"]
    most = compare_actors({"car": 1}, [{"car": 1}] * 6 + [{"car": 2}] * 4, "car")
    assert most["same"] and not judge_conversion({**_PASSING, "actors": most}, FailureInteraction(), {"type": "collision"}, 0.3)


# --------------------------------------------------------------------------- a counterpart through an affine expression
def _cut_script(gap_param, gap_range, gap_expression, name="car1"):
    return (_CUT_PARENT.replace("cut_in_gap = Range(5, 11)", f"{gap_param} = {gap_range}")
            .replace("cutter = new Car", f"{name} = new Car")
            .replace("CutIn(globalParameters.cut_in_gap,", f"CutIn({gap_expression},"))


@pytest.mark.parametrize("gap_range, expression, interval, inside", [
    ("Range(-6, 1)", "globalParameters.g + 10", [4.0, 11.0], True),       # an offset that still covers 6
    ("Range(5, 11)", "globalParameters.g + 10", [15.0, 21.0], False),     # an offset that no longer does
    ("Range(2.5, 5.5)", "2 * globalParameters.g", [5.0, 11.0], True),     # scaled, covering
    ("Range(5, 11)", "globalParameters.g * 2", [10.0, 22.0], False),      # scaled, not covering
    ("Range(5, 11)", "globalParameters.g / 2", [2.5, 5.5], False),        # a quotient by a number
    ("Range(-11, -5)", "-globalParameters.g", [5.0, 11.0], True),         # unary minus
    ("Range(1, 3)", "-(2 * (1 - globalParameters.g)) / 2 + 5", [5.0, 7.0], True),   # nested
    ("Range(1, 3)", "-(2 * (1 - globalParameters.g)) / 2 + 6", [6.0, 8.0], True),   # nested, at the edge
    ("Range(1, 3)", "-(2 * (1 - globalParameters.g)) / 2 + 6.5", [6.5, 8.5], False),
    ("Range(1, 2) * 3", "globalParameters.g + 1", [4.0, 7.0], True),      # the declaration scaled too
    ("Uniform(5, 7, 9) - 10", "globalParameters.g + 5", [0.0, 4.0], False),
])
def test_a_counterpart_set_through_an_affine_expression_is_compared_by_the_interval_it_produces(
        gap_range, expression, interval, inside):
    """The generated script's gap is ``g + 10``, ``2 * g``, ...: the failing gap (6) must lie in the interval that
    expression produces over g's range, not in g's own range; the reason quotes the expression and the interval."""
    compared, rejections = _judged(_cut_script("g", gap_range, expression))
    gap = compared["compared"]["cut_in_gap"]
    assert gap["script_name"] == "g" and gap["by"] == "meaning"
    assert gap["interval"] == interval and gap["quantity"] == 6.0 and gap["expression"] == expression
    if inside:
        assert compared["outside"] == [] and rejections == []
    else:
        assert compared["outside"] == ["cut_in_gap"]
        (reason,) = rejections
        low, high = (f"{v:g}" for v in interval)
        assert f"cut_in_gap (the script's g: " in reason and f"= 6 outside {low}..{high}" in reason
        assert f"the new script's {expression} takes with g in" in reason


def test_a_counterpart_named_alike_is_compared_through_its_expression_and_the_parents_own():
    """Named like the parent's parameter, or set through an expression in the parent too: the failing value's
    quantity in the parent against the new expression's interval."""
    compared, rejections = _judged(_cut_script("cut_in_gap", "Range(5, 11)", "globalParameters.cut_in_gap + 10"))
    gap = compared["compared"]["cut_in_gap"]
    assert "by" not in gap and gap["interval"] == [15.0, 21.0] and compared["outside"] == ["cut_in_gap"]
    assert len(rejections) == 1 and "= 6 outside 15..21" in rejections[0]
    # the parent sets the gap to 2 * cut_in_gap = 12: g + 10 over 0..3 (10..13) covers it, 0..1 (10..11) does not
    parent = _CUT_PARENT.replace("CutIn(globalParameters.cut_in_gap,", "CutIn(2 * globalParameters.cut_in_gap,")
    compared, rejections = _judged(_cut_script("g", "Range(0, 3)", "globalParameters.g + 10"), parent=parent)
    assert compared["compared"]["cut_in_gap"]["quantity"] == 12.0 and rejections == []
    compared, rejections = _judged(_cut_script("g", "Range(0, 1)", "globalParameters.g + 10"), parent=parent)
    assert compared["outside"] == ["cut_in_gap"]
    assert "= 6, which the parent's 2 * globalParameters.cut_in_gap makes 12, outside 10..11" in rejections[0]


def test_an_expression_the_judge_cannot_read_stays_not_comparable():
    for expression in ("globalParameters.g * globalParameters.g", "globalParameters.g + egoS + 10",
                       "globalParameters.g * egoS", "globalParameters.g ** 2"):
        compared, _ = _judged(_cut_script("g", "Range(5, 11)", expression))
        assert "cut_in_gap" in compared["not_comparable"] and "cut_in_gap" not in compared["compared"]


def test_an_affine_placement_distance_is_read_through():
    from dv2s_gym.mining.conversion.parameters import compare_parameters

    parent = ("param lead_gap = Range(5, 11)\nego = new Car on lane.centerline\n"
              "lead = new Car ahead of ego by globalParameters.lead_gap\n")
    generated = ("param d = Range(1, 4)\nego = new Car on lane.centerline\n"
                 "other = new Car ahead of ego by globalParameters.d * 2 + 3\n")
    compared = compare_parameters({"lead_gap": 12.0}, generated, parent=parent)
    assert compared["compared"]["lead_gap"]["interval"] == [5.0, 11.0] and compared["outside"] == ["lead_gap"]
    assert compare_parameters({"lead_gap": 10.0}, generated, parent=parent)["outside"] == []


# --------------------------------------------------------------------------- every quantity a parameter sets is checked
_TWO_USES_PARENT = _CUT_PARENT.replace("    with speed 25,\n", "    with speed globalParameters.ego_speed + 3,\n")


def test_every_quantity_a_parameter_sets_is_checked_the_bare_ones_too():
    """ego_speed sets the ego's speed bare and the cutter's as ``ego_speed + 3``. A new script whose ego never
    drives the failing 20 (30..36) is rejected although its cutter's ``ego_speed - 12`` (18..24) covers the parent's
    23; the reason names the ego's speed. With the ego's range covering 20 too, it passes."""
    generated = (_TWO_USES_PARENT.replace("param ego_speed = Range(18, 25)", "param ego_speed = Range(30, 36)")
                 .replace("globalParameters.ego_speed + 3", "globalParameters.ego_speed - 12"))
    compared, rejections = _judged(generated, parent=_TWO_USES_PARENT)
    assert compared["outside"] == ["ego_speed"]
    (reason,) = rejections
    assert "ego_speed = 20 outside 30..36 (as the ego's speed)" in reason
    covering = (_TWO_USES_PARENT.replace("param ego_speed = Range(18, 25)", "param ego_speed = Range(20, 36)")
                .replace("globalParameters.ego_speed + 3", "globalParameters.ego_speed + 1"))
    compared, rejections = _judged(covering, parent=_TWO_USES_PARENT)
    assert compared["outside"] == [] and rejections == []
    assert compared["compared"]["ego_speed"]["interval"] == [21.0, 37.0]  # the cutter's, 23 inside
    # both quantities on one object: its speed g + 10 covers the parent's 6, its behaviour's gap g (-4..0) does not
    one_object = _cut_script("g", "Range(-4, 0)", "globalParameters.g").replace(
        "    with speed 25,\n", "    with speed globalParameters.g + 10,\n")
    parent = _CUT_PARENT.replace("    with speed 25,\n", "    with speed globalParameters.cut_in_gap,\n")
    compared, rejections = _judged(one_object, parent=parent)
    assert compared["outside"] == ["cut_in_gap"] and "behaviour argument gap" in rejections[0]


_CROSSING_PARENT = '''param ego_speed = Range(8, 12)
param crossing_distance = Range(35, 55)
param kerb = Range(2, 4)
ego = new Car on lane.centerline, with speed globalParameters.ego_speed
spot = new OrientedPoint following roadDirection from ego for globalParameters.crossing_distance
walker = new Pedestrian left of spot by globalParameters.kerb
'''


@pytest.mark.parametrize("placement, outside", [
    ("following roadDirection from ego for globalParameters.d - 15", False),       # 35..45 covers 40
    ("following roadDirection from ego for globalParameters.d + 12", True),        # 62..72
    ("following roadDirection from ego for 3 * globalParameters.d", True),         # 150..180
    ("at lane.centerline.pointAlongBy(egoS + globalParameters.d + 25)", True),     # 75..85 from the ego
    ("at lane.centerline.pointAlongBy(egoS + globalParameters.d - 15)", False),
])
def test_a_point_that_places_the_actor_hands_on_its_expression(placement, outside):
    """The crossing point is placed through an expression of d (50..60 here); the pedestrian it places is at that
    distance, so the failing 40 is compared with the interval the expression takes, not with d's own range."""
    generated = (_CROSSING_PARENT.replace("param crossing_distance = Range(35, 55)", "param d = Range(50, 60)")
                 .replace("following roadDirection from ego for globalParameters.crossing_distance", placement)
                 .replace("param kerb =", "param side =").replace("globalParameters.kerb", "globalParameters.side"))
    if "egoS" in placement:  # a distance along the lane from the ego's own point
        generated = generated.replace("ego = new Car on lane.centerline", "ego = new Car at lane.centerline.pointAlongBy(egoS)")
    failing = {"ego_speed": 10.0, "crossing_distance": 40.0, "kerb": 3.0}
    compared, rejections = _judged(generated, parent=_CROSSING_PARENT, failing=failing)
    crossing = compared["compared"]["crossing_distance"]
    assert crossing["script_name"] == "d" and crossing["quantity"] == 40.0
    assert compared["outside"] == (["crossing_distance"] if outside else [])
    if outside:
        assert "crossing_distance (the script's d: the Pedestrian walker's longitudinal placement" in rejections[0]


@pytest.mark.parametrize("distance, holds", [("Range(90, 110)", False), ("Range(38, 42)", True), ("40", True),
                                             ("80", False)])
def test_a_crossing_point_fixed_without_a_parameter_must_hold_the_failing_distance(distance, holds):
    """The point that places the pedestrian hands its fixed distance on: 90..110 m can never be the failing 40 m,
    whether the parameter is gone or still declared."""
    failing = {"ego_speed": 10.0, "crossing_distance": 40.0, "kerb": 3.0}
    generated = _CROSSING_PARENT.replace("from ego for globalParameters.crossing_distance", f"from ego for {distance}")
    for script in (generated, generated.replace("param crossing_distance = Range(35, 55)\n", "")):
        compared, rejections = _judged(script, parent=_CROSSING_PARENT, failing=failing)
        assert "crossing_distance" in compared["not_comparable"]
        assert (list(compared["key_fixed_outside"]) == []) is holds
        if not holds:
            assert rejections[0].startswith("parameters: a key quantity (of the failure's interaction) that the new "
                                            "script fixes must hold the failing value, and it does not: "
                                            "crossing_distance (the Pedestrian walker's longitudinal placement, "
                                            f"which the new script fixes at {distance} without a parameter")


def test_an_actor_placed_along_the_points_direction_does_not_take_the_points_distance():
    """``ahead of spot by 30`` adds to the point's distance: that placement is not read as the point's."""
    generated = _CROSSING_PARENT.replace("walker = new Pedestrian left of spot by globalParameters.kerb",
                                         "walker = new Pedestrian ahead of spot by 30")
    compared = _judged(generated, parent=_CROSSING_PARENT.replace(
        "walker = new Pedestrian left of spot by globalParameters.kerb", "walker = new Pedestrian ahead of spot by 0"),
        failing={"ego_speed": 10.0, "crossing_distance": 40.0})[0]
    assert "crossing_distance" in compared["not_comparable"]


def test_a_quantity_read_as_a_function_in_one_script_only_is_not_comparable():
    """The parent's speed is ``ego_speed + extra`` (not a function of extra alone), the new one's ``e + 50``
    (never the parent's 25 for any e in 4..8, so not "the same quantity" either): extra is not comparable as a
    parameter, but as a key quantity it is compared jointly and is outside; the other way round (the parent's
    read, the new one's not) it is not comparable."""
    parent = ("param ego_speed = Range(18, 25)\nparam extra = Range(4, 8)\nego = new Car on lane.centerline, "
              "with speed globalParameters.ego_speed\nrival = new Car ahead of ego by 20, "
              "with speed globalParameters.ego_speed + globalParameters.extra\n")
    generated = parent.replace("param extra", "param e").replace(
        "globalParameters.ego_speed + globalParameters.extra", "globalParameters.e + 50")
    failing = {"ego_speed": 20.0, "extra": 5.0}
    compared, _ = _judged(generated, parent=parent, failing=failing)
    # the rival's speed, a key quantity (every actor's, the key actor unknown), is compared jointly: the parent's
    # 20 + 5 against e + 50 over e in 4..8, 54..58
    assert "extra" not in compared["not_comparable"]
    assert compared["compared"]["extra"]["jointly"] == "the Car rival's speed" and compared["outside"] == ["extra"]
    assert compared["compared"]["extra"]["interval"] == [54.0, 58.0] and compared["compared"]["extra"]["quantity"] == 25
    # the parent's rival at extra + 50 (read), the new one's at ego_speed + e (not read)
    reversed_new = parent.replace("param extra", "param e").replace("globalParameters.extra", "globalParameters.e")
    reversed_parent = generated.replace("param e ", "param extra ").replace("globalParameters.e ",
                                                                           "globalParameters.extra ")
    compared, _ = _judged(reversed_new, parent=reversed_parent, failing=failing)
    assert "extra" in compared["not_comparable"] and "extra" not in compared["compared"]


@pytest.mark.parametrize("expression", [
    "min(globalParameters.g, 3)", "max(globalParameters.g, 20)", "globalParameters.g % 5",
    "globalParameters.g if globalParameters.g < 3 else 20", "globalParameters.g + Range(20, 30)",
    "globalParameters.g + egoS", "round(globalParameters.g)"])
def test_a_function_of_the_parameter_the_judge_cannot_read_is_not_comparable(expression):
    compared, _ = _judged(_cut_script("g", "Range(5, 11)", expression))
    assert "cut_in_gap" not in compared["compared"]
    assert "cannot read both as the same known function" in compared["not_comparable"]["cut_in_gap"]


@pytest.mark.parametrize("gap_range, expression, interval, inside", [
    ("Range(-11, -5)", "abs(globalParameters.g)", [5.0, 11.0], True),
    ("Range(-3, 1)", "abs(globalParameters.g)", [0.0, 3.0], False),
    ("Range(0, 4)", "abs(globalParameters.g - 2) * 2 + 3", [3.0, 7.0], True),
])
def test_the_absolute_value_of_an_expression_of_the_parameter_is_read_exactly(gap_range, expression, interval,
                                                                               inside):
    compared, _ = _judged(_cut_script("g", gap_range, expression))
    gap = compared["compared"]["cut_in_gap"]
    assert gap["interval"] == interval and compared["outside"] == ([] if inside else ["cut_in_gap"])


# --------------------------------------------------------------------------- a distribution that is not one interval
@pytest.mark.parametrize("gap_range, failing_gap, inside, values", [
    ("Uniform(4, 10)", 6.0, False, "4, 10"),                 # only 4 or 10
    ("Uniform(4, 6, 10)", 6.0, True, None),
    ("DiscreteRange(3, 8)", 6.5, False, "the integers 3..8"),
    ("DiscreteRange(3, 8)", 6.0, True, None),
    ("Uniform(Range(2, 3), 50)", 6.0, False, "50 or 2..3"),
    ("Uniform(Range(5, 7), 50)", 6.0, True, None),
    ("Options([2, 12])", 6.0, False, "2, 12"),
    ("DiscreteRange(1, 4) * 2", 6.0, True, None),            # 2, 4, 6, 8
    ("DiscreteRange(1, 4) * 2 + 1", 6.0, False, "3 to 9 in steps of 2"),
])
def test_a_discrete_distribution_must_take_the_failing_value(gap_range, failing_gap, inside, values):
    """``Uniform`` of numbers takes only those numbers, ``DiscreteRange`` only integers, a ``Uniform`` of parts any
    value of one of them: the failing value must be one of them, not only between the smallest and the largest."""
    failing = {**_CUT_FAILING, "cut_in_gap": failing_gap}
    for generated in (_cut_script("g", gap_range, "globalParameters.g"),
                      _cut_script("cut_in_gap", gap_range, "globalParameters.cut_in_gap")):
        compared, rejections = _judged(generated, failing=failing)
        assert "cut_in_gap" in compared["compared"]
        assert compared["outside"] == ([] if inside else ["cut_in_gap"])
        if not inside:
            assert f"= {failing_gap:g} not among the values" in rejections[0] and f"({values})" in rejections[0]
    from dv2s_gym.mining.conversion.parameters import compare_parameters
    by_name = compare_parameters(failing, _cut_script("cut_in_gap", gap_range, "globalParameters.cut_in_gap"))
    assert by_name["outside"] == ([] if inside else ["cut_in_gap"])


def test_a_discrete_distribution_is_compared_through_the_new_scripts_expression():
    """g takes -5, -3 or -1; ``g + 9`` then takes 4, 6 or 8 (the failing 6 among them), ``g + 8`` 3, 5 or 7."""
    compared, rejections = _judged(_cut_script("g", "Uniform(5, 7, 9) - 10", "globalParameters.g + 9"))
    assert compared["outside"] == [] and rejections == []
    compared, rejections = _judged(_cut_script("g", "Uniform(5, 7, 9) - 10", "globalParameters.g + 8"))
    assert compared["compared"]["cut_in_gap"]["interval"] == [3.0, 7.0] and compared["outside"] == ["cut_in_gap"]
    assert "= 6 not among the values the new script's globalParameters.g + 8 takes with g one of -5, -3, -1" in (
        rejections[0])


@pytest.mark.slow
def test_a_clip_that_cannot_be_written_is_recorded_without_this_machines_paths(record, tmp_path, monkeypatch):
    """The converted script's clip is extra: when writing it fails (a full disk here), the conversion is kept, the
    record says why, and the reason names the file inside the run folder, not the absolute path it had here."""
    def full_disk(script_path, episode, out_path, *args, **kwargs):
        raise OSError(28, "No space left on device", str(out_path))

    monkeypatch.setattr(convert_module, "write_script_episode_video", full_disk)  # where convert calls it
    out = convert_failure(record, tmp_path / "run", KEEP_LANE, bank=Bank(tmp_path / "bank"),
                          cluster=f"{SCENARIO}/collision/0")
    assert out.to_dict()["status"] == "kept", out.to_dict()["reason"]
    clip = out.to_dict()["reproduction"]["clip"]
    assert clip["file"] is None and "No space left on device" in clip["error"]
    assert f"failures/{SCENARIO}__collision__0/conversion/converted.webm" in clip["error"]
    assert str(tmp_path) not in clip["error"]


_KEY_PARENT = '''param ego_speed = Range(18, 25)
param gap = Range(5, 11)
param dur = Range(1.8, 3.0)
param traffic_speed = Range(20, 30)

behavior Merge(gap, duration):
    wait

ego = new Car at lane.centerline.pointAlongBy(egoS),
    with speed globalParameters.ego_speed
merger = new Car at lane.centerline.pointAlongBy(egoS + 10),
    with name "merger",
    with speed 25,
    with behavior Merge(globalParameters.gap, globalParameters.dur)
walker = new Pedestrian ahead of ego by 60,
    with speed globalParameters.traffic_speed
'''
_KEY_FAILING = {"ego_speed": 20.0, "gap": 6.0, "dur": 2.0, "traffic_speed": 25.0}


def _key_script(gap_expression, extra=""):
    return (_KEY_PARENT.replace("param gap = Range(5, 11)", "param g = Range(5, 11)" + extra)
            .replace("Merge(globalParameters.gap,", f"Merge({gap_expression},")
            .replace('    with name "merger",\n', ""))


@pytest.mark.parametrize("gap_expression, extra", [
    ("globalParameters.g * globalParameters.g", ""), ("10 / globalParameters.g", ""),
    ("min(globalParameters.g, 3)", ""), ("globalParameters.g % 5", ""), ("globalParameters.g + Range(20, 30)", ""),
    ("globalParameters.g + egoS", ""), ("globalParameters.g", "\nparam h = Range(1, 2)\nx = 1")])
def test_a_key_parameter_the_new_script_sets_by_its_own_parameter_must_be_compared(gap_expression, extra):
    """The merger's gap is a quantity of the failure's interaction (the key actor's): when the new script sets it by
    a parameter of its own the judge cannot compare, the script is rejected for that, though 3 of the failure's 4
    parameters compare (the half rule alone let it pass)."""
    from dv2s_gym.mining.conversion.judge import judge_conversion
    from dv2s_gym.mining.conversion.parameters import compare_parameters

    interaction = FailureInteraction.from_dict({"actor": "merger", "kind": "car"})
    compared = compare_parameters(_KEY_FAILING, _key_script(gap_expression, extra), parent=_KEY_PARENT,
                                  interaction=interaction)
    assert compared["key"] == {"ego_speed": "the ego's speed", "gap": "the Car merger's behaviour argument gap",
                               "dur": "the Car merger's behaviour argument duration"}
    reasons = [str(r) for r in judge_conversion({**_PASSING, "parameters": compared}, interaction, {"type": "collision"}, 0.3)]
    if gap_expression == "globalParameters.g":  # the control: the same script, gap set by g alone
        assert reasons == [] and compared["compared"]["gap"]["script_name"] == "g"
        return
    assert "gap" in compared["not_comparable"] and list(compared["key_not_compared"]) == ["gap"]
    (reason,) = reasons
    assert reason.startswith("parameters: a key parameter (it sets a quantity of the failure's interaction) that the "
                             "new script sets with a parameter of its own must be compared, and the judge could not: "
                             "gap (the Car merger's behaviour argument gap, which the new script sets by ")
    assert "(its own parameter g)" in reason


def test_a_parameter_of_an_actor_beside_the_interaction_stays_within_the_half_rule():
    """The walker is no part of the failure with the merger: its speed set by the new script's own unreadable
    parameter is not compared, and with the other 3 compared the script passes."""
    from dv2s_gym.mining.conversion.judge import judge_conversion
    from dv2s_gym.mining.conversion.parameters import compare_parameters

    interaction = FailureInteraction.from_dict({"actor": "merger", "kind": "car"})
    generated = (_KEY_PARENT.replace("param traffic_speed = Range(20, 30)", "param w = Range(4, 6)")
                 .replace("globalParameters.traffic_speed", "globalParameters.w * globalParameters.w"))
    compared = compare_parameters(_KEY_FAILING, generated, parent=_KEY_PARENT, interaction=interaction)
    assert "traffic_speed" in compared["not_comparable"] and "traffic_speed" not in compared["key"]
    assert judge_conversion({**_PASSING, "parameters": compared}, interaction, {"type": "collision"}, 0.3) == []
    # with the key actor unknown, every actor's quantities are key: the walker's speed too
    unknown = compare_parameters(_KEY_FAILING, generated, parent=_KEY_PARENT)
    assert list(unknown["key_not_compared"]) == ["traffic_speed"]


@pytest.mark.parametrize("fixed, holds", [("6", True), ("Range(5, 8)", True), ("Options([6, 9])", True),
                                          ("7", False), ("Range(40, 60)", False), ("Options([5, 9])", False),
                                          ("globalParameters.dur * 0 + 6", True),
                                          ("globalParameters.dur * 0 - 15", False)])
def test_a_key_quantity_the_new_script_fixes_without_a_parameter_must_hold_the_failing_value(fixed, holds):
    """A generated script parameterises the scene its own way: a key quantity it fixes (a number, an inline range,
    discrete values; a parameter times 0 is a number) is no comparison the judge failed and counts within the half
    rule, but only when it holds the failing value: the merger's gap fixed at 40..60 can never be the failing 6."""
    from dv2s_gym.mining.conversion.judge import judge_conversion
    from dv2s_gym.mining.conversion.parameters import compare_parameters

    generated = _key_script(fixed).replace("param g = Range(5, 11)\n", "")
    compared = compare_parameters(_KEY_FAILING, generated, parent=_KEY_PARENT, interaction=FailureInteraction(actor="merger"))
    assert "gap" in compared["not_comparable"] and compared["key_not_compared"] == {}
    reasons = [str(r) for r in judge_conversion({**_PASSING, "parameters": compared}, FailureInteraction(), {"type": "collision"}, 0.3)]
    if holds:
        assert reasons == [] and compared["key_fixed_outside"] == {}
        return
    assert list(compared["key_fixed_outside"]) == ["gap"]
    (reason,) = reasons
    shown = "-15" if "dur" in fixed else fixed
    assert reason == ("parameters: a key quantity (of the failure's interaction) that the new script fixes must hold "
                      "the failing value, and it does not: gap (the Car merger's behaviour argument gap, which the new "
                      f"script fixes at {shown} without a parameter, while the failing gap = 6 (held within 0.12))")


def test_a_parameter_times_zero_is_no_use_of_it():
    from dv2s_gym.mining.conversion.param_meaning import parameter_uses

    uses = parameter_uses(_key_script("globalParameters.dur * 0 - 15"))
    assert {slot for _, _, slot, _, _ in uses["dur"]} == {"behavior:duration"}


@pytest.mark.parametrize("generated, reason_start", [
    # the ego's speed fixed at 40 (failing 20), ego_speed still set on the walker: compared there, never on the ego
    (_KEY_PARENT.replace("    with speed globalParameters.ego_speed\n", "    with speed 40\n")
     .replace("with speed globalParameters.traffic_speed", "with speed globalParameters.ego_speed / 5"),
     "ego_speed (the ego's speed, which the new script fixes at 40 without a parameter, while the failing ego_speed = 20 (held within "
     "0.14))"),
    # the gap moved to the walker's placement, the merger's gap fixed at 50
    (_KEY_PARENT.replace("Merge(globalParameters.gap,", "Merge(50,")
     .replace("ahead of ego by 60", "ahead of ego by globalParameters.gap + 54"),
     "gap (the Car merger's behaviour argument gap, which the new script fixes at 50 without a parameter"),
])
def test_a_key_quantity_fixed_away_from_the_failing_value_is_rejected_whatever_else_uses_the_parameter(
        generated, reason_start):
    from dv2s_gym.mining.conversion.judge import judge_conversion
    from dv2s_gym.mining.conversion.parameters import compare_parameters

    interaction = FailureInteraction.from_dict({"actor": "merger", "kind": "car"})
    compared = compare_parameters(_KEY_FAILING, generated, parent=_KEY_PARENT, interaction=interaction)
    reasons = [str(r) for r in judge_conversion({**_PASSING, "parameters": compared}, interaction, {"type": "collision"}, 0.3)]
    assert reasons and reasons[0].startswith("parameters: a key quantity (of the failure's interaction) that the new "
                                             "script fixes must hold the failing value, and it does not: " + reason_start)


@pytest.mark.parametrize("fixed, holds", [
    # the merger's gap: parent range 5..11 (width 6), failing 6: within 2 % of 6 = 0.12 on either side
    ("6.1", True), ("5.9", True), ("6.12", True), ("6.13", False), ("5.87", False), ("6.5", False),
    ("Range(6.11, 7)", True), ("Range(6.2, 7)", False)])
def test_a_fixed_key_value_holds_the_failing_value_within_the_replay_narrowing_of_the_parents_width(fixed, holds):
    """A faithful script may fix a timing at a round number: it holds the failing value when it lies within
    FIXED_TOLERANCE (the replay narrowing, NARROW) of the width the parent's range gives the quantity, no further."""
    from dv2s_gym.mining.conversion.judge import judge_conversion
    from dv2s_gym.mining.conversion.keys import FIXED_TOLERANCE
    from dv2s_gym.mining.conversion.parameters import compare_parameters
    from dv2s_gym.mining.conversion.exact_replay import NARROW

    assert FIXED_TOLERANCE == NARROW == 0.02
    generated = _key_script(fixed).replace("param g = Range(5, 11)\n", "")
    compared = compare_parameters(_KEY_FAILING, generated, parent=_KEY_PARENT, interaction=FailureInteraction(actor="merger"))
    reasons = [str(r) for r in judge_conversion({**_PASSING, "parameters": compared}, FailureInteraction(), {"type": "collision"}, 0.3)]
    assert (reasons == []) is holds
    assert (compared["key_fixed_outside"] == {}) is holds


def test_the_tolerance_of_a_fixed_key_value_follows_the_parents_expression():
    """The parent sets the merger's speed by ego_speed + 5 (range 18..25, width 7: 0.14 of tolerance on the
    quantity, failing quantity 25): 25.1 holds it, 25.2 does not."""
    from dv2s_gym.mining.conversion.parameters import compare_parameters

    parent = _KEY_PARENT.replace("    with speed 25,\n", "    with speed globalParameters.ego_speed + 5,\n")
    interaction = FailureInteraction.from_dict({"actor": "merger", "kind": "car"})
    for speed, holds in (("25.1", True), ("24.87", True), ("25.2", False), ("24.8", False)):
        generated = parent.replace("    with speed globalParameters.ego_speed + 5,\n", f"    with speed {speed},\n")
        compared = compare_parameters(_KEY_FAILING, generated, parent=parent, interaction=interaction)
        assert ("ego_speed" not in compared["key_fixed_outside"]) is holds, speed


_OVERRIDE_PARENT = '''param ego_speed = Range(8, 12)
param pace = Range(1.0, 2.0)
param gap = Range(5, 11)

behavior Walk(pace, gap):
    take SetWalkingSpeedAction(pace)
    wait

ego = new Car at lane.centerline.pointAlongBy(egoS),
    with speed globalParameters.ego_speed
walker = new Pedestrian ahead of ego by 30,
    with name "walker",
    with behavior Walk(globalParameters.pace, globalParameters.gap)
'''
_OVERRIDE_FAILING = {"ego_speed": 10.0, "pace": 1.4, "gap": 7.0}


@pytest.mark.parametrize("statement, holds", [
    ("pace = 3", False), ("pace = pace * 4", False), ("pace += 1", False),
    ("if self.speed > 1:\n        pace = 0.1", False), ("pace = 1.41", True), ("paced = 3", True)])
def test_a_key_behaviour_argument_the_behaviour_assigns_anew_is_rejected(statement, holds):
    """The walker's pace is passed to Walk, but a body that assigns pace anew walks at another pace whatever the
    parameter: rejected as an override, unless the value it assigns holds the failing value (1.41 against 1.4,
    within 0.02); another name assigned is no override."""
    from dv2s_gym.mining.conversion.judge import judge_conversion
    from dv2s_gym.mining.conversion.parameters import compare_parameters

    generated = _OVERRIDE_PARENT.replace("    take SetWalkingSpeedAction(pace)\n",
                                         f"    {statement}\n    take SetWalkingSpeedAction(pace)\n")
    interaction = FailureInteraction.from_dict({"actor": "walker", "kind": "pedestrian"})
    assert [str(r) for r in judge_conversion({**_PASSING, "parameters": compare_parameters(
        _OVERRIDE_FAILING, _OVERRIDE_PARENT, parent=_OVERRIDE_PARENT, interaction=interaction)},
        interaction, {"type": "collision"}, 0.3)] == []
    compared = compare_parameters(_OVERRIDE_FAILING, generated, parent=_OVERRIDE_PARENT, interaction=interaction)
    reasons = [str(r) for r in judge_conversion({**_PASSING, "parameters": compared}, interaction, {"type": "collision"}, 0.3)]
    if holds:
        assert reasons == []
        return
    assert list(compared["key_overridden"]) == ["pace"]
    (reason,) = reasons
    assert reason.startswith("parameters: a key quantity (of the failure's interaction) that the new script passes "
                             "to a behaviour must be what the behaviour uses, and the behaviour assigns it anew: pace "
                             "(the Pedestrian walker's behaviour argument pace: the new script's behaviour assigns "
                             "that argument anew (")


def test_a_behaviour_the_parent_overrides_alike_is_no_override():
    from dv2s_gym.mining.conversion.judge import judge_conversion
    from dv2s_gym.mining.conversion.parameters import compare_parameters

    parent = _OVERRIDE_PARENT.replace("    take SetWalkingSpeedAction(pace)\n",
                                      "    pace = pace + 0.1\n    take SetWalkingSpeedAction(pace)\n")
    interaction = FailureInteraction.from_dict({"actor": "walker", "kind": "pedestrian"})
    compared = compare_parameters(_OVERRIDE_FAILING, parent, parent=parent, interaction=interaction)
    assert "key_overridden" not in compared
    assert judge_conversion({**_PASSING, "parameters": compared}, interaction, {"type": "collision"}, 0.3) == []


@pytest.mark.parametrize("target, holds", [("30", False), ("10", True), ("10.05", True), ("10.2", False),
                                           ("globalParameters.ego_speed", True)])
def test_the_egos_target_speed_is_read_as_its_speed(target, holds):
    """The parent sets the ego's speed by ego_speed and gives it no behaviour; the new script keeps the start speed
    but drives the ego at a fixed target speed: it must hold the failing 10 (within 2 % of 8..12, 0.08)."""
    from dv2s_gym.mining.conversion.judge import judge_conversion
    from dv2s_gym.mining.conversion.parameters import compare_parameters

    generated = _OVERRIDE_PARENT.replace("    with speed globalParameters.ego_speed\n",
                                         "    with speed globalParameters.ego_speed,\n"
                                         f"    with behavior FollowLaneBehavior(target_speed={target})\n")
    interaction = FailureInteraction.from_dict({"actor": "walker", "kind": "pedestrian"})
    compared = compare_parameters(_OVERRIDE_FAILING, generated, parent=_OVERRIDE_PARENT, interaction=interaction)
    reasons = [str(r) for r in judge_conversion({**_PASSING, "parameters": compared}, interaction, {"type": "collision"}, 0.3)]
    assert (reasons == []) is holds
    if not holds:
        assert "ego_speed (the ego's speed (as its behaviour's target speed), which the new script fixes at " in reasons[0]


def test_a_behaviour_of_the_same_name_and_arguments_keeps_its_argument_check():
    """A body edited but the behaviour's name and arguments kept: a key argument fixed away from the failing value is
    still checked (a behaviour renamed, or with other arguments, may read it otherwise and is not)."""
    from dv2s_gym.mining.conversion.parameters import compare_parameters

    interaction = FailureInteraction.from_dict({"actor": "walker", "kind": "pedestrian"})
    edited = _OVERRIDE_PARENT.replace("    wait\n", "    wait\n    wait\n").replace(
        "Walk(globalParameters.pace,", "Walk(3,")
    assert list(compare_parameters(_OVERRIDE_FAILING, edited, parent=_OVERRIDE_PARENT,
                                   interaction=interaction)["key_fixed_outside"]) == ["pace"]
    renamed = edited.replace("Walk", "Stroll")
    assert compare_parameters(_OVERRIDE_FAILING, renamed, parent=_OVERRIDE_PARENT,
                              interaction=interaction)["key_fixed_outside"] == {}


_JUNCTION_PARENT = '''param ego_speed = Range(6, 10)
param ego_distance = Range(20, 40)
param bus_speed = Range(7, 11)
param bus_extra = Range(1, 3)

ego = new Car at egoManeuver.startLane.centerline.pointAlongBy(-globalParameters.ego_distance),
    with speed globalParameters.ego_speed
bus = new Bus at busManeuver.startLane.centerline.pointAlongBy(-20),
    with name "bus",
    with speed globalParameters.bus_speed + globalParameters.bus_extra
'''
_JUNCTION_FAILING = {"ego_speed": 8.0, "ego_distance": 30.0, "bus_speed": 9.0, "bus_extra": 2.0}


@pytest.mark.parametrize("ego_distance, times, holds", [
    (30.0, "Range(1.0, 2.0)\nparam lag = Range(1.5, 2.5)", True),   # 8 * (1..2 + 1.5..2.5) = 20..36 holds 30
    (38.0, "Range(1.0, 2.0)\nparam lag = Range(1.5, 2.5)", False),  # 38 is past 36
    (30.0, "Range(0.5, 1.0)\nparam lag = Range(1.0, 1.5)", False),  # 8 * (1.5..2.5) = 12..20
])
def test_a_key_placement_set_by_a_product_of_parameters_is_compared_jointly(ego_distance, times, holds):
    """The parent places the ego ego_distance before the junction; the new script places it ego_speed * (lead +
    lag), a product the judge reads jointly: ego_speed held at the failing 8, lead and lag over their ranges."""
    from dv2s_gym.mining.conversion.judge import judge_conversion
    from dv2s_gym.mining.conversion.parameters import compare_parameters

    generated = (_JUNCTION_PARENT.replace("param ego_distance = Range(20, 40)", "param lead = " + times)
                 .replace("pointAlongBy(-globalParameters.ego_distance)",
                          "pointAlongBy(-(globalParameters.ego_speed * (globalParameters.lead + globalParameters.lag)))"))
    failing = {**_JUNCTION_FAILING, "ego_distance": ego_distance}
    interaction = FailureInteraction.from_dict({"actor": "bus", "kind": "bus"})
    compared = compare_parameters(failing, generated, parent=_JUNCTION_PARENT, interaction=interaction)
    assert compared["key_not_compared"] == {}
    assert compared["compared"]["ego_distance"]["jointly"] == "the ego's longitudinal placement"
    reasons = [str(r) for r in judge_conversion({**_PASSING, "parameters": compared}, interaction, {"type": "collision"}, 0.3)]
    assert (reasons == []) is holds
    if not holds:
        assert compared["outside"] == ["ego_distance"]
        assert reasons[0].startswith("parameters: the new scenario's ranges do not contain the failing values: "
                                     f"ego_distance = {ego_distance:g}, which the parent's -globalParameters.ego_distance "
                                     f"makes {-ego_distance:g} as the ego's longitudinal placement, outside ")


def test_a_product_that_uses_a_sampled_value_twice_is_not_read_jointly():
    from dv2s_gym.mining.conversion.parameters import compare_parameters

    generated = (_JUNCTION_PARENT.replace("param ego_distance = Range(20, 40)", "param lead = Range(3, 5)")
                 .replace("pointAlongBy(-globalParameters.ego_distance)",
                          "pointAlongBy(-(globalParameters.ego_speed * (globalParameters.lead + globalParameters.lead)))"))
    compared = compare_parameters(_JUNCTION_FAILING, generated, parent=_JUNCTION_PARENT,
                                  interaction=FailureInteraction(actor="bus", kind="bus"))
    assert list(compared["key_not_compared"]) == ["ego_distance"]


@pytest.mark.parametrize("speed_range, holds", [("Range(10, 12)", True), ("Range(7, 10)", False)])
def test_a_relative_speed_rewritten_as_absolute_is_compared_jointly(speed_range, holds):
    """The parent drives the bus at bus_speed + bus_extra (failing 9 + 2 = 11); the new script drives it at one
    parameter of its own: it must hold 11."""
    from dv2s_gym.mining.conversion.judge import judge_conversion
    from dv2s_gym.mining.conversion.parameters import compare_parameters

    generated = (_JUNCTION_PARENT.replace("param bus_extra = Range(1, 3)", "")
                 .replace("param bus_speed = Range(7, 11)", f"param bus_v = {speed_range}")
                 .replace("globalParameters.bus_speed + globalParameters.bus_extra", "globalParameters.bus_v"))
    interaction = FailureInteraction.from_dict({"actor": "bus", "kind": "bus"})
    compared = compare_parameters(_JUNCTION_FAILING, generated, parent=_JUNCTION_PARENT, interaction=interaction)
    reasons = [str(r) for r in judge_conversion({**_PASSING, "parameters": compared}, interaction, {"type": "collision"}, 0.3)]
    assert (reasons == []) is holds, reasons


@pytest.mark.parametrize("distribution, holds", [("Normal(1.5, 0.1)", True), ("Normal(1.45, 0.02)", True),
                                                 ("Normal(2.0, 0.1)", False), ("Normal(1.5, 0.03)", False)])
def test_a_normal_parameter_is_read_as_three_standard_deviations_about_its_mean(distribution, holds):
    """The walker's pace drawn from a Normal: the failing 1.4 must lie within 3 standard deviations of its mean
    (1.2..1.8 and 1.39..1.51 hold it; 1.7..2.3 and 1.41..1.59 do not)."""
    from dv2s_gym.mining.conversion.judge import judge_conversion
    from dv2s_gym.mining.conversion.parameters import compare_parameters
    from dv2s_gym.mining.conversion.ranges import NORMAL_SPREAD

    assert NORMAL_SPREAD == 3.0
    generated = _OVERRIDE_PARENT.replace("param pace = Range(1.0, 2.0)", f"param pace = {distribution}")
    interaction = FailureInteraction.from_dict({"actor": "walker", "kind": "pedestrian"})
    compared = compare_parameters(_OVERRIDE_FAILING, generated, parent=_OVERRIDE_PARENT, interaction=interaction)
    assert "pace" in compared["compared"]
    reasons = [str(r) for r in judge_conversion({**_PASSING, "parameters": compared}, interaction, {"type": "collision"}, 0.3)]
    assert (reasons == []) is holds
    assert (compared["outside"] == ["pace"]) is not holds


@pytest.mark.parametrize("loop, runs", [("for k in range(1):", True), ("for k in range(3):", True),
                                       ("for k in range(0):", False), ("for k in range(n):", False)])
def test_an_actor_made_in_a_top_level_loop_that_runs_is_read_as_made_at_the_top_level(loop, runs):
    """The walker made in the body of a loop over range(1) or range(3) is compared as in the parent (its body runs;
    a specifier line after a trailing comma continues the statement at any indentation); over range(0), or a count
    the judge does not know, its parameters reach no object."""
    from dv2s_gym.mining.conversion.judge import judge_conversion
    from dv2s_gym.mining.conversion.parameters import compare_parameters

    generated = _OVERRIDE_PARENT.replace("walker = new Pedestrian ahead of ego by 30,\n    with name \"walker\",\n",
                                         f"{loop}\n    walker = new Pedestrian ahead of ego by 30,\n"
                                         "        with name \"walker\",\n")
    assert loop in generated
    interaction = FailureInteraction.from_dict({"actor": "walker", "kind": "pedestrian"})
    compared = compare_parameters(_OVERRIDE_FAILING, generated, parent=_OVERRIDE_PARENT, interaction=interaction)
    reasons = [str(r) for r in judge_conversion({**_PASSING, "parameters": compared}, interaction, {"type": "collision"}, 0.3)]
    assert (sorted(compared["compared"]) == ["ego_speed", "gap", "pace"]) is runs
    assert (reasons == []) is runs


_SLOWER_PARENT = '''param ego_speed = Range(18, 25)
param slower_by = Range(2, 4)
param gap = Range(5, 11)

behavior Drift(gap, slowerBy):
    wait

ego = new Car at lane.centerline.pointAlongBy(egoS),
    with speed globalParameters.ego_speed
drifter = new Car at lane.centerline.pointAlongBy(egoS + 30),
    with name "drifter",
    with speed globalParameters.ego_speed - globalParameters.slower_by,
    with behavior Drift(globalParameters.gap, globalParameters.slower_by)
'''


@pytest.mark.parametrize("speed", ["globalParameters.ego_speed - 3", "globalParameters.ego_speed"])
def test_a_parameter_compared_on_its_key_quantity_stays_compared_when_another_quantity_cannot_be_read(speed):
    """ego_speed sets the ego's speed the same way in both scripts (compared, inside); the drifter's speed the new
    script computes otherwise cannot be compared: it is listed, and it does not make the ego's speed a key parameter
    the judge could not compare."""
    from dv2s_gym.mining.conversion.judge import judge_conversion
    from dv2s_gym.mining.conversion.parameters import compare_parameters

    generated = _SLOWER_PARENT.replace("globalParameters.ego_speed - globalParameters.slower_by", speed)
    failing = {"ego_speed": 20.0, "slower_by": 3.0, "gap": 6.0}
    interaction = FailureInteraction.from_dict({"actor": "drifter", "kind": "car"})
    compared = compare_parameters(failing, generated, parent=_SLOWER_PARENT, interaction=interaction)
    assert "ego_speed" in compared["compared"] and compared["key_not_compared"] == {}
    assert "the Car drifter's speed" in compared["quantities_not_compared"]["ego_speed"]
    assert judge_conversion({**_PASSING, "parameters": compared}, interaction, {"type": "collision"}, 0.3) == []
    # the ego's own speed moved: outside, whatever the drifter
    moved = generated.replace("param ego_speed = Range(18, 25)", "param ego_speed = Range(30, 35)")
    outside = compare_parameters(failing, moved, parent=_SLOWER_PARENT, interaction=interaction)
    assert outside["outside"] == ["ego_speed"]


@pytest.mark.parametrize("assignment, inside", [("x = globalParameters.g + 20", False),
                                                ("x = globalParameters.g", True),
                                                ("x = (globalParameters.g - 1) * 2 - 4", True)])
def test_a_variable_computed_from_a_parameter_is_followed_like_an_expression(assignment, inside):
    """``x = g + 20`` then ``Merge(x, ...)`` sets the gap to ``g + 20`` (25..31, never the failing 6): compared
    through that expression; ``x = g`` is ``g`` itself."""
    compared, rejections = _judged(_CUT_PARENT.replace("param cut_in_gap = Range(5, 11)",
                                                       f"param g = Range(5, 11)\n{assignment}")
                                   .replace("CutIn(globalParameters.cut_in_gap,", "CutIn(x,"))
    gap = compared["compared"]["cut_in_gap"]
    assert gap["script_name"] == "g"
    assert (rejections == []) is inside
    if not inside:
        assert gap["interval"] == [25.0, 31.0] and "= 6 outside 25..31" in rejections[0]


def test_each_bank_scenario_judged_against_itself_compares_every_parameter():
    """The judge on a shipped scenario and itself (failing values in the middle of each range): every parameter is
    compared, none outside, no rejection, whatever the key actor."""
    from dv2s_gym.mining.conversion.judge import judge_conversion
    from dv2s_gym.mining.conversion.parameters import compare_parameters
    from dv2s_gym.mining.conversion.ranges import script_ranges

    bank = Bank()
    for name in sorted(bank.names()):
        script = bank.get(name).script
        failing = {p: (low + high) / 2 for p, (low, high) in script_ranges(script).items()}
        compared = compare_parameters(failing, script, parent=script)
        assert compared["not_comparable"] == {} and compared["outside"] == [], name
        assert len(compared["compared"]) == len(failing), name
        assert judge_conversion({**_PASSING, "parameters": compared}, FailureInteraction(), {"type": "collision"}, 0.3) == [], name


@pytest.mark.parametrize("expression", ["(globalParameters.g + 1e16) - 1e16", "globalParameters.g + 1e400",
                                        "globalParameters.g * 1e9 / 1e9"])
def test_a_number_beyond_what_floating_point_keeps_makes_the_expression_unread(expression):
    """Scenic computes ``(g + 1e16) - 1e16`` in floating point (6 becomes 6 or 8): the judge does not read it as
    ``g``; the key quantity is then not comparable and the script rejected."""
    from dv2s_gym.mining.conversion.scenic_values import affine_form

    assert affine_form(expression, "g") is None
    compared, rejections = _judged(_CUT_PARENT.replace("param cut_in_gap = Range(5, 11)", "param g = Range(5, 11)")
                                   .replace("CutIn(globalParameters.cut_in_gap,", f"CutIn({expression},"))
    assert "cut_in_gap" in compared["not_comparable"] and "cut_in_gap" not in compared["compared"]
    assert rejections and rejections[0].startswith("parameters: a key parameter")


@pytest.mark.parametrize("reference, compared_by_distance", [("egoS", True), ("otherS", False), ("", False)])
def test_a_distance_along_the_lane_is_read_only_from_the_egos_point(reference, compared_by_distance):
    """``pointAlongBy(egoS + g)`` places the actor ``g`` ahead of the ego (the ego is at ``pointAlongBy(egoS)``);
    from another point (``otherS + g``) or from the lane's start (``g``) the same number is another distance: the
    judge does not read it as the parent's distance from the ego (the key quantity is then not comparable)."""
    from dv2s_gym.mining.conversion.parameters import compare_parameters

    parent = ("param lead_gap = Range(10, 20)\negoS = Range(50, 400)\notherS = Range(0, 600)\n"
              "ego = new Car at lane.centerline.pointAlongBy(egoS)\n"
              "lead = new Car at lane.centerline.pointAlongBy(egoS + globalParameters.lead_gap), with speed 0\n")
    start = f"{reference} + " if reference else ""
    generated = (parent.replace("lead_gap = Range(10, 20)", "g = Range(10, 20)")
                 .replace("pointAlongBy(egoS + globalParameters.lead_gap)", f"pointAlongBy({start}globalParameters.g)"))
    compared = compare_parameters({"lead_gap": 15.0}, generated, parent=parent)
    assert ("lead_gap" in compared["compared"]) is compared_by_distance
    if not compared_by_distance:
        assert list(compared["key_not_compared"]) == ["lead_gap"]
