"""The values a Scenic expression can take, read from its text without running it.

A mined failure's parameters are compared with a generated script's ranges, and an exact replay narrows a
parent's distributions around the failing values; both need to know what values an expression takes:
:func:`read_interval` and :func:`read_support` read a distribution (``Range(20, 40)``, ``Uniform(0.3, 1.0)``,
``DiscreteRange(1, 3)``, offset or scaled by numbers) as an interval or a set of numbers, :func:`affine_form`
and :func:`quantity_of` read an expression that is an affine function of one parameter, and
:func:`joint_interval` the interval an expression of several parameters spans.
"""

from __future__ import annotations

import ast
import re
from typing import Any, Dict, List, Mapping, Optional, Sequence, Set, Tuple

__all__ = ["is_number", "affine_node", "LARGEST", "parse_expression", "affine_form", "Quantity", "mentions", "quantity_of", "read_interval", "joint_interval", "placement_parts", "Part", "read_support", "support_hull", "support_contains", "support_text"]

_INTERVAL_CALLS = ("Range", "Uniform")


def is_number(node: ast.AST) -> bool:
    return isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool)


def affine_node(node: ast.AST, param: Optional[str]) -> Optional[Tuple[float, float]]:
    """``(scale, offset)`` of ``node`` as ``scale * globalParameters.<param> + offset``; ``None`` when it is built
    from anything but that parameter, numbers, ``+ - * /`` (a product or quotient by a number only) and unary
    minus or plus."""
    if is_number(node) and _plain(node.value):
        return 0.0, float(node.value)
    if (param is not None and isinstance(node, ast.Attribute) and node.attr == param
            and isinstance(node.value, ast.Name) and node.value.id == "globalParameters"):
        return 1.0, 0.0
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        inner = affine_node(node.operand, param)
        if inner is None:
            return None
        return (-inner[0], -inner[1]) if isinstance(node.op, ast.USub) else inner
    if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.Sub, ast.Mult, ast.Div)):
        left, right = affine_node(node.left, param), affine_node(node.right, param)
        if left is None or right is None:
            return None
        if not all(map(_plain, left + right)):
            return None  # a part beyond LARGEST: rounding may cancel the parameter
        if isinstance(node.op, ast.Add):
            return left[0] + right[0], left[1] + right[1]
        if isinstance(node.op, ast.Sub):
            return left[0] - right[0], left[1] - right[1]
        if isinstance(node.op, ast.Mult):
            if left[0] and right[0]:
                return None  # the parameter times itself: not affine
            return (left[0] * right[1] + right[0] * left[1], left[1] * right[1])
        if right[0] or right[1] == 0.0:
            return None  # a quotient by the parameter, or by zero
        return left[0] / right[1], left[1] / right[1]
    return None


LARGEST = 1e6
"""The largest number (in absolute value) the judge reads in an expression: Scenic computes in floating point, and
beside a larger one a parameter's value is rounded away (``(g + 1e16) - 1e16`` is not ``g``: 6 becomes 6 or 8);
an expression holding one, or whose affine form reaches one, is not read (not comparable). A scene's quantities
(metres, seconds, m/s) stay far below it, where the rounding is below the judge's tolerance of 1e-9."""


def _plain(number: float) -> bool:
    return abs(number) <= LARGEST


def parse_expression(text: str) -> Optional[ast.AST]:
    try:
        return ast.parse(text.strip(), mode="eval").body
    except (SyntaxError, ValueError):
        return None


def affine_form(expression: str, param: str) -> Optional[Tuple[float, float]]:
    """``(scale, offset)`` when ``expression`` is ``scale * globalParameters.<param> + offset`` built from that
    parameter, numbers, sums and differences, products and quotients by numbers and unary minus (nested, in
    brackets), the parameter appearing with a non-zero scale; else ``None``."""
    node = parse_expression(expression)
    form = affine_node(node, param) if node is not None else None
    if form is not None and not all(map(_plain, form)):
        return None  # beyond what floating point keeps exact enough (LARGEST)
    return form if form is not None and form[0] != 0.0 else None


