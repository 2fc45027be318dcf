"""Which global parameter of one Scenic script means the same as one of another, read from the scripts' structure.

A generated script names its parameters anew (``car1_cut_gap`` for the parent's ``cut_in_gap``), so the conversion
judge (:func:`dv2s_gym.mining.conversion.parameters.compare_parameters`) cannot find most of a failure's parameters by
name. Here a parameter's *meaning* is where it goes: which object it feeds (the ego, or another actor, with its kind)
and which quantity of it it sets (its *slot*):

- ``speed``: the object's ``with speed``; ``with:<property>``: another ``with`` specifier;
- ``behavior:<argument>``: an argument of the object's behaviour, by the behaviour's own name for it (positional
  arguments read against the ``behavior NAME(...)`` definition in the script, case and underscores ignored);
- ``longitudinal`` (``at ...pointAlongBy(...)``, ``following ... for``, ``ahead of``, ``behind``), ``lateral``
  (``left of``, ``right of``); an offset in an oriented point's frame (``offset by X @ Y``, ``offset along
  roadDirection by X @ Y``, ``at ego offset by X @ Y``: :func:`_offset_form`) sets both, ``Y`` ahead
  (``longitudinal``) and ``X`` to the right (``lateral:right``); ``offset`` (any other ``offset by``/``offset
  along``), ``heading`` (``facing``) and ``position`` (any other placement);

and how it enters the expression there (``scaled`` next to ``*`` or ``/``, ``subtracted`` after a minus, else
``additive``: alone or added, as a distance from a reference point is either way; ``derived ...`` when the
parameter reaches the object only through a top-level variable's computation). An expression that is an affine
function of the one parameter alone (``globalParameters.g + 10``, ``2 * globalParameters.h``,
``-(globalParameters.d - 1) / 2``: numbers, ``+ - * /`` by numbers and unary minus, nested) sets the quantity to a
known function of it: such a use counts as ``additive`` and its quantity keeps the function, so the judge
compares the interval the expression produces rather than the parameter's own range; :func:`quantity_uses` lists
every use with the quantity it sets as such a function (``abs(...)`` of one read exactly too) or ``None`` when it
cannot be read so (another sampled value or reference point beside the parameter, a call, ``%``, a conditional).
A point that only places an actor (``spot = new OrientedPoint ...`` then ``new Pedestrian right of spot``) and a
top-level variable hand their parameters on to the actor that uses them; the point hands on its expression too
(``d + 30``). A variable that is a computation on parameters alone (``x = globalParameters.g + 20``: parameters,
numbers, operators, calls of plain functions) is followed like an expression: where it is used, it stands for its
expression in brackets (``with speed x`` sets the speed to ``g + 20``); any other variable (``crossS = egoS +
globalParameters.d``) hands its parameters on as ``derived`` uses whose quantity is not read.

:func:`key_parameters` names the parameters that set a quantity of the failure's interaction: the ego's or the
adversary's (an actor of the failure's kind).

:func:`meaning_map` pairs the parameters one script does not share by name with the other's: the objects are paired
first (the ego with the ego; another actor with the only one of its kind that has such parameters, else the one whose
slots it shares most, ties broken by the slots set the same way and then by the fewest slots on one side only, when
that is unique), then a parameter with the only parameter of the paired object that has
one of its (slot, how) pairs, counting only the uses where no other unpaired parameter shares the expression (in
``egoS + a + b`` neither ``a`` nor ``b`` alone sets the placement). A pairing that is not one to one (two parameters claiming one, or one matching two) is
left out: what cannot be paired reliably is reported as not comparable, never guessed.
"""

from __future__ import annotations

import ast
import re
from dv2s_gym.mining.conversion.scenic_statements import split_top, top_statements
from dv2s_gym.mining.conversion.scenic_values import (Quantity, affine_node, is_number, mentions, parse_expression, quantity_of,
                                           read_support)
from typing import Any, Dict, List, Mapping, Optional, Sequence, Set, Tuple

__all__ = ["parameter_uses", "meaning_map", "PLACEMENT_KINDS", "name_mismatch", "tied_objects",
           "script_parameters", "quantity_uses", "key_parameters", "key_uses",
           "actor_objects", "counterpart_objects", "fixed_quantities", "script_objects",
           "behaviour_overrides", "object_behaviour_heads", "DEFAULT_LENGTHS", "object_lengths", "placements",
           "lengths_along"]

PLACEMENT_KINDS = ("OrientedPoint", "Point")
"""Classes that place actors but are not actors themselves."""

_PARAM = re.compile(r"globalParameters\.(\w+)")
_OBJECT = re.compile(r"^(?:(\w+)\s*=\s*)?new\s+(\w+)\b(.*)$", re.S)
_ASSIGN = re.compile(r"^(\w+)\s*=\s*(.+)$", re.S)
_BEHAVIOR = re.compile(r"^behavior\s+(\w+)\s*\(([^)]*)\)\s*:", re.M)
_SKIP = ("behavior", "def", "param", "model", "import", "from", "require", "monitor", "scenario", "terminate",
         "record", "mutate", "#", '"""', "'''")

Use = Tuple[str, str, str, str, frozenset]
"""``(object name, its kind, slot, how, the parameters in the same expression)``."""



def _norm(name: str) -> str:
    return name.replace("_", "").casefold()




def _how(expression: str, name: str) -> str:
    """How parameter ``name`` enters ``expression``: ``scaled`` when it, or a bracketed group around it, sits next to
    ``*`` or ``/``; else ``subtracted`` when it, or such a group, follows a minus; else ``additive`` (alone, or
    added, as a distance from a reference point is either way). A function call's brackets end the search (the
    parameter is that call's argument)."""
    found = "additive"
    for match in re.finditer(rf"globalParameters\.{name}\b", expression):
        begin, end = match.start(), match.end()
        how = "additive"
        while True:
            before = expression[:begin].rstrip()
            after = expression[end:].lstrip()
            if before.endswith(("*", "/")) or after.startswith(("*", "/")):
                how = "scaled"
                break
            if before.endswith("-") and how == "additive":
                how = "subtracted"
            if not before.endswith("(") or re.search(r"[\w\]\)]\s*\($", before):
                break  # no group around it, or a call's argument list
            opened = len(before) - 1
            depth, close = 0, None
            for index in range(opened, len(expression)):
                depth += {"(": 1, ")": -1}.get(expression[index], 0)
                if depth == 0:
                    close = index
                    break
            if close is None:
                break
            begin, end = opened, close + 1
        if how == "scaled" or (how == "subtracted" and found == "additive"):
            found = how
    return found + _constant_terms(expression)


