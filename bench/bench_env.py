"""Speed and memory of DV2S-v0, measured against native highway-env in one run.

    python -m bench.bench_env            # full run (about two minutes)
    python -m bench.bench_env --quick    # smaller counts

Baseline: highway-env's ``highway-v0`` with the same scene size as
``six_cars_highway.scenic``: 4 straight lanes, the ego and 5 other cars, 15 Hz
physics, 5 Hz policy, the same action (DiscreteMetaAction, IDLE) and the same
Kinematics observation config, and the same episode end: both terminate when the
ego crashes (highway-v0's rule) and neither when it leaves the road. Native NPCs
are IDMVehicles; ours run Scenic's FollowLaneBehavior. Only steps are timed, not
the resets after a crash.

Four envs run interleaved in the same process, so their ratios share the
machine's load:

* ``native/stock``  - highway-v0 as shipped (highway-env's pandas Kinematics)
* ``native/fast``   - highway-v0 with the project's NumPy Kinematics injected
* ``dv2s/stock``    - DV2S-v0 with highway-env's pandas Kinematics put back
* ``dv2s/fast``     - DV2S-v0 as shipped (NumPy Kinematics)

It prints steps/s for each, the like-for-like ratios (same observation on
both), the as-shipped ratio, where DV2S-v0's step time goes (cProfile), the
reset time after the first compile and resident-memory growth over many resets.
"""

from __future__ import annotations

import argparse
import cProfile
import gc
import os
import pstats
import statistics
import time
import types
from pathlib import Path

import gymnasium as gym
import highway_env  # noqa: F401  (registers highway-v0)
import numpy as np
from highway_env.envs.common.observation import KinematicObservation

import dv2s_gym  # noqa: F401  (registers DV2S-v0)
from envs.observations import FastKinematicObservation

SCENE = Path(__file__).with_name("six_cars_highway.scenic")
OTHER_CARS = 5
FREQ = {"simulation_frequency": 15, "policy_frequency": 5}
OBS = {"type": "Kinematics", "vehicles_count": 8, "features": ["presence", "x", "y", "vx", "vy", "cos_h", "sin_h"]}
IDLE = 1


def with_observation(env, cls):
    """Make ``env`` build its Kinematics observation as ``cls`` (on every reset too)."""
    define_spaces = env.define_spaces

    def define(self):
        define_spaces()
        if isinstance(self.observation_type, KinematicObservation):
            self.observation_type.__class__ = cls

    env.define_spaces = types.MethodType(define, env)
    env.define_spaces()
    return env


def make_native(observation=KinematicObservation):
    """``highway-v0`` with the benchmark scene size; ``observation`` is the Kinematics class."""
    env = gym.make(
        "highway-v0",
        config={**FREQ, "lanes_count": 4, "vehicles_count": OTHER_CARS, "controlled_vehicles": 1,
                "duration": 1000, "observation": OBS, "action": {"type": "DiscreteMetaAction"}},
    ).unwrapped
    return with_observation(env, observation)


def make_dv2s(observation=FastKinematicObservation):
    """DV2S-v0 on ``six_cars_highway.scenic``; ``observation`` is the Kinematics class."""
    env = gym.make("DV2S-v0", scenario=str(SCENE),
                   config={**FREQ, "duration": 1000, "observation": OBS,
                           "terminate_on_collision": True, "terminate_off_road": False}).unwrapped
    return with_observation(env, observation)


def check_same_scene(envs: dict) -> None:
    """Refuse to compare envs whose scenes differ in size, lanes or observation class."""
    for name, env in envs.items():
        env.reset(seed=0)
        cars = len(env.road.vehicles)
        lanes = len(env.road.network.all_side_lanes(env.vehicle.lane_index))
        want_cls = KinematicObservation if name.endswith("stock") else FastKinematicObservation
        if cars != OTHER_CARS + 1 or lanes != 4 or type(env.observation_type) is not want_cls:
            raise RuntimeError(f"{name}: {cars} vehicles on {lanes} lanes with {type(env.observation_type).__name__}; "
                               f"the benchmark needs {OTHER_CARS + 1} on 4 lanes with {want_cls.__name__}")
        if (env.config["simulation_frequency"], env.config["policy_frequency"]) != (15, 5):
            raise RuntimeError(f"{name}: frequencies differ from 15 Hz / 5 Hz")


class Runner:
    """Steps one env under the IDLE action, timing steps only (resets after an episode ends are not timed)."""

    def __init__(self, env, seed: int) -> None:
        self.env, self.seed = env, seed
        self.elapsed, self.steps, self.resets, self.crashed_steps = 0.0, 0, 0, 0
        env.reset(seed=seed)

    def run(self, steps: int) -> None:
        env = self.env
        for _ in range(steps):
            start = time.perf_counter()
            _, _, terminated, truncated, _ = env.step(IDLE)
            self.elapsed += time.perf_counter() - start
            self.steps += 1
            self.crashed_steps += any(v.crashed for v in env.road.vehicles)
            if terminated or truncated:
                self.resets += 1
                env.reset(seed=self.seed * 100_003 + self.steps)

    @property
    def rate(self) -> float:
        return self.steps / self.elapsed


