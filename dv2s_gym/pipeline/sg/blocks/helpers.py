"""Scenic helper functions of the road geometry (section 3 of a script) and of the behaviours."""

from __future__ import annotations

from typing import Dict

__all__ = ["HELPERS"]

HELPERS: Dict[str, str] = {
    "pathBlocked": '''\
def pathBlocked(car, margin):
    # something (vehicle, pedestrian, prop) in the car's own corridor that it is closing in on
    for obj in simulation().objects:
        if obj is car:
            continue
        rel = (obj.position - car.position).rotatedBy(-car.heading)
        # where it will be in 1.2 s: someone about to step into the corridor counts already
        soon = (obj.position + obj.velocity * 1.2 - car.position).rotatedBy(-car.heading)
        entering = abs(soon.x) <= 2.3 or rel.x * soon.x < 0
        if rel.y <= 0 or (abs(rel.x) > 2.3 and not entering):
            continue
        closing = (car.velocity - obj.velocity).rotatedBy(-car.heading).y
        if rel.y < margin + 0.35 * car.speed + max(0, closing) * 1.6:
            return True
        if obj.speed < 0.5 and rel.y < margin + 8:
            return True  # stay stopped behind something that stands still
    return False
''',
    "laneSides": '''\
def laneLeftOf(lane):
    section = None if lane is None else lane.sections[0]._laneToLeft
    return None if section is None or section.isForward != lane.sections[0].isForward else section.lane

def laneRightOf(lane):
    section = None if lane is None else lane.sections[0]._laneToRight
    return None if section is None else section.lane

def lanesLeftOf(lane):
    found = []
    lane = laneLeftOf(lane)
    while lane is not None:
        found.append(lane)
        lane = laneLeftOf(lane)
    return found

def lanesRightOf(lane):
    found = []
    lane = laneRightOf(lane)
    while lane is not None:
        found.append(lane)
        lane = laneRightOf(lane)
    return found
''',
    "approach": '''\
def approachDir(lane):
    # direction in which traffic on `lane` drives as it reaches its end (the junction)
    return lane.centerline[-1] - lane.centerline[-2]

def sideOf(a, b):
    # > 0: a car arriving on lane b comes from the right of a driver arriving on lane a
    da = approachDir(a)
    db = approachDir(b)
    return da.x * db.y - da.y * db.x

def opposite(a, b):
    da = approachDir(a)
    db = approachDir(b)
    return da.x * db.x + da.y * db.y < -0.7 * da.norm() * db.norm()
''',
}
