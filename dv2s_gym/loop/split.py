"""Splitting a round's mined scenarios into a fine-tuning part and a held-out part.

:func:`split_by_family` (what ``dv2s loop`` uses) holds out whole *families*: a mined scenario's
family is its parent bank scenario (the sidecar's provenance ``parent``, else the first
``/``-part of its cluster id). No held-out scenario shares a parent with a fine-tuning one, and
the loop also keeps the held-out families' parent scenarios out of fine-tuning, so the held-out
failures come from scenarios the fine-tuning never drew in any form. Across rounds a family keeps its side:
one held out earlier stays held out, and one an earlier round fine-tuned on (a mined scenario of it, or its
parent scenario in the fine-tuning mix) stays on the fine-tuning side.

The split is deterministic from ``seed``: the family groups are shuffled with that seed and dealt so the
held-out share is ``fraction`` of them.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Dict, List, Mapping, Sequence, Tuple

import numpy as np

from dv2s_gym.mining.errors import MiningError
from dv2s_gym.loop.record import MinedEntry, SplitRecord
from scenario_bank.families import UnionFind

__all__ = ["split_by_family", "family_of", "family_groups", "FamilyGroup", "FamilySplit"]


def family_of(entry: MinedEntry) -> str:
    """A mined entry's family: its ``parent`` when known, else the first ``/``-part of its cluster id (a JSON
    object of one is read as a :class:`~dv2s_gym.loop.record.MinedEntry`)."""
    entry = MinedEntry.from_dict(entry)
    return str(entry.parent) if entry.parent else str(entry.cluster).split("/")[0]


@dataclass(frozen=True)
class FamilyGroup:
    """Mined entries tied together (:func:`family_groups`): their ``families``, ``clusters`` and ``scenarios``,
    each sorted."""

    families: Tuple[str, ...]
    clusters: Tuple[str, ...]
    scenarios: Tuple[str, ...]


@dataclass(frozen=True)
class FamilySplit:
    """A round's split of its mined scenarios by family (:func:`split_by_family`), each list sorted: the scenarios,
    clusters and families to fine-tune on (``fine_tune``, ``fine_tune_clusters``, ``fine_tune_families``) and to hold
    out (``held_out``, ``held_out_clusters``, ``held_out_families``), the number of family ``groups`` split, and the
    families held out in an earlier round that a tie to a fine-tuned family moved to the fine-tuning side
    (``moved_to_fine_tune``)."""

    fine_tune: Tuple[str, ...]
    held_out: Tuple[str, ...]
    fine_tune_clusters: Tuple[str, ...]
    held_out_clusters: Tuple[str, ...]
    fine_tune_families: Tuple[str, ...]
    held_out_families: Tuple[str, ...]
    groups: int
    moved_to_fine_tune: Tuple[str, ...]

    def to_dict(self) -> Dict[str, Any]:
        """The split's JSON object, as a loop round's record holds it (``"by": "family"`` first)."""
        return {"by": "family", "fine_tune": list(self.fine_tune), "held_out": list(self.held_out),
                "fine_tune_clusters": list(self.fine_tune_clusters), "held_out_clusters": list(self.held_out_clusters),
                "fine_tune_families": list(self.fine_tune_families), "held_out_families": list(self.held_out_families),
                "groups": self.groups, "moved_to_fine_tune": list(self.moved_to_fine_tune)}

    def record(self) -> SplitRecord:
        """The split as a loop round records it (its ``split`` step; :meth:`to_dict` is its JSON object)."""
        return SplitRecord(by="family", fine_tune=self.fine_tune, held_out=self.held_out,
                           fine_tune_clusters=self.fine_tune_clusters, held_out_clusters=self.held_out_clusters,
                           fine_tune_families=self.fine_tune_families, held_out_families=self.held_out_families,
                           groups=self.groups, moved_to_fine_tune=self.moved_to_fine_tune)


def family_groups(entries: Sequence[MinedEntry]) -> List[FamilyGroup]:
    """Connected groups of mined entries: two entries are in one group when they share a family, a cluster
    or a scenario (a failure merged into another family's scenario ties the two families), sorted by their first
    family."""
    entries = [MinedEntry.from_dict(entry) for entry in entries]
    sets = UnionFind()
    find, union = sets.find, sets.union
    for entry in entries:
        family = "f:" + family_of(entry)
        union(family, "c:" + str(entry.cluster))
        union(family, "s:" + str(entry.scenario))
    groups: Dict[str, Dict[str, set]] = {}
    for entry in entries:
        group = groups.setdefault(find("f:" + family_of(entry)), {"families": set(), "clusters": set(),
                                                                   "scenarios": set()})
        group["families"].add(family_of(entry))
        group["clusters"].add(str(entry.cluster))
        group["scenarios"].add(str(entry.scenario))
    result = [FamilyGroup(families=tuple(sorted(g["families"])), clusters=tuple(sorted(g["clusters"])),
                          scenarios=tuple(sorted(g["scenarios"]))) for g in groups.values()]
    return sorted(result, key=lambda g: g.families[0])


def split_by_family(entries: Sequence[MinedEntry], fraction: float = 0.5, seed: int = 0,
                    held_families: Sequence[str] = (), tuned_families: Sequence[str] = ()) -> FamilySplit:
    """Split mined entries (:class:`~dv2s_gym.loop.record.MinedEntry`: cluster, scenario and optionally
    parent) by family.

    ``fraction`` of the family groups (rounded, at least one and at most all but one when there are two or
    more) go to the held-out part, chosen by a shuffle seeded with ``seed``. A group holding one of
    ``held_families`` (families held out in an earlier round) is held out, and a group holding one of
    ``tuned_families`` (families an earlier round fine-tuned on, in any form) is fine-tuned on, so a family
    never changes sides across rounds. When one group holds both (a failure tied an earlier held-out family to
    an earlier fine-tuned one), it goes to the fine-tuning side: a held-out family must be one no round ever
    trained on, and the tie already broke that. Such families are listed in ``"moved_to_fine_tune"``.
    Returns the :class:`FamilySplit` (its :meth:`~FamilySplit.to_dict`: ``{"by": "family", "fine_tune", "held_out",
    "fine_tune_clusters", "held_out_clusters", "fine_tune_families", "held_out_families", "groups",
    "moved_to_fine_tune"}``).
    """
    if not 0.0 <= float(fraction) <= 1.0:
        raise MiningError(f"the held-out fraction must be in [0, 1], not {fraction}")
    groups = family_groups(entries)
    forced, trained = set(held_families), set(tuned_families)
    order = [groups[i] for i in np.random.default_rng([int(seed), 11]).permutation(len(groups))]
    count = len(groups)
    target = int(round(fraction * count))
    if count >= 2 and 0.0 < fraction < 1.0:
        target = min(max(target, 1), count - 1)
    pinned = [g for g in order if trained & set(g.families)]
    held = [g for g in order if forced & set(g.families) and g not in pinned]
    for group in order:
        if len(held) >= target:
            break
        if group not in held and group not in pinned:
            held.append(group)
    tuned = [g for g in order if g not in held]
    return FamilySplit(
        fine_tune=tuple(sorted(s for g in tuned for s in g.scenarios)),
        held_out=tuple(sorted(s for g in held for s in g.scenarios)),
        fine_tune_clusters=tuple(sorted(c for g in tuned for c in g.clusters)),
        held_out_clusters=tuple(sorted(c for g in held for c in g.clusters)),
        fine_tune_families=tuple(sorted(f for g in tuned for f in g.families)),
        held_out_families=tuple(sorted(f for g in held for f in g.families)),
        groups=count,
        moved_to_fine_tune=tuple(sorted(f for g in pinned for f in g.families if f in forced)),
    )
