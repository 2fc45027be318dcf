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
and harness overhead (harness/1 time over raw time - 1, target <= 10 %), end to end and in
steady state (from the first finished episode to the last: without the worker pool's start,
which is a fixed cost of about one interpreter start plus the simulator's imports), and the
time to the first result.

Other processes on the machine take cores from the 2-worker run, so the bench also measures
the machine's parallel capacity in the same run: a pure-Python busy loop run in 2 processes
at once against 1 (2.0x on two free cores). Scaling is bounded by that figure.
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


def run_raw(episodes: Sequence[Tuple[str, int]]) -> Tuple[float, float]:
    """Seconds to step every episode in a plain loop in this process, and from the first episode's end to the last's."""
    import numpy as np

    from envs.dv2s_env import DV2SEnv
    from policies.registry import load_policy

    start = time.perf_counter()
    env = DV2SEnv(scenario=None)
    policy = load_policy(POLICY)
    policy.bind([env])
    ends = []
    for scenario, seed in episodes:
        observation, _ = env.reset(seed=seed, options={"scenario": scenario})
        policy.reset(0)
        done = False
        while not done:
            action = policy.act(np.asarray(observation)[None])[0]
            observation, _, terminated, truncated, _ = env.step(action)
            done = terminated or truncated
        ends.append(time.perf_counter())
    env.close()
    return time.perf_counter() - start, ends[-1] - ends[0]


def run_harness(count: int, workers: int) -> Tuple[float, float, float]:
    """``run_regression`` over the same episodes with ``workers`` processes: seconds end to end, from the
    first result to the last, and to the first result."""
    from dv2s_gym.regress.runner import RegressSettings, WorkerSettings, run_regression

    ends: List[float] = []
    with tempfile.TemporaryDirectory(prefix="bench-regress-") as out:
        start = time.perf_counter()
        report = run_regression(POLICY, None, RegressSettings(scenarios=[SCENARIOS], episodes=count),
                                workers=WorkerSettings(workers=workers), out_dir=out, progress=False,
                                on_result=lambda _: ends.append(time.perf_counter()))
        seconds = time.perf_counter() - start
    if report.errors:
        raise RuntimeError(f"benchmark episodes ended in errors: {[error.to_dict() for error in report.errors[:2]]}")
    return seconds, ends[-1] - ends[0], ends[0] - start


def _spin(_: int) -> float:
    start = time.perf_counter()
    total = 0
    for i in range(10_000_000):
        total += i
    return time.perf_counter() - start


def parallel_capacity() -> float:
    """Throughput of two busy loops in two processes over one busy loop alone (2.0 on two free cores)."""
    import multiprocessing

    context = multiprocessing.get_context("spawn")
    with context.Pool(2) as pool:
        pool.map(_spin, [0, 1])  # start both processes first
        start = time.perf_counter()
        pool.map(_spin, [0])
        one = time.perf_counter() - start
        start = time.perf_counter()
        pool.map(_spin, [0, 1], chunksize=1)
        two = time.perf_counter() - start
    return 2.0 * one / two


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
    steady: Dict[str, List[float]] = {"raw": [], "harness/1": [], "harness/2": []}
    first: List[float] = []
    capacity: List[float] = []
    for round_ in range(args.repeats):
        capacity.append(parallel_capacity())
        total, span = run_raw(episodes)
        times["raw"].append(total)
        steady["raw"].append(span)
        for workers in (1, 2):
            total, span, to_first = run_harness(count, workers)
            times[f"harness/{workers}"].append(total)
            steady[f"harness/{workers}"].append(span)
            if workers == 1:
                first.append(to_first)
        print(f"round {round_ + 1}: " + ", ".join(f"{k} {v[-1]:.1f} s" for k, v in times.items())
              + f"; parallel capacity {capacity[-1]:.2f}x", flush=True)
    load_after = os.getloadavg()
    median = {k: statistics.median(v) for k, v in times.items()}
    median_steady = {k: statistics.median(v) for k, v in steady.items()}
    rate = {k: 60.0 * len(episodes) / v for k, v in median.items()}
    scaling = median["harness/1"] / median["harness/2"]
    scaling_steady = median_steady["harness/1"] / median_steady["harness/2"]
    overhead = median["harness/1"] / median["raw"] - 1.0
    overhead_steady = median_steady["harness/1"] / median_steady["raw"] - 1.0
    print(f"{len(episodes)} episodes ({SCENARIOS} x {count} seeds, policy {POLICY!r}), "
          f"median of {args.repeats} round(s); load average {load_before[0]:.1f} before, {load_after[0]:.1f} after; "
          f"{os.cpu_count()} cores; parallel capacity of the machine {statistics.median(capacity):.2f}x")
    for key in times:
        print(f"  {key:<10} {median[key]:7.1f} s   {rate[key]:7.1f} episodes/min   "
              f"(first to last episode {median_steady[key]:.1f} s)")
    print(f"scaling 2 workers / 1 worker: {scaling:.2f}x end to end, {scaling_steady:.2f}x steady state "
          f"(target >= 1.8x; bounded by the capacity {statistics.median(capacity):.2f}x)")
    print(f"harness overhead over raw stepping (1 worker): {100 * overhead:+.1f} % end to end, "
          f"{100 * overhead_steady:+.1f} % steady state (target <= 10 %); first result after "
          f"{statistics.median(first):.1f} s")
    return {"scaling": scaling, "scaling_steady": scaling_steady, "overhead": overhead,
            "overhead_steady": overhead_steady, "capacity": statistics.median(capacity),
            **{f"rate/{k}": v for k, v in rate.items()}}

if __name__ == "__main__":
    main()
