"""dv2s regress keeps the roles apart: one policy instance per role, and neither role always runs first."""

import pytest

from regress_call import run_regression
from dv2s_gym.regress.runner import plan_tasks

COUNTING = "regress_helpers:EpisodeCountingPolicy?slow=1"


@pytest.mark.slow
def test_a_stateful_policy_against_itself_drives_alike_in_both_roles(tmp_path):
    report = run_regression(COUNTING, COUNTING, scenarios=["highway_lead_vehicle_brakes"], episodes=3, workers=1,
                            out_dir=tmp_path, env_config={"duration": 2}, stall_seconds=1, progress=False)
    assert report.to_dict()["errors"] == []
    for episode in report.to_dict()["episodes"]:  # each role's own instance has seen the same episodes before this one
        assert episode["candidate"]["trajectory_hash"] == episode["baseline"]["trajectory_hash"], episode["id"]


def test_which_role_runs_first_alternates_from_pair_to_pair():
    tasks = plan_tasks({"candidate": "rule", "baseline": "idm"}, ["a", "b"], [0, 1], env_config={}, bank_dir=None,
                       trace_dir=None)
    firsts = [tasks[i].role for i in range(0, len(tasks), 2)]
    assert firsts == ["candidate", "baseline", "candidate", "baseline"]
    assert all(tasks[i].scenario == tasks[i + 1].scenario and tasks[i].seed == tasks[i + 1].seed
               for i in range(0, len(tasks), 2))