_CONSTANT = re.compile(r"([-+*/])\s*(?<![\w.])(\d+(?:\.\d+)?)(?![\w.])|(?<![\w.])(\d+(?:\.\d+)?)(?![\w.])\s*([-+*/])")


def _constant_terms(expression: str) -> str:
    """The constant terms an expression adds or multiplies (``" +10"``, ``" *2"``), as part of a parameter's meaning:
    ``gap + 10`` does not set the same quantity as ``gap``; ``""`` without any."""
    terms = []
    for match in _CONSTANT.finditer(expression):
        operator, number = (match.group(1), match.group(2)) if match.group(1) else (match.group(4), match.group(3))
        if (operator in "+-" and float(number) == 0.0) or (operator in "*/" and float(number) == 1.0):
            continue  # adding 0 or multiplying by 1 changes nothing
        terms.append(f"{operator}{float(number):g}")
    return (" " + " ".join(sorted(terms))) if terms else ""


def _behaviors(script: str) -> Dict[str, List[str]]:
    """``{behaviour name: its argument names}`` of the script's ``behavior`` definitions."""
    found = {}
    for name, formals in _BEHAVIOR.findall(script):
        found[name] = [f.split("=")[0].strip() for f in split_top(formals) if f.strip()]
    return found


def _slots(specifier: str, behaviors: Mapping[str, List[str]],
           oriented: Optional[Set[str]] = None) -> List[Tuple[str, str]]:
    """``[(slot, expression)]`` of one specifier of a ``new`` statement. A placement offset in an oriented point's
    frame (:func:`_offset_form`; ``oriented``: the names of the script's objects that are oriented points, the ego
    always) sets two slots, ``longitudinal`` and ``lateral:right``, with the same expression."""
    text = specifier.strip()
    match = re.match(r"with\s+behavior\s+(\w+)\s*\((.*)\)\s*$", text, re.S)
    if match:
        formals = behaviors.get(match.group(1), [])
        out = []
        for index, argument in enumerate(split_top(match.group(2))):
            keyword = re.match(r"^(\w+)\s*=(?!=)\s*(.*)$", argument, re.S)
            if keyword:
                out.append((f"behavior:{_norm(keyword.group(1))}", keyword.group(2)))
            elif index < len(formals):
                out.append((f"behavior:{_norm(formals[index])}", argument))
        return out
    match = re.match(r"with\s+(\w+)\s+(.*)$", text, re.S)
    if match:
        prop = match.group(1)
        return [("speed" if prop == "speed" else f"with:{_norm(prop)}", match.group(2))]
    form = _offset_form(text)
    if form is not None and form[0] in (oriented or set()) | {"ego"}:
        return [("longitudinal", text), ("lateral:right", text)]
    for pattern, slot in ((r"at\b.*pointAlongBy", "longitudinal"), (r"following\b", "longitudinal"),
                          (r"ahead of\b", "longitudinal"), (r"behind\b", "longitudinal:behind"),
                          (r"left of\b", "lateral:left"), (r"right of\b", "lateral:right"),
                          (r"offset\s+(by|along)\b", "offset"), (r"facing\b", "heading")):
        if re.match(pattern, text, re.S):
            return [(slot, text)]
    return [("position", text)]


def _value_part(slot: str, expression: str, reference: Optional[str] = None) -> str:
    """The part of a slot's expression that is the quantity: a behaviour argument or a ``with`` value whole, the
    distance after ``by`` of ``ahead of``/``behind``/``left of``/``right of`` and after ``for`` of ``following``,
    the vector's second component (ahead) or first (to the right) of an offset (:func:`_offset_form`); ``""`` for
    other placements."""
    if slot.startswith(("behavior:", "with:")) or slot == "speed":
        return expression
    form = _offset_form(expression) if slot in _OFFSET_SLOTS else None
    if form is not None:
        return form[2] if slot == "longitudinal" else form[1]
    if slot == "longitudinal" and "pointAlongBy" in expression:
        return _along(expression, reference)
    match = re.match(r"^(?:ahead of|behind|left of|right of)\s+[\w.]+\s+by\s+(.+)$", expression.strip(), re.S)
    if match is None:
        match = re.match(r"^following\b.*?\bfor\s+(.+)$", expression.strip(), re.S)
    return match.group(1) if match else ""


_OFFSET_SLOTS = ("longitudinal", "lateral:right")
"""The slots an offset in an oriented point's frame sets (:func:`_offset_form`): ahead, and to the right."""


def _unbracketed(text: str) -> str:
    """``text`` without the brackets that enclose all of it."""
    text = text.strip()
    while text.startswith("(") and text.endswith(")"):
        depth = 0
        for index, char in enumerate(text):
            depth += {"(": 1, ")": -1}.get(char, 0)
            if depth == 0:
                break
        if index != len(text) - 1:
            break
        text = text[1:-1].strip()
    return text


def _offset_form(text: str) -> Optional[Tuple[str, str, str]]:
    """``(reference, lateral, longitudinal)`` of a placement offset in an oriented point's frame, or ``None``: the
    specifiers ``offset by X @ Y`` and ``offset along D by X @ Y`` (from the ego) and ``at P offset by X @ Y`` and
    ``at P offset along D by X @ Y`` (from ``P``, a name; in brackets or not). In Scenic 3 ``P offset by X @ Y`` of
    an oriented point ``P`` is ``P``'s local frame: ``Y`` ahead along its heading, ``X`` to its right; ``offset
    along D`` turns the frame to ``D``, read here only when ``D`` is ``roadDirection`` (the road's direction at the
    reference point) or the reference's own ``heading``/``orientation``. The vector must be ``X @ Y`` or
    ``Vector(X, Y)`` (the same offset in Scenic 3.1.1) as a whole (``0 @ g - 90`` is ``(0 @ g) - 90`` in Scenic: not
    read). Whether ``P`` is an oriented point (a vector offset by
    a vector is a sum in the world's frame) is the caller's to check."""
    text = " ".join(text.split())
    at = re.match(r"^at\s+(.*)$", text, re.S)
    if at is not None:
        found = re.match(r"^(\w+)\s+offset\s+(.*)$", _unbracketed(at.group(1)), re.S)
        if found is None:
            return None
        reference, rest = found.group(1), found.group(2)
    else:
        found = re.match(r"^offset\s+(.*)$", text, re.S)
        if found is None:
            return None
        reference, rest = "ego", found.group(1)
    along = re.match(r"^along\s+(.+?)\s+by\s+(.+)$", rest, re.S)
    if along is not None:
        if along.group(1) not in ("roadDirection", f"{reference}.heading", f"{reference}.orientation"):
            return None
        vector = along.group(2)
    elif re.match(r"^by\b", rest):
        vector = rest[2:]
    else:
        return None
    source = vector.strip()
    node = parse_expression(source)
    if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "Vector"
            and len(node.args) == 2 and not node.keywords):
        left, right = node.args  # Vector(X, Y) is X @ Y
    elif isinstance(node, ast.BinOp) and isinstance(node.op, ast.MatMult):
        left, right = node.left, node.right
    else:
        return None
    lateral, longitudinal = ast.get_source_segment(source, left), ast.get_source_segment(source, right)
    if lateral is None or longitudinal is None:
        return None
    return reference, _unbracketed(lateral), _unbracketed(longitudinal)


