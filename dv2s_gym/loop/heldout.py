"""Paired evaluation of policies on the loop's held-out mined scenarios.

An *episode* is ``(scenario, seed)``; every policy evaluated under a role (``before``,
``after``) runs the same list of episodes, so the before/after outcomes pair up by
episode (same scene, same seed). An episode *fails* when the mining monitors
(:func:`dv2s_gym.mining.monitors.detect_failure`: collision, off road, time-to-collision
under the threshold, stall) report a failure, the same test the miner used to find it.

Results stream into a JSON-lines store (``one line per (role, scenario, seed)``, appended
and fsynced), so an interrupted evaluation rerun with the same store runs only what is
missing. Several workers run on the local process pool (:class:`dv2s_gym.workers.pool.LocalBackend`:
each worker keeps its env and loaded policies between episodes; a worker that crashes or
hangs past ``timeout`` is replaced and its episode run once more, then recorded as an error).
An errored episode stays an error in the store (it is not run again on resume, nor when the ``after`` step reads
the starting policy's episodes back), so its pair is left out of every rate and test, as the loop report says.
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path
from tqdm import tqdm
from typing import Any, Callable, Dict, Iterable, List, Mapping, Optional, Sequence, Tuple

__all__ = ["HeldOutStore", "heldout_task", "evaluate_heldout", "paired_summary", "episode_failed", "failure_types"]

import numpy as np
from dv2s_gym.mining.jsonl import read_rows
from dv2s_gym.loop.record import PairedSummary, PairedTable
from dv2s_gym.mining.tasks import HeldOutTask, heldout_task
from scenario_bank.records import HeldOutEpisode
from scenario_bank.run_paths import read_paths, record_paths
from dv2s_gym.regress.stats import mcnemar_exact, PairedTable as Outcomes
from policies.stats import Rate
from dv2s_gym.workers.pool import LocalBackend
from dv2s_gym.workers.settings import WorkerSettings
from scenario_bank.read_files import ReadFile

Episode = Tuple[str, int]

def episode_failed(record: HeldOutEpisode) -> Optional[bool]:
    """The record's outcome: ``True`` failed, ``False`` did not, ``None`` an error."""
    return None if record.error else bool(record.failed)


class HeldOutStore:
    """The finished episodes of one evaluation, one JSON line each, keyed by (role, scenario, seed)."""

    def __init__(self, path: os.PathLike | str,
                 on_reads: Optional[Callable[[Iterable[ReadFile]], None]] = None) -> None:
        self.path = Path(path)
        self.on_reads = on_reads  # given the user's files the workers read so far, before each episode is saved
        self.records: Dict[Tuple[str, str, int], HeldOutEpisode] = {}
        # a line cut by a kill is left out: its episode runs again. An episode that errored is finished too (its
        # error is its outcome): running only the errored episodes again would give one policy a second draw on
        # exactly those episodes, and the report, which counts them in no rate or test, would not say so
        # paths in the loop folder where it is now (a moved loop resumes)
        for row in read_paths(list(read_rows(self.path)), self.path.parent):
            record = HeldOutEpisode.from_dict(row)
            self.records[(record.role, record.scenario, record.seed)] = record

    def append(self, record: HeldOutEpisode, reads: Iterable[ReadFile] = ()) -> None:
        """Save one finished episode (fsynced), after giving ``on_reads`` the user's files read to run it and the
        earlier ones (``reads``: by the workers; :attr:`dv2s_gym.workers.pool.LocalBackend.files_read`)."""
        if self.on_reads is not None:
            self.on_reads(reads)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with open(self.path, "a", encoding="utf-8") as handle:
            row = record_paths(json.loads(json.dumps(record.to_dict(), default=str)), self.path.parent)
            handle.write(json.dumps(row, sort_keys=True) + "\n")
            handle.flush()
            os.fsync(handle.fileno())
        self.records[(record.role, record.scenario, record.seed)] = record

    def get(self, role: str, scenario: str, seed: int) -> Optional[HeldOutEpisode]:
        """The record of one episode, or ``None`` when it has not run."""
        return self.records.get((role, scenario, int(seed)))


