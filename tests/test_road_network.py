"""Tests for envs.road_network: Scenic road network -> highway-env RoadNetwork."""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest
from highway_env.road.lane import LineType, StraightLane
from highway_env.road.road import Road, RoadNetwork
from highway_env.vehicle.controller import ControlledVehicle

from envs.coordinates import (
    scenic_to_hw_heading,
    scenic_to_hw_position,
    wrap_angle,
)
from envs.errors import DV2SError
from envs.road_network import (
    ConvertedNetwork,
    IndexedRoadNetwork,
    MapLoadError,
    MapNotFoundError,
    PolylineLane,
    load_road_network,

)

ROOT = Path(__file__).resolve().parents[1]
CARLA = ROOT / "tests" / "data" / "maps" / "CARLA"
BANK = ROOT / "scenario_bank" / "maps"
DT = 1.0 / 15.0


# A hand-written OpenDRIVE road: 100 m line + 100 m arc, two lanes each way,
# and a third forward lane that only exists in the second lane section (it
# starts half-way along the lane group, like an acceleration lane).
pytestmark = pytest.mark.usefixtures("in_process_simulator")


def _synthetic_xodr() -> str:
    def lane(i: int, pred: int | None = None, succ: int | None = None) -> str:
        link = ""
        if pred is not None or succ is not None:
            link = "<link>"
            link += f'<predecessor id="{pred}"/>' if pred is not None else ""
            link += f'<successor id="{succ}"/>' if succ is not None else ""
            link += "</link>"
        return (
            f'<lane id="{i}" type="driving" level="false">{link}'
            '<width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane>'
        )

    hdg = 0.3
    x1, y1 = 100 * math.cos(hdg), 100 * math.sin(hdg)
    center = '<center><lane id="0" type="driving" level="false"/></center>'
    return f"""<?xml version="1.0" standalone="yes"?>
<OpenDRIVE>
<header revMajor="1" revMinor="4" name="synthetic" version="1.00" north="0" south="0" east="0" west="0"/>
<road name="r" length="200" id="1" junction="-1">
<link/>
<planView>
<geometry s="0" x="0" y="0" hdg="{hdg}" length="100"><line/></geometry>
<geometry s="100" x="{x1:.12f}" y="{y1:.12f}" hdg="{hdg}" length="100"><arc curvature="0.01"/></geometry>
</planView>
<lanes>
<laneSection s="0">
<left>{lane(2, succ=2)}{lane(1, succ=1)}</left>{center}
<right>{lane(-1, succ=-1)}{lane(-2, succ=-2)}</right>
</laneSection>
<laneSection s="100">
<left>{lane(2, pred=2)}{lane(1, pred=1)}</left>{center}
<right>{lane(-1, pred=-1)}{lane(-2, pred=-2)}{lane(-3)}</right>
</laneSection>
</lanes>
</road>
</OpenDRIVE>
"""