def _ego_point(script: str) -> Optional[str]:
    """The name the ego is placed at along a lane (``ego = new Car at lane.centerline.pointAlongBy(egoS)``: ``egoS``),
    or ``None``."""
    for statement in top_statements(script):
        found = re.match(r"ego\s*=\s*new\s+\w+\s+at\s+.*?pointAlongBy\s*\(\s*(\w+)\s*\)", statement, re.S)
        if found:
            return found.group(1)
    return None


def _offset_pair(slots: Sequence[Tuple[str, str]]) -> bool:
    """Whether ``slots`` are the two an offset in an oriented point's frame sets (:func:`_slots`): each takes its
    parameters from its own component, and a point it is offset from is handed on once, for both."""
    return tuple(slot for slot, _ in slots) == _OFFSET_SLOTS and _offset_form(slots[0][1]) is not None


def _step(slots: Sequence[Tuple[str, str]], carried: str, slot: str, value: str, offset: bool) -> str:
    """``"<slot> by <distance>"``: how far an object is placed from a point along the direction the point was placed
    in (``carried``, the point's slot): for an offset, its component along that direction."""
    if offset:
        for other, expression in slots:
            if _slot_base(other) == _slot_base(carried):
                return f"{other} by {' '.join(_value_part(other, expression).split())}"
    return f"{slot} by {' '.join(value.split())}"


DEFAULT_LENGTHS: Dict[str, float] = {"Car": 4.5, "NPCCar": 4.5, "Vehicle": 4.5, "Truck": 9.0, "Bus": 12.0,
                                     "Motorcycle": 2.2, "Bicycle": 1.8, "Pedestrian": 0.75, "Obstacle": 1.0,
                                     "OrientedPoint": 0.0, "Point": 0.0}
"""Each class's default length in metres in the model scripts compile against (``envs/scenic_highway/model.scenic``,
over Scenic 3.1.1's driving model: a ``Car`` is 4.5 m long); a placing point has none."""


def _own_length(kind: str, specifiers: Sequence[str]) -> Optional[float]:
    """The length of an object of class ``kind`` made with ``specifiers``: its ``with length N`` when ``N`` is a
    number, else its class's :data:`DEFAULT_LENGTHS`; ``None`` when the judge does not know it (a sampled or computed
    length, a class not listed)."""
    for specifier in specifiers:
        found = re.match(r"^with\s+length\s+(.+)$", specifier.strip(), re.S)
        if found is not None:
            node = parse_expression(found.group(1).strip())
            return float(node.value) if is_number(node) and isinstance(node, ast.Constant) else None
    return DEFAULT_LENGTHS.get(kind)


def object_lengths(script: str) -> Dict[str, Optional[float]]:
    """``{object: its length}`` of the objects ``script`` makes at its top level (placing points included, at 0):
    :func:`_own_length`, ``None`` when the judge does not know it."""
    lengths: Dict[str, Optional[float]] = {}
    for statement in top_statements(script):
        found = _OBJECT.match(statement)
        if found is not None and not statement.startswith(_SKIP):
            lengths[found.group(1) or f"<{found.group(2)}>"] = _own_length(found.group(2), split_top(found.group(3)))
    return lengths


def _between_faces(value: str, expression: str, own: Optional[float],
                   lengths: Mapping[str, Optional[float]]) -> Optional[str]:
    """An offset's distance ahead (``value``, ``Y`` of ``offset by X @ Y``: between the reference's centre and the
    object's) as the distance ``ahead of`` measures, between the reference's front and the object's back: ``Y``
    less half of each length (``own``: the object's; the reference's from ``lengths``), so both forms read as one
    quantity. ``None`` when a length is not known."""
    reference = _offset_form(expression)
    other = lengths.get(reference[0]) if reference is not None else None
    if own is None or other is None:
        return None
    half = (own + other) / 2
    return value if half == 0 else f"({value}) - {half:.12g}"


def _oriented_names(script: str) -> Set[str]:
    """The names of the objects ``script`` makes that are oriented points (any but a ``Point``), and the ego."""
    names = {"ego"}
    for statement in top_statements(script):
        found = _OBJECT.match(statement)
        if found is not None and found.group(1) and found.group(2) != "Point" and not statement.startswith(_SKIP):
            names.add(found.group(1))
    return names


