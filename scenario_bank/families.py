"""A bank's scenario families by lineage and by content: :func:`content_families`.

A scenario's family is the end of its ``source.parent`` chain (the first scenario with no parent in the bank).
Two entries whose scripts are twins (:func:`twins`) are one family too, whatever their lineage: near-duplicates
(:func:`scenario_bank.dedup.near_duplicate`: the same map and elements, overlapping numeric parameter ranges), or
near-copies (:func:`scenario_bank.dedup.changed_code_lines`: at most :data:`~scenario_bank.dedup.NEAR_COPY_LINES`
lines of code apart, whatever their elements say and however far apart the ranges of a changed line lie: the same
program with one range moved, or with other elements declared, plays the same story). Holding out one of them while
fine-tuning on the other would test on what was trained on. A family is named by the first (sorted)
lineage root it joins, so a bank without near-duplicates keeps every family's name.
"""

from __future__ import annotations

from typing import Any, Dict, Iterable, List

from scenario_bank.dedup import NEAR_COPY_LINES, changed_code_lines, near_duplicate

__all__ = ["UnionFind", "lineage_root", "content_families", "near_duplicates_of", "twins"]


class UnionFind:
    """Disjoint sets of string keys; each set is named by its smallest key, so groups do not depend on order."""

    def __init__(self) -> None:
        self.parent: Dict[str, str] = {}

    def find(self, key: str) -> str:
        parent = self.parent
        while parent.setdefault(key, key) != key:
            parent[key] = parent[parent[key]]
            key = parent[key]
        return key

    def union(self, a: str, b: str) -> None:
        a, b = self.find(a), self.find(b)
        if a != b:
            self.parent[max(a, b)] = min(a, b)


def lineage_root(bank: Any, name: str) -> str:
    """The end of ``name``'s ``source.parent`` chain in ``bank`` (``name`` itself when it is no entry)."""
    current, seen = name, {name}
    while current in bank:
        parent = bank.get(current).source.parent
        if not parent or str(parent) in seen:
            break
        current = str(parent)
        seen.add(current)
    return current


def _scripts(entries: Iterable[Any]) -> Dict[str, Any]:
    """``{name: (entry, script)}`` of the entries whose script is readable (an unreadable one is no one's twin)."""
    found: Dict[str, Any] = {}
    for entry in entries:
        try:
            found[entry.name] = (entry, entry.script)
        except OSError:
            continue
    return found


def _twins(scripts: Dict[str, Any]) -> Iterable[tuple]:
    """Pairs ``(a, b)`` of names in ``scripts`` (:func:`_scripts`), ``a < b``, whose scripts are near-duplicates."""
    names = sorted(scripts)
    for i, name in enumerate(names):
        first, script = scripts[name]
        for other in names[i + 1:]:
            second, other_script = scripts[other]
            if twins(first, script, second, other_script):
                yield name, other


def twins(first: Any, script: str, second: Any, other_script: str) -> bool:
    """Whether two bank entries (with their scripts) are one scenario for held-out purposes: near-duplicates (the same
    map and elements, overlapping parameter ranges) or near-copies (at most ``NEAR_COPY_LINES`` lines of code apart)."""
    if near_duplicate(first.elements, first.map, script, second.elements, second.map, other_script):
        return True
    return changed_code_lines(script, other_script) <= NEAR_COPY_LINES


def content_families(bank: Any) -> Dict[str, str]:
    """``{entry name: family}`` for every entry of ``bank``: lineage roots joined by near-duplicate scripts,
    each family named by its first (sorted) root."""
    entries = sorted(bank, key=lambda e: e.name)
    roots = {e.name: lineage_root(bank, e.name) for e in entries}
    families = UnionFind()
    for first, second in _twins(_scripts(entries)):
        families.union(roots[first], roots[second])
    return {name: families.find(root) for name, root in roots.items()}


def near_duplicates_of(bank: Any, name: str) -> List[str]:
    """The other entries of ``bank`` whose scripts are near-duplicates of entry ``name``'s (sorted): one comparison
    per other entry, not the bank's every pair."""
    scripts = _scripts(bank)
    if name not in scripts:
        return []
    entry, script = scripts.pop(name)
    return sorted(other for other, (second, other_script) in scripts.items() if twins(entry, script, second, other_script))
