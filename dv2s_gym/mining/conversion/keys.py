"""The judge's checks of a failure's key parameters: those that set a quantity of the failure's interaction (the
ego's, or the key actor's) in the parent script.

:func:`check_keys` runs them all for :func:`~dv2s_gym.mining.conversion.parameters.compare_parameters`: a key
quantity the new script sets by a parameter of its own that the judge cannot compare (:func:`key_set_otherwise`),
compared jointly when both scripts' expressions can be read so (:func:`compare_jointly`); one it fixes without a
parameter away from the failing value (:func:`key_fixed_outside`, within :data:`FIXED_TOLERANCE`); a key actor's
placement it writes in a form the judge cannot read (:func:`key_placement_unread`); and a behaviour argument its
behaviour assigns anew (:func:`key_overridden`).
"""

from __future__ import annotations

import re
from typing import Any, Dict, Mapping, Optional, Sequence, Tuple

from dv2s_gym.mining.conversion.ranges import comparison_contains, exact_number, script_ranges, script_supports
from dv2s_gym.mining.conversion.exact_replay import NARROW
from dv2s_gym.mining.conversion.param_meaning import (actor_objects, behaviour_overrides, counterpart_objects, fixed_quantities,
                                           lengths_along, object_behaviour_heads, placements, quantity_uses,
                                           script_objects, script_parameters)
from dv2s_gym.mining.conversion.scenic_values import joint_interval, placement_parts, read_support, support_contains

__all__ = ["FIXED_TOLERANCE", "check_keys", "key_set_otherwise", "compare_jointly", "key_fixed_outside",
           "key_placement_unread", "key_overridden"]


FIXED_TOLERANCE = NARROW
"""How far a key quantity the new script fixes at a value (``with speed 20``, ``CutIn(2.5)``) may lie from the
failing value's quantity and still hold it, as a share of the width the parent's range of the parameter gives
that quantity: the exact replay narrows each parameter to this share of its width on either side of the failing
value (:data:`~dv2s_gym.mining.conversion.exact_replay.NARROW`) and takes any value in that band as the failing scene's, so
a fixed value as close stands for the failing scene as well as the replay's draws do. A parent range of no width
allows no distance."""


def _counterpart_finder(parent: str, script: str, actor: Optional[str] = None):
    """``counterpart(object, kind)``: the new script's object that stands for the parent's (the ego for the ego; the
    paired object; the key ``actor``'s object by its name; the only object of the kind on both sides), or ``None``."""
    objects = counterpart_objects(parent, script)
    new_objects = script_objects(script)
    named = actor_objects(script)
    old_named = actor_objects(parent)
    old_objects = script_objects(parent)

    def counterpart(obj: str, kind: str) -> Optional[Tuple[str, str]]:
        if obj == "ego":
            return ("ego", kind) if ("ego", kind) in new_objects else None
        if (obj, kind) in objects:
            return objects[(obj, kind)]
        if actor and old_named.get(actor) == obj and named.get(actor):
            found = [o for o in new_objects if o[0] == named[actor] and o[1] == kind]
            if found:
                return found[0]
        same = [o for o in new_objects if o[1] == kind and o[0] != "ego"]
        old_same = [o for o in old_objects if o[1] == kind and o[0] != "ego"]
        return same[0] if len(same) == 1 and len(old_same) == 1 else None
    return counterpart