def _along(expression: str, reference: Optional[str] = None) -> str:
    """The distance a ``pointAlongBy(...)`` placement sets from its reference point: the argument without the one
    name it adds (``egoS + globalParameters.gap + 10`` -> ``globalParameters.gap + 10``); ``""`` when the argument
    is not read so: no single reference point added, or one that is not ``reference`` (the name the ego is placed at,
    ``pointAlongBy(egoS)``): a distance from another point (``otherS + gap``) or from the lane's start is not a
    distance from the ego, whatever its value."""
    match = re.search(r"pointAlongBy\s*\(", expression)
    if match is None:
        return ""
    depth, start = 1, match.end()
    for index in range(start, len(expression)):
        depth += {"(": 1, ")": -1}.get(expression[index], 0)
        if depth == 0:
            break
    else:
        return ""
    node = parse_expression(expression[start:index])
    if node is None:
        return ""
    terms: List[Tuple[int, ast.AST]] = []

    def flatten(part: ast.AST, sign: int) -> None:
        if isinstance(part, ast.BinOp) and isinstance(part.op, (ast.Add, ast.Sub)):
            flatten(part.left, sign)
            flatten(part.right, sign if isinstance(part.op, ast.Add) else -sign)
        else:
            terms.append((sign, part))

    flatten(node, 1)
    references = [index for index, (sign, part) in enumerate(terms) if isinstance(part, ast.Name)]
    if len(references) != 1 or terms[references[0]][0] < 0 or terms[references[0]][1].id != reference:
        return ""
    rest = [term for index, term in enumerate(terms) if index not in references]
    if not rest:
        return ""
    built: Optional[ast.AST] = None
    for sign, part in rest:
        if built is None:
            built = part if sign > 0 else ast.UnaryOp(op=ast.USub(), operand=part)
        else:
            built = ast.BinOp(left=built, op=ast.Add() if sign > 0 else ast.Sub(), right=part)
    return ast.unparse(built)


def parameter_uses(script: str) -> Dict[str, Set[Use]]:
    """``{parameter: {(object, kind, slot, how, parameters in the same expression)}}``: where each global parameter
    of ``script`` goes (module docstring); a parameter that feeds no object (a ``require``, a behaviour's body) has
    no use."""
    return _read_uses(script)[0]


QuantityUse = Tuple[str, Optional[Quantity], str]
"""``(how, the quantity as a known function of the parameter or None, the expression's text)``."""


def quantity_uses(script: str) -> Dict[str, Dict[Tuple[str, str, str], List[QuantityUse]]]:
    """``{parameter: {(object, kind, slot): [(how, quantity, expression)]}}``: every use of each global parameter
    of ``script`` on an object (those :func:`parameter_uses` lists), with the quantity it sets as a known function
    of that parameter alone (:func:`quantity_of`; the bare parameter is ``g``, affine) or ``None`` when the judge
    cannot read it so (another sampled value or reference point beside it, a call, a variable's computation). A
    point that places the actor hands its function on: ``spot`` at ``d + 30`` places the actor at ``d + 30``; an
    actor placed along the same direction from the point (``ahead of spot by 5``) adds to it, so that use is not
    read (and its ``how`` says so)."""
    return _read_uses(script)[1]


def _slot_base(slot: str) -> str:
    return slot.split(":", 1)[0]


def _read_uses(script: str) -> Tuple[Dict[str, Set[Use]],
                                     Dict[str, Dict[Tuple[str, str, str], List[QuantityUse]]]]:
    behaviors = _behaviors(script)
    uses: Dict[str, Set[Use]] = {}
    quantities: Dict[str, Dict[Tuple[str, str, str], List[QuantityUse]]] = {}
    # variable or placement -> [(param, slot, how, quantity, text)]
    carried: Dict[str, List[Tuple[str, str, str, Optional[Quantity], str]]] = {}

    def carried_by(expression: str) -> List[Tuple[str, str, str, Optional[Quantity], str]]:
        return [item for name, items in carried.items() if re.search(rf"\b{re.escape(name)}\b", expression)
                for item in items]

    numbers: Dict[str, str] = {}  # variable -> its expression, when it is a computation on parameters
    ego_point = _ego_point(script)
    oriented = _oriented_names(script)
    lengths = object_lengths(script)
    centred: Set[str] = set()  # placing points offset from an object (see _object_items)
    for statement in top_statements(script):
        if statement.startswith(_SKIP):
            continue
        statement = _followed(statement, numbers)
        found = _OBJECT.match(statement)
        if found is None:
            assign = _ASSIGN.match(statement)
            if assign and "new " not in assign.group(2):
                expression = assign.group(2)
                if _is_computation(expression):  # followed where it is used, as if written there
                    numbers[assign.group(1)] = " ".join(expression.split())
                    carried.pop(assign.group(1), None)
                    continue
                numbers.pop(assign.group(1), None)
                text = " ".join(expression.split())
                # a parameter that reaches an object through a variable is part of a computation: "derived", and
                # the quantity it sets is not read
                carried[assign.group(1)] = ([(p, "position", "derived " + _how(expression, p), None, text)
                                             for p in _PARAM.findall(expression)]
                                            + [(p, s, how if how.startswith("derived") else "derived " + how, None, t)
                                               for p, s, how, _, t in carried_by(expression)])
            continue
        name, kind, rest = found.group(1) or f"<{found.group(2)}>", found.group(2), found.group(3)
        context = (behaviors, oriented, ego_point, lengths, centred)
        items = _object_items(kind, split_top(rest), context, carried_by)
        if kind in PLACEMENT_KINDS and any(_offset_pair(_slots(spec, behaviors, oriented))
                                           for spec in split_top(rest)):
            centred.add(name)  # its distance ahead, read between faces, leaves out the half length of what it places
        if kind in PLACEMENT_KINDS:
            carried[name] = [(p, s, how, quantity, text) for p, s, how, _, quantity, text in items]
            continue  # handed on to the actor it places
        for param, slot, how, together, quantity, text in items:
            uses.setdefault(param, set()).add((name, kind, slot, how, together))
            listed = quantities.setdefault(param, {}).setdefault((name, kind, slot), [])
            if not any(h == how and (q.key if q else t) == (quantity.key if quantity else text)
                       for h, q, t in listed):
                listed.append((how, quantity, text))
    return uses, quantities


