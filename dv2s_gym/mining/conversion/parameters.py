"""The judge's comparison of a failure's parameter values with the ranges of the new script
(:func:`compare_parameters`): by name, else by meaning given the parent script the failure ran
(:func:`parent_script`), each compared parameter checked on every quantity it sets in both scripts.
"""

from __future__ import annotations

import os
from typing import Any, Dict, List, Mapping, Optional, Sequence, Tuple, Union

import numpy as np

from dv2s_gym.mining.conversion.interaction import FailureInteraction
from dv2s_gym.mining.conversion.keys import check_keys
from dv2s_gym.mining.conversion.ranges import comparison_contains, script_ranges, script_supports
from dv2s_gym.mining.conversion.param_meaning import (key_uses, meaning_map, name_mismatch, quantity_uses, script_parameters,
                                           tied_objects)
from scenario_bank.bank import Bank
from scenario_bank.errors import BankError

__all__ = ["compare_parameters", "parent_script", "AMBIGUOUS", "SET_OTHERWISE"]


PathLike = Union[str, os.PathLike]


def compare_parameters(failing: Mapping[str, Any], script: str, parent: Optional[str] = None,
                       interaction: Optional[FailureInteraction] = None) -> Dict[str, Any]:
    """The failing parameter values against the ranges of the new script's global parameters that mean the same:
    first by name, without regard to case (``param x = Range(a, b)`` and the other numeric forms
    :func:`scenario_bank.dedup.param_ranges` reads), then, given the ``parent`` script the failure ran, by meaning
    for the rest (:func:`dv2s_gym.mining.conversion.param_meaning.meaning_map`: the same quantity of the same actor, read
    from the two scripts' structure). Returns ``{"compared": {name: {"value", "range": [low, high]}} (plus
    ``"script_name"`` when the script spells it differently, and ``"by": "meaning"`` with ``"basis"`` when paired
    by meaning), "outside": [names whose range does not contain the failing value], "not_comparable": {failing
    parameter: why it could not be compared}, "not_in_script": [the same names]}``.

    A distribution built from ``Range``/``Uniform`` and numbers by sums, differences, products and quotients with
    numbers and unary minus (``Range(2, 4) * 2 + 1``) is read as the interval it produces
    (:func:`~dv2s_gym.mining.conversion.scenic_values.read_interval`). Given the parent, a counterpart that sets the quantity
    through an affine expression of itself alone (``CutIn(globalParameters.g + 10)``) is compared through that
    expression: the quantity the failing value set in the parent (through the parent's own expression) against
    the interval the new expression produces over the counterpart's range (``"expression"``, ``"interval"``,
    ``"quantity"`` in its comparison; ``"parent_expression"`` when the parent's is not the bare parameter), on every
    quantity the parameter sets in both scripts (``"where"`` names the one kept when there are several). A
    distribution that is not one interval (``Uniform(5, 9)``, ``DiscreteRange(5, 9)``, ``Uniform(Range(1, 2),
    100)``) keeps its values in ``"support"`` (:func:`~dv2s_gym.mining.conversion.scenic_values.read_support`): the failing
    value must be one of them.

    Given the parent, ``"key"`` holds ``{failing parameter: the quantity it sets}`` for the numeric failing parameters
    that set a quantity of the failure's interaction in the parent (the ego's or the key actor's, the
    ``interaction``'s ``actor``, else an actor's of its ``kind``, every actor's when neither is known:
    :func:`~dv2s_gym.mining.conversion.param_meaning.key_parameters`): the judge requires each of them compared
    (:func:`~dv2s_gym.mining.conversion.judge.judge_conversion`); ``"key_fixed_outside"`` those whose key quantity the
    new script fixes without a parameter away from the failing value
    (:func:`~dv2s_gym.mining.conversion.keys.key_fixed_outside`), ``"key_overridden"`` (when any) those whose key
    behaviour argument the new script's behaviour assigns anew
    (:func:`~dv2s_gym.mining.conversion.keys.key_overridden`), ``"key_unread"`` (when any) those whose key actor's
    placement the new script writes in another quantity or form the judge cannot read
    (:func:`~dv2s_gym.mining.conversion.keys.key_placement_unread`), and ``"quantities_not_compared"`` (when any)
    ``{parameter: why}`` for a compared parameter's other quantity the judge could not read
    (:func:`_through_quantities`). A key parameter the new script sets by parameters of its own is compared jointly when
    both scripts' expressions can be read so (:func:`~dv2s_gym.mining.conversion.keys.compare_jointly`)."""
    ranges, supports = script_ranges(script), script_supports(script)
    folded: Dict[str, str] = {}
    for script_name in sorted(ranges):
        folded.setdefault(script_name.casefold(), script_name)
    compared: Dict[str, Any] = {}
    outside: List[str] = []
    absent: List[str] = []
    numeric = {name: value for name, value in sorted(failing.items())
               if not isinstance(value, bool) and isinstance(value, (int, float)) and np.isfinite(value)}
    for name, value in numeric.items():
        script_name = name if name in ranges else folded.get(str(name).casefold())
        if script_name is None:
            absent.append(name)
            continue
        compared[name] = {"value": float(value), "range": [float(v) for v in ranges[script_name]]}
        if script_name in supports:
            compared[name]["support"] = supports[script_name]
        if script_name != name:
            compared[name]["script_name"] = script_name
    why = {name: "the new script defines no numeric parameter of that name" for name in absent}
    keyed: Dict[str, List[Tuple[str, str, str, str]]] = {}
    if parent is not None:
        interaction = interaction if interaction is not None else FailureInteraction()
        keyed = {name: where for name, where in key_uses(parent, interaction.kind,
                                                         interaction.actor).items() if name in numeric}
        meanings = {name: {(obj == "ego", kind, slot) for obj, kind, slot, _ in where} for name, where in keyed.items()}
        why = _by_meaning(parent, script, numeric, compared, absent, ranges, meanings)
    for name in sorted(compared):
        if not comparison_contains(name, compared[name]):
            outside.append(name)
    not_comparable = {name: why[name] for name in sorted(why) if name not in compared}
    out = {"compared": dict(sorted(compared.items())), "outside": outside, "not_comparable": not_comparable,
           "not_in_script": list(not_comparable)}
    partly = {name: comparison.pop("quantities_not_compared") for name, comparison in out["compared"].items()
              if "quantities_not_compared" in comparison}
    if partly:
        out["quantities_not_compared"] = partly
    if parent is not None:
        check_keys(parent, script, keyed, numeric, out, interaction.actor)
    return out


