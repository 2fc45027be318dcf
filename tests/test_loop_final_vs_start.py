"""The loop report compares the last fine-tuned policy with the starting one on the starting bank.

The rounds' regression reports are made from hand-written episode results (two scenarios x four seeds) with
the regression test's own report builder, as ``dv2s loop`` writes them: round 1 tests P1 against the start
P0, round 2 tests P2 against P1. The final comparison pairs round 1's P0 episodes with round 2's P2 episodes.
"""

from __future__ import annotations

import json
from pathlib import Path

from dv2s_gym.loop.record import LoopReportBody, RecordedLoopSettings, RoundRecord
from dv2s_gym.loop.report import final_vs_start, write_loop_reports
from dv2s_gym.loop.settings import LoopError, LoopSettings
from dv2s_gym.regress.records import RegressReport
from dv2s_gym.regress.report import write_json
from regress_report_data import report_from_json

NAMES = ["scenario_a", "scenario_b"]
SEEDS = [0, 1, 2, 3]

LOOP_SETTINGS = {**LoopSettings().recorded(), "policy": "p0"}
"""The settings a loop records (every one), started from ``p0``."""


def _result(failed: bool) -> dict:
    return {"failed": failed, "collided": failed, "off_road": False, "success": not failed, "error": None,
            "min_ttc": 1.0, "mean_speed": 10.0, "episode_return": 1.0}


def _regress(path: Path, candidate: str, baseline: str, cand_fail: set, base_fail: set, hashes=None) -> str:
    episodes = [{"id": f"{n}:{s}", "scenario": n, "seed": s, "candidate": _result((n, s) in cand_fail),
                 "baseline": _result((n, s) in base_fail)} for n in NAMES for s in SEEDS]
    bank = {"path": "bank", "version": 1, "scenarios": NAMES, "hashes": hashes or {n: "h-" + n for n in NAMES}}
    report = report_from_json(bank=bank, settings={"margin": 0.05, "alpha": 0.05, "episodes": 4, "seed": 0,
                                                      "failure": ["collision", "off_road"]},
                              candidate={"spec": candidate}, baseline={"spec": baseline}, episodes=episodes)
    return str(write_json(report, path))


P0_FAILS = {("scenario_a", 0)}
P1_FAILS = {("scenario_a", 0), ("scenario_b", 1)}
P2_FAILS = {(n, s) for n in NAMES for s in SEEDS} - {("scenario_b", 3)}


def _loop(tmp_path: Path, rounds: int, hashes2=None) -> LoopReportBody:
    records = [{"round": 1, "policy": "p0", "new_policy": "p1", "steps": {"regress": {
        "verdict": "PASS", "report": _regress(tmp_path / "r1.json", "p1", "p0", P1_FAILS, P0_FAILS)}}}]
    if rounds > 1:
        records.append({"round": 2, "policy": "p1", "new_policy": "p2", "steps": {"regress": {
            "verdict": "FAIL", "report": _regress(tmp_path / "r2.json", "p2", "p1", P2_FAILS, P1_FAILS, hashes2)}}})
    return LoopReportBody.from_dict({"schema": "dv2s-loop", "schema_version": 1, "settings": LOOP_SETTINGS,
                                     "policy": records[-1]["new_policy"], "rounds": records})


def test_final_policy_is_paired_with_the_starting_policy(tmp_path):
    final = final_vs_start(_loop(tmp_path, 2), tmp_path / "loop")
    assert final.to_dict()["start"] == "p0" and final.to_dict()["final"] == "p2" and final.to_dict()["rounds"] == [1, 2]
    assert final.to_dict()["episodes"] == 8
    assert final.to_dict()["new_failure_rate"]["value"] == 7 / 8 and final.to_dict()["old_failure_rate"]["value"] == 1 / 8
    assert final.to_dict()["difference"]["value"] == 6 / 8
    assert final.to_dict()["verdict"] == "FAIL"  # 6 discordant pairs all against P2: McNemar p = 1/64
    paired = json.loads(Path(final.to_dict()["report"]).read_text())
    assert paired["baseline"]["spec"] == "p0" and paired["candidate"]["spec"] == "p2"
    assert sum(e["baseline"]["failed"] for e in paired["episodes"]) == 1