def _key_checks(parent: str, script: str, keyed: Mapping[str, Sequence[Tuple[str, str, str, str]]],
                actor: Optional[str] = None):
    """``[(parameter, parent's (object, kind, slot), the new script's (object, kind, slot), words, the parent's
    quantity function, tolerance, read as a target speed?)]`` for each key quantity the parent sets as one known
    function of the parameter alone and whose object has a counterpart in the new script (:func:`_counterpart_finder`);
    ``tolerance`` is :data:`FIXED_TOLERANCE` of the width that function takes over the parent's range of the parameter.
    The ego's or an actor's speed is checked as its behaviour's ``target_speed`` too when the parent sets no target
    speed of its own there (``FollowLaneBehavior(target_speed=30)`` keeps the object at 30 whatever its start speed)."""
    old_uses = quantity_uses(parent)
    parent_fixed = fixed_quantities(parent)
    ranges = script_ranges(parent)
    counterpart = _counterpart_finder(parent, script, actor)
    out = []
    for name in sorted(keyed):
        for obj, kind, slot, words in keyed[name]:
            functions = {q.key: q for _, q, _ in old_uses.get(name, {}).get((obj, kind, slot), ()) if q is not None}
            other = counterpart(obj, kind)
            if len(functions) != 1 or other is None:
                continue
            function = next(iter(functions.values()))
            tolerance = 0.0
            if name in ranges:
                start, end = function.over(*ranges[name])
                tolerance = FIXED_TOLERANCE * abs(end - start)
            out.append((name, (obj, kind, slot), (other[0], other[1], slot), words, function, tolerance, False))
            target = "behavior:targetspeed"
            parent_sets_target = ((obj, kind, target) in parent_fixed
                                  or any((obj, kind, target) in by_slot for by_slot in old_uses.values()))
            if slot == "speed" and not parent_sets_target:
                out.append((name, (obj, kind, target), (other[0], other[1], target),
                            f"{words} (as its behaviour's target speed)", function, tolerance, True))
    return out


def key_fixed_outside(parent: str, script: str, keyed: Mapping[str, Sequence[Tuple[str, str, str, str]]],
                      numeric: Mapping[str, float], actor: Optional[str] = None) -> Dict[str, str]:
    """``{key parameter: the key quantity and the value the new script fixes it at}`` for each key parameter whose
    key quantity (the ego's, or the key actor's: the same quantity of its counterpart in the new script;
    :func:`_key_checks`, a speed read as a target speed too) the new script sets without a parameter, to a value (a
    number, an inline ``Range``, discrete values: :func:`~dv2s_gym.mining.conversion.param_meaning.fixed_quantities`) that
    does not hold the failing value's quantity (the parameter's value through the parent's expression) within
    :data:`FIXED_TOLERANCE`: the new script cannot produce the failing scene's quantity, whatever else it does with
    the parameter. A key quantity the parent sets other than as a known function of the parameter alone, or that
    the new script sets with a parameter (compared as a parameter) or not at all, is not checked here; nor is a
    behaviour argument of an object that runs another behaviour than in the parent, by name or argument names
    (:func:`~dv2s_gym.mining.conversion.param_meaning.object_behaviour_heads`: the argument may mean something else there; a
    behaviour of the same name and arguments whose body differs is held to the same meaning)."""
    fixed = fixed_quantities(script)
    if not fixed:
        return {}
    new_uses = quantity_uses(script)
    set_by_parameter = {where for by_slot in new_uses.values() for where in by_slot}
    old_heads, new_heads = object_behaviour_heads(parent), object_behaviour_heads(script)
    found: Dict[str, str] = {}
    for name, (obj, _, slot), where, words, function, tolerance, target in _key_checks(parent, script, keyed, actor):
        value = fixed.get(where) if where not in set_by_parameter else None
        if value is None and where[2] in _OPPOSITE:
            value = _flipped(script, where, fixed, set_by_parameter)
        if name in found or value is None:
            continue
        if slot.startswith("behavior:") and not target and old_heads.get(obj) != new_heads.get(where[0]):
            continue  # another behaviour: its argument of that name may mean something else
        parts = read_support(value)
        quantity = function.at(float(numeric[name]))
        if parts is not None and not support_contains(parts, quantity, tolerance=tolerance):
            made = (f", which the parent's {function.text} makes {exact_number(quantity)}"
                    if function.text != f"globalParameters.{name}" else "")
            found[name] = (f"{words}, which the new script fixes at {value} without a parameter, while the "
                           f"failing {name} = {exact_number(float(numeric[name]))}{made} (held within "
                           f"{exact_number(round(tolerance, 12))})")
    return found


_OPPOSITE = {"longitudinal": "longitudinal:behind", "longitudinal:behind": "longitudinal"}
"""A distance ahead and a distance behind: each is the other read with its sign flipped (:func:`_flipped`)."""


