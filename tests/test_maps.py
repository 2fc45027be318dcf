"""Tests for the shipped OpenDRIVE maps (scenario_bank/maps) and the map registry.

Every map is parsed once per module with Scenic's driving domain (2D) and the
parsed ``Network`` is shared between tests.
"""

from __future__ import annotations

import random
import shutil
import subprocess
import sys
import textwrap
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # allow plain `pytest` from any folder
    sys.path.insert(0, str(ROOT))

from scenario_bank.maps import (  # noqa: E402
    MAPS_DIR,
    UnknownMapError,
    list_maps,
    resolve_map,
)
from scenario_bank.maps import build_maps  # noqa: E402
from scenario_bank.maps.dimensions import ROUNDABOUT_ARM_START, ROUNDABOUT_RING_RADIUS  # noqa: E402
from scenario_bank.maps.opendrive_model import format_float  # noqa: E402

import scenic  # a core dependency: a broken install fails here
from scenic.domains.driving.roads import ManeuverType, Network  # noqa: E402

pytestmark = pytest.mark.usefixtures("in_process_simulator")

ALL_MAPS = [
    "highway_straight",
    "highway_onramp",
    "urban_two_way",
    "urban_parking",
    "urban_multilane",
    "urban_crossroads",
    "urban_t_junction",
    "urban_roundabout",
]
URBAN_MAPS = [name for name in ALL_MAPS if name.startswith("urban_")]
LANE_WIDTH = 3.5


@pytest.fixture(scope="module")
def network():
    """``network(name)`` -> parsed Scenic Network, cached for the module.

    Parse warnings are kept on the network as ``_test_warnings``.
    """
    cache = {}

    def load(name: str) -> Network:
        if name not in cache:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                net = Network.fromFile(
                    MAPS_DIR / f"{name}.xodr", useCache=False, writeCache=False
                )
            net._test_warnings = [str(w.message) for w in caught]
            cache[name] = net
        return cache[name]

    return load


def roads_by_name(net: Network):
    return {road.name: road for road in net.allRoads}


def lane_with_id(section, opendrive_id: int):
    return section.lanesByOpenDriveID[opendrive_id]


# ---------------------------------------------------------------------------
# Generator
# ---------------------------------------------------------------------------


def test_shipped_maps_are_the_generated_ones():
    assert list_maps() == sorted(ALL_MAPS)
    assert list(build_maps.MAP_BUILDERS) == ALL_MAPS


def test_generator_is_deterministic_and_committed_maps_are_current(tmp_path):
    first, second = tmp_path / "a", tmp_path / "b"
    assert build_maps.main(["--out", str(first)]) == 0
    # second run through the command line, as documented
    subprocess.run(
        [sys.executable, "-m", "scenario_bank.maps.build_maps", "--out", str(second)],
        cwd=ROOT,
        check=True,
        capture_output=True,
    )
    names = sorted(p.name for p in first.iterdir())
    assert names == sorted(f"{name}.xodr" for name in ALL_MAPS)
    assert sorted(p.name for p in second.iterdir()) == names
    for file_name in names:
        generated = (first / file_name).read_bytes()
        assert generated == (second / file_name).read_bytes(), file_name
        assert generated == (MAPS_DIR / file_name).read_bytes(), (
            f"{file_name} is out of date: run `python -m scenario_bank.maps.build_maps`"
        )


@pytest.mark.parametrize("name", ALL_MAPS)
def test_xodr_header_and_no_timestamp(name):
    text = (MAPS_DIR / f"{name}.xodr").read_text(encoding="utf-8")
    root = ET.fromstring(text)
    assert root.tag == "OpenDRIVE"
    header = root.find("header")
    assert header.get("revMajor") == "1" and header.get("revMinor") == "4"
    assert header.get("name") == name
    assert "date" not in header.attrib
    # only line and arc geometries, lane widths given for every lane
    for geometry in root.iter("geometry"):
        assert [child.tag for child in geometry] in (["line"], ["arc"])
    for lane in root.iter("lane"):
        if lane.get("id") != "0":
            assert lane.find("width") is not None


