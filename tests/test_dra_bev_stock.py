"""The ``bev`` DRA on frames drawn by stock highway-env (rendered here, small): vehicles of every stock
class and colour are found, trucks are told by their size and not their hue, and the scale is measured
from the vehicles in view at several ``scaling`` values and screen sizes."""

import os

import numpy as np
import pytest

if os.environ.get("SDL_VIDEODRIVER", "dummy") == "dummy":
    os.environ["SDL_VIDEODRIVER"] = "offscreen"

from dv2s_gym.pipeline.dra.bev.detection import _detect_blobs
from dv2s_gym.pipeline.dra.bev.frames import _hsv
from dv2s_gym.pipeline.dra.bev.scale import body_scale, estimate_scale, is_long_vehicle

VEHICLE_KINDS = ("ego", "car", "truck", "yellow", "red")


def _stock_env(scaling, size):
    import gymnasium as gym
    import highway_env  # noqa: F401

    env = gym.make("highway-v0", render_mode="rgb_array",
                   config={"offscreen_rendering": True, "screen_width": size[0], "screen_height": size[1],
                           "scaling": scaling, "centering_position": [0.5, 0.5], "vehicles_count": 0, "initial_lane_id": 1,
                           "show_trajectories": False})
    env.reset(seed=0)
    return env


def _scene(env):
    """The stock MDPVehicle ego (lane 1) and one vehicle of each stock class around it, no colour set."""
    from highway_env.vehicle.behavior import AggressiveVehicle, DefensiveVehicle, IDMVehicle, LinearVehicle

    u = env.unwrapped
    road, ego = u.road, u.vehicle
    road.vehicles = [ego]
    s = ego.lane.local_coordinates(ego.position)[0]
    lane0 = ego.lane_index[:2]
    placed = {}
    for name, cls, lane, ds in [("linear", LinearVehicle, 0, 12.0), ("idm", IDMVehicle, 2, 10.0),
                                ("aggressive", AggressiveVehicle, 2, -12.0), ("defensive", DefensiveVehicle, 3, 4.0),
                                ("truck", IDMVehicle, 0, -14.0)]:
        v = cls.make_on_lane(road, (*lane0, lane), s + ds, speed=20.0)
        road.vehicles.append(v)
        placed[name] = v
    placed["truck"].LENGTH = 10.0
    return ego, placed


@pytest.fixture(scope="module", params=[(3.5, (320, 160)), (5.5, (320, 240)), (8.0, (400, 240))],
                ids=["scaling3.5", "scaling5.5", "scaling8"])
def rendered(request):
    scaling, size = request.param
    env = _stock_env(scaling, size)
    try:
        ego, placed = _scene(env)
        frame = np.ascontiguousarray(env.render()[..., :3])
        screen = env.unwrapped.viewer.sim_surface
        pix = {n: screen.pos2pix(*v.position) for n, v in {"ego": ego, **placed}.items()}
    finally:
        env.close()
    return scaling, frame, pix


def _nearest(blobs, xy):
    return min(blobs, key=lambda b: (b.x - xy[0]) ** 2 + (b.y - xy[1]) ** 2)


def test_every_stock_class_is_found_whatever_its_colour(rendered):
    scaling, frame, pix = rendered
    blobs = [b for b in _detect_blobs(frame, _hsv(frame)) if b.kind in VEHICLE_KINDS]
    assert len(blobs) == len(pix)          # ego, Linear, IDM, Aggressive, Defensive, the long IDM
    for name, xy in pix.items():
        b = _nearest(blobs, xy)
        # the centre of the coloured body: the lighter headlights are not part of it (0.36 m back at most)
        assert abs(b.x - xy[0]) < 0.6 * scaling and abs(b.y - xy[1]) < 0.6 * scaling, name
    kinds = {name: _nearest(blobs, xy).kind for name, xy in pix.items()}
    # highway-env's colours: MDPVehicle green, LinearVehicle and its subclasses yellow, IDMVehicle blue
    assert kinds["ego"] == "ego"
    assert kinds["linear"] == kinds["aggressive"] == kinds["defensive"] == "yellow"
    assert kinds["idm"] == kinds["truck"] == "car"


def test_scale_is_measured_from_the_vehicles_in_view(rendered):
    scaling, frame, pix = rendered
    blobs = [b for b in _detect_blobs(frame, _hsv(frame)) if b.kind in VEHICLE_KINDS]
    ego = _nearest(blobs, pix["ego"])
    others = [(b.length, b.width) for b in blobs if b is not ego]
    est = estimate_scale([(ego.length, ego.width)], others)
    assert est.px_per_m == pytest.approx(scaling, rel=0.08)
    assert est.samples == 5                # the ego and the four 5 m cars; the 10 m vehicle left out
    # trucks by size: the 10 m vehicle is long, the yellow LinearVehicle is not
    truck, linear = _nearest(blobs, pix["truck"]), _nearest(blobs, pix["linear"])
    assert is_long_vehicle(truck.length, est.common_length_px)
    assert not is_long_vehicle(linear.length, est.common_length_px)


def test_scale_follows_the_scaling_not_a_constant():
    # the same 5 m x 2 m body at two scalings gives scales in the same ratio
    a = body_scale(5 * 4.0 - 2, 2 * 4.0 - 2)
    b = body_scale(5 * 8.0 - 2, 2 * 8.0 - 2)
    assert b / a == pytest.approx(2.0, rel=0.01)
    with pytest.raises(ValueError, match="no ego vehicle"):
        estimate_scale([])


def test_crashed_stock_vehicle_is_found_in_its_red():
    env = _stock_env(5.5, (240, 160))
    try:
        ego, placed = _scene(env)
        placed["idm"].crashed = True       # highway-env draws a crashed vehicle without a colour in red
        frame = np.ascontiguousarray(env.render()[..., :3])
        xy = env.unwrapped.viewer.sim_surface.pos2pix(*placed["idm"].position)
    finally:
        env.close()
    b = _nearest(_detect_blobs(frame, _hsv(frame)), xy)
    assert b.kind == "red" and abs(b.x - xy[0]) < 0.6 * 5.5


@pytest.mark.slow
def test_analysis_reads_a_long_blue_vehicle_as_a_truck_and_a_yellow_one_as_a_car():
    from types import SimpleNamespace

    from dv2s_gym.pipeline.dra.bev.analyze import analyze_bev

    env = _stock_env(5.0, (320, 240))
    try:
        ego, placed = _scene(env)
        for v in [ego, *placed.values()]:
            v.speed, v.target_speed = 20.0, 20.0
        for v in placed.values():
            v.enable_lane_change = False
        frames = []
        for _ in range(12):
            frames.append(np.ascontiguousarray(env.render()[..., :3]))
            env.step(1)
    finally:
        env.close()
    clip = SimpleNamespace(frames=frames, times=np.arange(len(frames)) / 5.0, path=None)
    result = analyze_bev(clip)
    kinds = [t["kind"] for t in result.tracks]
    # one truck (the long blue IDMVehicle); the yellow Linear/Aggressive/Defensive and the blue IDM are cars
    # (a car leaving the view may be followed as two tracks)
    assert kinds.count("truck") == 1 and set(kinds) == {"car", "truck"} and kinds.count("car") >= 4, kinds
    assert result.debug["scale_px_per_m"] == pytest.approx(5.0, rel=0.08)
    assert result.debug["scale"]["vehicle_views"] >= 12
    # the lane lines' spacing at highway-env's 4 m lane width, measured beside it
    assert result.debug["scale"]["lane_px_per_m"] == pytest.approx(5.0, rel=0.03)
