"""The shipped bank against the NHTSA pre-crash typology (scenario_bank/README.md), and the actor-bound
story blocks of the sidecars that have one.

Fast tests: the README's typology table has one row per type 1..37, each naming bank scenarios that exist
or saying why the type is left out; every story block names actors the script names (``with name``) and
speaks the element vocabulary.

Slow tests (``-m slow``): the point of some typology scenarios, read off the trajectories with the
constant-speed ego (which never gets out of the way): the manoeuvre happens in front of the ego.
"""

from __future__ import annotations

import json
import math
import re
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:  # allow plain `pytest` from any folder
    sys.path.insert(0, str(ROOT))

from scenario_bank import BANK_DIR, list_scenarios  # noqa: E402
from scenario_bank.elements import ACTIONS, PARTICIPANTS, RELATIONS  # noqa: E402

README = ROOT / "scenario_bank" / "README.md"
NAMES = list_scenarios()
WITH_STORY = [n for n in NAMES if "story" in json.loads((BANK_DIR / n / "meta.json").read_text(encoding="utf-8"))]


def typology_rows():
    """``{type number: cell text}`` of the README's typology table."""
    rows = {}
    for line in README.read_text(encoding="utf-8").splitlines():
        match = re.match(r"^\| (\d+) \| [^|]+ \| (.+) \|$", line)
        if match:
            number = int(match.group(1))
            assert number not in rows, f"type {number} listed twice"
            rows[number] = match.group(2)
    return rows


def test_the_readme_lists_every_type_of_the_typology_once():
    assert sorted(typology_rows()) == list(range(1, 38))


def test_every_type_names_existing_scenarios_or_says_why_not():
    for number, cell in typology_rows().items():
        left_out = cell.startswith(("left out:", "not yet covered:"))
        named = re.findall(r"`([a-z0-9_]+)`", cell)
        if left_out:
            assert len(cell) > 40, f"type {number} says it is left out without saying why"
            # a left-out type may point at the scenarios nearest to it (and name other things in code style)
            named = [n for n in named if n.startswith(("highway_", "urban_"))]
        else:
            assert named, f"type {number} names no scenario: {cell}"
        for name in named:
            assert name in NAMES, f"type {number} names {name!r}, which is not a bank scenario"


def test_the_typology_scenarios_are_in_the_bank_listing():
    covered = {name for cell in typology_rows().values() if not cell.startswith(("left out", "not yet"))
               for name in re.findall(r"`([a-z0-9_]+)`", cell)}
    # every scenario with a story block was written for a type of the typology
    assert set(WITH_STORY) <= covered


@pytest.mark.parametrize("name", WITH_STORY)
def test_story_block_names_script_actors_in_the_vocabulary(name):
    meta = json.loads((BANK_DIR / name / "meta.json").read_text(encoding="utf-8"))
    script = (BANK_DIR / name / "scenario.scenic").read_text(encoding="utf-8")
    story = meta["story"]
    named = set(re.findall(r'with name "([^"]+)"', script))
    assert story["actors"] and set(story["actors"]) <= named, (story["actors"], named)
    assert all(kind in PARTICIPANTS and kind != "ego" for kind in story["actors"].values())
    assert story["steps"]
    for step in story["steps"]:
        # a step of the ego itself is required only of the script's own ego (dv2s_gym/story_check.py)
        assert step["actor"] in story["actors"] or step["actor"] == "ego"
        assert step["action"] in ACTIONS
        for relation, other in step.get("relations", []):
            assert relation in RELATIONS and other == "ego"
        assert step.get("within_s", 1.0) > 0
        # the element block states the same (by kind), so element-based search and metrics see the story;
        # an obstacle has no action in the elements read off a trace, its step only marks a moment
        kind = "ego" if step["actor"] == "ego" else story["actors"][step["actor"]]
        if kind != "obstacle":
            assert [kind, step["action"]] in meta["elements"]["actions"]


# ------------------------------------------------- the manoeuvre happens in front of the ego

DT = 0.2  # s per trace step (policy frequency 5 Hz)
LANE_HALF = 1.75


def _episode(name: str, seed: int):
    from dv2s_gym.story import run_episode

    trace = run_episode(str(BANK_DIR / name / "scenario.scenic"), "keep_lane", seed)
    names = trace.states[0].keys()
    tracks = {n: np.array([s[n] for s in trace.states if n in s], float) for n in names}
    return trace, tracks


def _actor(tracks, prefix: str):
    (name,) = [n for n in tracks if n.startswith(prefix)]
    return tracks[name]


def _hit(trace, prefix: str):
    """Time of the ego's collision with the actor named ``prefix...``, or None."""
    for event in trace.events:
        actors = event.get("actors") or []
        if event.get("kind") == "collision" and "ego" in actors and any(a.startswith(prefix) for a in actors):
            return event["time"]
    return None


def _rel(ego, other):
    """Per step: (metres ahead of the ego, metres to its left) of ``other`` (highway-env frame, y down)."""
    n = min(len(ego), len(other))
    dx, dy = other[:n, 0] - ego[:n, 0], other[:n, 1] - ego[:n, 1]
    c, s = np.cos(ego[:n, 2]), np.sin(ego[:n, 2])
    return np.stack([dx * c + dy * s, dx * s - dy * c], axis=1)


def _slow_lead(trace, t):
    ego, lead = t["ego"], _actor(t, "lead")
    hit = _hit(trace, "lead")
    m = len(lead) if hit is None else max(1, int(hit / DT) - 1)
    rel = _rel(ego, lead)
    assert np.all(np.abs(rel[:m, 1]) < LANE_HALF) and np.all(rel[:m, 0] > 0), "the lead leaves the ego's lane"
    assert np.ptp(lead[:m, 3]) < 1.0, "the lead does not keep a constant speed"
    assert hit is not None or rel[0, 0] - rel[:, 0].min() > 25, "the ego never closes in"