def test_format_float_is_stable():
    f = format_float
    assert f(0.0) == f(-0.0) == f(1e-12) == f(-1e-12) == "0"
    assert f(2000.0) == "2000"
    assert f(-10.5) == "-10.5"
    assert f(1.0 / 12.0) == "0.0833333333333"
    assert float(f(2 * 3.5 / 80**3)) == pytest.approx(2 * 3.5 / 80**3, rel=1e-11)
    with pytest.raises(ValueError):
        f(float("nan"))


# ---------------------------------------------------------------------------
# Scenic parsing
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("name", ALL_MAPS)
def test_map_parses_in_scenic_without_warnings(network, name):
    net = network(name)
    assert net._test_warnings == []
    assert net.roads and net.lanes
    assert not net.drivableRegion.polygons.is_empty
    for lane in net.lanes:
        # every lane is a real strip, not a sliver
        assert lane.polygon.area > 10.0, lane.uid


def test_highway_straight(network):
    net = network("highway_straight")
    assert len(net.roads) == 1 and not net.connectingRoads and not net.intersections
    (road,) = net.roads
    assert len(road.lanes) == 4
    assert len(road.forwardLanes.lanes) == 4 and road.backwardLanes is None
    assert sorted(road.sections[0].lanesByOpenDriveID) == [-4, -3, -2, -1]
    assert road.centerline.length >= 2000.0
    assert road.centerline.length == pytest.approx(2000.0, rel=0.01)
    for lane in road.lanes:
        assert lane.centerline.length == pytest.approx(2000.0, rel=0.01)
        assert lane.polygon.area / lane.centerline.length == pytest.approx(LANE_WIDTH, rel=0.01)
        assert lane.centerline[0].x < lane.centerline[-1].x  # drives along +x
        assert abs(lane.centerline[0].y - lane.centerline[-1].y) < 1e-6  # straight
    assert len(net.shoulders) == 1 and not net.sidewalks


def test_highway_onramp_lanes_and_links(network):
    net = network("highway_onramp")
    roads = roads_by_name(net)
    before, merge, after, ramp = (
        roads["highway_before"],
        roads["highway_merge"],
        roads["highway_after"],
        roads["onramp"],
    )
    assert len(net.roads) == 4 and len(net.connectingRoads) == 2
    assert len(before.lanes) == 3 and len(after.lanes) == 3 and len(ramp.lanes) == 1
    assert len(merge.lanes) == 4
    total = before.centerline.length + merge.centerline.length + after.centerline.length
    total += roads["highway_through_junction"].centerline.length  # inside the junction
    assert total == pytest.approx(1500.0, rel=0.01)

    # merge road: 3 through lanes + acceleration lane (-4) for ~250 m, then taper
    accel_sec, taper_sec = merge.sections
    assert sorted(accel_sec.lanesByOpenDriveID) == [-4, -3, -2, -1]
    accel = lane_with_id(accel_sec, -4)
    rightmost = lane_with_id(accel_sec, -3)
    assert accel.centerline.length == pytest.approx(250.0, rel=0.02)
    assert accel._laneToLeft is rightmost and accel._laneToRight is None
    assert accel.lane in rightmost.lane.group.lanes
    assert accel.lane.group is merge.forwardLanes
    assert rightmost.lane in accel.lane.adjacentLanes
    assert accel.polygon.area / accel.centerline.length == pytest.approx(LANE_WIDTH, rel=0.02)
    taper = lane_with_id(taper_sec, -4)
    assert taper.lane is accel.lane  # one Scenic lane through both sections
    assert taper.polygon.area == pytest.approx(LANE_WIDTH * 80.0 / 2, rel=0.05)
    assert accel.lane._successor is None  # the acceleration lane ends
    for lane_id in (-1, -2, -3):  # through lanes continue into road 3
        assert lane_with_id(taper_sec, lane_id).lane.successor.road is after

    # the ramp lane leads through the junction into the acceleration lane
    (ramp_lane,) = ramp.lanes
    (maneuver,) = ramp_lane.maneuvers
    assert maneuver.endLane is accel.lane
    assert maneuver.type is ManeuverType.STRAIGHT
    assert ramp_lane.successor is maneuver.connectingLane
    assert ramp_lane.successor.successor is accel.lane
    assert ramp_lane.successor.road in net.connectingRoads
    (junction,) = net.intersections
    assert maneuver.intersection is junction
    assert len(junction.maneuvers) == 4
    # the three main-line lanes continue straight into the same lanes of road 2
    through = {lane_with_id(accel_sec, i).lane for i in (-1, -2, -3)}
    for lane in before.lanes:
        (m,) = lane.maneuvers
        assert m.endLane in through and m.type is ManeuverType.STRAIGHT


