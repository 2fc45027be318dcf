"""A bank's scenario families by lineage and by content: :func:`content_families`.

A scenario's family is the end of its ``source.parent`` chain (the first scenario with no parent in the bank).
Two entries whose scripts are near-duplicates (:func:`scenario_bank.dedup.near_duplicate`: the same map and
elements, overlapping numeric parameter ranges) are one family too, whatever their lineage: holding out one of
them while fine-tuning on the other would test on what was trained on. A family is named by the first (sorted)
lineage root it joins, so a bank without near-duplicates keeps every family's name.
"""

from __future__ import annotations

from typing import Any, Dict, Iterable, List

from scenario_bank.dedup import near_duplicate

__all__ = ["lineage_root", "content_families", "near_duplicates_of"]


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


def _twins(entries: List[Any]) -> Iterable[tuple]:
    """Pairs of entry names whose scripts are near-duplicates (unreadable scripts are no one's twin)."""
    scripts: Dict[str, str] = {}
    for entry in entries:
        try:
            scripts[entry.name] = entry.script
        except OSError:
            continue
    readable = [e for e in entries if e.name in scripts]
    for i, first in enumerate(readable):
        for second in readable[i + 1:]:
            if first.map == second.map and near_duplicate(first.elements, first.map, scripts[first.name],
                                                          second.elements, second.map, scripts[second.name]):
                yield first.name, second.name


def content_families(bank: Any) -> Dict[str, str]:
    """``{entry name: family}`` for every entry of ``bank``: lineage roots joined by near-duplicate scripts,
    each family named by its first (sorted) root."""
    entries = sorted(bank, key=lambda e: e.name)
    roots = {e.name: lineage_root(bank, e.name) for e in entries}
    leader: Dict[str, str] = {root: root for root in roots.values()}

    def find(root: str) -> str:
        while leader[root] != root:
            leader[root] = leader[leader[root]]
            root = leader[root]
        return root

    for first, second in _twins(entries):
        a, b = find(roots[first]), find(roots[second])
        if a != b:
            leader[max(a, b)] = min(a, b)
    return {name: find(root) for name, root in roots.items()}


def near_duplicates_of(bank: Any, name: str) -> List[str]:
    """The other entries of ``bank`` whose scripts are near-duplicates of entry ``name``'s (sorted)."""
    entries = sorted(bank, key=lambda e: e.name)
    return sorted({b if a == name else a for a, b in _twins(entries) if name in (a, b)})
