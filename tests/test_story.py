"""The story rule (dv2s_gym/story.py) and the baseline egos (policies/baselines.py)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from dv2s_gym.story import ego_collisions, required_elements, story_problem
from policies.baselines import IDMEgo, KeepLaneEgo
from policies.rule_based import FASTER, IDLE, SLOWER
from scenario_bank.elements import Elements

STORY = Elements.from_dict({
    "actions": [["car", "go_straight"], ["ego", "turn_left"]],
    "relations": [["car", "crossing_path", "ego"], ["car", "oncoming", "ego"]],
})


def test_ego_actions_are_required_only_of_the_scripts_own_ego():
    assert ("ego", "turn_left") in required_elements(STORY, "scenic")
    for ego in ("rule", "keep_lane", "idm"):
        assert required_elements(STORY, ego) == {("car", "go_straight"), ("car", "crossing_path", "ego"),
                                                 ("car", "oncoming", "ego")}


def test_story_problem_names_what_is_missing():
    shown = Elements(actions=(("car", "go_straight"),), relations=(("car", "oncoming", "ego"),))
    assert story_problem(STORY, shown, "idm") == "missing car crossing_path ego"
    shown = Elements(actions=shown.actions, relations=shown.relations + (("car", "crossing_path", "ego"),))
    assert story_problem(STORY, shown, "idm") is None
    assert story_problem(STORY, shown, "scenic") == "missing ego turn_left"


def test_a_collision_with_a_story_actor_counts_but_not_with_a_bystander():
    assert story_problem(STORY, Elements(), "rule", ego_hit=["car"]) is None
    assert story_problem(STORY, Elements(), "rule", ego_hit=["pedestrian"]) is not None


def test_ego_collisions_reads_the_kinds_of_what_the_ego_hit():
    trace = SimpleNamespace(kinds={}, events=[
        {"kind": "collision", "actors": ["ego", "Pedestrian1"]},
        {"kind": "collision", "actors": ["Car1", "Car2"]},
        {"kind": "lane_change", "actors": ["ego"]},
    ])
    assert ego_collisions(trace) == ["pedestrian"]


def _fake_env(ego_speed: float, leader_gap: float = None, leader_speed: float = 0.0, lateral: float = 0.0):
    ego = SimpleNamespace(position=np.array([0.0, 0.0]), heading=0.0, speed=ego_speed, LENGTH=5.0, WIDTH=2.0)
    others = [ego]
    if leader_gap is not None:
        others.append(SimpleNamespace(position=np.array([leader_gap + 5.0, lateral]), WIDTH=2.0, LENGTH=5.0,
                                      velocity=np.array([leader_speed, 0.0])))
    base = SimpleNamespace(vehicle=ego, steps=0, config={"action": {"type": "DiscreteMetaAction"}},
                           road=SimpleNamespace(vehicles=others, objects=[]))
    base.unwrapped = base
    return base


def test_keep_lane_ego_always_idles():
    driver = KeepLaneEgo(_fake_env(20.0, leader_gap=3.0))
    assert [driver() for _ in range(5)] == [IDLE] * 5


def test_keep_lane_ego_keeps_its_speed_in_a_real_episode():
    from envs.dv2s_env import DV2SEnv

    env = DV2SEnv(scenario="highway_truck_cut_in", config={"duration": 4, "ego_policy": "agent"})
    try:
        env.reset(seed=0)
        start = float(env.unwrapped.vehicle.speed)
        driver = KeepLaneEgo(env)
        speeds = []
        for _ in range(20):
            env.step(driver())
            speeds.append(float(env.unwrapped.vehicle.speed))
    finally:
        env.close()
    assert start % 5.0 > 0.2 and 5.0 - start % 5.0 > 0.2, "the scene should start off the 5 m/s grid"
    assert max(abs(v - start) for v in speeds) < 0.2


def test_idm_ego_brakes_for_a_close_slow_leader_and_ignores_the_next_lane():
    assert IDMEgo(_fake_env(20.0, leader_gap=8.0, leader_speed=5.0)).act() == SLOWER
    assert IDMEgo(_fake_env(20.0, leader_gap=8.0, leader_speed=5.0, lateral=3.5)).act() == IDLE
    assert IDMEgo(_fake_env(20.0)).act() == IDLE  # free road at its own desired speed
    assert IDMEgo(_fake_env(10.0), desired_speed=20.0).act() == FASTER
    assert math.isinf(IDMEgo._leader(_fake_env(20.0).vehicle, [])[0])


def test_baselines_refuse_other_action_types():
    env = _fake_env(20.0)
    env.config["action"]["type"] = "ContinuousAction"
    with pytest.raises(ValueError, match="DiscreteMetaAction"):
        IDMEgo(env)


@pytest.mark.slow
def test_cli_story_table_and_exit_code(tmp_path, capsys):
    """`dv2s bank validate --story`: 0 when every scenario plays its story, 1 (naming it, with the step it
    missed and a seed that shows it) when one does not."""
    import json
    import shutil

    from dv2s_gym.cli import main
    from scenario_bank import BANK_DIR

    bank = tmp_path / "bank"
    shutil.copytree(BANK_DIR / "highway_lead_vehicle_stopped", bank / "stopped")
    shutil.copytree(BANK_DIR / "highway_lead_vehicle_stopped", bank / "untold")
    for name in ("stopped", "untold"):
        meta = json.loads((bank / name / "meta.json").read_text())
        meta["name"] = name
        if name == "untold":  # a story step this script never plays
            meta["story"]["steps"].append({"actor": "stopped", "action": "turn_left"})
        (bank / name / "meta.json").write_text(json.dumps(meta))
    argv = ["bank", "--bank", str(bank), "validate", "--story", "--seeds", "2", "--egos", "keep_lane", "idm", "--"]
    assert main(argv[:-1] + ["--json", "--", "stopped"]) == 0
    data = json.loads(capsys.readouterr().out)
    assert data["table"]["stopped"]["idm"]["rate"] == 1.0 and data["under_threshold"] == []
    assert main(argv) == 1
    out = capsys.readouterr().out
    assert "under: untold" in out
    assert "missed stopped turn_left in 2/2 seeds, e.g. seed 0: not seen" in out
    assert main(argv + ["nosuch"]) == 2
    assert "unknown scenario 'nosuch'" in capsys.readouterr().err


def test_probe_egos_drive_as_their_docstrings_say():
    from policies.probe_drivers import HangbackEgo, RushEgo, SurgeEgo, WeaveEgo
    from policies.state_driver import LANE_LEFT, LANE_RIGHT

    # hangback: slows down from its start speed towards 60% of it
    assert HangbackEgo(_fake_env(20.0)).act() == SLOWER
    # rush: FASTER until its target is 10 m/s above its start speed, then holds it
    env = _fake_env(22.0)
    env.vehicle.target_speed = 22.0
    rush = RushEgo(env)
    actions = []
    for _ in range(4):
        actions.append(rush.act())
        if actions[-1] == FASTER:
            env.vehicle.target_speed = 5.0 * (env.vehicle.target_speed // 5.0 + 1)  # the next speed of the grid
    assert actions == [FASTER, FASTER, IDLE, IDLE] and env.vehicle.target_speed == 30.0
    # surge: IDLE until 3 s, FASTER on two steps, then IDLE
    env = _fake_env(20.0)
    surge = SurgeEgo(env)
    actions = []
    for step in range(25):
        env.time = step * 0.2
        actions.append(surge.act())
    assert actions == [IDLE] * 15 + [FASTER] * 2 + [IDLE] * 8
    # weave: left at 1 s, back right at 4 s; from the leftmost lane right at once instead, back left at 4 s
    for leftmost, expected in ((0, {5: LANE_LEFT, 20: LANE_RIGHT}), (1, {5: LANE_LEFT, 6: LANE_RIGHT, 20: LANE_LEFT})):
        env = _fake_env(20.0)
        env.vehicle.target_lane_index = ("a", "b", 1)
        weave = WeaveEgo(env)
        asked = {}
        for step in range(22):
            env.time = step * 0.2
            action = weave.act()
            if action != IDLE:
                asked[step] = action
                lane = env.vehicle.target_lane_index[2] + (-1 if action == LANE_LEFT else 1)
                if lane >= leftmost:  # highway-env leaves the target lane as it is when there is no lane there
                    env.vehicle.target_lane_index = ("a", "b", lane)
        assert asked == expected


def test_story_table_and_the_cli_refuse_an_unknown_ego(capsys):
    from dv2s_gym.cli import main
    from dv2s_gym.story import ALL_EGOS, EGOS, PROBE_EGOS, story_table

    assert set(PROBE_EGOS) == {"hangback", "rush", "surge", "weave"} and not set(PROBE_EGOS) & set(EGOS)
    assert ALL_EGOS == EGOS + tuple(PROBE_EGOS)
    with pytest.raises(ValueError, match="unknown ego.*nosuch.*choose from scenic"):
        story_table(["highway_lead_vehicle_stopped"], ["nosuch"], range(1), progress=False)
    assert main(["bank", "validate", "--story", "--egos", "keep_lane,nosuch", "--", "highway_lead_vehicle_stopped"]) == 2
    err = capsys.readouterr().err
    assert "unknown ego 'nosuch'" in err and "hangback" in err