def test_the_report_shows_the_comparison_only_with_two_tested_rounds(tmp_path):
    paths = write_loop_reports(_loop(tmp_path, 2), tmp_path / "two")
    data = json.loads(paths["json"].read_text())
    assert data["final_vs_start"]["verdict"] == "FAIL"
    markdown = paths["md"].read_text()
    assert "Round 2's fine-tuned policy `p2` against the starting policy `p0`" in markdown and "**FAIL**" in markdown
    assert "failure rate fine-tuned " in markdown and "Round 2&#x27;s fine-tuned policy" in paths["html"].read_text()
    for text in (markdown, paths["html"].read_text()):  # "final" is no name for a policy the user reads
        assert "final policy" not in text.lower() and "failure rate final" not in text

    (tmp_path / "one").mkdir()
    paths = write_loop_reports(_loop(tmp_path / "one", 1), tmp_path / "one")
    assert "final_vs_start" not in json.loads(paths["json"].read_text())
    assert "starting policy `" not in paths["md"].read_text()


def test_a_changed_starting_bank_is_not_compared(tmp_path):
    changed = {"scenario_a": "h-scenario_a", "scenario_b": "edited"}
    final = final_vs_start(_loop(tmp_path, 2, hashes2=changed))
    assert "scenario_b" in final.to_dict()["error"] and "no paired comparison" in final.to_dict()["error"]
    missing = _loop(tmp_path, 2)
    Path(missing.rounds[0].steps.regress.report).unlink()
    assert final_vs_start(missing).error.startswith("cannot read the rounds' regression reports")


def _accepted(record: dict) -> dict:
    """``record`` as a round whose own tests accepted its policy (regression PASS, held-out no worse)."""
    from dv2s_gym.loop.verdict import heldout_worse

    fine = {"f1": {"both_fail": 0, "candidate_only": 0, "baseline_only": 2, "neither": 28},
            "f2": {"both_fail": 0, "candidate_only": 0, "baseline_only": 2, "neither": 28}}
    steps = {**record["steps"], "fine_tune": {}, "regress": {**record["steps"]["regress"], "verdict": "PASS"},
             "after": {"pairs": 60, "significantly_worse": {"start": heldout_worse(fine, "start"), "control": None}}}
    return {**record, "steps": steps}


def _state(rounds: list):
    """A loop's state holding ``rounds`` (their JSON objects) as the loop holds them, written nowhere."""
    from types import SimpleNamespace

    records = [RoundRecord.from_dict(record) for record in rounds]

    def update(record: RoundRecord, save: bool = True) -> RoundRecord:
        records[record.round - 1] = record
        return record

    return SimpleNamespace(settings=RecordedLoopSettings(policy="p0"), rounds=records, update=update,
                           round=lambda number: records[number - 1])


def test_the_next_round_and_the_report_never_use_a_policy_the_cross_round_check_rejected(tmp_path):
    from types import SimpleNamespace

    from dv2s_gym.loop import run as loop_module

    body = _loop(tmp_path, 2)
    rounds = [_accepted(record.to_dict()) for record in body.rounds]  # round 2 passes against P1 but P2 FAILs against P0
    loop = SimpleNamespace(state=_state(rounds), out=tmp_path)
    assert loop_module._next_start(loop, 2, "p1") == "p0"
    # round 3 starts from p0 and its own regression test FAILs
    rounds = [record.to_dict() for record in loop.state.rounds]
    rounds.append({"round": 3, "policy": "p0", "new_policy": "p3", "steps": {"fine_tune": {}, "regress": {
        "verdict": "FAIL", "report": _regress(tmp_path / "r3.json", "p3", "p0", P2_FAILS, P0_FAILS)}}})
    loop = SimpleNamespace(state=_state(rounds), out=tmp_path)
    assert loop_module._next_start(loop, 3, "p0") == "p0"
    rounds = [record.to_dict() for record in loop.state.rounds]
    paths = write_loop_reports(LoopReportBody.from_dict({**body.to_dict(), "policy": "p3", "rounds": rounds}),
                               tmp_path / "loop")
    data = json.loads(paths["json"].read_text())
    assert data["rounds"][1]["final_vs_start"]["verdict"] == "FAIL"
    assert data["recommendation"]["policy"] == "p0" and "Policy to use: `p0`" in paths["md"].read_text()


