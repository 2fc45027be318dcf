"""Speed and memory of DV2S-v0, measured against native highway-env in one run.

    python -m bench.bench_env            # full run (about a minute)
    python -m bench.bench_env --quick    # smaller counts

Baseline: highway-env's ``highway-v0`` on the same kind of road (4 straight lanes),
the same number of actors (ego + 5 cars), the same frequencies (15 Hz physics,
5 Hz policy), the same observation (Kinematics) and action (DiscreteMetaAction,
IDLE). Native NPCs are IDMVehicles; ours run Scenic's FollowLaneBehavior.

Measured twice, like with like: (a) both envs with highway-env's stock pandas
``KinematicObservation``, (b) both with the project's NumPy ``FastKinematicObservation``
(same array). The observation class is set on both envs by the same helper.
"""

from __future__ import annotations

import argparse
import cProfile
import gc
import pstats
import statistics
import time
from pathlib import Path

import gymnasium as gym
import highway_env  # noqa: F401  (registers highway-v0)
import numpy as np

from highway_env.envs.common.observation import KinematicObservation

import dv2s_gym  # noqa: F401  (registers DV2S-v0)
from envs.observations import FastKinematicObservation

SCENE = Path(__file__).with_name("six_cars_highway.scenic")
FREQ = {"simulation_frequency": 15, "policy_frequency": 5}
OBS = {"type": "Kinematics", "vehicles_count": 8, "features": ["presence", "x", "y", "vx", "vy", "cos_h", "sin_h"]}


def with_observation(env, cls):
    """Make ``env`` (either kind) observe Kinematics with ``cls``, now and after every reset."""
    define = env.define_spaces

    def define_with_cls():
        define()
        if isinstance(env.observation_type, KinematicObservation):
            env.observation_type.__class__ = cls

    env.define_spaces = define_with_cls
    define_with_cls()
    return env


def make_native():
    return gym.make(
        "highway-v0",
        config={**FREQ, "lanes_count": 4, "vehicles_count": 5, "controlled_vehicles": 1,
                "duration": 1000, "observation": OBS, "action": {"type": "DiscreteMetaAction"}},
    ).unwrapped


def make_dv2s():
    return gym.make("dv2s_gym:DV2S-v0", scenario=str(SCENE),
                    config={**FREQ, "duration": 1000, "observation": OBS,
                            "terminate_on_collision": False, "terminate_off_road": False}).unwrapped


def steps_per_second(env, steps: int, seed: int = 0) -> float:
    env.reset(seed=seed)
    done = 0
    start = time.perf_counter()
    while done < steps:
        _, _, terminated, truncated, _ = env.step(1)
        done += 1
        if terminated or truncated:
            env.reset(seed=seed + done)
    return steps / (time.perf_counter() - start)


def rss_mb() -> float:
    with open("/proc/self/statm") as f:
        pages = int(f.read().split()[1])
    import os

    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20


def where_time_goes(env, steps: int) -> list:
    """Share of step time (cumulative, so parts may nest) spent in the main components."""
    profile = cProfile.Profile()
    env.reset(seed=123)
    profile.enable()
    for _ in range(steps):
        env.step(1)
    profile.disable()
    stats = pstats.Stats(profile).stats
    total = max(ct for (_f, _l, func), (_cc, _nc, _tt, ct, _c) in stats.items() if func == "step")

    def cum(file_part: str, func: str) -> float:
        return sum(ct for (f, _l, fn), (_cc, _nc, _tt, ct, _c) in stats.items() if file_part in f and fn == func)

    rows = [
        ("Scenic behaviours (NPC decisions)", cum("scenic/core/dynamics/behaviors.py", "_step")),
        ("Scenic requirements & monitors", cum("scenic/core/dynamics/scenarios.py", "_step")),
        ("Scenic state read-back", cum("scenic/core/simulators.py", "updateObjects")),
        ("highway-env physics (road.step)", cum("envs/hw_road.py", "step")),
        ("  of which collision tests", cum("envs/hw_road.py", "_collide")),
        ("lane look-ups", cum("envs/road_network.py", "get_closest_lane_index")),
        ("observation", cum("envs/observations.py", "observe")),
        ("time-to-collision", cum("envs/safety_metrics.py", "time_to_collision")),
    ]
    return [(label, 100.0 * value / total) for label, value in rows]


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args(argv)
    steps = 150 if args.quick else 600
    resets = 300 if args.quick else 1000

    for label, cls in (("stock pandas Kinematics", KinematicObservation),
                       ("same fast Kinematics", FastKinematicObservation)):
        native, ours = with_observation(make_native(), cls), with_observation(make_dv2s(), cls)
        assert type(native.observation_type) is cls and type(ours.observation_type) is cls
        steps_per_second(native, 20)
        steps_per_second(ours, 20)
        native_runs, our_runs = [], []
        for round_ in range(3):
            native_runs.append(steps_per_second(native, steps, seed=round_))
            our_runs.append(steps_per_second(ours, steps, seed=round_))
        n, o = statistics.median(native_runs), statistics.median(our_runs)
        print(f"env steps/s, {label:<24} native highway-v0: {n:7.1f}   DV2S-v0: {o:7.1f}   "
              f"ratio DV2S/native: {o / n:.2f}x")
        native.close()
    print("where DV2S-v0 step time goes (% of env.step, cumulative; rows may nest):")
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
