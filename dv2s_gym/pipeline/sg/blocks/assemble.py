"""Gluing blocks into Scenic text: the blocks a name needs, their text, and the hash of them all."""

from __future__ import annotations

import hashlib
from typing import Dict, Iterable, List, Tuple

from dv2s_gym.pipeline.sg.blocks.crossing_behaviors import CROSSING_BEHAVIORS
from dv2s_gym.pipeline.sg.blocks.helpers import HELPERS
from dv2s_gym.pipeline.sg.blocks.lane_behaviors import LANE_BEHAVIORS
from dv2s_gym.pipeline.sg.blocks.route_behaviors import ROUTE_BEHAVIORS

__all__ = ["BEHAVIORS", "behavior_text", "helper_text", "context_hash"]

BEHAVIORS: Dict[str, Tuple[str, Tuple[str, ...]]] = {**LANE_BEHAVIORS, **ROUTE_BEHAVIORS, **CROSSING_BEHAVIORS}
"""Every behaviour block: name -> (Scenic text, names of the blocks it needs)."""

def _closure(names: Iterable[str]) -> List[str]:
    """Block names with everything they need, dependencies first, each once."""
    ordered: List[str] = []

    def visit(name: str) -> None:
        if name in ordered:
            return
        deps = BEHAVIORS[name][1] if name in BEHAVIORS else ()
        for dep in deps:
            visit(dep)
        ordered.append(name)

    for name in names:
        visit(name)
    return ordered


def helper_text(names: Iterable[str]) -> str:
    """Scenic text of the helper functions among ``names`` (and their dependencies)."""
    return "\n".join(HELPERS[n] for n in _closure(names) if n in HELPERS)


def behavior_text(names: Iterable[str]) -> str:
    """Scenic text of the behaviours ``names`` with every block they need."""
    blocks = _closure(names)
    return "\n".join([HELPERS[n] for n in blocks if n in HELPERS] + [BEHAVIORS[n][0] for n in blocks if n in BEHAVIORS])


def context_hash() -> str:
    """Hash of every block: changes whenever the generator's building blocks change."""
    digest = hashlib.sha256()
    for table in (HELPERS, {k: v[0] for k, v in BEHAVIORS.items()}):
        for name in sorted(table):
            digest.update(name.encode())
            digest.update(table[name].encode())
    return digest.hexdigest()[:16]
