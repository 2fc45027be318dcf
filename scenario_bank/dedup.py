"""When two scenarios are the same: byte-for-byte (:func:`content_hash`), semantically (:func:`semantic_key`:
the same elements, map and parameter ranges), near-duplicates (:func:`near_duplicate`: the same map and elements,
overlapping numeric parameter ranges) or near-copies (:func:`changed_code_lines`), and the searches of a bank's
entries for each (what :meth:`scenario_bank.bank.Bank.add` refuses or merges into).
"""

from __future__ import annotations

import ast
import difflib
import hashlib
import json
import re
from typing import Any, Callable, Dict, List, Mapping, Optional, Tuple

from scenario_bank.elements import Elements

__all__ = ["content_hash", "names_something", "semantic_key", "param_ranges", "near_duplicate", "NEAR_COPY_LINES",
           "changed_code_lines", "find_duplicate", "find_near_duplicate", "find_near_copy"]


def content_hash(script: str) -> str:
    """SHA-256 of a script's UTF-8 bytes (the sidecar's ``content_hash``)."""
    return hashlib.sha256(script.encode("utf-8")).hexdigest()


_PARAM = re.compile(r"^\s*param\s+(\w+)\s*=\s*(.+?)\s*$", re.M)
_RANDOM = re.compile(r"\b(Range|DiscreteRange|Uniform|Discrete|Normal|TruncatedNormal|Options|VerifaiRange|"
                     r"VerifaiDiscreteRange|VerifaiOptions)\s*\(")


def names_something(elements: Optional[Elements]) -> bool:
    """Whether ``elements`` say what happens in a scene: at least one participant, action or relation. Elements
    that name nothing (a hand-added script without ``--elements``) tell no two scenes apart, so they make no
    semantic duplicate (only the scripts' bytes compare) and a near-duplicate only through shared parameters."""
    if elements is None:
        return False
    return bool(elements.participants or elements.actions or elements.relations)


def semantic_key(elements: Elements, map_name: Optional[str], script: str) -> str:
    """What makes two scenarios the same: elements, map and the multiset of parameter ranges."""
    ranges = sorted(re.sub(r"\s+", "", value) for name, value in _PARAM.findall(script)
                    if name not in ("map", "weather") and _RANDOM.search(value))
    payload = json.dumps([elements.to_dict(), map_name, ranges], sort_keys=True)
    return hashlib.sha256(payload.encode()).hexdigest()


_RANGE_CALLS = ("Range", "DiscreteRange", "VerifaiRange", "VerifaiDiscreteRange", "Uniform", "Options",
                "Discrete", "VerifaiOptions")


def _numeric_interval(node: ast.AST) -> Optional[Tuple[float, float]]:
    """``(low, high)`` a Scenic parameter expression ranges over, for the numeric forms only."""
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
        return float(node.value), float(node.value)
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        inner = _numeric_interval(node.operand)
        if inner is None:
            return None
        return (-inner[1], -inner[0]) if isinstance(node.op, ast.USub) else inner
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in _RANGE_CALLS \
            and node.args and not node.keywords:
        bounds = [_numeric_interval(arg) for arg in node.args]
        if any(b is None for b in bounds):
            return None
        if node.func.id in ("Range", "DiscreteRange", "VerifaiRange", "VerifaiDiscreteRange") and len(bounds) != 2:
            return None
        return min(b[0] for b in bounds), max(b[1] for b in bounds)
    return None


def param_ranges(script: str) -> Dict[str, Tuple[float, float]]:
    """The numeric global parameters of a script (``param x = Range(a, b)``, ``-Range(...)``, a number,
    ``Uniform``/``Options`` of numbers) as ``name -> (low, high)``; other parameters are left out."""
    out: Dict[str, Tuple[float, float]] = {}
    for name, value in _PARAM.findall(script):
        try:
            tree = ast.parse(value.split("#", 1)[0].strip(), mode="eval")
        except SyntaxError:
            continue
        interval = _numeric_interval(tree.body)
        if interval is not None:
            out[name] = interval
    return out