def _object_items(kind: str, specifiers: Sequence[str], context: Tuple[Any, ...],
                  carried_by) -> List[Tuple[str, str, str, frozenset, Optional[Quantity], str]]:
    """``[(parameter, slot, how, the parameters in the same expression, quantity, text)]`` of one ``new`` statement
    of class ``kind`` (:func:`_read_uses`); ``context``: the script's behaviours, oriented names, the ego's point along
    its lane, the objects' lengths (:func:`object_lengths`) and the placing points offset from an object
    (``centred``). An offset's distance ahead is read between faces, as ``ahead of`` measures it
    (:func:`_between_faces`; a placing point offset from an object has no length, so the actor it places takes off
    its own half length where it hands the distance on); with a length not known, it is not read."""
    behaviors, oriented, ego_point, lengths, centred = context
    own = _own_length(kind, specifiers)
    items: List[Tuple[str, str, str, frozenset, Optional[Quantity], str]] = []
    for specifier in specifiers:
        slots = _slots(specifier, behaviors, oriented)
        offset = _offset_pair(slots)
        for index, (slot, expression) in enumerate(slots):
            value = _value_part(slot, expression, ego_point)
            measured = (_between_faces(value, expression, own, lengths) if offset and slot == "longitudinal"
                        else value)
            here: List[Tuple[str, str, str, Optional[Quantity], str]] = []
            for p in dict.fromkeys(_PARAM.findall(value if offset else expression)):
                if value and _zero_use(value, p):
                    continue  # times 0: the parameter does not set the quantity (a constant, or others)
                quantity = quantity_of(measured, p) if measured else None
                if quantity is None:
                    here.append((p, slot, _how(value if offset else expression, p), None,
                                 " ".join(expression.split())))
                else:  # a known function of p alone: compared through the interval it produces
                    here.append((p, slot, "additive", quantity, quantity.text))
            bases = {_slot_base(s) for s, _ in slots} if offset else {_slot_base(slot)}
            from_centred = any(re.search(rf"\b{re.escape(point)}\b", expression) for point in centred)
            for p, s, how, quantity, text in (carried_by(expression) if not (offset and index) else []):
                if s == "position":
                    here.append((p, slot, how, quantity, text))
                elif value and _slot_base(s) in bases:
                    # placed along the same direction from the point: the distances add up
                    here.append((p, s, f"{how} then {_step(slots, s, slot, value, offset)}", None,
                                 f"{text}, then {' '.join(expression.split())}"))
                elif s == "longitudinal" and from_centred and quantity is not None:
                    quantity = quantity_of(f"({quantity.text}) - {own / 2:.12g}", p) if own is not None else None
                    here.append((p, s, how, quantity, quantity.text if quantity is not None else text))
                else:
                    here.append((p, s, how, quantity, text))
            items += [(p, s, how, frozenset(q for q, t, _, _, _ in here if t == s), quantity, text)
                      for p, s, how, quantity, text in here]
    return items


def placements(script: str) -> Dict[str, List[str]]:
    """``{object: its placement specifiers}``: the specifiers of each top-level ``new`` statement that are not ``with``
    ones (``ahead of ego by 10``, ``at ego.position + Vector(0, 40)``, ``facing 30 deg``), each on one line."""
    out: Dict[str, List[str]] = {}
    for statement in top_statements(script):
        found = _OBJECT.match(statement)
        if found is not None and not statement.startswith(_SKIP):
            out[found.group(1) or f"<{found.group(2)}>"] = [
                " ".join(spec.split()) for spec in split_top(found.group(3))
                if spec.strip() and not re.match(r"^with\b", spec.strip())]
    return out


def lengths_along(script: str, obj: str) -> Optional[float]:
    """The length of ``obj`` plus the length of the object its distance ahead or behind is measured from (``ahead of
    P``, ``behind P``, an offset from ``P``: :func:`_offset_form`): what separates ``ahead of P by d`` from ``behind P
    by -d - lengths`` (the two measure from opposite faces); ``None`` when it is placed otherwise or a length is not
    known (:func:`object_lengths`)."""
    lengths = object_lengths(script)
    for specifier in placements(script).get(obj, []):
        form = _offset_form(specifier)
        found = re.match(r"^(?:ahead of|behind)\s+(\w+)\b", specifier)
        reference = form[0] if form is not None else found.group(1) if found else None
        if reference is not None:
            own, other = lengths.get(obj), lengths.get(reference)
            return None if own is None or other is None else own + other
    return None


def _zero_use(value: str, param: str) -> bool:
    """Whether ``globalParameters.<param>`` enters ``value`` only with a coefficient 0 (``g * 0 - 15``, ``0 * g +
    h``): whatever its value, the quantity is the same, so it is no use of the parameter. Read by the affine form with
    the other parameters held as unknowns (each other parameter is replaced by a number, twice: the parameter's
    coefficient must be 0 both times)."""
    node = parse_expression(value)
    if node is None or not mentions(node, param):
        return False
    for probe in (1.0, 2.0):
        class _Others(ast.NodeTransformer):
            def visit_Attribute(self, n: ast.Attribute) -> ast.AST:
                if (isinstance(n.value, ast.Name) and n.value.id == "globalParameters" and n.attr != param):
                    return ast.Constant(value=probe)
                return n
        form = affine_node(_Others().visit(parse_expression(value)), param)
        if form is None or form[0] != 0.0:
            return False
    return True


def fixed_quantities(script: str) -> Dict[Tuple[str, str, str], str]:
    """``{(object, kind, slot): the value it is fixed at}``: each quantity of an object (the slots
    :func:`quantity_uses` reads: speed, a placement's distance, a behaviour argument, a ``with`` property) that
    ``script`` sets with no global parameter, to a value :func:`read_support` reads (a number, an inline ``Range``,
    ``Uniform``, ``Options``...; a parameter times 0 counts as a number). A point that places an object hands its
    fixed distance on, as it hands on a parameter's (:func:`quantity_uses`); a top-level variable holding such a value
    is followed."""
    behaviors = _behaviors(script)
    fixed: Dict[Tuple[str, str, str], str] = {}
    carried: Dict[str, List[Tuple[str, str]]] = {}
    constants: Dict[str, str] = {}
    ego_point = _ego_point(script)
    oriented = _oriented_names(script)
    lengths = object_lengths(script)
    centred: Set[str] = set()  # placing points offset from an object: _object_items

    def constant(value: str) -> Optional[str]:
        text = " ".join(value.split())
        if text in constants:
            text = constants[text]
        for p in dict.fromkeys(_PARAM.findall(text)):
            if not _zero_use(text, p):
                return None
            form = affine_node(parse_expression(text), p)
            if form is None:
                return None
            text = f"{form[1]:g}"
        return text if text and read_support(text) is not None else None

    for statement in top_statements(script):
        if statement.startswith(_SKIP):
            continue
        found = _OBJECT.match(statement)
        if found is None:
            assign = _ASSIGN.match(statement)
            if assign and "new " not in assign.group(2):
                text = " ".join(assign.group(2).split())
                if not _PARAM.search(text) and read_support(text) is not None:
                    constants[assign.group(1)] = text
                else:
                    constants.pop(assign.group(1), None)
            continue
        name, kind, rest = found.group(1) or f"<{found.group(2)}>", found.group(2), found.group(3)
        own = _own_length(kind, split_top(rest))
        here: List[Tuple[str, str]] = []
        for specifier in split_top(rest):
            slots = _slots(specifier, behaviors, oriented)
            offset = _offset_pair(slots)
            for index, (slot, expression) in enumerate(slots):
                value = _value_part(slot, expression, ego_point)
                bases = {_slot_base(s) for s, _ in slots} if offset else {_slot_base(slot)}
                for point, items in (carried.items() if not (offset and index) else ()):
                    if re.search(rf"\b{re.escape(point)}\b", expression):
                        if value and any(_slot_base(s) in bases for s, _ in items):
                            continue  # placed along the same direction from the point: the distances add up
                        here += [_less_half(item, own) if point in centred else item for item in items]
                read = constant(value) if value else None
                if read is not None and offset and slot == "longitudinal":
                    read = _between_faces(read, expression, own, lengths)  # as ahead of measures it
                if read is not None:
                    here.append((slot, read))
        if kind in PLACEMENT_KINDS:
            carried[name] = [item for item in here if item[1] is not None]
            if any(_offset_pair(_slots(spec, behaviors, oriented)) for spec in split_top(rest)):
                centred.add(name)
            continue
        for slot, text in here:
            if text is not None:
                fixed.setdefault((name, kind, slot), text)
    return fixed


