"""Grouping failures so a report counts distinct failures, not repeats of one.

A failure's cluster is ``"<scenario>/<failure class>/<region>"``: its scenario, its class
(``collision:rear_end``, ``off_road``...; :attr:`~dv2s_gym.mining.monitors.Failure.kind`)
and the cell of a regular grid over the scenario's parameter space (each parameter's
range cut into :data:`REGION_BINS` equal parts) its parameters fall in. Grid cells do
not move when more failures arrive, so a cluster keeps its id across a resumed run and
across runs, and the conversion of a cluster is done once.
"""

from __future__ import annotations

from collections import defaultdict
from typing import Any, Dict, Iterable, List, Sequence

__all__ = ["REGION_BINS", "region_of", "cluster_id", "cluster_failures", "slug"]

REGION_BINS = 3


def region_of(point: Sequence[float], bins: int = REGION_BINS) -> str:
    """Grid cell of a unit-box point, e.g. ``"r0.2.1"`` (``"r"`` for a scenario without parameters)."""
    cells = [str(min(bins - 1, max(0, int(float(u) * bins)))) for u in point]
    return "r" + ".".join(cells)


def cluster_id(record: Dict[str, Any], bins: int = REGION_BINS) -> str:
    """The cluster of a failed episode record."""
    return f"{record['scenario']}/{record['failure']['kind']}/{region_of(record.get('point') or [], bins)}"


def cluster_failures(records: Iterable[Dict[str, Any]], bins: int = REGION_BINS) -> Dict[int, str]:
    """``{episode index: cluster id}`` for every failed episode record."""
    return {int(r["index"]): cluster_id(r, bins) for r in records if r.get("failure") and not r.get("error")}


def group(records: Iterable[Dict[str, Any]], bins: int = REGION_BINS) -> Dict[str, List[Dict[str, Any]]]:
    """Failed records by cluster id (each list in index order)."""
    groups: Dict[str, List[Dict[str, Any]]] = defaultdict(list)
    for record in sorted(records, key=lambda r: int(r["index"])):
        if record.get("failure") and not record.get("error"):
            groups[cluster_id(record, bins)].append(record)
    return dict(groups)


def slug(cluster: str) -> str:
    """A file-name-safe form of a cluster id."""
    return cluster.replace("/", "__").replace(":", "-")
