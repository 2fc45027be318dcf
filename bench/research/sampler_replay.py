"""Offline design check of scenario-level samplers: replay a random run's episodes as their draws.

    python -m bench.research.sampler_replay RUN/episodes.jsonl [...] --budget 60 --sims 300

A scenario-level sampler (it picks the scenario; the scene's parameters are uniform over the scenario's own
box, as ``novelty-bandit`` draws them) is simulated on a random run's records: drawing scenario ``s`` takes the
next unused episode of ``s`` from the run (in a per-simulation random order; these are independent uniform scenes
of ``s``, so the draw is exact while the pool lasts). A scenario whose pool is used up is reused from its start,
which finds nothing new and so penalises a sampler that concentrates: the figures are a lower bound for
concentrating samplers. Feedback reaches the sampler ``--window`` draws late (the miner draws ahead of results).

Variants: ``random`` (uniform scenario), ``bandit/state`` (``novelty-bandit`` with its default ``state-novelty``
feedback), ``bandit/cluster`` (the same rule fed ``cluster-novelty``: a failure counts only in a behaviour
cluster not yet found), each bandit also with ``explore`` 0.5. Scored on behaviour clusters and (family, failure
type) pairs found, mean over ``--sims`` simulations with a 95 % bootstrap interval of the ratio to random's.
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from typing import Any, Dict, List

import numpy as np

from dv2s_gym.mining.cluster import cluster_id, pair_of
from dv2s_gym.mining.failure_state import NOVELTY_RADIUS, distance, is_novel
from scenario_bank.records import EpisodeRecord


def load(path: str) -> List[EpisodeRecord]:
    with open(path) as f:
        rows = [EpisodeRecord.from_dict(json.loads(line)) for line in f if line.strip()]
    return [r for r in rows if not r.error]


def simulate(records, budget: int, variant: str, explore: float, rng: np.random.Generator, window: int = 8,
             prior=(2.0, 1.0), cover: int = 0, c: float = 0.5, radius: float = NOVELTY_RADIUS) -> Dict[str, int]:
    pools: Dict[str, List[EpisodeRecord]] = defaultdict(list)
    for r in records:
        pools[r.scenario].append(r)
    names = sorted(pools)
    order = {s: list(rng.permutation(len(pools[s]))) for s in names}
    used = {s: 0 for s in names}
    drawn = np.zeros(len(names))
    new = np.zeros(len(names))
    pending: List[tuple] = []
    seen_clusters, seen_pairs, archive = set(), set(), defaultdict(list)
    fed_clusters = set()
    modes: Dict[str, List[int]] = defaultdict(list)
    centres: Dict[str, List[Any]] = defaultdict(list)
    for _ in range(budget):
        untried = np.flatnonzero(drawn < cover)
        if variant == "random" or rng.random() < explore:
            i = int(rng.integers(len(names)))
        elif len(untried):
            i = int(untried[rng.integers(len(untried))])
        elif variant == "good-ucb":
            t = drawn.sum() + 1
            singletons = np.array([sum(1 for n in modes[s] if n == 1) for s in names], dtype=float)
            with np.errstate(divide="ignore", invalid="ignore"):
                score = np.where(drawn > 0, singletons / np.maximum(drawn, 1) + c * np.sqrt(np.log(t) / np.maximum(drawn, 1)), np.inf)
            best = np.flatnonzero(score >= score.max() - 1e-12)
            i = int(best[rng.integers(len(best))])
        else:
            score = (new + prior[0]) / (drawn + prior[0] + prior[1])
            best = np.flatnonzero(score >= score.max() - 1e-12)
            i = int(best[rng.integers(len(best))])
        s = names[i]
        drawn[i] += 1
        k = used[s] % len(pools[s])
        r = pools[s][order[s][k]]
        used[s] += 1
        repeat_of_pool = used[s] > len(pools[s])
        if r.failure and not repeat_of_pool:
            seen_clusters.add(cluster_id(r))
            seen_pairs.add(pair_of(r))
        pending.append((i, r, repeat_of_pool))
        if len(pending) > window:
            j, rec, rep = pending.pop(0)
            if rec.failure and not rep:
                if variant == "bandit/state":
                    st = rec.failure_state
                    if is_novel(st, archive[rec.scenario]):
                        new[j] += 1
                    if st is not None:
                        archive[rec.scenario].append(st)
                elif variant == "good-ucb":
                    st = rec.failure_state
                    if st is not None:
                        near = [k for k, centre in enumerate(centres[rec.scenario]) if distance(st, centre) <= radius]
                        if near:
                            k = min(near, key=lambda k: distance(st, centres[rec.scenario][k]))
                            modes[rec.scenario][k] += 1
                        else:
                            centres[rec.scenario].append(st)
                            modes[rec.scenario].append(1)
                elif variant == "bandit/cluster":
                    c = cluster_id(rec)
                    if c not in fed_clusters:
                        new[j] += 1
                    fed_clusters.add(c)
    return {"clusters": len(seen_clusters), "pairs": len(seen_pairs)}


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("runs", nargs="+")
    p.add_argument("--budget", type=int, default=60)
    p.add_argument("--sims", type=int, default=300)
    p.add_argument("--variants", nargs="*", default=["random:1", "bandit/state:0.2", "bandit/cluster:0.2",
                                                      "bandit/state:0.5", "bandit/cluster:0.5"],
                   help="VARIANT:EXPLORE[:COVER] (COVER: draws of every scenario before the scores rank them)")
    args = p.parse_args()
    variants = []
    for text in args.variants:
        name, explore, *rest = text.split(":")
        extra = dict(item.split("=") for item in rest[1:])
        variants.append((name, float(explore), int(rest[0]) if rest else 0, float(extra.get("c", 0.5)),
                         float(extra.get("r", NOVELTY_RADIUS))))
    print("| run (episodes) | sampler | explore | behaviour clusters | pairs | clusters vs random [95 %] | "
          "pairs vs random [95 %] |\n|---|---|---:|---:|---:|---:|---:|")
    for path in args.runs:
        records = load(path)
        policy = records[0].policy
        results = {}
        for v, e, c, cc, rr in variants:
            rng = np.random.default_rng(12345)
            sims = [simulate(records, args.budget, v, e, rng, cover=c, c=cc, radius=rr) for _ in range(args.sims)]
            results[(v, e, c, cc, rr)] = {m: np.array([x[m] for x in sims], dtype=float) for m in ("clusters", "pairs")}
        base = next(res for key, res in results.items() if key[0] == "random")
        boot = np.random.default_rng(7)
        for (v, e, c, cc, rr), res in results.items():
            cells = []
            for m in ("clusters", "pairs"):
                ratios = []
                for _ in range(1000):
                    a = boot.integers(args.sims, size=args.sims)
                    b = boot.integers(args.sims, size=args.sims)
                    ratios.append(res[m][a].mean() / base[m][b].mean())
                lo, hi = np.percentile(ratios, [2.5, 97.5])
                cells.append(f"{res[m].mean() / base[m].mean():.2f}x [{lo:.2f}, {hi:.2f}]")
            print(f"| {policy} ({len(records)}) | {v}{f' cover {c}' if c else ''}{f' c={cc} r={rr}' if v == 'good-ucb' else ''} | {e if v != 'random' else '-'} | {res['clusters'].mean():.1f} | "
                  f"{res['pairs'].mean():.1f} | {cells[0]} | {cells[1]} |", flush=True)


if __name__ == "__main__":
    main()
