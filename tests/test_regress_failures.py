"""dv2s regress: what counts as a failure (collision, off-road, stall by default; --failure), each kind apart."""

from __future__ import annotations

import pytest

from dv2s_gym.cli import main
from dv2s_gym.regress import RegressError
from regress_call import run_regression
from dv2s_gym.regress.failures import apply_failure, parse_failure

STOP = "regress_helpers:StopPolicy"
FREE_ROAD = "highway_cut_in_from_left"  # nothing stands in the ego's lane ahead: standing still is a stall
CONFIG = {"duration": 10}


def test_failure_kinds_are_parsed_and_applied():
    assert parse_failure(None) == ["collision", "off_road", "stall"]
    assert parse_failure("stall, collision") == ["collision", "stall"]
    assert parse_failure(["off-road"]) == ["off_road"]
    with pytest.raises(RegressError, match="unknown failure kind 'crash'; give a comma-separated list of collision"):
        parse_failure("collision,crash")
    with pytest.raises(RegressError, match="no failure kind given"):
        parse_failure(" , ")
    result = {"collided": False, "off_road": True, "stalled": True}
    assert apply_failure(dict(result), ["collision", "stall"]) == {**result, "failed": True, "failure_kinds": ["stall"]}
    assert apply_failure(dict(result), ["collision"])["failed"] is False


@pytest.mark.slow
def test_a_policy_that_stands_still_fails_by_stalling(tmp_path):
    report = run_regression(STOP, "rule", scenarios=[FREE_ROAD], episodes=6, workers=2, out_dir=tmp_path / "stall",
                            env_config=CONFIG, progress=False, clips=False)
    candidate = report.to_dict()["scenarios"][FREE_ROAD]["candidate"]
    assert candidate["stall_rate"]["value"] == 1.0 and candidate["collision_rate"]["value"] == 0.0
    assert candidate["failure_rate"]["value"] == 1.0
    assert report.to_dict()["verdict"] == "FAIL" and report.to_dict()["regressed"] == [FREE_ROAD]
    assert all(e["candidate"]["failure_kinds"] == ["stall"] for e in report.to_dict()["episodes"])
    assert all(e["candidate"]["trace"] for e in report.to_dict()["episodes"])  # a stall keeps its trace like any failure
    assert report.to_dict()["settings"]["failure"] == ["collision", "off_road", "stall"]
    # without stall among the failure kinds the stalls are still reported, but nothing fails
    lenient = run_regression(STOP, "rule", scenarios=[FREE_ROAD], episodes=2, workers=1, out_dir=tmp_path / "lenient",
                             env_config=CONFIG, progress=False, failure="collision,off_road")
    candidate = lenient.to_dict()["scenarios"][FREE_ROAD]["candidate"]
    assert candidate["stall_rate"]["value"] == 1.0 and candidate["failure_rate"]["value"] == 0.0


def test_an_unknown_failure_kind_is_bad_input_before_any_episode(tmp_path, capsys):
    code = main(["regress", "--policy", "rule", "--baseline", "rule", "--scenarios", FREE_ROAD, "--episodes", "1",
                 "--failure", "collision,crashes", "--out", str(tmp_path), "--no-progress"])
    assert code == 2 and "unknown failure kind 'crashes'" in capsys.readouterr().err
    assert not (tmp_path / "results.jsonl").exists()


def test_regress_and_the_miner_share_one_stall_default():
    """One stall duration, defined with the stall measure: a change there moves both tools' default."""
    import envs.safety_metrics as measure
    from dv2s_gym.mining import monitors
    from dv2s_gym.mining.settings import MineSettings
    from dv2s_gym.regress import failures

    assert failures.DEFAULT_STALL_SECONDS is measure.DEFAULT_STALL_SECONDS
    assert monitors.DEFAULT_STALL_SECONDS is measure.DEFAULT_STALL_SECONDS
    assert MineSettings().stall_seconds == measure.DEFAULT_STALL_SECONDS == 5.0