def interleaved_rates(envs: dict, steps: int, seed: int, chunk: int = 25) -> dict:
    """Run every env ``steps`` steps from ``seed``, alternating every ``chunk`` steps so they share the load."""
    runners = {name: Runner(env, seed) for name, env in envs.items()}
    for _ in range(0, steps, chunk):
        for runner in runners.values():
            runner.run(chunk)
    return runners


def rss_mb() -> float:
    with open("/proc/self/statm") as f:
        pages = int(f.read().split()[1])
    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


def where_time_goes(env, steps: int) -> list:
    """Share of step time (cumulative, so parts may nest) spent in the main components."""
    profile = cProfile.Profile()
    env.reset(seed=123)
    profile.enable()
    for _ in range(steps):
        env.step(IDLE)
    profile.disable()
    stats = pstats.Stats(profile).stats
    total = max(ct for (_f, _l, func), (_cc, _nc, _tt, ct, _c) in stats.items() if func == "step")

    def cum(file_part: str, *funcs: str) -> float:
        return sum(ct for (f, _l, fn), (_cc, _nc, _tt, ct, _c) in stats.items() if file_part in f and fn in funcs)

    rows = [
        ("Scenic behaviours (NPC decisions)", cum("scenic/core/dynamics/behaviors.py", "_step")),
        ("Scenic requirements & monitors", cum("scenic/core/dynamics/scenarios.py", "_step")),
        ("Scenic state read-back", cum("scenic_highway/simulator.py", "updateObjects")),
        ("highway-env physics (road.step)", cum("envs/hw_road.py", "step")),
        ("  of which collision tests", cum("envs/hw_road.py", "_collide")),
        ("lane look-ups", cum("envs/road_network/lanes.py", "get_closest_lane_index")),
        ("observation", cum("envs/observations.py", "observe")),
        ("time-to-collision", cum("envs/safety_metrics.py", "time_to_collision")),
        ("trace record (actor states)", cum("envs/dv2s_env.py", "_record_state")),
    ]
    return [(label, 100.0 * value / total) for label, value in rows]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args(argv)
    steps = 150 if args.quick else 600
    resets = 300 if args.quick else 1000
    os.environ.setdefault("OMP_NUM_THREADS", "1")

    envs = {
        "native/stock": make_native(KinematicObservation),
        "native/fast": make_native(FastKinematicObservation),
        "dv2s/stock": make_dv2s(KinematicObservation),
        "dv2s/fast": make_dv2s(FastKinematicObservation),
    }
    check_same_scene(envs)
    interleaved_rates(envs, 25, seed=99)  # warm-up
    runs = {name: [] for name in envs}
    crashed = {name: 0 for name in envs}
    ended = {name: 0 for name in envs}
    for round_ in range(3):
        for name, runner in interleaved_rates(envs, steps, seed=round_).items():
            runs[name].append(runner.rate)
            crashed[name] += runner.crashed_steps
            ended[name] += runner.resets
    rate = {name: statistics.median(r) for name, r in runs.items()}
    print(f"load average at the end of the speed runs: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    print(f"env steps/s (median of 3 rounds, seeds 0-2, {steps} steps each; the four envs alternate every 25 steps):")
    for name, value in rate.items():
        print(f"    {name:<14} {value:8.1f}   (episodes ended {ended[name]:3d}x, "
              f"{100 * crashed[name] / (3 * steps):4.1f}% of steps with a crashed car on the road)")
    print("ratios DV2S-v0 / native highway-v0:")
    print(f"    same stock (pandas) Kinematics on both : {rate['dv2s/stock'] / rate['native/stock']:.2f}x")
    print(f"    same fast (NumPy) Kinematics on both   : {rate['dv2s/fast'] / rate['native/fast']:.2f}x   (target >= 1.0x)")
    print(f"    as shipped (DV2S fast vs native stock) : {rate['dv2s/fast'] / rate['native/stock']:.2f}x   (target >= 2.0x)")
    print("    per round (seeds 0, 1, 2), same fast observation:",
          ", ".join(f"{o / n:.2f}x" for o, n in zip(runs["dv2s/fast"], runs["native/fast"])))

    ours = envs["dv2s/fast"]
    print("where DV2S-v0 step time goes (% of env.step under cProfile, cumulative; rows may nest):")
    for label, pct in where_time_goes(ours, steps // 2):
        print(f"    {label:<36} {pct:5.1f}%")

    times = []
    for i in range(60):
        t = time.perf_counter()
        ours.reset(seed=1000 + i)
        times.append(time.perf_counter() - t)
    print(f"reset() after first compile, six actors: median {1000 * statistics.median(times):.1f} ms, "
          f"p90 {1000 * float(np.percentile(times, 90)):.1f} ms")

    gc.collect()
    before = rss_mb()
    for i in range(resets):
        ours.reset(seed=5000 + i)
    gc.collect()
    after = rss_mb()
    print(f"{resets} resets: resident memory {before:.0f} MB -> {after:.0f} MB (growth {after - before:+.1f} MB)")


if __name__ == "__main__":
    main()