def _flipped(script: str, where: Tuple[str, str, str], fixed: Mapping[Tuple[str, str, str], str],
             set_by_parameter: Any) -> Optional[str]:
    """The distance ``where`` (an object's distance ahead or behind) as the new script fixes it in the opposite
    direction (``ahead of ego by Range(-60, -50)`` for a distance behind): ``-(d) - lengths``, the two forms measuring
    from opposite faces (:func:`~dv2s_gym.mining.conversion.param_meaning.lengths_along`); ``None`` when it is not fixed so or
    the lengths are not known."""
    obj, kind, slot = where
    opposite = (obj, kind, _OPPOSITE[slot])
    if opposite not in fixed or opposite in set_by_parameter:
        return None
    lengths = lengths_along(script, obj)
    return None if lengths is None else f"-({fixed[opposite]}) - {lengths:.12g}"


def key_placement_unread(parent: str, script: str, keyed: Mapping[str, Sequence[Tuple[str, str, str, str]]],
                         out: Mapping[str, Any], actor: Optional[str] = None) -> Dict[str, str]:
    """``{key parameter: its quantity and how the new script places the actor}`` for each key parameter that sets
    where an actor (not the ego) is, a distance ahead, behind or to a side (the parent's slot), when that actor has a
    counterpart in the new script (:func:`_counterpart_finder`) whose placement does not give that quantity: not
    compared, not listed already (``key_not_compared``, ``key_fixed_outside``), and not fixed by the new script in
    that direction (or, for a distance ahead or behind, the opposite one: :func:`_flipped`). The new script then places
    the actor by another quantity or form (a vector in the world's frame, an offset along another direction, a
    distance to the side for one ahead, a distance in the opposite direction set by a parameter of its own), and the
    failing value cannot be checked: a rejection, whatever share of the parameters was compared."""
    done = set(out["compared"]) | set(out.get("key_not_compared") or {}) | set(out.get("key_fixed_outside") or {})
    fixed = fixed_quantities(script)
    counterpart = _counterpart_finder(parent, script, actor)
    placed = placements(script)
    found: Dict[str, str] = {}
    for name in sorted(set(keyed) - done):
        for obj, kind, slot, words in keyed[name]:
            other = counterpart(obj, kind)
            if obj == "ego" or slot.split(":", 1)[0] not in ("longitudinal", "lateral") or other is None:
                continue
            if any((other[0], other[1], s) in fixed for s in {slot, _OPPOSITE.get(slot, slot)}):
                continue
            how = "; ".join(placed.get(other[0], [])) or "no placement"
            found[name] = (f"{words}: the new script places its {other[1]} {other[0]} by {how}, "
                           f"{_unread_form(placed.get(other[0], []), slot)}")
            break
    return found


def _unread_form(specifiers: Sequence[str], slot: str) -> str:
    """Why a placement (``specifiers``) gives no reading of the quantity ``slot``, in words."""
    text = " ".join(specifiers)
    if slot.startswith("longitudinal") and re.search(r"\b(left|right) of\b", text):
        return "a distance to the side, not along the ego's heading"
    side = {"lateral:left": "right", "lateral:right": "left"}.get(slot)
    if side and re.search(rf"\b{side} of\b", text):
        return f"a distance to the {side}, the other side"
    if re.search(r"\boffset\s+along\b", text):
        return "an offset along a direction the judge does not read as the reference's heading or the road's"
    if re.search(r"\.position\b|\bVector\s*\(|\bat\s+\(?\s*\d", text):
        return ("a point in the world's frame: how far ahead of or beside the ego it lies depends on the ego's "
                "heading")
    if re.search(r"\b(ahead of|behind)\b", text):
        return "a distance in the other direction set by a parameter of its own or a form the judge does not read"
    return "a placement from which the judge reads no distance in that direction"


