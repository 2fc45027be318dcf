"""Exact replays for every failure cluster of a mining run, not only the converted ones.

Converting a failure through D-V2S (video, description, script, judge) is slow and keeps few scripts, so a run
converts at most a few clusters. The exact replay of a failing scene (:mod:`dv2s_gym.mining.conversion.exact_replay`) needs
none of that: the parent script narrowed around the failing parameters, one episode to check that it replays
the recorded one step for step, and a bank add. :func:`replay_clusters` keeps one for each avoidable cluster
that no conversion has tried yet (a conversion makes its own replay first), taking the scenario families in turn
(:func:`replay_order`: each family's largest cluster, then each one's next), and appends
a row per cluster to the run's ``replays.jsonl`` (:data:`REPLAYS_FILE`), so a resumed call replays only the
clusters left. :func:`replay_entries` reads the replay entries of a run back, from both files.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Dict, List, Mapping, Optional, Sequence, Tuple, Union

from dv2s_gym.mining.conversion import convert
from dv2s_gym.mining.conversion.settings import ConversionSettings
from dv2s_gym.mining.conversion.episodes import reference_passed
from dv2s_gym.mining.cluster import group
from dv2s_gym.mining.errors import MiningError
from dv2s_gym.mining.family import record_family
from dv2s_gym.mining.conversion.record import ConversionRecord, read_conversions, read_replays, ReplayRow
from dv2s_gym.mining.jsonl import JsonlAppender
from dv2s_gym.loop.record import MinedEntry
from dv2s_gym.mining.miner import progress_bar, read_records
from dv2s_gym.mining.settings import read_run_settings, SETTINGS_FILE
from scenario_bank.bank import Bank
from scenario_bank.records import EpisodeRecord

__all__ = ["REPLAYS_FILE", "replay_clusters", "replay_order", "replay_entries", "reference_passed"]

REPLAYS_FILE = "replays.jsonl"
"""The rows of :func:`replay_clusters` in a mining run folder (one JSON object a line)."""


def replay_clusters(run_dir: os.PathLike | str, *, bank_dir: os.PathLike | str,
                    max_replays: Optional[int] = None, progress: bool = True) -> List[ReplayRow]:
    """Add the exact replay of one failure per avoidable cluster of the mining run in ``run_dir`` to the bank in
    ``bank_dir`` (the loop's working bank; the parent scripts come from the bank the run mined), skipping clusters a conversion or an earlier call has tried;
    at most ``max_replays`` rows in ``replays.jsonl`` (``None``: every cluster), the clusters taken round-robin over
    the families (:func:`replay_order`). The representative failure is the
    one the conversion would take (lowest robustness, then lowest index). Returns every row of the run's
    ``replays.jsonl`` (:class:`~dv2s_gym.mining.conversion.record.ReplayRow`: what
    :func:`dv2s_gym.mining.conversion.replay.replay_failure_entry` returns)."""
    run_dir = Path(run_dir)
    settings = read_run_settings(run_dir)
    if settings is None:
        raise MiningError(f"{run_dir} holds no mining run (no {SETTINGS_FILE}); mine into it first")
    path = run_dir / REPLAYS_FILE
    existing = read_replays(path)
    converted = {str(record.cluster) for record in read_conversions(run_dir / "conversions.jsonl")}
    replayed = {str(row.cluster) for row in existing}
    groups = group(read_records(run_dir / "episodes.jsonl"))
    room = None if max_replays is None else max(0, int(max_replays) - len(existing))
    # the order over every cluster no conversion tried, so a resumed call goes on where a first call stopped
    order = replay_order({cluster: members for cluster, members in groups.items() if cluster not in converted})
    todo = [(cluster, record) for cluster, record in order if cluster not in replayed][:room]
    if not todo:
        return existing
    bank = Bank(bank_dir)
    replay = ConversionSettings(policy=settings.policy, env_config=settings.env_config,
                                bank_dir=settings.bank_dir,  # the bank the run mined (the parents')
                                monitor=settings.monitor)
    appender = JsonlAppender(path)
    bar = progress_bar(progress, len(todo), 0, desc="exact replays")
    try:
        for cluster, record in todo:
            row = convert.replay_failure_entry(record, run_dir, replay, bank=bank, cluster=cluster)
            appender.append(row)
            existing.append(row)
            if bar is not None:
                bar.update(1)
    finally:
        appender.close()
        if bar is not None:
            bar.close()
    return existing


def replay_order(groups: Mapping[str, Sequence[EpisodeRecord]]) -> List[Tuple[str, EpisodeRecord]]:
    """``[(cluster, representative failure)]``: the order in which the clusters of ``groups`` (failed records by
    cluster, :func:`dv2s_gym.mining.cluster.group`) get their exact replay, round-robin over the scenario
    families, so that a round's few replays spread over its families instead of all coming from the family with
    the most failures. The families take turns in the order of their largest cluster (most avoidable failures,
    then the family's name); each turn gives a family its largest cluster not yet taken (most avoidable
    failures, then the cluster id). Only failures the reference driver passed count (:func:`reference_passed`):
    clusters without one get none. The representative is the
    failure a conversion would take (lowest robustness, then lowest index). Deterministic: a function of
    ``groups`` only."""
    by_family: Dict[str, List[Tuple[int, str, EpisodeRecord]]] = {}
    for cluster, members in groups.items():
        avoidable = [r for r in members if reference_passed(r)]
        if not avoidable:
            continue
        representative = min(avoidable, key=lambda r: (float(r.rho or 0.0), int(r.index)))
        family = record_family(representative)
        by_family.setdefault(family, []).append((len(avoidable), str(cluster), representative))
    queues = []
    for family, clusters in by_family.items():
        clusters.sort(key=lambda c: (-c[0], c[1]))
        queues.append((-clusters[0][0], family, clusters))
    queues.sort(key=lambda q: (q[0], q[1]))
    order: List[Tuple[str, EpisodeRecord]] = []
    for turn in range(max((len(q[2]) for q in queues), default=0)):
        order += [(q[2][turn][1], q[2][turn][2]) for q in queues if turn < len(q[2])]
    return order


def replay_entries(run_dir: os.PathLike | str) -> List[MinedEntry]:
    """The exact replay entries a mining run added (:class:`~dv2s_gym.loop.record.MinedEntry`: cluster,
    scenario, parent, no reproduction, ``replay`` true; ``not_narrowed``: ``{parameter: why}`` when the replay leaves
    some at the parent's distribution), from the conversions' ``replay_entry`` and from ``replays.jsonl``, one per
    entry."""
    run_dir = Path(run_dir)
    found: Dict[str, MinedEntry] = {}
    episodes = None
    rows: List[Union[ConversionRecord, ReplayRow]] = [*read_conversions(run_dir / "conversions.jsonl"),
                                                      *read_replays(run_dir / REPLAYS_FILE)]
    for row in rows:
        name = row.replay_entry
        if not name or name in found:
            continue
        parent = row.scenario if isinstance(row, ReplayRow) else None
        if not parent:  # conversion rows do not name the parent: the failing episode does
            if episodes is None:
                episodes = {r.index: r for r in read_records(run_dir / "episodes.jsonl")}
            episode = episodes.get(row.index)
            parent = episode.scenario if episode is not None else None
        # not_narrowed: parameters the replay leaves at the parent's distribution, with why
        found[name] = MinedEntry(cluster=str(row.cluster), scenario=name, parent=parent, reproduction=None,
                                 replay=True, not_narrowed=dict(row.replay_not_narrowed)
                                 if row.replay_not_narrowed else None)
    return [found[name] for name in sorted(found)]
