"""What a Scenic script draws outside its ``param`` lines: the randomness an exact replay cannot narrow.

A mining run records the values of a scene's global parameters, so an exact replay entry
(:mod:`dv2s_gym.mining.conversion.exact_replay`) can narrow those around the failure. A script also draws inside its body:
a variable set to a distribution (``egoS = Range(50, 1200)``), a distribution written into an object's
specifiers (``with speed Range(20, 27)``), a choice of lanes (``Uniform(*lanes)``), a position drawn on a region
(``new Car on lane``, ``in``, ``visible``, or no position specifier at all, which the driving model fills with a
random point on the road) and draws inside a behaviour. None of these is recorded, so the replay keeps the
parent's distribution for each: the entry is the failing scene at its own seed and the failure's neighbourhood at
any other. :func:`inline_draws` names each, so the entry's provenance says so.
"""

from __future__ import annotations

import re
from dv2s_gym.mining.conversion.param_meaning import PLACEMENT_KINDS
from dv2s_gym.mining.conversion.scenic_statements import split_top, top_statements
from typing import Collection, Dict, List

__all__ = ["inline_draws", "DRAWS"]

DRAWS = re.compile(r"\b(Range|Uniform|Normal|TruncatedNormal|Options|Discrete|DiscreteRange|VerifaiRange|"
                   r"VerifaiOptions|VerifaiParameter|resample)\s*\(")
"""A call that draws a value when the scene is sampled."""

_CHOICES = ("Uniform", "Options", "Discrete", "VerifaiOptions")
_OBJECT = re.compile(r"^(?:(\w+)\s*=\s*)?new\s+(\w+)\b(.*)$", re.S)
_ASSIGN = re.compile(r"^(\w+)\s*=\s*(.+)$", re.S)
_HEAD = re.compile(r"^(behavior|def|monitor|scenario)\s+(\w+)")
_FIXED_POSITION = re.compile(r"^(at|offset\s+by|offset\s+along|left\s+of|right\s+of|ahead\s+of|behind|beyond|"
                             r"following)\b")
_REGION_POSITION = re.compile(r"^(on|in|visible|not\s+visible|contained\s+in)\b")
_NOT_SCENE = re.compile(r"^(param|model|import|from|require|terminate|record|mutate)\b")
"""Statements that draw nothing of the scene (a ``param`` line is narrowed or listed on its own)."""


def _calls(text: str) -> List[str]:
    """The distribution calls written in ``text``, each with its arguments (``Range(20, 27)``)."""
    found = []
    for match in DRAWS.finditer(text):
        depth, end = 0, len(text)
        for index in range(match.end() - 1, len(text)):
            depth += {"(": 1, ")": -1}.get(text[index], 0)
            if depth == 0:
                end = index + 1
                break
        call = " ".join(text[match.start():end].split())
        arguments = split_top(call[call.index("(") + 1:-1])
        if match.group(1) in _CHOICES and len(arguments) == 1 and not arguments[0].startswith("*"):
            continue  # a choice of one value draws nothing
        found.append(call)
    return found


def _position_draw(kind: str, specifiers: str) -> str:
    """Why an object's position is drawn by the seed, or ``""`` when a specifier fixes it."""
    positional = [spec.strip() for spec in split_top(specifiers) if spec.strip() and not spec.strip().startswith(
        ("with ", "facing ", "apparently facing "))]
    if any(_FIXED_POSITION.match(spec) for spec in positional):
        return ""
    region = next((spec for spec in positional if _REGION_POSITION.match(spec)), None)
    if region is not None:
        return f"its position is drawn at random ({' '.join(region.split())})"
    if kind in PLACEMENT_KINDS:
        return ""
    return "its position is drawn at random (no specifier fixes it, so the model's default region places it)"


def _label(statement: str, index: int) -> str:
    head = _HEAD.match(statement)
    if head is not None:
        return f"{head.group(1)} {head.group(2)}"
    named = _OBJECT.match(statement) or _ASSIGN.match(statement)
    if named is not None and named.group(1):
        return named.group(1)
    created = _OBJECT.match(statement)
    return f"<{created.group(2)} {index}>" if created else f"<statement {index}>"


def inline_draws(script: str, taken: Collection[str] = ()) -> Dict[str, str]:
    """``{what: why}`` of every value ``script`` draws outside its ``param`` lines, one entry per top-level
    statement that draws (a variable's name, an object's name, ``behavior NAME``, or ``<Car 7>`` for the 7th
    statement when unnamed): the distributions it writes and, for an object, a position drawn on a region
    (``"outside the params, draws Range(50, 1200)"``). No mining run records these, so a replay keeps the parent's
    draw for each. A label already used, here or in ``taken`` (the params listed beside these), gets a ``'``."""
    out: Dict[str, str] = {}
    for index, statement in enumerate(top_statements(script), start=1):
        if _NOT_SCENE.match(statement):
            continue
        draws = _calls(statement)
        created = _OBJECT.match(statement)
        position = _position_draw(created.group(2), created.group(3)) if created else ""
        if not draws and not position:
            continue
        parts = ([f"draws {', '.join(dict.fromkeys(draws))}"] if draws else []) + ([position] if position else [])
        label = _label(statement, index)
        while label in out or label in taken:
            label += "'"
        out[label] = "outside the params, " + "; ".join(parts)
    return out