def _less_half(item: Tuple[str, Optional[str]], own: Optional[float]) -> Tuple[str, Optional[str]]:
    """A fixed distance ahead a placing point offset from an object hands on (``(slot, value)``), less the half
    length of the actor it places (``own``; ``None``, not read, when that is not known): :func:`_object_items`."""
    slot, text = item
    if slot != "longitudinal" or text is None:
        return item
    return (slot, f"({text}) - {own / 2:.12g}" if own is not None else None)


_REASSIGN = re.compile(r"^(\w+)\s*([-+*/]?=)(?!=)\s*(.+)$")


def object_behaviour_heads(script: str) -> Dict[str, Tuple[str, Tuple[str, ...]]]:
    """``{object: (its behaviour's name, the behaviour's argument names)}`` for each object given a behaviour
    (the argument names empty for a behaviour the script does not define)."""
    behaviors = _behaviors(script)
    out: Dict[str, Tuple[str, Tuple[str, ...]]] = {}
    for statement in top_statements(script):
        found = _OBJECT.match(statement)
        if found is None or statement.startswith(_SKIP):
            continue
        called = re.search(r"\bwith\s+behavior\s+(\w+)", found.group(3))
        if called:
            out[found.group(1) or f"<{found.group(2)}>"] = (called.group(1),
                                                             tuple(behaviors.get(called.group(1), ())))
    return out


def behaviour_overrides(script: str) -> Dict[Tuple[str, str, str], str]:
    """``{(object, kind, "behavior:<argument>"): the statement}`` for each argument of an object's behaviour that the
    behaviour's body assigns anew (``extraSpeed = 25``, ``speed += 1``, anywhere in the body, under a condition
    too): the value the object is given for that argument is then not (or not only) what the behaviour uses, so a
    parameter passed there does not set the quantity alone. The first such statement is kept."""
    lines = script.splitlines()
    overridden: Dict[str, Dict[str, str]] = {}
    for index, line in enumerate(lines):
        head = _BEHAVIOR.match(line)
        if head is None:
            continue
        formals = {f.split("=")[0].strip() for f in split_top(head.group(2)) if f.strip()}
        found: Dict[str, str] = {}
        for following in lines[index + 1:]:
            if following.strip() and not following[0].isspace():
                break
            statement = re.sub(r"#.*$", "", following).strip()
            match = _REASSIGN.match(statement)
            if match and match.group(1) in formals:
                found.setdefault(_norm(match.group(1)), " ".join(statement.split()))
        overridden[head.group(1)] = found
    out: Dict[Tuple[str, str, str], str] = {}
    kinds = dict(script_objects(script))
    for obj, (name, _) in object_behaviour_heads(script).items():
        for argument, statement in overridden.get(name, {}).items():
            out[(obj, kinds.get(obj, ""), f"behavior:{argument}")] = statement
    return out


def script_objects(script: str) -> List[Tuple[str, str]]:
    """``[(object, kind)]`` of the actors ``script`` makes at its top level (placing points left out), in order."""
    objects = []
    for statement in top_statements(script):
        if statement.startswith(_SKIP):
            continue
        found = _OBJECT.match(statement)
        if found is not None and found.group(2) not in PLACEMENT_KINDS:
            objects.append((found.group(1) or f"<{found.group(2)}>", found.group(2)))
    return objects


def _is_computation(expression: str) -> bool:
    """Whether a top-level variable's ``expression`` is a computation on global parameters alone: it mentions one
    and, besides ``globalParameters.<name>``, holds only numbers, operators and calls of plain functions (``min``,
    ``Range``...), so where the variable is used it stands for that expression (``x = globalParameters.g + 20``, then
    ``with speed x``, sets the speed to ``g + 20``)."""
    node = parse_expression(expression.split("#", 1)[0])
    if node is None or not _PARAM.search(expression):
        return False
    calls = {id(n.func) for n in ast.walk(node) if isinstance(n, ast.Call)}
    for child in ast.walk(node):
        if isinstance(child, ast.Attribute):
            if not (isinstance(child.value, ast.Name) and child.value.id == "globalParameters"):
                return False
        elif isinstance(child, ast.Name):
            if child.id != "globalParameters" and id(child) not in calls:
                return False
        elif isinstance(child, (ast.Lambda, ast.ListComp, ast.GeneratorExp, ast.DictComp, ast.SetComp,
                                ast.Starred, ast.NamedExpr)):
            return False
    return True


def _followed(statement: str, numbers: Mapping[str, str]) -> str:
    """``statement`` with each use of a variable :func:`_is_computation` read (not an attribute, a keyword or the
    name it assigns) replaced by its expression in brackets."""
    if not numbers:
        return statement
    assigned = _ASSIGN.match(statement)
    head, body = ((statement[:assigned.start(2)], statement[assigned.start(2):]) if assigned
                  else ("", statement))
    pattern = re.compile(r"(?<![\w.])(" + "|".join(map(re.escape, sorted(numbers, key=len, reverse=True)))
                         + r")(?![\w])(?!\s*=(?!=))")
    return head + pattern.sub(lambda m: f"({numbers[m.group(1)]})", body)