@pytest.fixture(scope="module")
def synthetic_map(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("maps") / "synthetic.xodr"
    path.write_text(_synthetic_xodr())
    return path


MAP_PATHS = [CARLA / "Town01.xodr", CARLA / "Town02.xodr"] + sorted(BANK.glob("*.xodr"))
MAP_IDS = [p.stem for p in MAP_PATHS]


@pytest.fixture(scope="module", params=MAP_PATHS + ["synthetic"], ids=MAP_IDS + ["synthetic"])
def converted(request, synthetic_map) -> ConvertedNetwork:
    path = synthetic_map if request.param == "synthetic" else request.param
    return load_road_network(path)


def _scenic_lanes(conv: ConvertedNetwork):
    return [conv.scenic_lane(index) for index in conv.scenic_lane_of]


def _sample_fractions(n: int = 9) -> np.ndarray:
    return np.linspace(0.05, 0.95, n)


# ---------------------------------------------------------------------------
# Structure
# ---------------------------------------------------------------------------


def test_every_scenic_lane_becomes_one_hw_lane(converted: ConvertedNetwork):
    net = converted.scenic_network
    hw_lanes = converted.hw_network.lanes_list()
    scenic_uids = {lane.uid for lane in net.lanes}
    maneuver_lanes = {
        m.connectingLane.uid
        for i in net.intersections
        for m in i.maneuvers
        if m.connectingLane is not None
    }
    connecting_road_lanes = {lane.uid for road in net.connectingRoads for lane in road.lanes}
    assert maneuver_lanes <= scenic_uids  # connecting lanes are listed in network.lanes
    assert connecting_road_lanes <= scenic_uids
    assert maneuver_lanes <= converted.connecting_lanes
    assert len(hw_lanes) == len(net.lanes) == len(scenic_uids)
    assert set(converted.lane_index_of) == scenic_uids
    assert len(set(converted.lane_index_of.values())) == len(scenic_uids)
    for uid, index in converted.lane_index_of.items():
        assert converted.scenic_lane_of[index] == uid
        assert converted.hw_network.get_lane(index) is converted.hw_lane(uid)
    assert isinstance(converted.hw_network, RoadNetwork)


def test_lengths_match_scenic_centerlines(converted: ConvertedNetwork):
    worst = 0.0
    for lane in _scenic_lanes(converted):
        expected = lane.centerline.length
        got = converted.hw_lane(lane).length
        worst = max(worst, abs(got - expected) / expected)
    assert worst < 0.01


def test_straight_lanes_use_straight_lane_class(converted: ConvertedNetwork):
    for lane in _scenic_lanes(converted):
        pts = np.asarray(lane.centerline.lineString.coords)[:, :2]
        chord = np.linalg.norm(pts[-1] - pts[0])
        hw_lane = converted.hw_lane(lane)
        if isinstance(hw_lane, StraightLane):
            assert abs(chord - lane.centerline.length) < 1e-3 * lane.centerline.length + 1e-6
        elif len(pts) == 2:  # a single segment is straight by definition...
            assert isinstance(hw_lane, PolylineLane) and hw_lane._width_s is not None  # ...unless tapering


def test_group_lanes_are_side_lanes_left_to_right(converted: ConvertedNetwork):
    net = converted.scenic_network
    hw = converted.hw_network
    for group in net.laneGroups:
        lanes = list(group.lanes)
        if len(lanes) < 2:
            continue
        edges = {converted.index_of(lane)[:2] for lane in lanes}
        assert edges == {converted.edge_of_group[group.uid]}
        ids = sorted(converted.index_of(lane)[2] for lane in lanes)
        assert ids == list(range(ids[0], ids[0] + len(ids)))  # contiguous in the edge
        edge = converted.edge_of_group[group.uid]
        for i in ids:
            index = (*edge, i)
            assert set(hw.all_side_lanes(index)) >= {(*edge, j) for j in ids}
            if i + 1 in ids:
                assert (*edge, i + 1) in hw.side_lanes(index)
                assert index in hw.side_lanes((*edge, i + 1))
                _assert_right_of(converted, (*edge, i), (*edge, i + 1))


def _assert_right_of(conv: ConvertedNetwork, left: tuple, right: tuple) -> None:
    """Lane ``right`` lies to the right of lane ``left`` in the driving direction."""
    left_hw = conv.hw_network.get_lane(left)
    right_hw = conv.hw_network.get_lane(right)
    left_sc, right_sc = conv.scenic_lane(left), conv.scenic_lane(right)
    lats = []
    for f in _sample_fractions():
        point_sc = right_sc.centerline.lineString.interpolate(f, normalized=True)
        lon, lat = left_hw.local_coordinates(scenic_to_hw_position(point_sc.x, point_sc.y))
        if not 0.0 <= lon <= left_hw.length:
            continue
        lats.append(lat)
        # Independent check in Scenic's own frame: right of the lane's direction.
        left_line = left_sc.centerline.lineString
        along = left_line.project(point_sc)
        nearest = left_line.interpolate(along)
        yaw = _chord_heading(left_line, along)
        forward = np.array([-math.sin(yaw), math.cos(yaw)])
        delta = np.array([point_sc.x - nearest.x, point_sc.y - nearest.y])
        assert forward[0] * delta[1] - forward[1] * delta[0] < 0.0  # cross < 0: to the right
    assert lats, f"lanes {left} and {right} do not overlap"
    # positive highway-env lateral = right of the driver; about one lane width away
    assert min(lats) > 0.5 and max(lats) < 2.5 * max(left_hw.width, right_hw.width)


def test_lane_zero_is_top_of_screen_when_driving_plus_x(converted: ConvertedNetwork):
    for edge in {converted.edge_of_group[g.uid] for g in converted.scenic_network.laneGroups}:
        lanes = converted.hw_network.graph[edge[0]][edge[1]]
        if len(lanes) < 2:
            continue
        mids = [lane.position(lane.length / 2, 0.0) for lane in lanes]
        headings = [lane.heading_at(lane.length / 2) for lane in lanes]
        for i in range(len(lanes) - 1):
            if abs(wrap_angle(headings[i])) < math.radians(30) and abs(wrap_angle(headings[i + 1])) < math.radians(30):
                assert mids[i][1] < mids[i + 1][1]


def test_line_types(converted: ConvertedNetwork):
    for uid in converted.connecting_lanes:
        assert list(converted.hw_lane(uid).line_types) == [LineType.NONE, LineType.NONE]
    for group in converted.scenic_network.laneGroups:
        ids = sorted(converted.index_of(lane)[2] for lane in group.lanes)
        edge = converted.edge_of_group[group.uid]
        if any(converted.is_connecting(lane) for lane in group.lanes):
            continue
        first = converted.hw_network.get_lane((*edge, ids[0]))
        last = converted.hw_network.get_lane((*edge, ids[-1]))
        assert first.line_types[0] == LineType.CONTINUOUS_LINE  # median / opposing side
        assert last.line_types[1] == LineType.CONTINUOUS_LINE  # curb side
        for i in ids[1:]:
            assert converted.hw_network.get_lane((*edge, i)).line_types[0] == LineType.STRIPED


def test_successors_are_connected_in_graph(converted: ConvertedNetwork):
    graph = converted.hw_network.graph
    linked = 0
    for lane in _scenic_lanes(converted):
        if not (lane.maneuvers or lane._successor is not None):
            continue
        _, to, _ = converted.index_of(lane)
        assert to in graph and graph[to], f"{lane.uid} has successors but its end node is a dead end"
        for nxt in converted.successors_of[lane.uid]:
            if converted.scenic_lane(converted.index_of(nxt)).group is lane.group:
                continue  # merge into a neighbour inside the group (not a graph link)
            assert converted.index_of(nxt)[0] == to
            linked += 1
    if converted.connecting_lanes:
        assert linked > 0
    for m in (m for i in converted.scenic_network.intersections for m in i.maneuvers):
        start, conn, end = (converted.index_of(x) for x in (m.startLane, m.connectingLane, m.endLane))
        assert start[1] == conn[0] and conn[1] == end[0]


def test_no_unrepresentable_links_on_these_maps(converted: ConvertedNetwork):
    assert converted.warnings == ()


def _chord_heading(line, s: float, half: float = 0.5) -> float:
    """Scenic heading of the centerline chord spanning s +- half."""
    a = line.interpolate(max(s - half, 0.0))
    b = line.interpolate(min(s + half, line.length))
    return math.atan2(-(b.x - a.x), b.y - a.y)  # Scenic: 0 = +y, counter-clockwise


def test_centerline_samples_map_onto_hw_lane(converted: ConvertedNetwork):
    worst_lat, worst_heading, samples, artifacts = 0.0, 0.0, 0, 0
    for lane in _scenic_lanes(converted):
        hw_lane = converted.hw_lane(lane)
        line = lane.centerline.lineString
        for f in _sample_fractions(15):
            s = f * line.length
            p = line.interpolate(s)
            pos = scenic_to_hw_position(p.x, p.y)
            lon, lat = hw_lane.local_coordinates(pos)
            worst_lat = max(worst_lat, abs(lat))
            assert abs(lon - s) < 0.05 * line.length + 0.5
            scenic_heading = lane.orientation[(p.x, p.y)].yaw
            samples += 1
            if abs(wrap_angle(scenic_heading - _chord_heading(line, s))) > math.radians(30):
                # Scenic's nearest-segment orientation on a centimetre-long seam
                # artifact of its centerline (it can point backwards); the hw lane
                # follows the local direction of the lane instead.
                artifacts += 1
                scenic_heading = _chord_heading(line, s)
            expected = scenic_to_hw_heading(scenic_heading)
            worst_heading = max(worst_heading, abs(wrap_angle(hw_lane.heading_at(lon) - expected)))
    assert worst_lat < 0.1
    assert worst_heading < math.radians(3)
    assert artifacts <= 0.02 * samples


def test_closest_lane_index_matches_highway_env(converted: ConvertedNetwork):
    hw = converted.hw_network
    assert isinstance(hw, IndexedRoadNetwork)
    lanes = hw.lanes_list()
    rng = np.random.default_rng(1)
    for k in range(150):
        lane = lanes[rng.integers(len(lanes))]
        pos = lane.position(rng.uniform(-10, lane.length + 10), rng.normal(0, 6))
        heading = None if k % 3 == 0 else rng.uniform(-math.pi, math.pi)
        fast = hw.get_closest_lane_index(pos, heading)
        slow = RoadNetwork.get_closest_lane_index(hw, pos, heading)
        if fast != slow:  # only acceptable for an exact tie
            d_fast = hw.get_lane(fast).distance_with_heading(pos, heading)
            d_slow = hw.get_lane(slow).distance_with_heading(pos, heading)
            assert d_fast == pytest.approx(d_slow, abs=1e-9)


def test_closest_lane_bounds_same_in_python_and_numpy(converted: ConvertedNetwork, monkeypatch):
    """Small networks bound lanes in plain Python, large ones with NumPy: the same bounds and lane."""
    import envs.road_network.lanes as lanes_module

    hw = converted.hw_network
    lanes = hw.lanes_list()
    rng = np.random.default_rng(2)
    points = []
    for _ in range(100):
        lane = lanes[rng.integers(len(lanes))]
        pos = lane.position(rng.uniform(-10, lane.length + 10), rng.normal(0, 6))
        points.append((pos, rng.uniform(-math.pi, math.pi)))
    hw.get_closest_lane_index(points[0][0])  # builds the index
    index = hw._closest_index
    monkeypatch.setattr(lanes_module, "_SMALL_NETWORK", 10**6)
    python = [(index.lower_bounds(*pos), hw.get_closest_lane_index(pos, h)) for pos, h in points]
    monkeypatch.setattr(lanes_module, "_SMALL_NETWORK", -1)
    numpy = [(index.lower_bounds(*pos), hw.get_closest_lane_index(pos, h)) for pos, h in points]
    for (b_py, lane_py), (b_np, lane_np) in zip(python, numpy):
        assert lane_py == lane_np
        assert sorted(k for _, k in b_py) == list(range(len(lanes)))
        by_lane = dict((k, b) for b, k in b_np)
        assert all(b == pytest.approx(by_lane[k], abs=1e-9) for b, k in b_py)


def test_polyline_lane_coordinates_round_trip():
    pts = [(0.0, 0.0), (10.0, 0.0), (17.0, 7.0), (17.0, 20.0), (5.0, 25.0)]
    lane = PolylineLane(pts, width=3.0)
    assert lane.length == pytest.approx(10 + math.hypot(7, 7) + 13 + 13)
    vertices = np.concatenate(([0.0], np.cumsum([10, math.hypot(7, 7), 13, 13])))
    for s in np.linspace(0.5, lane.length - 0.5, 40):
        near_vertex = np.min(np.abs(vertices - s)) < 2.0  # piecewise frames overlap there
        for r in (0.0,) if near_vertex else (-1.2, 0.0, 1.2):
            pos = lane.position(s, r)
            lon, lat = lane.local_coordinates(pos)
            assert lon == pytest.approx(s, abs=1e-6) and lat == pytest.approx(r, abs=1e-6)
    # extrapolates like StraightLane beyond both ends
    assert lane.local_coordinates(np.array([-4.0, 1.0])) == pytest.approx((-4.0, 1.0))
    end_lon, end_lat = lane.local_coordinates(np.array([5.0, 25.0]) + 2 * np.array([-12, 5]) / 13)
    assert end_lon == pytest.approx(lane.length + 2) and end_lat == pytest.approx(0.0, abs=1e-9)
    clone = PolylineLane.from_config(lane.to_config()["config"])
    assert clone.length == pytest.approx(lane.length)


# ---------------------------------------------------------------------------
# Driving a highway-env vehicle along converted lanes
# ---------------------------------------------------------------------------


def _drive(conv: ConvertedNetwork, start_uid: str, seconds: float, speed: float, seed: int = 0):
    """Drive a ControlledVehicle along a random Scenic route; check it stays on its lane."""
    rng = np.random.default_rng(seed)
    route = [start_uid]
    while len(route) < 400:
        options = conv.successors_of[route[-1]]
        if not options:
            break
        route.append(options[int(rng.integers(len(options)))])
    hw_route = conv.route_for(route)
    road = Road(network=conv.hw_network, np_random=np.random.default_rng(0), record_history=False)
    lane = conv.hw_lane(start_uid)
    vehicle = ControlledVehicle(
        road,
        lane.position(2.0, 0.0),
        lane.heading_at(2.0),
        speed=speed,
        target_lane_index=hw_route[0],
        target_speed=speed,
        route=list(hw_route),
    )
    road.vehicles.append(vehicle)
    targets, occupied, distance, worst = [hw_route[0]], set(), 0.0, 0.0
    for _ in range(int(round(seconds / DT))):
        road.act()
        before = vehicle.position.copy()
        road.step(DT)
        distance += float(np.linalg.norm(vehicle.position - before))
        if vehicle.target_lane_index != targets[-1]:
            targets.append(vehicle.target_lane_index)
        occupied.add(vehicle.lane_index)
        lon, lat = vehicle.lane.local_coordinates(vehicle.position)
        assert vehicle.on_road, f"left the road on {vehicle.lane_index} at {vehicle.position}"
        assert abs(lat) <= vehicle.lane.width_at(lon) / 2
        worst = max(worst, abs(lat))
        _, to, _ = vehicle.target_lane_index
        target = conv.hw_network.get_lane(vehicle.target_lane_index)
        if not conv.hw_network.graph.get(to) and target.local_coordinates(vehicle.position)[0] > target.length - 6.0:
            break  # end of the map
    return hw_route, targets, occupied, distance, worst


DRIVES = [  # map, start lane (index among candidates), speed, min lanes, min connecting lanes
    (CARLA / "Town01.xodr", 0, 10.0, 8, 3),
    (CARLA / "Town01.xodr", 37, 10.0, 8, 3),
    (CARLA / "Town02.xodr", 0, 10.0, 8, 3),
    (CARLA / "Town02.xodr", 21, 10.0, 8, 3),
    (BANK / "urban_crossroads.xodr", 0, 10.0, 3, 1),
]


@pytest.mark.parametrize(
    "map_path,start,speed,min_lanes,min_connecting",
    [pytest.param(*d, id=f"{d[0].stem}-{d[1]}") for d in DRIVES],
)
def test_vehicle_drives_through_intersections(map_path, start, speed, min_lanes, min_connecting):
    assert map_path.exists(), f"{map_path.name} is a shipped map and is missing"
    conv = load_road_network(map_path)
    starts = [
        lane.uid
        for lane in conv.scenic_network.lanes
        if not conv.is_connecting(lane) and conv.successors_of[lane.uid]
    ]
    route, targets, occupied, distance, worst = _drive(conv, starts[start % len(starts)], 60.0, speed=speed)
    n = min(len(route), len(targets))
    assert targets[:n] == route[:n]  # followed the planned route, lane by lane
    assert len(targets) >= min_lanes
    assert sum(conv.is_connecting(t) for t in targets) >= min_connecting
    assert distance > 100.0


def test_vehicle_merges_from_onramp_with_a_lane_change():
    """Ramp -> junction -> acceleration lane -> LANE_LEFT into the main road."""
    path = BANK / "highway_onramp.xodr"
    assert path.exists(), f"{path.name} is a shipped map and is missing"
    conv = load_road_network(path)
    hw = conv.hw_network
    # the ramp: a one-lane ordinary road whose connecting lane ends in a wider edge
    ramp = next(
        lane
        for lane in conv.scenic_network.lanes
        if not conv.is_connecting(lane)
        and len(hw.all_side_lanes(conv.index_of(lane))) == 1
        and conv.successors_of[lane.uid]
    )
    route = [conv.index_of(ramp)]
    while conv.next_lanes(route[-1]):
        route.append(conv.next_lanes(route[-1])[0])
    accel = route[-1]
    assert len(hw.all_side_lanes(accel)) >= 2 and accel[2] == len(hw.all_side_lanes(accel)) - 1
    road = Road(network=hw, np_random=np.random.default_rng(0), record_history=False)
    lane = hw.get_lane(route[0])
    vehicle = ControlledVehicle(
        road, lane.position(2.0, 0.0), lane.heading_at(2.0), speed=25.0,
        target_lane_index=route[0], target_speed=25.0, route=list(route),
    )
    road.vehicles.append(vehicle)
    targets = [route[0]]
    for _ in range(int(60 / DT)):
        action = None
        if vehicle.target_lane_index == accel and hw.get_lane(accel).local_coordinates(vehicle.position)[0] > 60:
            action = "LANE_LEFT"
        vehicle.act(action)
        road.step(DT)
        if vehicle.target_lane_index != targets[-1]:
            targets.append(vehicle.target_lane_index)
        lon, lat = vehicle.lane.local_coordinates(vehicle.position)
        assert vehicle.on_road and abs(lat) <= vehicle.lane.width_at(lon) / 2
        _, to, _ = vehicle.target_lane_index
        if not hw.graph.get(to) and hw.get_lane(vehicle.target_lane_index).local_coordinates(vehicle.position)[0] > hw.get_lane(vehicle.target_lane_index).length - 6:
            break
    assert targets[:3] == route[:3]
    assert targets[3] == (accel[0], accel[1], accel[2] - 1)  # the lane change, same edge
    assert not hw.graph.get(targets[-1][1])  # reached the last road of the map
    assert not conv.is_connecting(targets[-1]) and len(hw.all_side_lanes(targets[-1])) >= 2


# ---------------------------------------------------------------------------
# Loading, caching and bad input
# ---------------------------------------------------------------------------


def test_load_is_cached_until_the_file_changes(synthetic_map, tmp_path):
    first = load_road_network(synthetic_map)
    assert load_road_network(str(synthetic_map)) is first
    copy = tmp_path / "copy.xodr"
    copy.write_text(synthetic_map.read_text())
    other = load_road_network(copy)
    assert other is not first and other.source == copy.resolve()
    stat = copy.stat()
    os.utime(copy, ns=(stat.st_atime_ns, stat.st_mtime_ns + 10**9))
    reloaded = load_road_network(copy)
    assert reloaded is not other
    assert len(reloaded.hw_network.lanes_list()) == len(other.hw_network.lanes_list())


def test_missing_map_raises_file_not_found(tmp_path):
    missing = tmp_path / "nope" / "missing_map.xodr"
    with pytest.raises(FileNotFoundError) as info:
        load_road_network(missing)
    assert isinstance(info.value, MapLoadError) and isinstance(info.value, MapNotFoundError)
    assert "missing_map.xodr" in str(info.value)


@pytest.mark.parametrize(
    "content",
    [
        b"this is not xml at all \x00\xff",
        b"<?xml version='1.0'?><OpenDRIVE><road id='1' length='10'><planView>",
        b"<?xml version='1.0'?><OpenDRIVE><header/></OpenDRIVE>",
    ],
    ids=["garbage", "truncated", "empty"],
)
def test_corrupt_map_raises_map_load_error(tmp_path, content):
    bad = tmp_path / "corrupt.xodr"
    bad.write_bytes(content)
    with pytest.raises(MapLoadError) as info:
        load_road_network(bad)
    message = str(info.value)
    assert "corrupt.xodr" in message
    assert "OpenDRIVE" in message  # suggests what to check
    assert isinstance(info.value, ValueError) and isinstance(info.value, DV2SError)


def test_unknown_extension_raises_map_load_error(tmp_path):
    bad = tmp_path / "map.txt"
    bad.write_text("hello")
    with pytest.raises(MapLoadError, match="map.txt"):
        load_road_network(bad)


def _two_road_map(speed_on_second: str) -> str:
    """An OpenDRIVE map of two 200 m straight roads, one lane each way, side by side 50 m apart; the first gives no
    speed limit, the second ``speed_on_second`` (a road type's ``<speed>`` element)."""
    def road(number: int, y: float, speed: str) -> str:
        lane = '<lane id="{}" type="driving" level="false"><width sOffset="0" a="3.5" b="0" c="0" d="0"/></lane>'
        return (f'<road name="r{number}" length="200" id="{number}" junction="-1"><link/>'
                + (f'<type s="0" type="town">{speed}</type>' if speed else "")
                + f'<planView><geometry s="0" x="0" y="{y}" hdg="0" length="200"><line/></geometry></planView>'
                '<lanes><laneSection s="0"><left>' + lane.format(1)
                + '</left><center><lane id="0" type="driving" level="false"/></center><right>' + lane.format(-1)
                + "</right></laneSection></lanes></road>")

    return ('<?xml version="1.0" standalone="yes"?>\n<OpenDRIVE><header revMajor="1" revMinor="4" name="plain" '
            'version="1.00" north="0" south="0" east="0" west="0"/>' + road(1, 0.0, "") + road(2, 50.0, speed_on_second)
            + "</OpenDRIVE>\n")


def test_a_map_road_without_a_speed_limit_gets_20_m_s_in_the_env(tmp_path):
    """Most roads of real OpenDRIVE maps (CARLA's towns) give no speed limit: the env drives them at 20 m/s
    (highway-env's default), while a road that gives one keeps it (36 km/h here)."""
    (tmp_path / "plain.xodr").write_text(_two_road_map('<speed max="36" unit="km/h"/>'))
    script = tmp_path / "plain.scenic"
    script.write_text("param map = localPath('plain.xodr')\nmodel scenic.domains.driving.model\n"
                      "ego = new Car at (60, -1.75), with speed 5\n")
    import gymnasium as gym

    import dv2s_gym  # noqa: F401  (registers DV2S-v0)

    env = gym.make("DV2S-v0", scenario=str(script), config={"duration": 1.0})
    try:
        env.reset(seed=0)
        road = env.unwrapped.road
        graph = road.network.graph
        lanes = [lane for start in graph for end in graph[start] for lane in graph[start][end]]
        limits = sorted({round(float(lane.speed_limit), 6) for lane in lanes})
        assert len(lanes) == 4 and limits == [10.0, 20.0]
        ego = env.unwrapped.vehicle
        assert ego.lane.speed_limit == 20.0  # the ego is on the first road, which gives none
    finally:
        env.close()