def _through_quantities(parent: str, script: str, compared: Dict[str, Any],
                        key_meanings: Optional[Mapping[str, Any]] = None) -> Dict[str, str]:
    """Each compared parameter is checked on every quantity it sets in both scripts (the same kind of object, the
    ego or not, and slot; :func:`~dv2s_gym.mining.conversion.param_meaning.quantity_uses`), bare uses included: the failing
    value's quantity in the parent (through the parent's own expression) against the interval the new script's
    expression takes over the counterpart's range. A quantity the judge cannot read on one side but can on the
    other (``ego_speed + extra`` against ``e + 100``, ``g`` against ``min(g, 3)``), that neither side reads and
    the two set differently, or that several objects of a kind set with different expressions, cannot be
    compared. The first quantity outside is kept in the comparison (``expression``, ``interval``, ``quantity``,
    ``parent_expression``, ``where``), else, with every quantity inside, the first set through an expression;
    with none outside and one that cannot be compared, the parameter leaves ``compared``, unless one of its key
    quantities (``key_meanings``: ``{parameter: {(the ego?, kind, slot)}}``, the ego's or the key actor's) was
    checked: the parameter is then compared on it (its key quantities first, in the reason too) and each quantity
    that could not be is listed (``quantities_not_compared`` in its comparison). Returns ``{parameter: why it is not
    comparable}``."""
    old_all, new_all = quantity_uses(parent), quantity_uses(script)

    def by_meaning(found: Mapping[Tuple[str, str, str], Any]) -> Dict[Tuple[bool, str, str], List[Any]]:
        keyed: Dict[Tuple[bool, str, str], List[Any]] = {}
        for (name, kind, slot), items in sorted(found.items()):
            keyed.setdefault((name == "ego", kind, slot), []).extend((name,) + tuple(item) for item in items)
        return keyed

    why: Dict[str, str] = {}
    for name, comparison in list(compared.items()):
        target = comparison.get("script_name", name)
        old, new = by_meaning(old_all.get(name, {})), by_meaning(new_all.get(target, {}))
        low, high = comparison["range"]
        outside, shown, unreadable, ambiguous, checked, key_checked = None, None, None, None, False, False
        own_keys = set((key_meanings or {}).get(name, ()))
        shared = sorted(set(old) & set(new), key=lambda key: (key not in own_keys, key))
        for key in shared:
            where = _quantity_words(key, new[key])
            checks, problem = _quantity_checks(old[key], new[key], name, comparison)
            if problem in (AMBIGUOUS, SET_OTHERWISE):  # left aside when another quantity is checked
                ambiguous = ambiguous or f"the {where}: {problem}"
                continue
            if problem is not None:
                unreadable = unreadable or f"the {where}: {problem}"
                continue
            checked = True
            key_checked = key_checked or key in own_keys
            for found, inside in checks:
                if len(shared) > 1:  # which of its quantities, in the reason
                    found["where"] = where
                if not inside and outside is None:
                    outside = found
                if inside and shown is None and "expression" in found:
                    shown = found
        if outside is not None:
            comparison.update(outside)
        elif unreadable is not None and key_checked:
            # compared on its key quantity; the quantity the judge could not read is listed, it does not cancel it
            comparison["quantities_not_compared"] = f"the quantity it also sets cannot be compared: {unreadable}"
            if shown is not None:
                comparison.update(shown)
        elif unreadable is not None or (ambiguous is not None and not checked):
            why[name] = f"the quantity it sets cannot be compared: {unreadable or ambiguous}"
            del compared[name]
        elif shown is not None:
            comparison.update(shown)
    return why


