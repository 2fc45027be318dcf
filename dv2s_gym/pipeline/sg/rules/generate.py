"""The entry point of the rule-based Scenario Generator: description -> :class:`~.frame.SGResult`."""

from __future__ import annotations

import random
from typing import List, Optional

from dv2s_gym.pipeline.semantics.text import parse_description
from dv2s_gym.pipeline.sg import blocks
from dv2s_gym.pipeline.sg.rules.coverage import absent_warnings, check_main_event, typed_collisions, unbuilt_warnings
from dv2s_gym.pipeline.sg.rules.describe import build_frame
from dv2s_gym.pipeline.sg.rules.frame import SGResult
from dv2s_gym.pipeline.sg.rules.junctions import compose_junction
from dv2s_gym.pipeline.sg.rules.lanes import compose_lanes
from dv2s_gym.pipeline.sg.rules.roads import JUNCTION_MAPS, MAP_ROADS
from dv2s_gym.pipeline.sg.rules.script import Script
from scenario_bank.elements import Elements, Road
from dv2s_gym.pipeline.errors import EmptyDescriptionError

__all__ = ["generate_rules"]


def generate_rules(description: str, seed: Optional[int] = None) -> SGResult:
    """Compose a Scenic script (four sections) for ``description``; deterministic given ``seed``."""
    if not isinstance(description, str) or not description.strip():
        raise EmptyDescriptionError("the description is empty: describe the road, the ego and what the other actors do")
    rng = random.Random(0 if seed is None else int(seed))
    parsed = parse_description(description)
    warnings: List[str] = []
    frame = build_frame(description, parsed, warnings)
    s = Script(frame, rng)
    s.warnings = warnings
    if not parsed.entities and not parsed.road:
        warnings.append("nothing in the description could be recognised (road, ego, cars, trucks, pedestrians, "
                        "obstacles): the script only has the ego driving")
    if frame.map in JUNCTION_MAPS:
        compose_junction(s)
    else:
        compose_lanes(s)
    script = s.render()
    check_main_event(parsed, s)
    typed_collisions(s)
    warnings.extend(unbuilt_warnings(parsed, s, warnings))
    warnings.extend(absent_warnings(parsed))
    road = MAP_ROADS.get(frame.map)
    elements = Elements("t_junction" if frame.road == Road.THREE_WAY else road, tuple(s.participants),
                        tuple(sorted(s.actions)), tuple(sorted(s.relations)))
    return SGResult(script=script, frame=frame, warnings=list(dict.fromkeys(warnings)), elements=elements,
                    backend="rules", context_hash=blocks.context_hash())