def near_duplicate(elements_a: Elements, map_a: Optional[str], script_a: str,
                   elements_b: Elements, map_b: Optional[str], script_b: str) -> bool:
    """Whether two scenarios are near-duplicates: the same map, the same elements and
    every numeric parameter both scripts define ranging over overlapping intervals. Elements that name nothing
    (:func:`names_something`) need at least one such parameter in common: two scripts without elements or shared
    parameters are told apart by nothing, so they are not called alike."""
    if map_a != map_b or elements_a != elements_b:
        return False
    ranges_a, ranges_b = param_ranges(script_a), param_ranges(script_b)
    shared = set(ranges_a) & set(ranges_b)
    if not shared and not names_something(elements_a):
        return False  # elements that name nothing and no parameter in common: nothing says they are alike
    return all(ranges_a[p][0] <= ranges_b[p][1] and ranges_b[p][0] <= ranges_a[p][1] for p in shared)


NEAR_COPY_LINES = 2
"""Two scripts whose code (comments and blank lines aside) differs in at most this many lines are near-copies
(:func:`changed_code_lines`)."""


def _code_lines(script: str) -> List[str]:
    lines: List[str] = []
    for line in script.splitlines():
        text = line.strip()
        if not text or text.startswith("#") or (not lines and text.startswith(('"' * 3, "'" * 3))):
            continue
        lines.append(text)
    return lines


def changed_code_lines(script_a: str, script_b: str) -> int:
    """How many lines of code (blank lines, comment lines and a leading one-line docstring aside) one script would
    need changed, added or removed to become the other."""
    a, b = _code_lines(script_a), _code_lines(script_b)
    matcher = difflib.SequenceMatcher(None, a, b, autojunk=False)
    return sum(max(i2 - i1, j2 - j1) for tag, i1, i2, j1, j2 in matcher.get_opcodes() if tag != "equal")


def find_duplicate(entries: Mapping[str, Any], semantic_keys: Mapping[str, str], script: str,
                   elements: Optional[Elements], map_name: Optional[str]) -> Optional[Tuple[str, str]]:
    """``(name, how)`` of the entry (of ``entries``, name -> entry; ``semantic_keys``, name -> its
    :func:`semantic_key`) byte-for-byte identical to ``script``, or semantically identical when ``elements`` is
    given and names something (:func:`names_something`); else ``None``."""
    digest = content_hash(script)
    for entry in entries.values():
        if entry.content_hash == digest:
            return entry.name, "byte-for-byte identical"
    if names_something(elements):
        key = semantic_key(elements, map_name, script)
        for name, other in semantic_keys.items():
            if other == key:
                return name, "semantically identical (same elements, map and parameter ranges)"
    return None


def find_near_duplicate(entries: Mapping[str, Any], semantic_keys: Mapping[str, str], script: str,
                        elements: Elements, map_name: Optional[str]) -> Optional[Tuple[str, str]]:
    """``(name, how)`` of an entry identical to this script (:func:`find_duplicate`) or a near-duplicate
    of it (:func:`near_duplicate`: same map and elements, overlapping numeric parameter ranges)."""
    duplicate = find_duplicate(entries, semantic_keys, script, elements, map_name)
    if duplicate is not None:
        return duplicate
    wanted = elements
    for name in sorted(entries):
        entry = entries[name]
        if entry.map != map_name or entry.elements != wanted:
            continue
        try:
            other = entry.script
        except OSError:
            continue
        if near_duplicate(entry.elements, entry.map, other, wanted, map_name, script):
            return name, "a near-duplicate (same map and elements, overlapping parameter ranges)"
    return None


def find_near_copy(entries: Mapping[str, Any], script: str, accept: Callable[[Any], bool]) -> Optional[Tuple[str, str]]:
    """``(name, how)`` of the first entry (by name) ``accept`` takes whose code differs from ``script`` in at most
    :data:`NEAR_COPY_LINES` lines."""
    for name in sorted(entries):
        entry = entries[name]
        if not accept(entry):
            continue
        try:
            other = entry.script
        except OSError:
            continue
        changed = changed_code_lines(other, script)
        if changed <= NEAR_COPY_LINES:
            return name, f"a near-copy ({changed} changed line(s) of code) of an entry of the same family"
    return None
