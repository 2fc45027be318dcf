"""A continuous descriptor of the state a failure happened in, and novelty against earlier ones.

:func:`failure_state` reads an episode's trace (every actor's ``[x, y, heading, speed]`` after every step)
at the failure step and returns a short vector of numbers, each scaled to about ``[-1, 1]``::

    [ego speed / 30, ego speed change over the last second / 10, ego sideways motion over the last
     two seconds / 4, failure time / episode duration, 1 if the actor is the failure's own (0: the
     nearest one), actor ahead in the ego's frame / 30, actor to the side / 8, actor's speed along the
     ego's heading minus the ego's / 20, |heading difference| / pi]

(the actor: the one the failure names, else the nearest other one; without any other actor its five numbers
are 0). The ``novelty-bandit`` sampler's feedback (:mod:`dv2s_gym.mining.sampling.novelty_sampler`) counts a failure
as new when its descriptor is farther than :data:`NOVELTY_RADIUS` from every earlier failure's in the same
scenario: novelty search over where the failure happened on the road, as quality-diversity methods do.

It is not a behaviour cluster (:mod:`dv2s_gym.mining.cluster`): no failure class, no actor kind, no
manoeuvre label, no threshold on any of them; two failures of one cluster can be far apart here and two of
different clusters close.
"""

from __future__ import annotations

import math
from typing import Any, List, Optional, Sequence

from scenario_bank.records import Failure

__all__ = ["failure_state", "distance", "is_novel", "NOVELTY_RADIUS", "STATE_SIZE"]

STATE_SIZE = 9
"""Numbers in a descriptor."""
NOVELTY_RADIUS = 0.35
"""Distance beyond which a failure's descriptor counts as new (Euclidean, in the scaled units above)."""


def _clip(value: float) -> float:
    return max(-1.0, min(1.0, float(value)))


def failure_state(trace: Any, failure: Optional[Failure]) -> Optional[List[float]]:
    """The descriptor (module docstring) of ``failure`` in ``trace``; ``None`` without a failure or without
    states."""
    if failure is None:
        return None
    states = list(getattr(trace, "states", None) or [])
    if not states:
        return None
    config = getattr(trace, "config", None) or {}
    frequency = float(config.get("policy_frequency", 5) or 5)
    duration = float(config.get("duration", 20.0) or 20.0)
    step = failure.step
    step = len(states) - 1 if not isinstance(step, int) else max(0, min(len(states) - 1, step))
    now = states[step]
    ego = now.get("ego")
    if not ego:
        return None
    second = states[max(0, step - int(round(frequency)))].get("ego", ego)
    two = states[max(0, step - int(round(2 * frequency)))].get("ego", ego)
    cos, sin = math.cos(ego[2]), math.sin(ego[2])
    sideways = -(ego[0] - two[0]) * math.sin(two[2]) + (ego[1] - two[1]) * math.cos(two[2])
    vector = [_clip(ego[3] / 30.0), _clip((ego[3] - second[3]) / 10.0), _clip(abs(sideways) / 4.0),
              _clip(step / (duration * frequency))]
    named = failure.with_
    others = {name: state for name, state in now.items() if name != "ego" and state}
    if named in others:
        name, own = named, 1.0
    elif others:
        name = min(others, key=lambda n: math.hypot(others[n][0] - ego[0], others[n][1] - ego[1]))
        own = 0.0
    else:
        return vector + [0.0] * (STATE_SIZE - len(vector))
    other = others[name]
    dx, dy = other[0] - ego[0], other[1] - ego[1]
    ahead, side = dx * cos + dy * sin, -dx * sin + dy * cos
    along = other[3] * math.cos(other[2] - ego[2]) - ego[3]
    turn = abs((other[2] - ego[2] + math.pi) % (2 * math.pi) - math.pi)
    return vector + [own, _clip(ahead / 30.0), _clip(side / 8.0), _clip(along / 20.0), turn / math.pi]


def distance(a: Sequence[float], b: Sequence[float]) -> float:
    """Euclidean distance between two descriptors."""
    return math.sqrt(sum((float(x) - float(y)) ** 2 for x, y in zip(a, b)))


def is_novel(state: Optional[Sequence[float]], archive: Sequence[Sequence[float]],
             radius: float = NOVELTY_RADIUS) -> bool:
    """True when ``state`` is farther than ``radius`` from every descriptor of ``archive`` (a failure without a
    descriptor counts as new)."""
    if state is None:
        return True
    return all(distance(state, other) > radius for other in archive)
