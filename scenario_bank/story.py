"""The ``story`` block of a bank scenario's sidecar: its format and its check on input.

A sidecar's ``story`` names the script's story actors (``with name "cutter"`` in the script) with
their vocabulary kinds, and the steps each must play, in order per actor::

    "story": {
      "actors": {"cutter": "car"},
      "steps": [
        {"actor": "cutter", "action": "overtake", "relations": [["left_of", "ego"]]},
        {"actor": "cutter", "action": "cut_in", "relations": [["ahead_of", "ego"]], "within_s": 3.0}
      ]
    }

A step holds ``actor`` (a story actor or ``ego``), ``action`` (:data:`scenario_bank.elements.ACTIONS`),
and optionally ``relations`` (``[relation, other]`` pairs, ``other`` the ego or another story actor),
``within_s`` (a time gap in seconds the step must happen within, ahead of the ego), ``hold`` (the
action's state lasts to the end of the episode) and ``when`` (another story actor: the step's relations
are read at the moment of that actor's last step, e.g. the cars that box the ego in are beside it when it
reaches the obstacle). What each means in an episode is
:mod:`dv2s_gym.story_check`'s business.
"""

from __future__ import annotations

import re
from typing import Any, Dict, Mapping

from scenario_bank.elements import ACTIONS, PARTICIPANTS, RELATIONS, ActorKind
from scenario_bank.errors import DV2SError

__all__ = ["StoryError", "normalize_story", "step_label", "STEP_KEYS"]

STEP_KEYS = {"actor", "action", "relations", "within_s", "hold", "when"}
"""The keys a step may have."""


class StoryError(DV2SError, ValueError):
    """A ``story`` block that does not follow the format."""


def normalize_story(story: Any, where: str = "story") -> Dict[str, Any]:
    """Check a ``story`` block; return it (steps with empty ``relations`` filled in).

    Raises :class:`StoryError` naming the offending entry and the fix.
    """
    if not isinstance(story, Mapping):
        raise StoryError(f"{where} must be an object with 'actors' and 'steps'")
    unknown = set(story) - {"actors", "steps"}
    if unknown:
        raise StoryError(f"{where} has unknown keys {sorted(unknown)}; allowed: actors, steps")
    actors = story.get("actors")
    if not isinstance(actors, Mapping) or not actors:
        raise StoryError(f"{where}.actors must map each story actor's script name to its kind, "
                         'e.g. {"cutter": "car"}')
    for name, kind in actors.items():
        if not isinstance(name, str) or not re.fullmatch(r"[A-Za-z_]\w*", name) or name == "ego":
            raise StoryError(f"{where}.actors: {name!r} is not a script object name (letters, digits, '_'; "
                             "not 'ego', which is always there)")
        if kind not in PARTICIPANTS or kind == ActorKind.EGO:
            raise StoryError(f"{where}.actors.{name}: unknown kind {kind!r}; use one of "
                             f"{', '.join(p for p in PARTICIPANTS if p != 'ego')}")
    steps = story.get("steps")
    if not isinstance(steps, list) or not steps:
        raise StoryError(f"{where}.steps must be a non-empty list of steps")
    known = set(actors) | {"ego"}
    out = []
    for k, step in enumerate(steps):
        at = f"{where}.steps[{k}]"
        if not isinstance(step, Mapping):
            raise StoryError(f"{at} must be an object with 'actor' and 'action'")
        extra = set(step) - STEP_KEYS
        if extra:
            raise StoryError(f"{at} has unknown keys {sorted(extra)}; allowed: {', '.join(sorted(STEP_KEYS))}")
        if step.get("actor") not in known:
            raise StoryError(f"{at}.actor {step.get('actor')!r} is not 'ego' nor listed in {where}.actors")
        if step.get("action") not in ACTIONS:
            raise StoryError(f"{at}.action {step.get('action')!r} is not an action of the vocabulary "
                             "(scenario_bank.elements.ACTIONS)")
        relations = step.get("relations", [])
        if not isinstance(relations, list):
            raise StoryError(f"{at}.relations must be a list of [relation, other] pairs")
        for pair in relations:
            if not (isinstance(pair, list) and len(pair) == 2 and pair[0] in RELATIONS and pair[1] in known
                    and pair[1] != step["actor"]):
                raise StoryError(f"{at}.relations: {pair!r} must be [relation, other] with a relation of "
                                 f"{', '.join(RELATIONS)} and other 'ego' or another story actor")
        within = step.get("within_s")
        if within is not None and (isinstance(within, bool) or not isinstance(within, (int, float)) or within <= 0):
            raise StoryError(f"{at}.within_s must be a positive number of seconds")
        if not isinstance(step.get("hold", False), bool):
            raise StoryError(f"{at}.hold must be true or false")
        when = step.get("when")
        if when is not None and (when not in actors or when == step["actor"]):
            raise StoryError(f"{at}.when {when!r} must name another story actor (the step is read at the moment "
                             "of that actor's last step)")
        clean = {"actor": step["actor"], "action": step["action"], "relations": [list(p) for p in relations]}
        if within is not None:
            clean["within_s"] = float(within)
        if step.get("hold"):
            clean["hold"] = True
        if when is not None:
            clean["when"] = when
        out.append(clean)
    return {"actors": dict(actors), "steps": out}


def step_label(step: Mapping[str, Any]) -> str:
    """A step in words: ``cutter cut_in ahead_of ego within 3.0 s``."""
    words = [step["actor"], step["action"]] + [" ".join(p) for p in step.get("relations", [])]
    if step.get("within_s") is not None:
        words.append(f"within {step['within_s']:g} s")
    if step.get("hold"):
        words.append("to the end")
    if step.get("when"):
        words.append(f"when {step['when']} does")
    return " ".join(words)