def test_urban_two_way(network):
    net = network("urban_two_way")
    (road,) = net.roads
    assert len(road.forwardLanes.lanes) == 1 and len(road.backwardLanes.lanes) == 1
    assert road.centerline.length == pytest.approx(600.0, rel=0.01)
    forward, backward = road.forwardLanes.lanes[0], road.backwardLanes.lanes[0]
    assert forward.centerline[0].x < forward.centerline[-1].x
    assert backward.centerline[0].x > backward.centerline[-1].x
    assert len(net.sidewalks) == 2
    for sidewalk in net.sidewalks:
        assert sidewalk.polygon.area == pytest.approx(2.0 * 600.0, rel=0.01)


def test_urban_multilane(network):
    """Two lanes per direction: same-direction neighbours are side lanes, the inner lanes border each other
    across the centre line, and both directions have a sidewalk at the kerb."""
    net = network("urban_multilane")
    (road,) = net.roads
    assert not net.connectingRoads and not net.intersections
    forward, backward = road.forwardLanes.lanes, road.backwardLanes.lanes
    assert len(forward) == 2 and len(backward) == 2 and len(net.lanes) == 4
    assert road.centerline.length == pytest.approx(600.0, rel=0.01)
    for lane in forward:
        assert lane.centerline[0].x < lane.centerline[-1].x
        assert lane.polygon.area / lane.centerline.length == pytest.approx(LANE_WIDTH, rel=0.01)
    for lane in backward:
        assert lane.centerline[0].x > lane.centerline[-1].x
    for group in (forward, backward):
        inner = next(lane for lane in group if lane.sections[0]._laneToRight is not None)
        outer = next(lane for lane in group if lane is not inner)
        assert inner.sections[0]._laneToRight.lane is outer
        assert outer.sections[0]._laneToLeft.lane is inner
        assert outer.sections[0]._laneToRight is None  # the kerb
        across = inner.sections[0]._laneToLeft  # the inner lane of the other direction
        assert across is not None and across.isForward != inner.sections[0].isForward
        # the inner lane lies next to the centre line, the outer one at the kerb
        assert abs(inner.centerline[0].y) == pytest.approx(LANE_WIDTH / 2)
        assert abs(outer.centerline[0].y) == pytest.approx(1.5 * LANE_WIDTH)
    assert len(net.sidewalks) == 2
    for sidewalk in net.sidewalks:
        assert sidewalk.polygon.area == pytest.approx(2.0 * 600.0, rel=0.01)


def test_urban_multilane_in_highway_env():
    """The env's road conversion gives one highway-env edge per direction, two lanes each, at town speed."""
    from envs.road_network import load_road_network

    converted = load_road_network(str(MAPS_DIR / "urban_multilane.xodr"))
    graph = converted.hw_network.graph
    edges = [(a, b) for a in graph for b in graph[a]]
    assert len(edges) == 2
    for a, b in edges:
        lanes = graph[a][b]
        assert len(lanes) == 2
        for lane in lanes:
            assert lane.speed_limit == pytest.approx(50 / 3.6, rel=1e-3)


def _check_junction_map(net, n_arms):
    assert len(net.roads) == n_arms
    for road in net.roads:
        assert len(road.forwardLanes.lanes) == 1 and len(road.backwardLanes.lanes) == 1
        assert road.centerline.length == pytest.approx(150.0, rel=0.01)
    (junction,) = net.intersections
    assert len(junction.roads) == n_arms
    n_moves = n_arms * (n_arms - 1)
    assert len(net.connectingRoads) == n_moves
    assert len(junction.maneuvers) == n_moves
    assert len(junction.incomingLanes) == n_arms and len(junction.outgoingLanes) == n_arms
    for maneuver in junction.maneuvers:
        # connecting roads are named <from>_to_<to>_<left|straight|right>
        kind = maneuver.connectingLane.road.name.rsplit("_", 1)[1]
        expected = {
            "left": ManeuverType.LEFT_TURN,
            "straight": ManeuverType.STRAIGHT,
            "right": ManeuverType.RIGHT_TURN,
        }[kind]
        assert maneuver.type is expected, maneuver.connectingLane.road.name
        assert maneuver.startLane.road is not maneuver.endLane.road
        # (a lane with several maneuvers keeps only one as its `successor`)
        assert maneuver.connectingLane.predecessor is maneuver.startLane
        assert maneuver.connectingLane.successor is maneuver.endLane
        assert maneuver.intersection is junction
    assert len(net.sidewalks) == 2 * n_arms
    assert not net.sidewalkRegion.polygons.is_empty
    return junction


