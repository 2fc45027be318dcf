"""The cost of the jail: DV2S-v0 on an untrusted script, jailed, against the same script in process.

    python -m bench.bench_jail            # full run (a few minutes)
    python -m bench.bench_jail --quick    # smaller counts

Baseline: the same env class on the same scene (``six_cars_highway.scenic``, 4 lanes,
the ego and 5 cars), the same config, seeds and actions, run in this process with
``trusted=True``. The jailed env (``DV2SEnv`` on the script's text, the default for
any script that does not ship with the package) simulates in a jailed worker and
sends observations back over a pipe. Both are measured interleaved in one run, so
their ratios share the machine's load.

Prints, for in-process and jailed:

* env start (construct + first compile) and reset (a new scene after the first compile);
* steps/s over episodes of IDLE actions;
* PPO training throughput (stable-baselines3, env steps per second of ``learn``).
"""

from __future__ import annotations

import argparse
import os

# the jailed worker runs with one BLAS/OpenMP thread; so does this process, or the comparison is of thread counts
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")
import platform  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import dv2s_gym  # noqa: E402,F401  (registers DV2S-v0)
from envs.dv2s_env import DV2SEnv  # noqa: E402

SCENE = Path(__file__).with_name("six_cars_highway.scenic")
CONFIG = {"duration": 40.0, "simulation_frequency": 15, "policy_frequency": 5}
IDLE = 1


def make(jailed: bool) -> DV2SEnv:
    """The benchmark env, in this process (``trusted=True``) or jailed (the default for this script)."""
    text = SCENE.read_text(encoding="utf-8")
    env = DV2SEnv(scenario=text, config=dict(CONFIG), trusted=not jailed)
    assert env.runs_in_jail == jailed
    return env


def time_start(jailed: bool) -> float:
    start = time.perf_counter()
    env = make(jailed)
    env.reset(seed=0)
    elapsed = time.perf_counter() - start
    env.close()
    return elapsed


def time_resets(env: DV2SEnv, seeds) -> float:
    """Median seconds of ``reset(seed)`` (a new scene; the script is compiled already)."""
    times = []
    for seed in seeds:
        start = time.perf_counter()
        env.reset(seed=int(seed))
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def steps_per_second(env: DV2SEnv, steps: int, seed: int) -> float:
    env.reset(seed=seed)
    done, elapsed = 0, 0.0
    while done < steps:
        start = time.perf_counter()
        _, _, terminated, truncated, _ = env.step(IDLE)
        elapsed += time.perf_counter() - start
        done += 1
        if terminated or truncated:
            env.reset(seed=seed + done)
    return done / elapsed


def ppo_steps_per_second(env: DV2SEnv, steps: int) -> float:
    from stable_baselines3 import PPO

    model = PPO("MlpPolicy", env, n_steps=128, batch_size=64, n_epochs=2, seed=0, device="cpu", verbose=0)
    start = time.perf_counter()
    model.learn(total_timesteps=steps)
    return steps / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="smaller counts")
    parser.add_argument("--rounds", type=int, default=None, help="interleaved rounds (default 3, quick 1)")
    args = parser.parse_args()
    rounds = args.rounds or (1 if args.quick else 3)
    step_count = 150 if args.quick else 600
    ppo_count = 256 if args.quick else 1024
    print(f"machine: {platform.node()} {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"load {os.getloadavg()[0]:.2f}; {time.strftime('%Y-%m-%d %H:%M')}")

    results = {name: {"start": [], "reset": [], "steps": [], "ppo": []} for name in ("in-process", "jailed")}
    envs = {"in-process": make(False), "jailed": make(True)}
    try:
        for round_ in range(rounds):
            for name, jailed in (("in-process", False), ("jailed", True)):
                results[name]["start"].append(time_start(jailed))
            for name, env in envs.items():
                results[name]["reset"].append(time_resets(env, range(10 * round_, 10 * round_ + 10)))
                results[name]["steps"].append(steps_per_second(env, step_count, seed=100 + round_))
                results[name]["ppo"].append(ppo_steps_per_second(env, ppo_count))
    finally:
        for env in envs.values():
            env.close()

    med = {name: {key: statistics.median(values) for key, values in r.items()} for name, r in results.items()}
    print(f"\n{'':12s}{'start (s)':>12s}{'reset (ms)':>12s}{'steps/s':>10s}{'PPO steps/s':>14s}")
    for name, m in med.items():
        print(f"{name:12s}{m['start']:12.2f}{1000 * m['reset']:12.1f}{m['steps']:10.1f}{m['ppo']:14.1f}")
    base, jail = med["in-process"], med["jailed"]
    print(f"\njailed / in-process: steps/s {jail['steps'] / base['steps']:.2f}x, PPO {jail['ppo'] / base['ppo']:.2f}x, "
          f"reset +{1000 * (jail['reset'] - base['reset']):.1f} ms, start +{jail['start'] - base['start']:.2f} s "
          f"(medians of {rounds} interleaved round(s), {step_count} steps and {ppo_count} PPO steps each)")


if __name__ == "__main__":
    main()