def key_overridden(parent: str, script: str, keyed: Mapping[str, Sequence[Tuple[str, str, str, str]]],
                   numeric: Mapping[str, float], actor: Optional[str] = None) -> Dict[str, str]:
    """``{key parameter: the key quantity and the statement}`` for each key parameter whose key quantity is a
    behaviour argument that the new script's behaviour assigns anew in its body
    (:func:`~dv2s_gym.mining.conversion.param_meaning.behaviour_overrides`) where the parent's does not do so alike: the
    parameter passed there does not decide what the behaviour uses. An override to a value
    (``extraSpeed = 25``) that holds the failing value's quantity within :data:`FIXED_TOLERANCE` is no rejection."""
    overrides = behaviour_overrides(script)
    if not overrides:
        return {}
    old_overrides = behaviour_overrides(parent)
    found: Dict[str, str] = {}
    for name, old_where, where, words, function, tolerance, _ in _key_checks(parent, script, keyed, actor):
        statement = overrides.get(where)
        if name in found or statement is None or old_overrides.get(old_where) == statement:
            continue
        value = statement.split("=", 1)[1].strip() if re.match(r"^\w+\s*=", statement) else None
        parts = read_support(value) if value is not None else None
        quantity = function.at(float(numeric[name]))
        if parts is not None and support_contains(parts, quantity, tolerance=tolerance):
            continue
        found[name] = (f"{words}: the new script's behaviour assigns that argument anew ({statement}), so the "
                       f"value passed does not decide it (failing {name} = {exact_number(float(numeric[name]))})")
    return found


def compare_jointly(parent: str, script: str, keyed: Mapping[str, Sequence[Tuple[str, str, str, str]]],
                    numeric: Mapping[str, float], out: Dict[str, Any], actor: Optional[str] = None) -> None:
    """Compare jointly each key parameter the judge could not compare although the new script sets its key quantity
    by parameters of its own (``out["key_not_compared"]``) when both scripts set that quantity by expressions of
    parameters, numbers and inline ``Range``s in the same frame (the same slot; a placement along a lane in the same
    form, :func:`~dv2s_gym.mining.conversion.scenic_values.placement_parts`): the parent's expression at the failing values
    (all of them failing parameters, and more than the parameter alone: a quantity the parent sets as a function of
    the parameter alone is compared as a parameter) gives the failing quantity; the new expression's interval
    (:func:`~dv2s_gym.mining.conversion.scenic_values.joint_interval`) holds each of its parameters that stands for a compared
    failing parameter (compared bare, by name or meaning) at that failing value and lets the others range over
    their ranges (each quantity on its own: a parameter of the new script that sets two of them may take one value
    for one and another for the other): ``ego_speed * (first_arrival + ego_gap_time)`` with the failing ego_speed and
    the two times over their ranges against the parent's ``ego_distance``. The parameter then moves to ``compared``
    (``"jointly"``: the quantity), inside or outside (a rejection) like any other. Updates ``out``."""
    missing = out.get("key_not_compared") or {}
    if not missing:
        return  # (a parameter named as a failing one but not compared means something else: it is not let range)
    old_uses, new_uses = quantity_uses(parent), quantity_uses(script)
    counterpart = _counterpart_finder(parent, script, actor)
    new_ranges = script_ranges(script)
    values: Dict[str, Tuple[float, float]] = {}
    standing = {comparison.get("script_name", name): comparison for name, comparison in out["compared"].items()}
    for param in script_parameters(script):
        if param in standing:
            comparison = standing[param]
            if not any(field in comparison for field in ("expression", "support")):
                values[param] = (comparison["value"], comparison["value"])
        elif param in new_ranges and param not in script_supports(script) and param not in numeric:
            values[param] = tuple(new_ranges[param])
    failing = {name: (float(value), float(value)) for name, value in numeric.items()}
    for name in sorted(missing):
        for obj, kind, slot, words in keyed[name]:
            other = counterpart(obj, kind)
            if other is None:
                continue
            old_texts = {(q is None, text) for _, q, text in old_uses.get(name, {}).get((obj, kind, slot), ())}
            new_texts = {(q is None, text) for by_slot in new_uses.values()
                         for _, q, text in by_slot.get((other[0], other[1], slot), ())}
            if len(old_texts) != 1 or len(new_texts) != 1:
                continue
            (old_whole, old_text), (new_whole, new_text) = next(iter(old_texts)), next(iter(new_texts))
            if not old_whole:
                continue  # the parent's quantity is a function of the parameter alone: compared as a parameter
            if "pointAlongBy" in new_text and not new_whole:
                continue  # a placement read from a reference point on one side: not the same frame
            (old_frame, old_value), (new_frame, new_value) = placement_parts(old_text), placement_parts(new_text)
            if old_frame != new_frame:
                continue
            quantity = joint_interval(old_value, failing)
            interval = joint_interval(new_value, values)
            if quantity is None or quantity[0] != quantity[1] or interval is None:
                continue
            comparison = {"value": float(numeric[name]), "range": list(interval), "interval": list(interval),
                          "quantity": quantity[0], "expression": new_value, "parent_expression": old_value,
                          "jointly": words}
            missing.pop(name)
            out["not_comparable"].pop(name, None)
            out["not_in_script"] = [n for n in out["not_in_script"] if n != name]
            out["compared"][name] = comparison
            out["compared"] = dict(sorted(out["compared"].items()))
            if not comparison_contains(name, comparison):
                out["outside"] = sorted(set(out["outside"]) | {name})
            break


