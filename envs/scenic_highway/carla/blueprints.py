"""CARLA blueprint ids, sizes and kinds, read from Scenic's own blueprint data.

Scenic 3.1.1 picks the blueprint table of the installed ``carla`` package; without
one it takes the newest (CARLA 0.10.0), which has no bicycles, motorcycles or
boxes. DV2S-v0 does not run CARLA, so here each category and dimension is looked
up across every CARLA version Scenic records, newest first: every blueprint a
script may name has a size. Only Scenic's data module is imported, never ``carla``.
"""

from __future__ import annotations

from typing import Any, Dict, List

from scenic.core.distributions import distributionFunction
from scenic.simulators.carla._blueprintData import _DIMS, _IDS

from envs.errors import UnsupportedConstructError

__all__ = ["blueprintsInCategory", "width", "length", "height", "kind_of", "KIND_OF_CATEGORY"]


def _version_key(version: str):
    return tuple(int(part) for part in version.split("."))


_VERSIONS = sorted(_IDS, key=_version_key, reverse=True)

KIND_OF_CATEGORY = {
    "truck": "truck",
    "bus": "bus",
    "motorcycle": "motorcycle",
    "bicycle": "bicycle",
    "walker": "pedestrian",
    "car": "car",
    "van": "car",
}
"""The vocabulary kind (``scenario_bank.elements``) of the actors of each CARLA blueprint category."""


def _category_ids() -> Dict[str, List[str]]:
    table: Dict[str, List[str]] = {}
    for version in _VERSIONS:
        for key, ids in _IDS[version].items():
            known = table.setdefault(key[: -len("Models")], [])
            known.extend(bp for bp in ids if bp not in known)
    return table


_CATEGORY_IDS = _category_ids()
_KIND_OF_ID = {bp: KIND_OF_CATEGORY[cat] for cat in KIND_OF_CATEGORY for bp in _CATEGORY_IDS.get(cat, ())}


def blueprintsInCategory(category: str) -> List[str]:
    """Every blueprint id of a category (``car``, ``truck``, ``cone``...) in any recorded CARLA version."""
    ids = _CATEGORY_IDS.get(category)
    if not ids:
        raise UnsupportedConstructError(
            f"unknown CARLA blueprint category {category!r}; known: {', '.join(sorted(_CATEGORY_IDS))}"
        )
    return list(ids)


def _dimension(blueprint: Any, key: str, default: float) -> float:
    for version in _VERSIONS:
        value = _DIMS.get(version, {}).get(blueprint, {}).get(key)
        if value:
            return value
    return default


@distributionFunction
def width(blueprint: Any, default: float) -> float:
    """Width [m] of a blueprint (``default`` when unknown)."""
    return _dimension(blueprint, "width", default)


@distributionFunction
def length(blueprint: Any, default: float) -> float:
    """Length [m] of a blueprint (``default`` when unknown)."""
    return _dimension(blueprint, "length", default)


@distributionFunction
def height(blueprint: Any, default: float) -> float:
    """Height [m] of a blueprint (``default`` when unknown)."""
    return _dimension(blueprint, "height", default)


@distributionFunction
def kind_of(blueprint: Any, default: str) -> str:
    """The vocabulary kind a blueprint makes (a truck blueprint on a ``Car`` makes a truck); ``default``
    for blueprints of no vehicle or walker category."""
    return _KIND_OF_ID.get(blueprint, default) if isinstance(blueprint, str) else default
