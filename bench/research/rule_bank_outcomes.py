"""Outcome of a policy on every starting bank scenario, one letter per seed (C collision, O off road, S success, s stall).

    python -m bench.research.rule_bank_outcomes --policy rule --episodes 12 --out /tmp/rule.json

How the reference driver ``rule`` was measured before and after its gap acceptance
(bench/RESULTS.md): seeds 10000.. per scenario, ``policies.evaluation.run_episode`` on the
shipped bank, one process. Prints one line per scenario and the totals; ``--out`` keeps the
per-episode rows (JSON).
"""

from __future__ import annotations

import argparse
import os

os.environ.setdefault("OMP_NUM_THREADS", "1")


def outcome_letter(result) -> str:
    """C collision, O off road, S success, s no failure but stalled (under the success distance)."""
    return "C" if result.collided else ("O" if result.off_road else ("S" if result.success else "s"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", default="rule", help="a policy spec (policies.registry.load_policy)")
    parser.add_argument("--episodes", type=int, default=12, help="seeds per scenario, from --seed")
    parser.add_argument("--seed", type=int, default=10000)
    parser.add_argument("--out", default=None, help="write the per-episode rows here (JSON)")
    args = parser.parse_args()

    from policies.evaluation import make_eval_env, run_episode
    from policies.registry import load_policy
    from scenario_bank.bank import Bank

    rows, totals = {}, {"C": 0, "O": 0, "S": 0, "s": 0}
    for name in sorted(entry.name for entry in Bank()):
        env = make_eval_env([name])
        policy = load_policy(args.policy)
        if hasattr(policy, "bind"):
            policy.bind([env])
        results = [run_episode(env, policy, name, seed)[0] for seed in range(args.seed, args.seed + args.episodes)]
        env.close()
        letters = "".join(outcome_letter(r) for r in results)
        for letter in letters:
            totals[letter] += 1
        rows[name] = {"outcomes": letters, "rows": [r.to_json() for r in results]}
        print(f"{name:45s} {letters}", flush=True)
    print("collisions {C}, off road {O}, successes {S}, stalls {s}".format(**totals))
    if args.out:
        from scenario_bank.atomic import atomic_write_json

        atomic_write_json(args.out, rows)


if __name__ == "__main__":
    main()