def key_set_otherwise(parent: str, script: str, keyed: Mapping[str, Sequence[Tuple[str, str, str, str]]],
                      out: Mapping[str, Any]) -> Dict[str, str]:
    """``{key parameter not comparable: the quantity and how the new script sets it}`` for each key parameter the
    judge could not compare although the new script sets one of its key quantities (the same quantity of the paired
    object) with a parameter of its own, one that stands for no compared failing parameter (``g * g``, ``10 / g``,
    ``min(g, 3)``, ``e + 100``, a ``Normal``): the new script then decides that quantity by a parameter the judge
    cannot check. A key quantity the new script sets with no parameter of its own (a number, a random term, a
    compared parameter alone) or not at all is not listed: it is no comparison the judge failed, it counts within
    :data:`~dv2s_gym.mining.conversion.judge.COMPARED_SHARE`."""
    unchecked = out["not_comparable"]
    if not any(name in unchecked for name in keyed):
        return {}
    paired = {comparison.get("script_name", name) for name, comparison in out["compared"].items()}
    objects = counterpart_objects(parent, script)
    new_uses = quantity_uses(script)
    found: Dict[str, str] = {}
    for name in sorted(keyed):
        if name not in unchecked:
            continue
        for obj, kind, slot, words in keyed[name]:
            other = objects.get((obj, kind))
            if other is None:
                continue
            own = sorted({(param, text) for param, by_slot in new_uses.items() if param not in paired
                          for (o, k, s), items in by_slot.items() if (o, k, s) == (other[0], other[1], slot)
                          for _, _, text in items})
            if own:
                found[name] = (f"{words}, which the new script sets by {own[0][1]} (its own parameter "
                               f"{own[0][0]}): {unchecked[name]}")
                break
    return found


def check_keys(parent: str, script: str, keyed: Mapping[str, Sequence[Tuple[str, str, str, str]]],
               numeric: Mapping[str, float], out: Dict[str, Any], actor: Optional[str]) -> None:
    """:func:`~dv2s_gym.mining.conversion.parameters.compare_parameters`' checks of the key parameters (``keyed``:
    ``{name: where it sets a key quantity in the parent}``), into ``out``: ``key``, ``key_not_compared``, the joint
    comparison, ``key_fixed_outside``, and ``key_unread`` and ``key_overridden`` when any."""
    out["key"] = {name: where[0][3] for name, where in keyed.items()}
    out["key_not_compared"] = key_set_otherwise(parent, script, keyed, out)
    compare_jointly(parent, script, keyed, numeric, out, actor)
    out["key_fixed_outside"] = key_fixed_outside(parent, script, keyed, numeric, actor)
    unread = key_placement_unread(parent, script, keyed, out, actor)
    if unread:
        out["key_unread"] = unread
    overridden = key_overridden(parent, script, keyed, numeric, actor)
    if overridden:
        out["key_overridden"] = overridden