def _actor_slots(uses: Mapping[str, Set[Use]], params: Sequence[str]) -> Dict[Tuple[str, str], Set[Tuple[str, str]]]:
    """``{(object, kind): {(slot, how)}}`` over ``params``."""
    actors: Dict[Tuple[str, str], Set[Tuple[str, str]]] = {}
    for param in params:
        for name, kind, slot, how, _ in uses.get(param, ()):
            actors.setdefault((name, kind), set()).add((slot, how))
    return actors


def _pair_actors(source: Mapping[Tuple[str, str], Set[Tuple[str, str]]],
                 target: Mapping[Tuple[str, str], Set[Tuple[str, str]]]) -> Dict[Tuple[str, str], Tuple[str, str]]:
    """Each source object with its target object: the ego with the ego; another with the only target object of its
    kind, else the one sharing the most slots when that is unique (ties broken by the slots set the same way, then by
    the fewest slots on one side only); one to one."""
    pairs: Dict[Tuple[str, str], Tuple[str, str]] = {}
    for actor, slots in source.items():
        if actor[0] == "ego":
            if ("ego", actor[1]) in target:
                pairs[actor] = ("ego", actor[1])
            continue
        same_kind = [other for other in target if other[1] == actor[1] and other[0] != "ego"]
        if len(same_kind) == 1:
            pairs[actor] = same_kind[0]
            continue
        names = {slot for slot, _ in slots}

        def score(other: Tuple[str, str]) -> Tuple[int, int, int]:
            # the slots shared, then the (slot, how) pairs shared, then the fewest slots on one side only
            theirs = {slot for slot, _ in target[other]}
            return len(names & theirs), len(slots & target[other]), -len(names ^ theirs)

        scores = sorted(((score(o), o) for o in same_kind), reverse=True)
        if scores and scores[0][0][0] > 0 and (len(scores) == 1 or scores[1][0] < scores[0][0]):
            pairs[actor] = scores[0][1]
    claimed: Dict[Tuple[str, str], int] = {}
    for other in pairs.values():
        claimed[other] = claimed.get(other, 0) + 1
    return {actor: other for actor, other in pairs.items() if claimed[other] == 1}


def meaning_map(source_script: str, target_script: str, source_params: Sequence[str],
                target_params: Sequence[str]) -> Dict[str, Any]:
    """Pair each of ``source_params`` (parameters of ``source_script``, e.g. a failure's parent, not found by name in
    the other script) with one of ``target_params`` (the other script's, not named like any source parameter) by
    meaning (module docstring). Returns ``{"pairs": {source: {"target", "object", "kind", "slot", "how"}},
    "unpaired": {source: why}}``."""
    open_source, open_target = set(source_params), set(target_params)

    def own(uses: Mapping[str, Set[Use]], free: Set[str]) -> Dict[str, Set[Tuple[str, str, str, str]]]:
        # a use counts only where no other unpaired parameter shares its expression: in ``egoS + a + b`` neither
        # a nor b alone sets the placement
        return {param: {(o, k, slot, how) for o, k, slot, how, together in found if not (together - {param}) & free}
                for param, found in uses.items()}

    source_all, target_all = parameter_uses(source_script), parameter_uses(target_script)
    source_uses, target_uses = own(source_all, open_source), own(target_all, open_target)
    actors = _pair_actors(_actor_slots(source_all, source_params), _actor_slots(target_all, target_params))
    candidates: Dict[str, List[Tuple[str, Tuple[str, str, str, str]]]] = {}
    unpaired: Dict[str, str] = {}
    for param in source_params:
        if not source_all.get(param):
            unpaired[param] = "feeds no object of its script (a behaviour's body, a requirement or unused)"
            continue
        found: Dict[str, Tuple[str, str, str, str]] = {}
        for name, kind, slot, how in sorted(source_uses.get(param, ())):
            other = actors.get((name, kind))
            if other is None:
                continue
            for target in target_params:
                if target not in found and (other[0], other[1], slot, how) in target_uses.get(target, ()):
                    found[target] = (other[0], other[1], slot, how)
        if not any(actors.get((name, kind)) for name, kind, _, _, _ in source_all[param]):
            unpaired[param] = "its object has no counterpart in the other script"
        elif not source_uses.get(param):
            unpaired[param] = "it sets its object's quantities only together with other parameters"
        elif not found:
            unpaired[param] = "no parameter of the other script sets the same quantity of that object"
        elif len(found) > 1:
            unpaired[param] = f"ambiguous: {', '.join(sorted(found))} set the same quantity"
        else:
            candidates[param] = list(found.items())
    claimed: Dict[str, List[str]] = {}
    for param, found in candidates.items():
        claimed.setdefault(found[0][0], []).append(param)
    pairs: Dict[str, Any] = {}
    for target, params in claimed.items():
        if len(params) > 1:
            for param in params:
                unpaired[param] = f"ambiguous: {', '.join(sorted(params))} all match {target}"
            continue
        name, kind, slot, how = candidates[params[0]][0][1]
        source = next(actor for actor, _, s, h in sorted(source_uses[params[0]])
                      if actors.get((actor, kind)) == (name, kind) and (s, h) == (slot, how))
        pairs[params[0]] = {"target": target, "object": name, "source_object": source, "kind": kind, "slot": slot,
                            "how": how}
    return {"pairs": dict(sorted(pairs.items())), "unpaired": dict(sorted(unpaired.items()))}


def key_parameters(script: str, kind: Optional[str] = None, actor: Optional[str] = None) -> Dict[str, str]:
    """``{parameter: the quantity it sets, in words}`` of the parameters of ``script`` that set a quantity of the
    failure's interaction (:func:`key_uses`)."""
    return {param: where[0][3] for param, where in key_uses(script, kind, actor).items()}