def test_urban_crossroads(network):
    junction = _check_junction_map(network("urban_crossroads"), 4)
    assert junction.is4Way
    types = [m.type for m in junction.maneuvers]
    for kind in (ManeuverType.LEFT_TURN, ManeuverType.STRAIGHT, ManeuverType.RIGHT_TURN):
        assert types.count(kind) == 4
    for lane in junction.incomingLanes:
        assert sorted(m.type.name for m in lane.maneuvers) == [
            "LEFT_TURN",
            "RIGHT_TURN",
            "STRAIGHT",
        ]


def test_urban_t_junction(network):
    junction = _check_junction_map(network("urban_t_junction"), 3)
    assert junction.is3Way
    types = [m.type for m in junction.maneuvers]
    for kind in (ManeuverType.LEFT_TURN, ManeuverType.STRAIGHT, ManeuverType.RIGHT_TURN):
        assert types.count(kind) == 2


def test_urban_roundabout(network):
    """Four two-way arms into one single-lane ring, driven counter-clockwise; every entry-to-exit movement
    (first, second, third exit) is a maneuver whose path runs on the ring around the central island."""
    net = network("urban_roundabout")
    junction = _check_junction_map(net, 4)
    assert len(junction.maneuvers) == 12
    types = [m.type for m in junction.maneuvers]
    for kind in (ManeuverType.LEFT_TURN, ManeuverType.STRAIGHT, ManeuverType.RIGHT_TURN):
        assert types.count(kind) == 4
    ring_radius = ROUNDABOUT_RING_RADIUS
    for maneuver in junction.maneuvers:
        kind = maneuver.connectingLane.road.name  # <from>_to_<to>_<first|second|third>_exit_<kind>
        points = np.array([(p[0], p[1]) for p in maneuver.connectingLane.centerline])
        radii = np.hypot(points[:, 0], points[:, 1])
        # never over the central island; on the ring (lane centre 1.75 m outside the island) part of the way
        assert radii.min() == pytest.approx(ring_radius + LANE_WIDTH / 2, abs=0.05), kind
        # counter-clockwise: the angle about the centre only grows along the path
        angles = np.unwrap(np.arctan2(points[:, 1], points[:, 0]))
        assert np.all(np.diff(angles) > -0.01), kind  # (Scenic leaves cm-long seams between geometries)
        exits = {"right": 1, "straight": 2, "left": 3}[kind.rsplit("_", 1)[1]]
        # from the inbound lane of one arm to the outbound lane of the next, 1.75 m off each arm's axis
        offset = 2 * np.arctan2(LANE_WIDTH / 2, ROUNDABOUT_ARM_START)
        assert angles[-1] - angles[0] == pytest.approx(exits * np.pi / 2 - offset, abs=0.02), kind
    # a circulating path shares the ring with the entry of every arm it passes (Scenic's conflictingManeuvers
    # counts centre lines that cross, which paths merging into the same ring do not always do)
    by_name = {m.connectingLane.road.name: m for m in junction.maneuvers}
    entering = by_name["north_to_west_first_exit_right"].connectingLane.polygon
    circulating = by_name["east_to_south_third_exit_left"].connectingLane.polygon  # passes the north arm
    assert entering.intersection(circulating).area > 20.0
    assert by_name["south_to_east_first_exit_right"].connectingLane.polygon.intersection(entering).area == 0.0


@pytest.mark.parametrize("name", URBAN_MAPS)
def test_urban_maps_have_sidewalks(network, name):
    net = network(name)
    assert net.sidewalks
    assert net.sidewalkRegion.polygons.area > 100.0
    assert not net.sidewalkRegion.polygons.intersects(net.laneRegion.polygons.buffer(-0.1))


