"""An :class:`~scenario_bank.maps.opendrive_model.OpenDriveMap` written as OpenDRIVE XML, always in the same
order and number format (byte-identical output), with the writer's checks on the lanes and junctions it writes."""

from __future__ import annotations

import xml.etree.ElementTree as ET

from scenario_bank.maps.opendrive_model import (
    WidthPoly,
    format_float,
    Line,
    RoadMark,
    Lane,
    LaneSection,
    Road,
    Junction,
    OpenDriveMap,
    map_bounds,
)

__all__ = [
    "road_to_xml",
    "junction_to_xml",
    "map_to_xml",
]


# ---------------------------------------------------------------------------
# XML writing
# ---------------------------------------------------------------------------


def _sub(parent: ET.Element, tag: str, **attrs) -> ET.Element:
    """Append a child element; ``None`` attributes are left out, numbers formatted."""
    elem = ET.SubElement(parent, tag)
    for key, value in attrs.items():
        if value is None:
            continue
        key = key.rstrip("_")
        if isinstance(value, bool) or isinstance(value, str):
            elem.set(key, str(value).lower() if isinstance(value, bool) else value)
        elif isinstance(value, int):
            elem.set(key, str(value))
        else:
            elem.set(key, format_float(value))
    return elem


def _poly(parent: ET.Element, tag: str, s_key: str, s: float, coeffs: WidthPoly) -> None:
    a, b, c, d = coeffs
    _sub(parent, tag, **{s_key: float(s)}, a=float(a), b=float(b), c=float(c), d=float(d))


def _link_xml(parent: ET.Element, road: Road) -> None:
    if road.predecessor is None and road.successor is None:
        return
    link = _sub(parent, "link")
    for tag, target in (("predecessor", road.predecessor), ("successor", road.successor)):
        if target is None:
            continue
        _sub(
            link,
            tag,
            elementType=target.element_type,
            elementId=str(target.element_id),
            contactPoint=target.contact_point,
        )


def _plan_view_xml(parent: ET.Element, road: Road) -> None:
    plan_view = _sub(parent, "planView")
    for s, (x, y, hdg), seg in road.geometries():
        geom = _sub(plan_view, "geometry", s=s, x=x, y=y, hdg=hdg, length=seg.length)
        if isinstance(seg, Line):
            _sub(geom, "line")
        else:
            _sub(geom, "arc", curvature=seg.curvature)


def _road_mark_xml(parent: ET.Element, mark: RoadMark) -> None:
    _sub(
        parent,
        "roadMark",
        sOffset=0.0,
        type_=mark.type,
        weight="standard",
        color=mark.color,
        material="standard",
        width=mark.width,
        laneChange=mark.lane_change,
    )


def _lane_xml(parent: ET.Element, lane: Lane) -> None:
    elem = _sub(parent, "lane", id=str(lane.id), type_=lane.type, level=False)
    if lane.predecessor is not None or lane.successor is not None:
        link = _sub(elem, "link")
        if lane.predecessor is not None:
            _sub(link, "predecessor", id=str(lane.predecessor))
        if lane.successor is not None:
            _sub(link, "successor", id=str(lane.successor))
    width = lane.width if isinstance(lane.width, tuple) else (lane.width, 0.0, 0.0, 0.0)
    _poly(elem, "width", "sOffset", 0.0, width)
    _road_mark_xml(elem, lane.mark)


def _check_section(road: Road, section: LaneSection) -> None:
    left_ids = [lane.id for lane in section.left]
    right_ids = [lane.id for lane in section.right]
    if left_ids != list(range(1, len(left_ids) + 1)):
        raise AssertionError(f"road {road.id}: left lane ids must be 1..n, got {left_ids}")
    if right_ids != list(range(-1, -len(right_ids) - 1, -1)):
        raise AssertionError(f"road {road.id}: right lane ids must be -1..-n, got {right_ids}")