class Quantity:
    """A quantity an expression sets as a known function of one parameter: ``at(value)`` is the quantity a value of
    the parameter gives, ``over(low, high)`` the interval it takes with the parameter in ``low..high``; ``key``
    identifies the function whatever the parameter is called (two scripts' ``g + 10`` and ``gap + 10`` are the same
    function), ``text`` is the expression."""

    def __init__(self, text: str, key: Tuple[Any, ...], node: ast.AST, param: str):
        self.text, self.key, self._node, self._param = text, key, node, param

    def at(self, value: float) -> float:
        return self.over(value, value)[0]

    def over(self, low: float, high: float) -> Tuple[float, float]:
        if self.key[0] == "affine":
            scale, offset = self.key[1], self.key[2]
            ends = sorted((scale * low + offset, scale * high + offset))
            return ends[0], ends[1]
        image = _image(self._node, self._param, low, high)
        assert image is not None  # read at construction
        return image

    def __repr__(self) -> str:
        return f"Quantity({self.text!r})"


def _is_param(node: ast.AST, param: str) -> bool:
    return (isinstance(node, ast.Attribute) and node.attr == param and isinstance(node.value, ast.Name)
            and node.value.id == "globalParameters")


def _image(node: ast.AST, param: str, low: float, high: float) -> Optional[Tuple[float, float]]:
    """The interval ``node`` takes with the parameter in ``low..high``, by interval arithmetic (exact when the
    parameter occurs once): numbers, the parameter, ``+ -``, ``* /`` by a non-zero number, unary minus or plus and
    ``abs``; ``None`` for anything else."""
    if is_number(node) and _plain(node.value):
        return float(node.value), float(node.value)
    if _is_param(node, param):
        return low, high
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        inner = _image(node.operand, param, low, high)
        if inner is None:
            return None
        return (-inner[1], -inner[0]) if isinstance(node.op, ast.USub) else inner
    if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "abs"
            and len(node.args) == 1 and not node.keywords):
        inner = _image(node.args[0], param, low, high)
        if inner is None:
            return None
        if inner[0] >= 0:
            return inner
        if inner[1] <= 0:
            return -inner[1], -inner[0]
        return 0.0, max(-inner[0], inner[1])
    if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.Sub, ast.Mult, ast.Div)):
        left, right = _image(node.left, param, low, high), _image(node.right, param, low, high)
        if left is None or right is None:
            return None
        if isinstance(node.op, ast.Add):
            return left[0] + right[0], left[1] + right[1]
        if isinstance(node.op, ast.Sub):
            return left[0] - right[1], left[1] - right[0]
        number = right if isinstance(node.op, ast.Div) or left[0] != left[1] else left
        if number[0] != number[1] or number[0] == 0.0 or not all(map(_finite, number)):
            return None  # a product of two sampled values, by zero, or a quotient by a sampled value or zero
        if isinstance(node.op, ast.Mult):
            ends = [a * b for a in left for b in right]
        else:
            ends = [a / right[0] for a in left]
        return min(ends), max(ends)
    return None


def _finite(number: float) -> bool:
    return number == number and abs(number) != float("inf")


def mentions(node: ast.AST, param: str) -> int:
    return sum(1 for child in ast.walk(node) if _is_param(child, param))


class _Renamed(ast.NodeTransformer):
    def __init__(self, param: str):
        self.param = param

    def visit_Attribute(self, node: ast.Attribute) -> ast.AST:
        return ast.Name(id="_parameter_", ctx=ast.Load()) if _is_param(node, self.param) else node


def quantity_of(expression: str, param: str) -> Optional[Quantity]:
    """The quantity ``expression`` sets as a known function of ``globalParameters.<param>`` alone: an affine one
    (:func:`affine_form`), or one the parameter occurs in once built from numbers, ``+ - * /`` by numbers, unary
    minus and ``abs`` (its interval read exactly); ``None`` for anything else (another sampled value, a call, ``%``,
    a conditional, a reference point)."""
    node = parse_expression(expression)
    if node is None:
        return None
    text = " ".join(expression.split())
    form = affine_form(expression, param)
    if form is not None:
        return Quantity(text, ("affine", form[0], form[1]), node, param)
    if mentions(node, param) != 1 or not any(isinstance(n, ast.Call) for n in ast.walk(node)):
        return None
    probe = [_image(node, param, low, high) for low, high in ((-1.0, 1.0), (2.0, 3.0))]
    if any(p is None or not all(map(_finite, p)) or p[0] == p[1] for p in probe):
        return None  # unreadable, or a constant however the parameter varies
    return Quantity(text, ("exact", ast.dump(_Renamed(param).visit(parse_expression(expression)))), node, param)