def key_uses(script: str, kind: Optional[str] = None,
             actor: Optional[str] = None) -> Dict[str, List[Tuple[str, str, str, str]]]:
    """``{parameter: [(object, kind, slot, the quantity in words)]}``: the quantities of the failure's interaction, the
    ones the failure depends on, each parameter of ``script`` sets: any quantity (speed, placement, behaviour
    argument, ``with`` property; directly, through a placing point or a variable) of the ego or of the failure's
    key actor (:func:`dv2s_gym.mining.conversion.interaction.failure_interaction`'s ``actor`` and ``kind``). The key actor is
    the object of ``script`` the simulation names ``actor`` (:func:`actor_objects`: its ``with name``, else its
    class and rank, ``Car2``); when no object is found so, every actor of the ``kind`` (``"car"``,
    ``"pedestrian"``: Scenic's class name, case ignored); when that is unknown too or no actor is of it, every
    actor. A parameter that sets only other actors' quantities (traffic beside the interaction) or feeds no object (a
    requirement, a behaviour's body) has none. The ego's quantities come first."""
    uses = parameter_uses(script)
    chosen = actor_objects(script).get(actor) if actor else None
    wanted = (kind or "").casefold()
    present = {k.casefold() for found in uses.values() for name, k, _, _, _ in found if name != "ego"}
    match = bool(wanted) and wanted in present

    def is_key(name: str, k: str) -> bool:
        if name == "ego":
            return True
        if chosen is not None:
            return name == chosen
        return not match or k.casefold() == wanted

    key: Dict[str, List[Tuple[str, str, str, str]]] = {}
    for param, found in sorted(uses.items()):
        where = sorted({(name, k, slot) for name, k, slot, _, _ in found if is_key(name, k)},
                       key=lambda use: (use[0] != "ego", use[2] != "speed") + use)
        if where:
            key[param] = [(name, k, slot, ("the ego" if name == "ego" else f"the {k} {name}")
                           + f"'s {_slot_words(slot)}") for name, k, slot in where]
    return key


def counterpart_objects(source_script: str, target_script: str) -> Dict[Tuple[str, str], Tuple[str, str]]:
    """``{(object, kind) of source_script: (object, kind) of target_script}``: the objects paired as
    :func:`meaning_map` pairs them, over every parameter of the two scripts."""
    source, target = parameter_uses(source_script), parameter_uses(target_script)
    return _pair_actors(_actor_slots(source, list(source)), _actor_slots(target, list(target)))


def actor_objects(script: str) -> Dict[str, str]:
    """``{the name a simulation gives an actor: the script's object}`` (the object's variable, or ``<Class>``), as
    the simulator names them: the ego ``ego``; another object its ``with name "..."`` when no other object has that
    name, else its name or class and its rank among those in the script's order (``Car1``, ``Car2``; two objects
    named "walker": ``walker1``, ``walker2``). Objects made in a loop or a condition are not known here."""
    objects: List[Tuple[str, str]] = []  # (object, label)
    named: List[Optional[str]] = []
    for statement in top_statements(script):
        if statement.startswith(_SKIP):
            continue
        found = _OBJECT.match(statement)
        if found is None or found.group(2) in PLACEMENT_KINDS:
            continue
        name = found.group(1) or f"<{found.group(2)}>"
        if name == "ego":
            continue
        given = re.search(r"\bwith\s+name\s+(['\"])(.+?)\1", found.group(3))
        named.append(given.group(2) if given else None)
        objects.append((name, given.group(2) if given else found.group(2)))
    out: Dict[str, str] = {}
    counts: Dict[str, int] = {}
    for name, label in objects:
        counts[label] = counts.get(label, 0) + 1
        out[f"{label}{counts[label]}"] = name
    taken = set(out) | {"ego"}
    for (name, _), given in zip(objects, named):
        if given and given != "ego" and named.count(given) == 1 and given not in taken:
            out[given] = name
            taken.add(given)
    return out


def _slot_words(slot: str) -> str:
    """``"speed"``, ``"behaviour argument gap"``, ``"longitudinal placement"``: a slot in words."""
    return (f"behaviour argument {slot.split(':', 1)[1]}" if slot.startswith("behavior:")
            else f"{slot.split(':', 1)[1]} property" if slot.startswith("with:") else f"{slot} placement"
            if slot in ("longitudinal", "lateral", "offset", "position") else slot)


def script_parameters(script: str) -> Dict[str, str]:
    """``{name: its distribution's text}`` of every ``param NAME = ...`` of ``script`` (also those not read as an
    interval: a ``Normal(...)``, an arithmetic expression)."""
    return {name: text.strip() for name, text in re.findall(r"^param\s+(\w+)\s*=\s*(.+)$", script, re.M)}


def _meaning_of(uses: Set[Use]) -> Set[Tuple[bool, str, str, str]]:
    """The meaning of a parameter's uses without the objects' names: (the ego?, kind, slot, how)."""
    return {(name == "ego", kind, slot, how) for name, kind, slot, how, _ in uses}


def name_mismatch(source_script: str, target_script: str, source_name: str, target_name: str) -> Optional[str]:
    """Why ``target_name`` of ``target_script``, named like ``source_name`` of ``source_script``, does not mean the
    same, or ``None`` when it does (or when the source parameter feeds no object, so its meaning is unknown): it
    reaches no object of the scene, or no use of it sets the same kind of object's same quantity, in the same
    direction and with the same constant terms, as a use of the source parameter does."""
    source = parameter_uses(source_script).get(source_name) or set()
    if not source:
        return None
    target = parameter_uses(target_script).get(target_name) or set()
    if not target:
        return f"the new script's {target_name} reaches no object of the scene"
    if not _meaning_of(source) & _meaning_of(target):
        def words(uses: Set[Use]) -> str:
            return ", ".join(sorted(f"{name} ({kind}) {slot} {how}" for name, kind, slot, how, _ in uses))
        return f"named alike but not the same meaning: the parent's sets {words(source)}, the new script's {words(target)}"
    return None


def tied_objects(source_script: str, target_script: str, source_name: str, target_name: str) -> Set[Tuple[str, str]]:
    """``{(source object, target object)}`` (other than the ego) that the two parameters tie together: a meaning
    (kind, slot, how) set on exactly one object in each script by that parameter."""
    source = parameter_uses(source_script).get(source_name) or set()
    target = parameter_uses(target_script).get(target_name) or set()
    ties = set()
    for meaning in _meaning_of(source) & _meaning_of(target):
        if meaning[0]:
            continue
        old = {name for name, kind, slot, how, _ in source if (name == "ego", kind, slot, how) == meaning}
        new = {name for name, kind, slot, how, _ in target if (name == "ego", kind, slot, how) == meaning}
        if len(old) == 1 and len(new) == 1:
            ties.add((next(iter(old)), next(iter(new))))
    return ties