def evaluate_heldout(role: str, policy: str, episodes: Sequence[Episode], *, store: HeldOutStore,
                     bank_dir: Optional[str], env_config: Optional[Dict[str, Any]] = None,
                     workers: WorkerSettings = WorkerSettings(workers=1),
                     progress: bool = True) -> List[HeldOutEpisode]:
    """Run ``policy`` as ``role`` on every episode not yet in ``store``; returns the records in episode order (an
    episode that did not run is a record whose ``error`` says so).

    ``workers``: local worker processes (``workers`` 1: in this process) and the seconds one episode may take on a
    worker before it counts as hung (``timeout``; default that of :class:`~dv2s_gym.workers.pool.LocalBackend`).
    """
    count = workers.workers if workers.workers is not None else (os.cpu_count() or 1)
    tasks = [HeldOutTask(role=role, policy=policy, scenario=scenario, seed=int(seed), bank_dir=bank_dir,
                         env_config=dict(env_config or {})).to_json()
             for scenario, seed in episodes if store.get(role, scenario, seed) is None]
    bar = None
    if progress:
        bar = tqdm(total=len(episodes), initial=len(episodes) - len(tasks), desc=f"held-out {role}", unit="episode",
                   file=sys.stderr, dynamic_ncols=True)
    try:
        if tasks and count <= 1:
            for task in tasks:
                store.append(heldout_task(task))
                if bar is not None:
                    bar.update(1)
        elif tasks:
            def finished(record: Any) -> None:  # a worker's HeldOutEpisode, or the JSON object of one it gave up on
                store.append(record if isinstance(record, HeldOutEpisode)
                             else HeldOutEpisode.from_dict({"policy": policy, **record}),
                             reads=list(backend.files_read.values()))
                if bar is not None:
                    bar.update(1)

            with LocalBackend(workers=count, timeout=workers.timeout) as backend:
                backend.run(tasks, finished)
    finally:
        if bar is not None:
            bar.close()
    found = [(scenario, seed, store.get(role, scenario, seed)) for scenario, seed in episodes]
    return [record if record is not None
            else HeldOutEpisode(role=role, scenario=scenario, seed=int(seed), policy=policy, error="did not run")
            for scenario, seed, record in found]


def _relative_drop(before: float, after: float) -> Optional[float]:
    return None if before <= 0 else (before - after) / before


def paired_summary(before: Sequence[HeldOutEpisode], after: Sequence[HeldOutEpisode], *,
                   bootstrap: int = 2000, seed: int = 0,
                   families: Optional[Mapping[str, str]] = None) -> PairedSummary:
    """Rates before and after (Wilson 95 %), relative drop with a bootstrap interval resampling whole families
    (``families`` maps each scenario to its family; default: each scenario its own), the paired table (candidate =
    after, baseline = before) and the exact two-sided McNemar p.

    Pairs are matched by (scenario, seed); a pair with an error on either side is left out. The scenarios of one
    family (replays of one failure, a conversion of it) are not independent: the split holds families out, so the
    bootstrap draws families, and ``relative_drop_interval_unit`` / ``relative_drop_interval_units`` say what it
    drew and how many. The McNemar test stays per pair (``mcnemar_unit`` ``"pair"``): pairs within one family are
    not independent, so its p is optimistic when a family holds several pairs.
    """
    after_by = {(r.scenario, int(r.seed)): r for r in after}
    pairs: List[Tuple[str, bool, bool]] = []
    errors = 0
    for record in before:
        twin = after_by.get((record.scenario, int(record.seed)))
        b, a = episode_failed(record), episode_failed(twin) if twin is not None else None
        if b is None or a is None:
            errors += 1
            continue
        pairs.append((record.scenario, b, a))
    table = Outcomes.from_outcomes([a for _, _, a in pairs], [b for _, b, _ in pairs])
    n = len(pairs)
    k_before, k_after = sum(b for _, b, _ in pairs), sum(a for _, _, a in pairs)
    drop = _relative_drop(k_before / n, k_after / n) if n else None
    interval = [None, None]
    scenarios = sorted({s for s, _, _ in pairs})
    family_of = {name: str((families or {}).get(name, name)) for name in scenarios}
    units = sorted(set(family_of.values()))
    if drop is not None and len(units) > 1 and bootstrap > 0:
        counts = np.array([[sum(1 for s, b, _ in pairs if family_of[s] == unit and b),
                            sum(1 for s, _, a in pairs if family_of[s] == unit and a)] for unit in units], dtype=float)
        rng = np.random.default_rng(seed)
        draws = rng.integers(0, len(units), size=(bootstrap, len(units)))
        sums = counts[draws].sum(axis=1)
        valid = sums[:, 0] > 0
        drops = (sums[valid, 0] - sums[valid, 1]) / sums[valid, 0]
        if len(drops):
            interval = [float(np.percentile(drops, 2.5)), float(np.percentile(drops, 97.5))]
    per_scenario = {}
    for name in scenarios:
        rows = [(b, a) for s, b, a in pairs if s == name]
        per_scenario[name] = {"n": len(rows), "before": sum(b for b, _ in rows), "after": sum(a for _, a in rows)}
    return PairedSummary(
        pairs=n, errors=errors, before=Rate.of(k_before, n), after=Rate.of(k_after, n), relative_drop=drop,
        relative_drop_interval=tuple(interval),
        relative_drop_interval_unit="family" if families is not None else "scenario",
        relative_drop_interval_units=len(units), mcnemar_unit="pair",
        pairs_per_family=({unit: sum(1 for s, _, _ in pairs if family_of[s] == unit) for unit in units}
                          if families is not None else None),
        table=PairedTable(both_fail=table.both_fail, after_only=table.candidate_only,
                          before_only=table.baseline_only, neither=table.neither),
        mcnemar_p=mcnemar_exact(table) if n else None, per_scenario=per_scenario)


def failure_types(records: Iterable[HeldOutEpisode]) -> Dict[str, int]:
    """How many records failed with each failure type."""
    counts: Dict[str, int] = {}
    for record in records:
        if record.failure is not None:
            counts[record.failure.type] = counts.get(record.failure.type, 0) + 1
    return counts
