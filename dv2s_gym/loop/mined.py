"""What a round's mining kept: the kept scenarios of a mining run (:func:`mined_entries`), the counts of its
folder (:func:`mining_summary`) and the scenario family each kept entry goes back to (:func:`with_parents`)."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Dict, List, Optional, Sequence

from dv2s_gym.loop.errored import errored_episodes
from dv2s_gym.loop.record import MinedEntry, MiningSummary
from dv2s_gym.loop.replays import REPLAYS_FILE, reference_passed, replay_entries
from dv2s_gym.mining.cluster import cluster_failures, group
from dv2s_gym.mining.conversion.record import read_conversions, read_replays
from dv2s_gym.mining.errors import MiningError
from dv2s_gym.mining.family import scenario_family
from dv2s_gym.mining.miner import read_records

__all__ = ["mined_entries", "mining_summary", "with_parents"]


def mined_entries(mine_out: os.PathLike | str, replays: bool = True) -> List[MinedEntry]:
    """The kept scenarios of a mining run (:class:`~dv2s_gym.loop.record.MinedEntry`: cluster, scenario,
    reproduction) from its ``conversions.jsonl`` (status ``kept`` with a bank entry), then (``replays``) the exact
    replays of its failing scenes (:func:`dv2s_gym.loop.replays.replay_entries`: ``replay`` true and ``parent``,
    from the conversions' ``replay_entry`` and from ``replays.jsonl``)."""
    records = read_conversions(Path(mine_out) / "conversions.jsonl")  # none when no cluster was converted
    entries: Dict[str, MinedEntry] = {}
    for record in records:
        if record.kept and record.bank_entry:
            entries[str(record.cluster)] = MinedEntry(cluster=str(record.cluster), scenario=record.bank_entry,
                                                      reproduction=(record.reproduction or {}).get("rate"))
    kept = {entry.scenario for entry in entries.values()}
    for record in records:  # a cluster merged into a scenario kept in this run is tied to it
        if record.merged and record.merged_into in kept:
            entries.setdefault(str(record.cluster), MinedEntry(
                cluster=str(record.cluster), scenario=record.merged_into,
                reproduction=(record.reproduction or {}).get("rate")))
    converted = [entries[key] for key in sorted(entries)]
    if not replays:
        return converted

    return converted + replay_entries(mine_out)


def mining_summary(mine_out: Path) -> MiningSummary:
    """Counts read from a mining run folder (episodes, failures, avoidable ones, clusters, conversions). Its
    ``episodes.jsonl`` is read as the miner reads it (:func:`~dv2s_gym.mining.miner.read_records`): a line that is
    no episode record is a :class:`~dv2s_gym.mining.errors.MiningError` naming it."""
    records = read_records(mine_out / "episodes.jsonl")
    episodes, errors = len(records), sum(1 for record in records if record.error)
    failures = sum(1 for record in records if record.failure is not None)
    counted = sum(1 for record in records if record.failure is not None and record.avoidable is not False)  # as MineRun.avoidable
    clusters: Optional[int] = None
    try:
        clusters = len(set(cluster_failures(records).values()))
    except MiningError:  # records the clusters cannot group (no family): the counts are informative, the loop goes on
        pass
    statuses: Dict[str, int] = {}
    reasons: List[str] = []
    conversions = read_conversions(mine_out / "conversions.jsonl")
    for record in conversions:
        status = str(record.status) if record.status is not None else "?"
        statuses[status] = statuses.get(status, 0) + 1
        if record.rejected and (record.rejections or record.reason):
            reasons += [str(r) for r in record.rejections or [record.reason]]  # every failed check
    converted = sum(statuses.values())
    tried = {str(record.cluster) for record in conversions}
    # clusters no conversion tried whose every failing scene the reference driver failed too: never replayed
    reference_failed = None
    if clusters is not None:
        reference_failed = sum(1 for cluster, members in group(records).items()
                               if cluster not in tried and not any(reference_passed(r) for r in members))
    replayed: Dict[str, int] = {}
    for row in read_replays(mine_out / REPLAYS_FILE):
        status = str(row.status) if row.status is not None else "?"
        replayed[status] = replayed.get(status, 0) + 1
    return MiningSummary(replays=replayed, episodes=episodes, errors=errors, errored=errored_episodes(records),
                         failures=failures, failures_against_policy=counted,
                         clusters=clusters, conversions=statuses, rejected_reasons=tuple(reasons[:40]),
                         rejected_reason_count=len(reasons),
                         clusters_not_converted=None if clusters is None else max(0, clusters - converted),
                         clusters_not_kept=None if clusters is None else max(0, clusters - converted
                                                                             - sum(replayed.values())),
                         clusters_reference_failed=reference_failed)


def with_parents(kept: Sequence[MinedEntry], bank: Optional[str]) -> List[MinedEntry]:
    """The kept entries with ``parent``: the scenario family their bank provenance goes back to
    (:func:`dv2s_gym.mining.family.scenario_family`, the family their failures were clustered by)."""
    entries = [MinedEntry.from_dict(e) for e in kept]
    if bank is None:
        return entries

    found = []
    for entry in entries:  # a parent's near-duplicate twins are its family too (scenario_bank.families)
        family = scenario_family(str(entry.parent or entry.scenario), str(bank))
        found.append(entry.replace(parent=family) if family != entry.scenario or entry.parent else entry)
    return found