def _signed(op: ast.unaryop, inner: Tuple[float, float]) -> Tuple[float, float]:
    """The interval of ``-x`` or ``+x`` for ``x`` in ``inner``."""
    return (-inner[1], -inner[0]) if isinstance(op, ast.USub) else inner


def _sum_difference_product(op: ast.operator, left: Tuple[float, float],
                            right: Tuple[float, float]) -> Tuple[float, float]:
    """The interval of ``a + b``, ``a - b`` or ``a * b`` (``op`` one of those) for ``a`` in ``left``, ``b`` in
    ``right``."""
    if isinstance(op, ast.Add):
        return left[0] + right[0], left[1] + right[1]
    if isinstance(op, ast.Sub):
        return left[0] - right[1], left[1] - right[0]
    ends = [a * b for a in left for b in right]
    return min(ends), max(ends)


def _interval_node(node: ast.AST) -> Optional[Tuple[float, float]]:
    if is_number(node) and _plain(node.value):
        return float(node.value), float(node.value)
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in _INTERVAL_CALLS \
            and node.args and not node.keywords:
        bounds = [_interval_node(arg) for arg in node.args]
        if any(b is None or b[0] != b[1] for b in bounds) or (node.func.id == "Range" and len(bounds) != 2):
            return None  # bounds must be numbers
        return min(b[0] for b in bounds), max(b[1] for b in bounds)
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        inner = _interval_node(node.operand)
        return None if inner is None else _signed(node.op, inner)
    if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.Sub, ast.Mult, ast.Div)):
        left, right = _interval_node(node.left), _interval_node(node.right)
        if left is None or right is None:
            return None
        if left[0] != left[1] and right[0] != right[1]:
            return None  # two sampled values: only constants may offset or scale a sampled one
        if not isinstance(node.op, ast.Div):
            return _sum_difference_product(node.op, left, right)
        if right[0] != right[1] or right[0] == 0.0:
            return None  # a quotient by a sampled value, or by zero
        ends = [a / right[0] for a in left]
        return min(ends), max(ends)
    return None


def read_interval(expression: str) -> Optional[Tuple[float, float]]:
    """``(low, high)`` a parameter's distribution ranges over when it is built from ``Range(a, b)``,
    ``Uniform(...)`` of numbers and numbers by sums and differences with numbers, products and quotients by numbers
    and unary minus (nested): ``Range(2, 4) * 2 + 1`` is ``(5, 9)``; ``None`` for anything else (a ``Normal``, two
    sampled values combined)."""
    node = parse_expression(expression.split("#", 1)[0])
    return _interval_node(node) if node is not None else None


def joint_interval(expression: str, values: Mapping[str, Tuple[float, float]]) -> Optional[Tuple[float, float]]:
    """``(low, high)``: the values ``expression`` takes when each ``globalParameters.<name>`` in it ranges over
    ``values[name]`` (a point when both ends are equal) and each inline ``Range(a, b)`` of numbers over its interval,
    built by sums, differences, products, quotients (by an interval without 0) and unary minus. Each sampled value
    (a parameter of non-zero width, an inline ``Range``) may appear once only: interval arithmetic is then the exact
    range of the expression over the box (with a value used twice, ``g - g``, it would be wider than the truth).
    ``None`` for anything else: another name, a call, a parameter missing from ``values``."""
    node = parse_expression(expression.split("#", 1)[0])
    if node is None:
        return None
    seen: Set[str] = set()

    def walk(part: ast.AST) -> Optional[Tuple[float, float]]:
        if is_number(part):
            return (float(part.value), float(part.value)) if _plain(part.value) else None
        if isinstance(part, ast.Attribute) and isinstance(part.value, ast.Name) and part.value.id == "globalParameters":
            if part.attr not in values:
                return None
            low, high = values[part.attr]
            if low != high:
                if part.attr in seen:
                    return None
                seen.add(part.attr)
            return float(low), float(high)
        if isinstance(part, ast.Call) and isinstance(part.func, ast.Name) and part.func.id == "Range":
            return _interval_node(part)
        if isinstance(part, ast.UnaryOp) and isinstance(part.op, (ast.USub, ast.UAdd)):
            inner = walk(part.operand)
            return None if inner is None else _signed(part.op, inner)
        if isinstance(part, ast.BinOp) and isinstance(part.op, (ast.Add, ast.Sub, ast.Mult, ast.Div)):
            left, right = walk(part.left), walk(part.right)
            if left is None or right is None:
                return None
            if not isinstance(part.op, ast.Div):
                return _sum_difference_product(part.op, left, right)
            if right[0] <= 0.0 <= right[1]:
                return None
            return _sum_difference_product(ast.Mult(), left, (1.0 / right[1], 1.0 / right[0]))
        return None

    found = walk(node)
    return found if found is not None and all(_finite(v) for v in found) else None