def _lanes_xml(parent: ET.Element, road: Road) -> None:
    lanes = _sub(parent, "lanes")
    _poly(lanes, "laneOffset", "s", 0.0, (0.0, 0.0, 0.0, 0.0))
    for section in road.sections:
        _check_section(road, section)
        sec = _sub(lanes, "laneSection", s=float(section.s))
        if section.left:
            left = _sub(sec, "left")
            for lane in reversed(section.left):  # outermost first, as in the spec
                _lane_xml(left, lane)
        center = _sub(sec, "center")
        center_lane = _sub(center, "lane", id="0", type_="none", level=False)
        _road_mark_xml(center_lane, section.center_mark)
        if section.right:
            right = _sub(sec, "right")
            for lane in section.right:
                _lane_xml(right, lane)


def road_to_xml(parent: ET.Element, road: Road) -> ET.Element:
    """Append the ``<road>`` element for ``road`` to ``parent``."""
    elem = _sub(
        parent,
        "road",
        name=road.name,
        length=road.length,
        id=str(road.id),
        junction=str(road.junction),
    )
    _link_xml(elem, road)
    road_type = _sub(elem, "type", s=0.0, type_=road.road_type)
    if road.speed_kmh is not None:
        _sub(road_type, "speed", max=road.speed_kmh, unit="km/h")
    _plan_view_xml(elem, road)
    elevation = _sub(elem, "elevationProfile")
    _poly(elevation, "elevation", "s", 0.0, (0.0, 0.0, 0.0, 0.0))
    lateral = _sub(elem, "lateralProfile")
    _poly(lateral, "superelevation", "s", 0.0, (0.0, 0.0, 0.0, 0.0))
    _lanes_xml(elem, road)
    return elem


def junction_to_xml(parent: ET.Element, junction: Junction) -> ET.Element:
    """Append the ``<junction>`` element for ``junction`` to ``parent``."""
    elem = _sub(parent, "junction", id=str(junction.id), name=junction.name)
    for index, conn in enumerate(junction.connections):
        c = _sub(
            elem,
            "connection",
            id=str(index),
            incomingRoad=str(conn.incoming),
            connectingRoad=str(conn.connecting),
            contactPoint=conn.contact,
        )
        for from_id, to_id in conn.lane_links:
            _sub(c, "laneLink", from_=str(from_id), to=str(to_id))
    return elem


def _check_map(odr: OpenDriveMap) -> None:
    road_ids = [road.id for road in odr.roads]
    if len(set(road_ids)) != len(road_ids):
        raise AssertionError(f"{odr.name}: duplicate road ids {road_ids}")
    roads = {road.id: road for road in odr.roads}
    for junction in odr.junctions:
        if junction.id == 0:
            raise AssertionError("junction id 0 is read as 'no junction' by Scenic")
        for conn in junction.connections:
            if roads[conn.connecting].junction != junction.id:
                raise AssertionError(
                    f"{odr.name}: road {conn.connecting} is not inside junction {junction.id}"
                )
            if conn.incoming not in roads:
                raise AssertionError(f"{odr.name}: unknown incoming road {conn.incoming}")


def map_to_xml(odr: OpenDriveMap) -> str:
    """Serialise a map to OpenDRIVE 1.4 XML text (deterministic)."""
    _check_map(odr)
    root = ET.Element("OpenDRIVE")
    north, south, east, west = map_bounds(odr.roads)
    _sub(
        root,
        "header",
        revMajor="1",
        revMinor="4",
        name=odr.name,
        version="1.0",
        north=north,
        south=south,
        east=east,
        west=west,
        vendor="dv2s-gym scenario_bank.maps.build_maps",
    )
    for road in odr.roads:
        road_to_xml(root, road)
    for junction in odr.junctions:
        junction_to_xml(root, junction)
    ET.indent(root, space="  ")
    body = ET.tostring(root, encoding="unicode", short_empty_elements=True)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + body + "\n"
