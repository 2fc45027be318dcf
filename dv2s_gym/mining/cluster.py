"""Grouping failures by behaviour, so a report counts distinct failures, not repeats of one.

A failure's cluster is ``"<family>/<failure class>/<actor>-<its manoeuvre>/ego-<ego manoeuvre>"``, e.g.
``"cut_in/collision:rear_end/car-braking/ego-keeping_lane"``: its scenario family (the bank scenario the
episode's scenario goes back to through the provenance of mined and replay entries,
:mod:`dv2s_gym.mining.family`), its class (``collision:rear_end``, ``off_road``, ``stall``...;
:attr:`~dv2s_gym.mining.monitors.Failure.kind`), the kind of the other actor involved and what it was doing,
and what the ego was doing, in the seconds before the failure (:mod:`dv2s_gym.mining.behaviour`, kept in
the episode record when it runs). The first two ``/``-parts are always the family and the failure class; the
entries a cluster's failures ran in are kept in its records (``scenario``) and listed in the reports.
A cluster id depends on its own record only, so it is the same across a resumed run and across runs,
and the conversion of a cluster is done once.

The scenario parameters are not part of the cluster: two failures that look the same on the road are one
behaviour whatever the parameters were. :func:`cell_id` (the failure's cell of a regular grid over the
parameters, :data:`REGION_BINS` per parameter) is what the ``novelty`` feedback of the adaptive samplers
and the ``split`` sampler's cell avoidance use: a signal about where in parameter space a sampler has
been, which is not what the reports count.
"""

from __future__ import annotations

from collections import defaultdict
from typing import Dict, Iterable, List, Sequence

from dv2s_gym.mining.behaviour import behaviour_of
from dv2s_gym.mining.family import record_family
from scenario_bank.records import EpisodeRecord

__all__ = ["REGION_BINS", "region_of", "cluster_id", "cell_id", "cluster_failures", "group", "slug", "pair_of"]

REGION_BINS = 3


def region_of(point: Sequence[float], bins: int = REGION_BINS) -> str:
    """Grid cell of a unit-box point, e.g. ``"r0.2.1"`` (``"r"`` for a scenario without parameters)."""
    cells = [str(min(bins - 1, max(0, int(float(u) * bins)))) for u in point]
    return "r" + ".".join(cells)


def cluster_id(record: EpisodeRecord) -> str:
    """The behaviour cluster of a failed episode record (module docstring)."""
    behaviour = behaviour_of(record)
    return (f"{record_family(record)}/{record.failure.kind}/{behaviour.actor}-{behaviour.actor_manoeuvre}"
            f"/ego-{behaviour.ego_manoeuvre}")


def cell_id(record: EpisodeRecord, bins: int = REGION_BINS) -> str:
    """``"<scenario>/<failure class>/<grid cell>"`` of a failed record: where in parameter space it failed."""
    return f"{record.scenario}/{record.failure.kind}/{region_of(record.point or [], bins)}"


def pair_of(record: EpisodeRecord) -> str:
    """``"<family>/<failure class>"`` of a failed record."""
    return f"{record_family(record)}/{record.failure.kind}"


def cluster_failures(records: Iterable[EpisodeRecord]) -> Dict[int, str]:
    """``{episode index: cluster id}`` for every failed episode record."""
    return {int(r.index): cluster_id(r) for r in records if r.failed}


def group(records: Iterable[EpisodeRecord]) -> Dict[str, List[EpisodeRecord]]:
    """Failed records by cluster id (each list in index order)."""
    groups: Dict[str, List[EpisodeRecord]] = defaultdict(list)
    for record in sorted(records, key=lambda r: int(r.index)):
        if record.failed:
            groups[cluster_id(record)].append(record)
    return dict(groups)


def slug(cluster: str) -> str:
    """A file-name-safe form of a cluster id."""
    return cluster.replace("/", "__").replace(":", "-")
