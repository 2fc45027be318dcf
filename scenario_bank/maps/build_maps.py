"""Deterministic generator for the OpenDRIVE maps shipped in this folder.

Run ``python -m scenario_bank.maps.build_maps [--out DIR]`` to (re)write every
map as ``<name>.xodr``; the default output folder is the one this file lives in.
The output is byte-identical on every run: there are no timestamps, floats are
printed with a fixed format, and elements and attributes are always written in
the same order.

All maps use a local metric frame (x east, y north, metres; OpenDRIVE headings
in radians counter-clockwise from +x) and right-hand traffic: lanes with
negative ids (right of the reference line) drive along increasing ``s``.

The maps are written for Scenic's OpenDRIVE parser
(``scenic.formats.opendrive.xodr_parser``), so they stick to what it handles:

* the plan view uses only ``line`` and ``arc`` geometries;
* roads that meet a junction carry no lane links at that end; the junction's
  ``laneLink`` entries and the connecting roads' own lane links connect them;
* every connecting road starts at its incoming road (``contactPoint="start"``)
  and has a single right lane (-1), so Scenic turns it into one maneuver;
* junction ids are non-zero (Scenic treats a junction id of 0 as "no junction").

The model and its XML are in :mod:`scenario_bank.maps.opendrive_model` and
:mod:`scenario_bank.maps.opendrive_xml`, the shared parts in :mod:`scenario_bank.maps.road_parts`, the maps in
:mod:`scenario_bank.maps.highway_maps` and :mod:`scenario_bank.maps.urban_maps`.

Maps:

``highway_straight``
    2000 m, one direction, 4 driving lanes (-1..-4) along +x, with a median
    strip on the left and a shoulder and border on the right.
``highway_onramp``
    1500 m, one direction, 3 driving lanes. Road 1 (before) and the ramp
    (road 4) meet in junction 10; both continue into road 2 (merge), whose first
    lane section has a 4th, acceleration lane (-4) for 250 m, which then tapers
    to zero width and ends. Road 3 (after) continues with 3 lanes.
``urban_two_way``
    600 m two-way road, one 3.5 m driving lane per direction and a 2 m sidewalk
    on each side.
``urban_parking``
    600 m two-way town street, one 3.5 m driving lane per direction, a 2.5 m
    parking lane (OpenDRIVE type ``parking``) at each kerb and a 2 m sidewalk
    beyond it.
``urban_multilane``
    600 m two-way town street, two 3.5 m driving lanes per direction (broken
    white line between same-direction lanes, solid double yellow centre line)
    and a 2 m sidewalk on each side.
``urban_crossroads``
    Four 150 m two-way arms with sidewalks meeting in junction 100, which holds
    12 connecting roads (left, straight and right from every incoming lane).
``urban_t_junction``
    Three 150 m two-way arms with sidewalks meeting in junction 100, which holds
    6 connecting roads (every movement except U-turns).
``urban_roundabout``
    Single-lane roundabout (ring lane 3.5 m wide around a 12 m central island,
    driven counter-clockwise) with four 150 m two-way arms with sidewalks, all
    in junction 100: 12 connecting roads, one per entry and exit (first, second
    and third exit), each an entry curve, part of the ring and an exit curve.
"""

from __future__ import annotations

import argparse
import pathlib
import sys
from typing import Callable, Dict, List, Optional, Sequence, Union

from scenario_bank.maps.opendrive_model import OpenDriveMap
from scenario_bank.maps.opendrive_xml import map_to_xml
from scenario_bank.maps.highway_maps import build_highway_straight, build_highway_onramp
from scenario_bank.maps.urban_maps import (
    build_urban_two_way,
    build_urban_parking,
    build_urban_multilane,
    build_urban_crossroads,
    build_urban_t_junction,
    build_urban_roundabout,
)

__all__ = [
    "DEFAULT_OUT_DIR",
    "MAP_BUILDERS",
    "write_maps",
    "main",
]


DEFAULT_OUT_DIR = pathlib.Path(__file__).resolve().parent

MAP_BUILDERS: Dict[str, Callable[[], OpenDriveMap]] = {
    "highway_straight": build_highway_straight,
    "highway_onramp": build_highway_onramp,
    "urban_two_way": build_urban_two_way,
    "urban_parking": build_urban_parking,
    "urban_multilane": build_urban_multilane,
    "urban_crossroads": build_urban_crossroads,
    "urban_t_junction": build_urban_t_junction,
    "urban_roundabout": build_urban_roundabout,
}
"""Map name -> builder, in the order the maps are written."""


# ---------------------------------------------------------------------------
# Entry point
# ---------------------------------------------------------------------------


def write_maps(out_dir: Union[str, pathlib.Path] = DEFAULT_OUT_DIR) -> List[pathlib.Path]:
    """Write every map to ``out_dir/<name>.xodr`` and return the paths."""
    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, builder in MAP_BUILDERS.items():
        odr = builder()
        assert odr.name == name, (odr.name, name)
        path = out / f"{name}.xodr"
        with open(path, "w", encoding="utf-8", newline="\n") as f:
            f.write(map_to_xml(odr))
        paths.append(path)
    return paths


def main(argv: Optional[Sequence[str]] = None) -> int:
    """Command-line entry point."""
    parser = argparse.ArgumentParser(
        prog="python -m scenario_bank.maps.build_maps",
        description="Write the shipped OpenDRIVE maps (deterministic output).",
    )
    parser.add_argument(
        "--out",
        type=pathlib.Path,
        default=DEFAULT_OUT_DIR,
        help=f"output folder (default: {DEFAULT_OUT_DIR})",
    )
    args = parser.parse_args(argv)
    for path in write_maps(args.out):
        print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
