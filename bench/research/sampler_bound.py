"""How much breadth any sampler can add over random at a budget: one large random run per policy.

    python -m bench.research.sampler_bound --policy idm --budget 60 --large 300 --seed 50 --out /tmp/bound

Random draws are independent of outcomes and of one another, so the large run's disjoint blocks of ``--budget``
episodes are independent random runs of that budget (``--large / --budget`` of them), and any ``--budget`` of its
episodes chosen at random are distributed as such a run. Reported per policy, on the product's breadth measures
(behaviour clusters, ``cluster_id``; (scenario family, failure type) pairs, ``pair_of``): what the whole large run
finds, what random finds at the budget (each block, and the mean over 2000 random subsets with its 5-95 %
range), the bound ``found at large / random's mean at budget`` (a sampler at the budget beats it only by
finding what the large random run does not), and Chao1's estimate of everything reachable (observed plus
singletons^2 / (2 doubletons)), which puts a number on what the large run misses.

``--analyse FILE.json`` recomputes from a saved run without simulating; ``--jsonl RUN/episodes.jsonl`` from a
run's episode records as they stand (a run stopped early is a random run of the episodes it has: its first N
episodes are exactly a random run of N with the same seed).
"""

from __future__ import annotations

import argparse
import json
import os
import random
import shutil
import statistics
import time
from collections import Counter
from typing import Any, Dict, List

from scenario_bank.records import EpisodeRecord


def _episodes(records: List[EpisodeRecord]) -> List[Dict[str, Any]]:
    from dv2s_gym.mining.cluster import cluster_id, pair_of

    out = []
    for r in sorted(records, key=lambda r: int(r.index)):
        failed = bool(r.failure) and not r.error
        out.append({"index": int(r.index), "scenario": r.scenario, "error": bool(r.error),
                    "cluster": cluster_id(r) if failed else None, "pair": pair_of(r) if failed else None})
    return out


def _count(eps: List[Dict[str, Any]], key: str) -> int:
    return len({e[key] for e in eps if e[key] is not None})


def _chao1(eps: List[Dict[str, Any]], key: str) -> float:
    freq = Counter(e[key] for e in eps if e[key] is not None)
    f1 = sum(1 for v in freq.values() if v == 1)
    f2 = sum(1 for v in freq.values() if v == 2)
    s = len(freq)
    return s + (f1 * f1 / (2 * f2) if f2 else f1 * (f1 - 1) / 2)


def analyse(eps: List[Dict[str, Any]], budget: int, subsets: int = 2000, seed: int = 0) -> Dict[str, Any]:
    rng = random.Random(seed)
    result: Dict[str, Any] = {"episodes": len(eps), "failures": sum(1 for e in eps if e["cluster"])}
    for key in ("cluster", "pair"):
        large = _count(eps, key)
        blocks = [_count(eps[i:i + budget], key) for i in range(0, len(eps) - budget + 1, budget)]
        draws = sorted(_count(rng.sample(eps, budget), key) for _ in range(subsets))
        mean = statistics.fmean(draws)
        result[key] = {"large": large, "blocks": blocks, "subset_mean": mean,
                       "subset_5_95": (draws[int(0.05 * subsets)], draws[int(0.95 * subsets) - 1]),
                       "bound": large / mean, "chao1": _chao1(eps, key),
                       "chao1_bound": _chao1(eps, key) / mean,
                       "curve": {n: statistics.fmean(_count(rng.sample(eps, n), key) for _ in range(300))
                                 for n in (budget, 2 * budget, 3 * budget, 4 * budget) if n <= len(eps)}}
    return result


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--policy", default="idm")
    p.add_argument("--budget", type=int, default=60)
    p.add_argument("--large", type=int, default=300)
    p.add_argument("--seed", type=int, default=50)
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--out", default="/tmp/sampler_bound")
    p.add_argument("--analyse", default=None, help="a saved episodes JSON: recompute only")
    p.add_argument("--jsonl", default=None, help="a run's episodes.jsonl (complete or not): recompute only")
    args = p.parse_args()
    if args.jsonl:
        with open(args.jsonl) as f:
            records = [EpisodeRecord.from_dict(json.loads(line)) for line in f if line.strip()]
        records = [r for r in records if not r.get("error")]
        saved = {"policy": records[0]["policy"] if records else args.policy, "seed": args.seed,
                 "large": len(records), "episodes": _episodes(records)}
    elif args.analyse:
        with open(args.analyse) as f:
            saved = json.load(f)
    else:
        from dv2s_gym.mining.miner import MineSettings, WorkerSettings, mine

        run_dir = os.path.join(args.out, "run")
        shutil.rmtree(run_dir, ignore_errors=True)
        start = time.time()
        settings = MineSettings(budget=args.large, sampler="random", seed=args.seed, reference=None)
        run = mine(args.policy, settings, out=run_dir, workers=WorkerSettings(workers=args.workers),
                   progress=False, reports=False)
        saved = {"policy": args.policy, "seed": args.seed, "large": args.large, "seconds": time.time() - start,
                 "load": os.getloadavg(), "episodes": _episodes(run.records)}
        os.makedirs(args.out, exist_ok=True)
        with open(os.path.join(args.out, "episodes.json"), "w") as f:
            json.dump(saved, f)
    res = analyse(saved["episodes"], args.budget)
    print(f"{saved['policy']} seed {saved['seed']}: {res['episodes']} episodes, {res['failures']} failures, "
          f"{len({e['scenario'] for e in saved['episodes']})} scenarios drawn")
    for key in ("cluster", "pair"):
        r = res[key]
        print(f"  {key}s: {r['large']} at {res['episodes']}; at {args.budget}: blocks {r['blocks']}, subset mean "
              f"{r['subset_mean']:.1f} (5-95 % {r['subset_5_95']}); bound {r['bound']:.2f}x; chao1 {r['chao1']:.1f} "
              f"-> {r['chao1_bound']:.2f}x; curve " + ", ".join(f"{n}: {v:.1f}" for n, v in r["curve"].items()))
    print(json.dumps({"policy": saved["policy"], **res}))


if __name__ == "__main__":
    main()