def test_the_cross_round_check_reads_a_moved_loop_folder_from_any_working_directory(tmp_path, monkeypatch):
    from types import SimpleNamespace

    from dv2s_gym.loop import run as loop_module
    from dv2s_gym.loop.verdict import recommendation

    monkeypatch.chdir(tmp_path)
    folder = tmp_path / "out" / "loop"
    rounds = []
    for number, (policy, fails, base_fails) in enumerate((("p0", P1_FAILS, P0_FAILS), ("p1", P2_FAILS, P1_FAILS)), 1):
        stored = folder / f"round_{number}" / "regress" / "report.json"  # absolute, as the loop records it
        _regress(stored, f"p{number}", policy, fails, base_fails)
        rounds.append(_accepted({"round": number, "policy": policy, "new_policy": f"p{number}",
                                 "steps": {"regress": {"report": str(stored)}}}))
    body = LoopReportBody.from_dict({"settings": LOOP_SETTINGS, "policy": "p2", "rounds": rounds})
    (tmp_path / "out").rename(tmp_path / "moved")  # the loop folder moved after the run
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    given = Path("../moved/loop")  # the moved loop folder, typed from another working directory
    assert final_vs_start(body, folder=given).verdict == "FAIL"
    paths = write_loop_reports(body, given)
    assert json.loads(paths["json"].read_text())["recommendation"]["policy"] == "p0"
    assert loop_module._next_start(SimpleNamespace(state=_state(rounds), out=given), 2, "p1") == "p0"
    # a cross-round check that cannot run (here: no loop folder to read the reports from) never accepts
    unread = final_vs_start(body)
    assert "cannot read" in unread.error
    verdict = recommendation(body.replace(final_vs_start=unread))
    assert verdict.verdict == "NOT ACCEPTED" and verdict.exit_code == 3 and verdict.policy == "p1"
    assert "could not run" in verdict.reason


def test_the_loop_records_regression_report_paths_that_do_not_depend_on_the_working_directory(tmp_path, monkeypatch):
    from dv2s_gym.loop.comparisons import _regress_summary

    monkeypatch.chdir(tmp_path)
    summary = _regress_summary(RegressReport.from_json({"verdict": "PASS"}), Path("out/loop/round_1/regress/report.json"))
    assert summary.report == str(tmp_path.resolve() / "out/loop/round_1/regress/report.json")


def test_a_round_begun_from_another_policy_than_the_rounds_before_it_recommend_is_refused(tmp_path):
    import pytest
    from types import SimpleNamespace

    from dv2s_gym.loop import run as loop_module

    record = {"round": 2, "policy": "p0", "steps": {"mine": {"kept": []}}}  # begun from p0 ...
    loop = SimpleNamespace(state=SimpleNamespace(round=lambda number: RoundRecord.from_dict(record)), out=tmp_path)
    with pytest.raises(LoopError, match="round 2 .* was begun from p0, not from p1.*--out"):
        loop_module._run_round(loop, 2, "p1")  # ... where round 1 recommends p1
    assert record["policy"] == "p0" and list(record["steps"]) == ["mine"]


def test_a_rounds_cross_round_check_is_a_field_written_as_read_null_included(tmp_path):
    body = _loop(tmp_path, 2)
    paths = write_loop_reports(body.replace(rounds=tuple(RoundRecord.from_dict(_accepted(record.to_dict()))
                                                         for record in body.rounds)), tmp_path / "loop")
    written = json.loads(paths["json"].read_text())["rounds"]
    # round 1: fewer than two tested rounds up to it, so no check could be made (null); round 2: FAIL against P0
    assert "final_vs_start" in written[0] and written[0]["final_vs_start"] is None
    first, second = (RoundRecord.from_dict(record) for record in written)
    assert first.cross_round_checked and first.final_vs_start is None and "final_vs_start" not in first.extra
    assert second.final_vs_start.verdict == "FAIL" and first.to_dict() == written[0]
    unchecked = RoundRecord.from_dict({"round": 1})
    assert not unchecked.cross_round_checked and "final_vs_start" not in unchecked.to_dict()
    assert unchecked.with_cross_round_check(None).to_dict() == {**unchecked.to_dict(), "final_vs_start": None}
    assert unchecked.with_cross_round_check(None).with_cross_round_check({"error": "x"}).to_dict() == {
        **unchecked.to_dict(), "final_vs_start": {"error": "x"}}
