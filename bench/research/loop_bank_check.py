"""A fine-tuned policy against the loop's starting policy on the starting bank, with many seeds per scenario.

    python -m bench.research.loop_bank_check --loop out/loop-seed0 --candidate out/sweep/NAME/policy/model.zip \
        --episodes 12 --out /tmp/bank12

The loop's own regression test runs ``--regress-episodes`` (default 4) seeds per starting scenario,
84 pairs on the shipped bank: too few to see one scenario regress. This runs ``dv2s regress``'s
``run_regression`` with the loop's settings (its starting policy as the baseline, its starting bank
and scenarios, its env config, seeds from 10000 like the loop's) and ``--episodes`` seeds per
scenario: the 252-pair check of bench/RESULTS.md. Prints the verdict with its reason and, per
scenario, the candidate's and the baseline's failure counts.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--loop", required=True, help="a `dv2s loop` output folder (reads its loop.json)")
    parser.add_argument("--candidate", required=True, help="the fine-tuned SB3 model.zip (or any policy spec)")
    parser.add_argument("--episodes", type=int, default=12, help="seeds per starting scenario (default 12)")
    parser.add_argument("--seed", type=int, default=10000, help="first seed (default 10000, the loop's)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--out", required=True, help="folder for the regression report")
    args = parser.parse_args()

    from dv2s_gym.regress.runner import RegressSettings, WorkerSettings, run_regression

    state_path = Path(args.loop) / "loop.json"
    if not state_path.is_file():
        parser.error(f"{state_path} does not exist: pass the --out folder of a `dv2s loop` run")
    state = json.loads(state_path.read_text())
    settings, start = state["settings"], state["start"]
    candidate = args.candidate
    if candidate.endswith(".zip") and ":" not in candidate:
        candidate = f"ppo:{candidate}"
    regress = RegressSettings(bank_dir=start["bank"], scenarios=start["scenarios"], episodes=args.episodes,
                              seed=args.seed, env_config=settings.get("env_config"))
    report = run_regression(candidate, settings["policy"], regress, workers=WorkerSettings(workers=args.workers),
                            out_dir=args.out, progress=False).to_dict()
    print(report["verdict"], "-", report["overall"]["comparison"].get("reason"))
    print(f"{'scenario':45s} candidate baseline (failures of {args.episodes})")
    for name, row in report["scenarios"].items():
        new = (row.get("candidate") or {}).get("failure_rate", {}).get("count")
        old = (row.get("baseline") or {}).get("failure_rate", {}).get("count")
        print(f"{name:45s} {new!s:>9} {old!s:>8}")


if __name__ == "__main__":
    main()