def placement_parts(text: str) -> Tuple[str, str]:
    """``(frame, value)`` of a use's text: for a placement along a lane (``at X.pointAlongBy(value)``) the frame is
    the text with the argument taken out and every name replaced by ``N`` (two placements along a lane from its start
    have the same frame whatever their objects are called), else the frame is ``""`` and the value the text whole."""
    match = re.search(r"pointAlongBy\s*\(", text)
    if match is None:
        return "", text
    depth, start = 1, match.end()
    for index in range(start, len(text)):
        depth += {"(": 1, ")": -1}.get(text[index], 0)
        if depth == 0:
            break
    else:
        return "", text
    frame = text[:start] + "#" + text[index:]
    return re.sub(r"\b[A-Za-z_]\w*\b", "N", re.sub(r"\s+", "", frame)), text[start:index]


_DISCRETE_RANGES = ("DiscreteRange", "VerifaiDiscreteRange")
_CHOICES = ("Uniform", "Options", "Discrete", "VerifaiOptions")
_GRID_LIMIT = 100000

Part = Tuple[Any, ...]
"""A part of the values a distribution takes: ``("interval", low, high)``, ``("points", [v, ...])`` or
``("grid", start, step, count)`` (``start + k * step`` for ``k`` in ``0..count-1``: integers, offset or scaled)."""


def _support_node(node: ast.AST) -> Optional[List[Part]]:
    if is_number(node) and _plain(node.value):
        return [("points", [float(node.value)])]
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.args and not node.keywords:
        call = node.func.id
        if call in ("Range", "VerifaiRange") + _DISCRETE_RANGES:
            bounds = [_interval_node(arg) for arg in node.args]
            if len(bounds) != 2 or any(b is None or b[0] != b[1] for b in bounds):
                return None
            low, high = sorted((bounds[0][0], bounds[1][0]))
            if call in _DISCRETE_RANGES:
                if not (float(low).is_integer() and float(high).is_integer()):
                    return None
                return [("grid", low, 1.0, int(high - low) + 1)]
            return [("interval", low, high)]
        if call in _CHOICES:
            args = list(node.args)
            if len(args) == 1 and isinstance(args[0], (ast.List, ast.Tuple)):
                args = list(args[0].elts)
            elif len(args) == 1 and isinstance(args[0], ast.Dict):
                args = [key for key in args[0].keys if key is not None]
            parts: List[Part] = []
            points: List[float] = []
            for arg in args:
                inner = _support_node(arg)
                if inner is None:
                    return None
                parts += [part for part in inner if part[0] != "points"]
                points += [v for part in inner if part[0] == "points" for v in part[1]]
            return ([("points", sorted(set(points)))] if points else []) + parts or None
        return None
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        inner = _support_node(node.operand)
        return None if inner is None else [_scaled(p, -1.0 if isinstance(node.op, ast.USub) else 1.0, 0.0)
                                           for p in inner]
    if isinstance(node, ast.BinOp) and isinstance(node.op, (ast.Add, ast.Sub, ast.Mult, ast.Div)):
        left, right = _support_node(node.left), _support_node(node.right)
        if left is None or right is None:
            return None
        number = lambda parts: (parts[0][1][0] if len(parts) == 1 and parts[0][0] == "points"  # noqa: E731
                                and len(parts[0][1]) == 1 else None)
        a, b = number(left), number(right)
        if isinstance(node.op, ast.Add):
            return [_scaled(p, 1.0, b) for p in left] if b is not None else (
                [_scaled(p, 1.0, a) for p in right] if a is not None else None)
        if isinstance(node.op, ast.Sub):
            return [_scaled(p, 1.0, -b) for p in left] if b is not None else (
                [_scaled(p, -1.0, a) for p in right] if a is not None else None)
        if isinstance(node.op, ast.Mult):
            if b is not None and b != 0.0:
                return [_scaled(p, b, 0.0) for p in left]
            return [_scaled(p, a, 0.0) for p in right] if a is not None and a != 0.0 else None
        return [_scaled(p, 1.0 / b, 0.0) for p in left] if b is not None and b != 0.0 else None
    return None


