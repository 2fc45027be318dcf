"""Scenic building blocks of the rule-based Scenario Generator (:mod:`dv2s_gym.pipeline.sg.rules`).

Each block is a piece of Scenic text: behaviours (section 2 of a script), helper
functions for road geometry (section 3) and the header (section 1). The
composer in :mod:`dv2s_gym.pipeline.sg.rules` picks the blocks a description
needs, fills their parameters and glues them into one script.

Conventions every block follows (they were measured on the highway-env model):

* lateral offsets are metres to the left of a centreline
  (``line.signedDistanceTo(point)`` is positive on the left);
* lane changes slide the car sideways relative to the centreline of the lane it
  starts in, so they also work into an opposite-direction lane (overtaking on a
  two-way street) where following that lane would turn the car around;
* conditions on other actors wait 0.4 s first, so nothing fires on the
  simulator's very first step;
* behaviours read only their arguments, ``self``, ``ego`` and the simulation.

The blocks live in :mod:`.helpers` (geometry helper functions), :mod:`.lane_behaviors`,
:mod:`.route_behaviors` and :mod:`.crossing_behaviors` (behaviours), :mod:`.weather` (the header's weathers);
:mod:`.assemble` glues the ones a script needs into text.
"""

from scenario_bank.maps.dimensions import LANE_WIDTH
from dv2s_gym.pipeline.sg.blocks.assemble import BEHAVIORS, behavior_text, context_hash, helper_text
from dv2s_gym.pipeline.sg.blocks.helpers import HELPERS
from dv2s_gym.pipeline.sg.blocks.weather import WEATHERS

__all__ = ["BEHAVIORS", "HELPERS", "WEATHERS", "LANE_WIDTH", "behavior_text", "helper_text", "context_hash"]