def _drift(trace, t):
    ego, drifter = t["ego"], _actor(t, "drifter")
    toward = np.sign(ego[0, 1] - drifter[0, 1])
    over = (drifter[:len(ego), 1] - drifter[0, 1]) * toward > LANE_HALF + 0.2
    rel = _rel(ego, drifter)
    assert np.any(over[:len(rel)] & (rel[:, 0] > 0)), "the drifter never crosses into the ego's lane ahead of it"


def _crosses_ahead(prefix):
    def check(trace, t):
        rel = _rel(t["ego"], _actor(t, prefix))
        ahead_in_lane = (np.abs(rel[:, 1]) < LANE_HALF) & (rel[:, 0] > 0) & (rel[:, 0] < 25)
        assert ahead_in_lane.any() or _hit(trace, prefix) is not None, f"the {prefix} never crosses ahead of the ego"
    return check


def _enters_lane_ahead(prefix, start_outside=True):
    def check(trace, t):
        ego, other = t["ego"], _actor(t, prefix)
        rel = _rel(ego, other)
        if start_outside:
            assert abs(rel[0, 1]) > 2.5, f"the {prefix} starts in the ego's lane"
        inside = (np.abs(other[:len(rel), 1] - ego[0, 1]) < 1.2) & (rel[:, 0] > 0)
        assert inside.any() or (_hit(trace, prefix) is not None and abs(rel[0, 1]) > 2.5), \
            f"the {prefix} never enters the ego's lane ahead of it"
    return check


def _speed_change_ahead(prefix, rise_first):
    def check(trace, t):
        ego, lead = t["ego"], _actor(t, prefix)
        rel, v = _rel(ego, lead), lead[:, 3]
        n = len(rel)
        def first(i0, sign):
            # the first step from which the speed rises (sign 1) or falls (-1) by 3 m/s within 2 s
            return next((i for i in range(i0, n) if (sign * (v[i:min(n, i + 11)] - v[i])).max() >= 3), None)
        start = 0
        if rise_first:
            up = first(0, 1)
            assert up is not None and rel[up, 0] > 0 and abs(rel[up, 1]) < LANE_HALF, "the lead never drives off ahead"
            start = up
        down = first(start, -1)
        assert down is not None and rel[down, 0] > 0 and abs(rel[down, 1]) < LANE_HALF, "the lead never brakes ahead"
    return check


def _backs_up(trace, t):
    ego, backer = t["ego"], _actor(t, "backer")
    forward = np.array([math.cos(backer[0, 2]), math.sin(backer[0, 2])])
    moved = (backer[:, :2] - backer[0, :2]) @ forward
    start = next((i for i in range(len(moved)) if moved[i] < -0.3), None)
    assert start is not None, "the car never backs up"
    rel = _rel(ego, backer)
    assert rel[start, 0] > 0 and abs(rel[start, 1]) < LANE_HALF, "it backs up, but not ahead of the ego in its lane"
    assert -moved.min() > 2 or _hit(trace, "backer") is not None


def _crosses_turning_path(trace, t):
    ego, cyclist = t["ego"], _actor(t, "cyclist")
    crossed = any(np.hypot(*(ego[i + 1:i + 16, :2] - cyclist[i, :2]).T).min() < 1.5
                  for i in range(min(len(ego), len(cyclist)) - 1))
    assert crossed or _hit(trace, "cyclist") is not None, "the cyclist never crosses the ego's path ahead of it"


def _obstacle_after_turn(trace, t):
    ego, obstacle = t["ego"], _actor(t, "obstacle")
    turned = np.abs((ego[:, 2] - ego[0, 2] + math.pi) % (2 * math.pi) - math.pi) > math.radians(60)
    assert turned.any(), "the ego never turns"
    first = int(np.argmax(turned))
    rel = _rel(ego, obstacle)
    in_lane_ahead = (rel[:, 0] > 0) & (np.abs(rel[:, 1]) < LANE_HALF)
    assert not in_lane_ahead[:first].any(), "the obstacle is in the ego's lane before the turn"
    assert in_lane_ahead[first:].any(), "the obstacle is not in the lane the ego turns into"


EVENTS = {
    "highway_slow_lead_vehicle": _slow_lead,
    "highway_adjacent_car_drifts": _drift,
    "urban_cyclist_crossing_paths": _crosses_ahead("cyclist"),
    "urban_parked_car_pulls_out": _enters_lane_ahead("parked"),
    "urban_lead_vehicle_turns": _speed_change_ahead("lead", rise_first=False),
    "urban_oncoming_car_overtakes": _enters_lane_ahead("passer"),
    "urban_lead_vehicle_accelerates_then_stops": _speed_change_ahead("lead", rise_first=True),
    "urban_car_backs_up_toward_ego": _backs_up,
    "urban_left_turn_across_cyclist": _crosses_turning_path,
    "highway_fast_car_passes_behind_slow_truck": _enters_lane_ahead("passer"),
    "urban_obstacle_after_right_turn": _obstacle_after_turn,
}


@pytest.mark.slow
@pytest.mark.usefixtures("in_process_simulator")
@pytest.mark.parametrize("name", sorted(EVENTS))
def test_the_manoeuvre_happens_in_front_of_a_constant_speed_ego(name):
    for seed in range(3):
        trace, tracks = _episode(name, seed)
        EVENTS[name](trace, tracks)
