"""The builder of the external evaluation set (bench/evalsets/make_external_evalset.py): every shipped clip
(bench/evalsets/highway_env) has the hand-written label of the builder's script table and is what the builder
renders, the set holds other scalings, screens and stock traffic, and the builder refuses a script whose event
does not happen."""

import json

import pytest

from bench.evalsets import make_external_evalset as m
from bench.evalsets.make_external_evalset import EXTERNAL_EVALSET_DIR, SCRIPTS, VARIANTS, Scene, Script, \
    render_script
from dv2s_gym.pipeline.evaluate import VIDEO_SUFFIXES, collect_items
from scenario_bank.elements import Elements


def test_every_clip_has_its_hand_written_label():
    items = collect_items(EXTERNAL_EVALSET_DIR)
    assert len(items) >= 66
    by_stem = {item.stem: item for item in items}
    expected = {f"{s.name}_v{k}": s for s in SCRIPTS for k in VARIANTS}
    assert set(by_stem) == set(expected)
    for stem, script in expected.items():
        item = by_stem[stem]
        assert item.video and item.video.endswith(".webm"), stem
        label = json.loads((EXTERNAL_EVALSET_DIR / f"{stem}.label.json").read_text(encoding="utf-8"))
        assert label["elements"] == Elements.from_dict(script.elements).to_dict(), stem
        assert label["description"] == script.description and label["use_case"] == script.use_case
        assert label["env"] == script.env_id in ("highway-v0", "merge-v0", "intersection-v0", "roundabout-v0")
    # every video has a label, and the folder holds nothing but videos, labels and the README
    videos = {p.name.rsplit(".", 1)[0] for p in EXTERNAL_EVALSET_DIR.iterdir() if p.suffix in VIDEO_SUFFIXES}
    assert videos == set(expected)
    assert {p.suffix for p in EXTERNAL_EVALSET_DIR.iterdir()} == {".webm", ".json", ".md"}
    assert {s.env_id for s in SCRIPTS} == {"highway-v0", "merge-v0", "intersection-v0", "roundabout-v0"}


def test_stock_classes_scales_and_traffic_are_in_the_set():
    """The set holds other scalings and screens, stock traffic, a long vehicle and a roundabout with several
    vehicles; their labels say how they were rendered and name a truck where the script placed one."""
    scalings = {s.scaling for s in SCRIPTS}
    assert {3.5, 5.5, 8.0} <= scalings
    assert len({tuple(s.size) for s in SCRIPTS}) >= 4
    assert any(s.stock_traffic > 0 for s in SCRIPTS)
    truck = next(s for s in SCRIPTS if s.name == "cls_truck_lead_brakes")
    assert "truck" in truck.elements["participants"]
    rb = [s for s in SCRIPTS if s.env_id == "roundabout-v0" and s.elements["participants"].count("car") >= 2]
    assert rb
    for s in SCRIPTS:
        label = json.loads((EXTERNAL_EVALSET_DIR / f"{s.name}_v0.label.json").read_text(encoding="utf-8"))
        if (s.scaling, tuple(s.size), s.stock_traffic) != (5.5, (480, 480), 0):
            assert label["render"] == {"scaling": s.scaling, "screen": list(s.size),
                                       "stock_traffic": s.stock_traffic}, s.name
        else:
            assert "render" not in label, s.name


def test_stock_classes_are_drawn_in_highway_envs_own_colours(tmp_path):
    """The new scripts set no colour: highway-env picks it from the class (MDPVehicle green, LinearVehicle
    yellow, IDMVehicle blue); the ego of the cut-in script is highway-env's MDPVehicle."""
    import gymnasium as gym
    import highway_env  # noqa: F401
    from highway_env.vehicle.graphics import VehicleGraphics

    script = next(s for s in SCRIPTS if s.name == "cls_linear_cut_in")
    env = gym.make(script.env_id, render_mode="rgb_array", config=m._env_config(script))
    try:
        env.reset(seed=0)
        env.unwrapped.road.vehicles = []
        scene = script.scene(env.unwrapped, 0)
        colours = {type(v).__name__: VehicleGraphics.get_color(v) for v in env.unwrapped.road.vehicles}
    finally:
        env.close()
    assert type(scene.ego).__name__ == "MDPVehicle"
    assert colours == {"MDPVehicle": VehicleGraphics.GREEN, "LinearVehicle": VehicleGraphics.YELLOW,
                       "DefensiveVehicle": VehicleGraphics.YELLOW}


@pytest.mark.slow
@pytest.mark.parametrize("name", ["hw_cut_in_from_left", "stock_traffic_ego_lane_change"])
def test_shipped_clip_is_what_the_builder_renders(tmp_path, name):
    """Deterministic, also with highway-env's own (seeded) traffic and another scaling and screen."""
    from dv2s_gym.pipeline.video import read_video
    import numpy as np

    script = next(s for s in SCRIPTS if s.name == name)
    path = tmp_path / "clip.webm"
    result = render_script(script, 1, path)
    assert result["problem"] is None
    fresh = read_video(path, fps=None, max_frames=200).frames
    shipped = read_video(EXTERNAL_EVALSET_DIR / f"{name}_v1.webm", fps=None, max_frames=200).frames
    assert len(fresh) == len(shipped) == result["frames"]
    assert all(np.array_equal(a, b) for a, b in zip(fresh, shipped))


def test_builder_refuses_a_script_whose_event_does_not_happen():
    def no_cut_in(env, k):
        ego = m._car(env.road, ("0", "1", 1), 200.0, 22.0, ego=True)
        car = m._car(env.road, ("0", "1", 0), 206.0, 27.0)   # never told to change lanes
        return Scene(ego, {"cutter": car}, [],
                     lambda r: m._require(m._lane_ids(r, "cutter")[-1] == 1, "the car did not cut in"))

    script = Script("broken", "highway-v0", "cut_in", "", {"road": "highway"}, no_cut_in, seconds=2.0)
    assert render_script(script, 0)["problem"] == "the car did not cut in"

    def rear_end(env, k):
        ego = m._car(env.road, ("0", "1", 1), 200.0, 30.0, ego=True)
        ego.enable_lane_change, ego.DISTANCE_WANTED, ego.TIME_WANTED = False, 0.0, 0.0
        m._car(env.road, ("0", "1", 1), 204.0, 0.0, target_speed=0.0)
        return Scene(ego, {}, [], lambda r: None)

    crash = Script("crash", "highway-v0", "x", "", {"road": "highway"}, rear_end, seconds=2.0)
    assert render_script(crash, 0)["problem"].startswith("unscripted crash")