def _scaled(part: Part, scale: float, offset: float) -> Part:
    if part[0] == "interval":
        ends = sorted((scale * part[1] + offset, scale * part[2] + offset))
        return ("interval", ends[0], ends[1])
    if part[0] == "points":
        return ("points", [scale * v + offset for v in part[1]])
    return ("grid", scale * part[1] + offset, scale * part[2], part[3])


def read_support(expression: str) -> Optional[List[Part]]:
    """The values a parameter's distribution takes, part by part (:data:`Part`), when it is built from numbers,
    ``Range``, ``DiscreteRange`` (integers), ``Uniform``/``Options``/``Discrete`` of those (their union), offset
    or scaled by numbers: ``Uniform(5, 9)`` is the points 5 and 9, ``Uniform(Range(1, 2), 100)`` the interval 1..2
    and the point 100; ``None`` for anything else."""
    node = parse_expression(expression.split("#", 1)[0])
    return _support_node(node) if node is not None else None


def _ends(part: Part) -> Tuple[float, float]:
    """The smallest and largest value of one :data:`Part`."""
    if part[0] == "interval":
        return part[1], part[2]
    if part[0] == "points":
        return min(part[1]), max(part[1])
    return tuple(sorted((part[1], part[1] + part[2] * (part[3] - 1))))


def support_hull(parts: Sequence[Part]) -> Tuple[float, float]:
    """The smallest interval holding every value of :func:`read_support`'s ``parts``."""
    ends = [end for part in parts for end in _ends(part)]
    return min(ends), max(ends)


def support_contains(parts: Sequence[Part], quantity: float, function: Optional["Quantity"] = None,
                     tolerance: float = 0.0) -> bool:
    """Whether ``quantity`` is a value the distribution ``parts`` takes, or, given ``function``, one that
    ``function`` of such a value takes (a grid of more than 100000 values is read as its interval); given
    ``tolerance``, whether it lies within ``tolerance`` of such a value."""
    close = lambda v: abs(v - quantity) <= tolerance + 1e-9 * max(1.0, abs(quantity))  # noqa: E731
    at = (lambda v: v) if function is None else function.at
    for part in parts:
        if part[0] == "interval":
            low, high = (part[1], part[2]) if function is None else function.over(part[1], part[2])
            if low - 1e-9 - tolerance <= quantity <= high + 1e-9 + tolerance:
                return True
        elif part[0] == "points":
            if any(close(at(v)) for v in part[1]):
                return True
        elif part[3] > _GRID_LIMIT:
            ends = _ends(part)
            low, high = ends if function is None else function.over(*ends)
            if low - 1e-9 - tolerance <= quantity <= high + 1e-9 + tolerance:
                return True
        elif any(close(at(part[1] + k * part[2])) for k in range(part[3])):
            return True
    return False


def support_text(parts: Sequence[Part]) -> str:
    """``"5, 9"``, ``"1..2 or 100"``, ``"the integers 5..9"``: the values of :func:`read_support`'s parts."""
    def number(v: float) -> str:
        short = f"{v:g}"
        return short if float(short) == v else repr(v)

    words = []
    for part in parts:
        if part[0] == "interval":
            words.append(f"{number(part[1])}..{number(part[2])}")
        elif part[0] == "points":
            words.append(", ".join(number(v) for v in part[1]))
        elif part[2] == 1.0:
            words.append(f"the integers {number(part[1])}..{number(part[1] + part[3] - 1)}")
        else:
            words.append(f"{number(part[1])} to {number(part[1] + part[2] * (part[3] - 1))} in steps of "
                         f"{number(part[2])}")
    return " or ".join(words)
