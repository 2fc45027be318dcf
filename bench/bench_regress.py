"""Throughput of ``dv2s regress``: episodes per minute with 1 and 2 workers, against raw env stepping.

    python -m bench.bench_regress              # 9 highway scenarios x 20 seeds, rule-based driver
    python -m bench.bench_regress --quick      # 9 x 4
    python -m bench.bench_regress --repeats 3  # interleave three rounds, report medians

The same episodes (every scenario of ``tag:highway``, seeds 0..N-1), the same policy
(``rule``), three ways, interleaved round by round so the ratios share the machine's load:

* ``raw``       - one process, no harness: one DV2S-v0 env over the bank, the policy
  bound to it, ``reset(seed, scenario)`` then ``act``/``step`` until the episode ends.
  Env creation and each scenario's first compile are timed (the harness pays them too);
  imports are not (already done).
* ``harness/1`` - ``run_regression`` with ``workers=1`` (candidate only, no baseline):
  the worker pool start, per-episode results, trajectory hashes, traces of failed
  episodes, the streamed ``results.jsonl`` and the reports, end to end.
* ``harness/2`` - the same with ``workers=2``.

Printed: episodes per minute of each, scaling (harness/2 over harness/1, target >= 1.8x)
and harness overhead (harness/1 time over raw time - 1, target <= 10 %), plus the load
average, since other processes on the machine take cores from the 2-worker run.
"""

from __future__ import annotations

import argparse
import os
import statistics
import tempfile
import time
from typing import Dict, List, Sequence, Tuple

os.environ.setdefault("OMP_NUM_THREADS", "1")

SCENARIOS = "tag:highway"
POLICY = "rule"


def episodes_of(count: int) -> List[Tuple[str, int]]:
    """The benchmark's (scenario, seed) pairs."""
    from scenario_bank import select_scenarios

    return [(name, seed) for seed in range(count) for name in select_scenarios([SCENARIOS])]


def run_raw(episodes: Sequence[Tuple[str, int]]) -> float:
    """Seconds to step every episode in a plain loop in this process."""
    import numpy as np

    from envs.dv2s_env import DV2SEnv
    from policies.registry import load_policy

    start = time.perf_counter()
    env = DV2SEnv(scenario=None)
    policy = load_policy(POLICY)
    policy.bind([env])
    for scenario, seed in episodes:
        observation, _ = env.reset(seed=seed, options={"scenario": scenario})
        policy.reset(0)
        done = False
        while not done:
            action = policy.act(np.asarray(observation)[None])[0]
            observation, _, terminated, truncated, _ = env.step(action)
            done = terminated or truncated
    env.close()
    return time.perf_counter() - start


def run_harness(count: int, workers: int) -> float:
    """Seconds for ``run_regression`` over the same episodes with ``workers`` processes, end to end."""
    from dv2s_gym.regress.runner import run_regression

    with tempfile.TemporaryDirectory(prefix="bench-regress-") as out:
        start = time.perf_counter()
        report = run_regression(POLICY, scenarios=[SCENARIOS], episodes=count, workers=workers, out_dir=out,
                                progress=False)
        seconds = time.perf_counter() - start
    if report["errors"]:
        raise RuntimeError(f"benchmark episodes ended in errors: {report['errors'][:2]}")
    return seconds


def main(argv: Sequence[str] | None = None) -> Dict[str, float]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="4 seeds per scenario instead of 20")
    parser.add_argument("--seeds", type=int, default=None, help="seeds per scenario (default 20)")
    parser.add_argument("--repeats", type=int, default=1, help="interleaved rounds (medians reported)")
    args = parser.parse_args(argv)
    count = args.seeds or (4 if args.quick else 20)
    episodes = episodes_of(count)
    load_before = os.getloadavg()
    times: Dict[str, List[float]] = {"raw": [], "harness/1": [], "harness/2": []}
    for round_ in range(args.repeats):
        times["raw"].append(run_raw(episodes))
        times["harness/1"].append(run_harness(count, 1))
        times["harness/2"].append(run_harness(count, 2))
        print(f"round {round_ + 1}: " + ", ".join(f"{k} {v[-1]:.1f} s" for k, v in times.items()), flush=True)
    load_after = os.getloadavg()
    median = {k: statistics.median(v) for k, v in times.items()}
    rate = {k: 60.0 * len(episodes) / v for k, v in median.items()}
    scaling = median["harness/1"] / median["harness/2"]
    overhead = median["harness/1"] / median["raw"] - 1.0
    print(f"{len(episodes)} episodes ({SCENARIOS} x {count} seeds, policy {POLICY!r}), "
          f"median of {args.repeats} round(s); load average {load_before[0]:.1f} before, {load_after[0]:.1f} after; "
          f"{os.cpu_count()} cores")
    for key in times:
        print(f"  {key:<10} {median[key]:7.1f} s   {rate[key]:7.1f} episodes/min")
    print(f"scaling 2 workers / 1 worker: {scaling:.2f}x (target >= 1.8x)")
    print(f"harness overhead over raw stepping (1 worker): {100 * overhead:+.1f} % (target <= 10 %)")
    return {"scaling": scaling, "overhead": overhead, **{f"rate/{k}": v for k, v in rate.items()}}


if __name__ == "__main__":
    main()
