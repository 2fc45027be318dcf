"""``novelty-bandit`` with and without ``cover`` against random, on breadth measures none of them is fed.

    python -m bench.research.sampler_cover --seeds 0 1 2 3 4 5 --out /var/tmp/cmp

Three arms per policy and seed, 60 episodes each, whole shipped bank, no reference driver, 2 workers:
``random``; ``nb-old``, ``novelty-bandit`` with ``cover`` 0 (the scores rank the scenarios from the first draw: the
sampler as it was before ``cover``); ``nb-cover1``, ``novelty-bandit`` with ``cover`` 1 (every scenario has one scene
before the scores rank them; the default). Counted per run: behaviour clusters, (scenario, failure type) pairs and
scenarios with a failure (``bench.bench_mine.mine_once``). One JSON line per run in ``OUT/rows.jsonl`` (a rerun skips
the runs already there), then the sums per policy and overall with the ratios to random.
"""

from __future__ import annotations

import argparse
import json
import os
from collections import defaultdict

POLICIES = ("idm", "keep_lane", "rule?action_noise=0.2")
ARMS = (("random", "random", None), ("nb-old", "novelty-bandit", {"cover": 0}),
        ("nb-cover1", "novelty-bandit", {"cover": 1}))
MEASURES = ("clusters", "kinds", "scenarios_failing")


def main() -> None:
    from bench.bench_mine import mine_once

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4, 5])
    parser.add_argument("--policies", nargs="+", default=list(POLICIES))
    parser.add_argument("--budget", type=int, default=60)
    parser.add_argument("--out", default="/tmp/sampler_cover")
    args = parser.parse_args()
    os.makedirs(args.out, exist_ok=True)
    path = os.path.join(args.out, "rows.jsonl")
    rows = [json.loads(line) for line in open(path)] if os.path.exists(path) else []
    done = {(r["policy"], r["seed"], r["arm"]) for r in rows}
    for policy in args.policies:
        for seed in args.seeds:
            for arm, name, options in ARMS:
                if (policy, seed, arm) in done:
                    continue
                row = mine_once(policy, name, seed, args.budget, 2, None, None, None,
                                os.path.join(args.out, f"run-{arm}"), options, None)
                record = {"policy": policy, "seed": seed, "arm": arm,
                          **{key: row[key] for key in ("failures",) + MEASURES}}
                print(record, flush=True)
                rows.append(record)
                with open(path, "a") as handle:
                    handle.write(json.dumps(record) + "\n")
    sums = defaultdict(lambda: defaultdict(int))
    for r in rows:
        if r["policy"] in args.policies and r["seed"] in args.seeds:
            for key in MEASURES:
                sums[(r["policy"], r["arm"])][key] += r[key]
                sums[("all", r["arm"])][key] += r[key]
    print("| policy | sampler | behaviour clusters | pairs | scenarios with a failure | clusters vs random | "
          "pairs vs random | scenarios vs random |\n|---|---|---:|---:|---:|---:|---:|---:|")
    for policy in list(args.policies) + ["all"]:
        base = sums[(policy, "random")]
        for arm, _, _ in ARMS:
            got = sums[(policy, arm)]
            print(f"| {policy} | {arm} | " + " | ".join(str(got[k]) for k in MEASURES) + " | "
                  + " | ".join(f"{got[k] / base[k]:.2f}x" if base[k] else "-" for k in MEASURES) + " |")


if __name__ == "__main__":
    main()
