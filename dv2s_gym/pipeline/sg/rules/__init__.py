"""The embedded, offline Scenario Generator backend ``rules``: description -> Scenic script.

:func:`generate_rules` parses a description with :mod:`dv2s_gym.pipeline.semantics.text`
into a :class:`ScenarioFrame` (road, ego, actors with counts, actions, triggers and
relations to the ego), then composes a Scenic script in the paper's four sections
from the building blocks of :mod:`dv2s_gym.pipeline.sg.blocks`:

1. map and global parameters (map chosen by road type, weather, randomized speeds,
   gaps, trigger distances and spawn offsets as ``param`` ranges);
2. adversarial behaviours (one block per actor type and action);
3. road geometry (lane tuples on straight maps, maneuver tuples at junctions);
4. spawn positions (one placement per relation to the ego).

Whatever it cannot place (an unknown kind of actor, an action a type cannot do,
a relation the map cannot realise) goes into ``warnings``; nothing
is dropped silently: every phrase the parser could not place is a ``could not place``
warning, and every parsed element the composed script does not mean to show is a
``not built: <element> ('<words>')`` warning (:func:`unbuilt_warnings`). ``elements``
lists what the script is meant to show; :func:`unshown_warnings` names what of it a
simulated run did not show (``Generation.note_simulated`` adds those after a run).
The output is deterministic for a given description and seed.

The package's modules, by what they hold: :mod:`.describe` (description -> :class:`ScenarioFrame`, with
:mod:`.map_choice` and :mod:`.roads`), :mod:`.script` (the script being composed), :mod:`.roles` (the
:class:`~.roles.Role` of an actor), :mod:`.lanes` (the straight-road composer, with :mod:`.lane_roles`,
:mod:`.lane_geometry`, :mod:`.lane_ego`, :mod:`.lane_spawn` and the modules it dispatches to),
:mod:`.junctions` (the junction composer, with the ``junction_*`` modules), :mod:`.pedestrians`,
:mod:`.coverage` (main event, ``not built`` and ``not shown`` warnings) and :mod:`.generate` (the entry point).
"""

from dv2s_gym.pipeline.sg.rules.coverage import unbuilt_warnings, unshown_warnings
from dv2s_gym.pipeline.sg.rules.describe import build_frame
from dv2s_gym.pipeline.sg.rules.frame import ActorFrame, ScenarioFrame, SGResult
from dv2s_gym.pipeline.sg.rules.generate import generate_rules
from dv2s_gym.pipeline.sg.rules.roads import (JUNCTION_MAPS, MAP_ROADS, MULTILANE_STREET, PARKING_STREET, RING_ENTRY,
                                              RING_MAP, RING_QUARTER, ROAD_MAPS)
from dv2s_gym.pipeline.sg.rules.roles import JunctionRole, Role

__all__ = ["ActorFrame", "ScenarioFrame", "SGResult", "generate_rules", "build_frame", "ROAD_MAPS", "unbuilt_warnings",
           "unshown_warnings", "MAP_ROADS", "JUNCTION_MAPS", "MULTILANE_STREET", "PARKING_STREET", "RING_MAP",
           "RING_ENTRY", "RING_QUARTER", "Role", "JunctionRole"]