def _quantity_checks(old: Sequence[Tuple[Any, ...]], new: Sequence[Tuple[Any, ...]], name: str,
                     comparison: Mapping[str, Any]) -> Tuple[List[Tuple[Dict[str, Any], bool]], Optional[str]]:
    """``([(comparison fields, inside?)], None)`` for one quantity the parameter sets in both scripts (``old`` and
    ``new``: ``(object, how, quantity or None, text)`` of each use there), or ``([], why it cannot be compared)``:
    one object on each side whose expressions the judge reads, or does not read but sets it the same way (the
    parameter's own range then); several objects of the kind, or several expressions, only when both scripts set
    it with the same expressions (each then checked)."""
    def keys(uses: Sequence[Tuple[Any, ...]]) -> Dict[Any, Any]:
        return {(q.key if q is not None else ("unread", how)): q for _, how, q, _ in uses}

    value, (low, high) = comparison["value"], comparison["range"]
    old_keys, new_keys = keys(old), keys(new)
    if len(old_keys) == 1 and len(new_keys) == 1:
        pairs = [(next(iter(old_keys.items())), next(iter(new_keys.items())))]
    elif set(old_keys) == set(new_keys):
        pairs = [((k, old_keys[k]), (k, new_keys[k])) for k in sorted(old_keys, key=repr)]
    elif len({use[0] for use in old}) > 1 or len({use[0] for use in new}) > 1:
        return [], AMBIGUOUS
    else:
        pairs = []
    checks: List[Tuple[Dict[str, Any], bool]] = []
    for (old_key, before), (new_key, after) in pairs:
        if before is None and after is None and old_key == new_key:
            # neither read, set the same way (the same direction and constant terms): the parameter's own range
            checks.append(({}, comparison_contains(name, comparison)))
            continue
        if before is None and after is None:
            return [], SET_OTHERWISE  # neither read, set differently: left aside when another quantity is checked
        if before is None or after is None:
            pairs = []
            break
        quantity = before.at(value)
        start, end = after.over(low, high)
        found: Dict[str, Any] = {}
        if (before.key, after.key) != (_BARE, _BARE):
            found = {"expression": after.text, "interval": [start, end], "quantity": quantity}
            if before.key != _BARE:
                found["parent_expression"] = before.text
        checks.append((found, comparison_contains(name, {**comparison, **found})))
    if not pairs:
        shown = lambda uses: "; ".join(sorted({text for _, _, _, text in uses}))  # noqa: E731
        return [], (f"the parent sets it by {shown(old)}, the new script by {shown(new)}, and the judge cannot "
                    "read both as the same known function of the parameter")
    return checks, None


_BARE = ("affine", 1.0, 0.0)


AMBIGUOUS = ("several objects of that kind set it with different expressions: which stands for which is not "
             "known")


SET_OTHERWISE = ("the two scripts compute it differently, each with more than the parameter, and the judge reads "
                 "neither")


def _quantity_words(key: Tuple[bool, str, str], uses: Sequence[Tuple[Any, ...]]) -> str:
    """``"ego's speed"``, ``"Car car1's behaviour argument gap"``: the quantity ``key`` names in the new script."""
    ego, kind, slot = key
    quantity = (f"behaviour argument {slot.split(':', 1)[1]}" if slot.startswith("behavior:")
                else f"{slot.split(':', 1)[1]} property" if slot.startswith("with:") else f"{slot} placement"
                if slot in ("longitudinal", "lateral", "offset", "position") else slot)
    names = sorted({use[0] for use in uses})
    return f"ego's {quantity}" if ego else f"{kind} {', '.join(names)}'s {quantity}"