# ---------------------------------------------------------------------------
# Scenic scenarios
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("name", ALL_MAPS)
def test_scenario_samples_cars_and_pedestrians(network, name, tmp_path):
    pedestrian = "ped = new Pedestrian on sidewalk\n" if name in URBAN_MAPS else ""
    program = tmp_path / f"{name}.scenic"
    program.write_text(
        textwrap.dedent(
            f"""\
            param map = r'{MAPS_DIR / (name + '.xodr')}'
            param map_options = dict(useCache=False, writeCache=False)
            model scenic.simulators.newtonian.driving_model
            ego = new Car on road
            other = new Car on road
            """
        )
        + pedestrian
    )
    random.seed(0)
    np.random.seed(0)
    scenario = scenic.scenarioFromFile(str(program), mode2D=True)
    scene, _ = scenario.generate(maxIterations=2000)
    net = network(name)
    cars = [obj for obj in scene.objects if type(obj).__name__ == "Car"]
    peds = [obj for obj in scene.objects if type(obj).__name__ == "Pedestrian"]
    assert len(cars) == 2
    assert len(peds) == (1 if pedestrian else 0)
    for car in cars:
        assert net.drivableRegion.containsPoint(car.position)  # `road` in Scenic
    for ped in peds:
        assert net.sidewalkRegion.containsPoint(ped.position)


# ---------------------------------------------------------------------------
# resolve_map
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("name", ALL_MAPS)
def test_resolve_map_by_name(name):
    path = resolve_map(name)
    assert path == MAPS_DIR / f"{name}.xodr"
    assert path.is_absolute() and path.is_file()


def test_resolve_map_by_path(tmp_path, monkeypatch):
    copy = tmp_path / "my map.xodr"
    shutil.copyfile(MAPS_DIR / "urban_two_way.xodr", copy)
    assert resolve_map(copy) == copy.resolve()
    assert resolve_map(str(copy)) == copy.resolve()
    monkeypatch.chdir(tmp_path)
    assert resolve_map("my map.xodr") == copy.resolve()
    assert resolve_map("./my map.xodr") == copy.resolve()
    # a shipped name wins over a same-named file in the working directory
    (tmp_path / "highway_straight").write_text("not a map")
    assert resolve_map("highway_straight") == MAPS_DIR / "highway_straight.xodr"


def test_resolve_map_unknown_name_suggests_near_match():
    with pytest.raises(UnknownMapError) as info:
        resolve_map("highway_strait")
    assert isinstance(info.value, ValueError)
    message = str(info.value)
    assert "highway_strait" in message
    assert "Did you mean 'highway_straight'" in message
    for name in ALL_MAPS:
        assert name in message
    assert ".xodr" in message


def test_resolve_map_unknown_name_without_near_match():
    with pytest.raises(UnknownMapError, match="Available maps: highway_onramp"):
        resolve_map("moon_base")


def test_resolve_map_missing_path(tmp_path, monkeypatch):
    with pytest.raises(FileNotFoundError, match="does not exist"):
        resolve_map(tmp_path / "missing.xodr")
    with pytest.raises(FileNotFoundError, match="does not exist"):
        resolve_map(str(tmp_path / "nested" / "missing.xodr"))
    monkeypatch.chdir(tmp_path)
    with pytest.raises(FileNotFoundError, match="short name 'urban_crossroads'"):
        resolve_map("urban_crossroads.xodr")


def test_resolve_map_rejects_other_files(tmp_path):
    other = tmp_path / "notes.txt"
    other.write_text("hello")
    with pytest.raises(ValueError, match=r"\.xodr"):
        resolve_map(other)
    with pytest.raises(FileNotFoundError):
        resolve_map(tmp_path)  # a folder is not a map file
    with pytest.raises(TypeError):
        resolve_map(42)


def test_scenario_bank_is_the_bottom_layer():
    code = (
        "import sys, scenario_bank, scenario_bank.maps, scenario_bank.maps.build_maps\n"
        "bad = sorted(m for m in sys.modules"
        " if m.split('.')[0] in {'envs', 'dv2s_gym', 'policies', 'bench'})\n"
        "print(bad)\n"
        "assert not bad, bad\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True
    )
    assert result.returncode == 0, result.stdout + result.stderr