def _by_meaning(parent: str, script: str, numeric: Mapping[str, float], compared: Dict[str, Any],
                absent: List[str], ranges: Mapping[str, Any],
                key_meanings: Optional[Mapping[str, Any]] = None) -> Dict[str, str]:
    """:func:`compare_parameters` given the parent script: a name match that does not mean the same (another actor,
    quantity, direction or constant term, or reaching no object) is not comparable; the rest are paired by meaning
    (their counterpart must be read as an interval); no object of the new script may stand for two parent actors.
    Updates ``compared``; returns ``{failing parameter: why it is not comparable}``."""

    declared, supports = script_parameters(script), script_supports(script)
    why: Dict[str, str] = {}
    for name in list(compared):
        mismatch = name_mismatch(parent, script, name, compared[name].get("script_name", name))
        if mismatch:
            why[name] = mismatch
            del compared[name]
    folded = {n.casefold(): n for n in declared}
    for name in list(absent):
        other = name if name in declared else folded.get(str(name).casefold())
        if other is not None:
            why[name] = (f"its counterpart {other} in the new script has a distribution the judge cannot read as an "
                         f"interval ({declared[other]})")
            absent.remove(name)
    named = {compared[name].get("script_name", name) for name in compared} | {
        folded.get(str(n).casefold(), n) for n in why}
    mapped = meaning_map(parent, script, absent, [n for n in sorted(declared) if n not in named])
    for name, pair in mapped["pairs"].items():
        if pair["target"] not in ranges:
            why[name] = (f"its counterpart {pair['target']} in the new script ({_basis_text(pair)}) has a "
                         f"distribution the judge cannot read as an interval ({declared[pair['target']]})")
            continue
        compared[name] = {"value": float(numeric[name]), "range": [float(v) for v in ranges[pair["target"]]],
                          "script_name": pair["target"], "by": "meaning", "basis": _basis_text(pair)}
        if pair["target"] in supports:
            compared[name]["support"] = supports[pair["target"]]
    why.update({name: f"no parameter of the new script means the same ({reason})"
                for name, reason in mapped["unpaired"].items()})
    why.update({name: "the new script defines no numeric parameter of that name" for name in absent
                if name not in mapped["pairs"] and name not in mapped["unpaired"]})
    why.update(_tied_twice(parent, script, compared))
    why.update(_through_quantities(parent, script, compared, key_meanings))
    return why


def _tied_twice(parent: str, script: str, compared: Dict[str, Any]) -> Dict[str, str]:
    """The compared parameters whose object in the new script is tied (by another compared parameter) to another
    actor of the parent too: one actor cannot stand for two; they leave ``compared``, each with why."""

    ties: Dict[str, Dict[str, List[str]]] = {}
    for name, comparison in compared.items():
        for old, new in tied_objects(parent, script, name, comparison.get("script_name", name)):
            ties.setdefault(new, {}).setdefault(old, []).append(name)
    why: Dict[str, str] = {}
    for new, olds in ties.items():
        if len(olds) > 1:
            for names in olds.values():
                for name in names:
                    why[name] = (f"the new script's {new} would stand for the parent's {' and '.join(sorted(olds))}: "
                                 "one actor cannot be two")
    for name in why:
        compared.pop(name, None)
    return why


def parent_script(scenario: str, bank_dir: Optional[PathLike]) -> Optional[str]:
    """The script of ``scenario``, the bank scenario the failure ran, in the bank in ``bank_dir`` (default the shipped
    bank); ``None`` when it cannot be read: the judge then compares by name only."""
    try:
        return (Bank(bank_dir) if bank_dir else Bank()).get(scenario).script
    except (BankError, OSError):  # the comparison by meaning is an addition; without the parent, names only
        return None


def _basis_text(pair: Mapping[str, Any]) -> str:
    """What a parameter paired by meaning sets, in words: ``"the car's behaviour argument gap (car1; cutter in the
    parent)"``."""
    slot = str(pair["slot"])
    quantity = (f"behaviour argument {slot.split(':', 1)[1]}" if slot.startswith("behavior:")
                else f"{slot.split(':', 1)[1]} property" if slot.startswith("with:") else f"{slot} placement"
                if slot in ("longitudinal", "lateral", "offset", "position") else slot)
    what = "the ego" if pair["object"] == "ego" else f"the {pair['kind']} {pair['object']}"
    parent = "" if pair["object"] == "ego" else f" ({pair['source_object']} in the parent)"
    return f"{what}'s {quantity}{parent}" + (", as a factor" if pair["how"] == "scaled" else "")
