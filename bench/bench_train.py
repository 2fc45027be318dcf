"""Training throughput on the bank: env steps/s of PPO learning in DV2S-v0, against highway-env.

    python -m bench.bench_train            # 3 rounds of 2048 steps per setting (about 5 minutes)
    python -m bench.bench_train --quick    # 2 rounds of 512 steps

Settings, all PPO with ``dv2s train``'s default hyperparameters
(:data:`policies.training.DEFAULT_HYPERPARAMETERS`: MlpPolicy [128, 128], n_steps 512 per env,
batch 64, 10 epochs), on the CPU with one torch thread, envs in ``SubprocVecEnv`` workers:

* ``dv2s x1`` - DV2S-v0 over the whole bank (uniform scenarios), 1 subprocess env
* ``dv2s x2`` - the same with 2 subprocess envs (what ``dv2s train --envs 2`` runs)
* ``highway-fast x1`` - highway-env's ``highway-fast-v0`` as shipped, 1 subprocess env (baseline)

Each setting keeps its model and envs for the whole run; after a warm-up ``learn`` (Scenic
compiles, first resets) the settings alternate round by round, so their ratios share the
machine's load. A round is ``model.learn(steps)`` timed whole: env stepping, the policy's
forward passes and the PPO updates. Reported: median steps/s per setting and the ratios
``dv2s x1 / highway-fast x1``, ``dv2s x2 / highway-fast x1`` and ``dv2s x2 / dv2s x1``.
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

os.environ.setdefault("OMP_NUM_THREADS", "1")


def _highway_fast() -> object:
    import gymnasium as gym
    import highway_env  # noqa: F401  (registers highway-fast-v0)

    return gym.make("highway-fast-v0")


def _model(venv, seed: int = 0):
    from stable_baselines3 import PPO

    from policies.training import DEFAULT_HYPERPARAMETERS

    hyperparameters = dict(DEFAULT_HYPERPARAMETERS["ppo"])
    policy = hyperparameters.pop("policy")
    net_arch = hyperparameters.pop("net_arch")
    return PPO(policy, venv, policy_kwargs={"net_arch": net_arch}, seed=seed, device="cpu", verbose=0,
               **hyperparameters)


def build_settings():
    """``name -> (model, venv)`` for the three settings."""
    from stable_baselines3.common.vec_env import SubprocVecEnv

    from policies.training import TrainEnvSpec, make_vec_env
    from scenario_bank import select_scenarios

    names = select_scenarios(None)
    uniform = {name: 1.0 / len(names) for name in names}
    settings = {}
    for label, n_envs in (("dv2s x1", 1), ("dv2s x2", 2)):
        venv = make_vec_env(TrainEnvSpec(names, {}, None, uniform), n_envs=n_envs, seed=0)
        settings[label] = (_model(venv), venv)
    venv = SubprocVecEnv([_highway_fast])
    settings["highway-fast x1"] = (_model(venv), venv)
    return settings


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="2 rounds of 512 steps")
    parser.add_argument("--rounds", type=int, default=None)
    parser.add_argument("--steps", type=int, default=None, help="env steps per round and setting")
    args = parser.parse_args(argv)
    rounds = args.rounds or (2 if args.quick else 3)
    steps = args.steps or (512 if args.quick else 2048)
    import torch

    torch.set_num_threads(1)
    settings = build_settings()
    rates = {label: [] for label in settings}
    try:
        for label, (model, _) in settings.items():  # warm-up: compiles, first resets, first update
            model.learn(512, reset_num_timesteps=False)
        for round_index in range(rounds):
            for label, (model, _) in settings.items():
                start = model.num_timesteps
                began = time.perf_counter()
                model.learn(steps, reset_num_timesteps=False)
                elapsed = time.perf_counter() - began
                rates[label].append((model.num_timesteps - start) / elapsed)
            print(f"round {round_index + 1}: " + ", ".join(f"{label} {values[-1]:.0f}" for label, values in rates.items()),
                  flush=True)
    finally:
        for _, venv in settings.values():
            venv.close()
    median = {label: statistics.median(values) for label, values in rates.items()}
    load = os.getloadavg()[0]
    print(f"\nPPO training throughput, env steps/s (median of {rounds} rounds of {steps} steps; load {load:.1f})")
    for label, value in median.items():
        print(f"  {label:<16} {value:7.1f}   (rounds: {', '.join(f'{v:.0f}' for v in rates[label])})")
    base = median["highway-fast x1"]
    print(f"  dv2s x1 / highway-fast x1 = {median['dv2s x1'] / base:.2f}x")
    print(f"  dv2s x2 / highway-fast x1 = {median['dv2s x2'] / base:.2f}x")
    print(f"  dv2s x2 / dv2s x1         = {median['dv2s x2'] / median['dv2s x1']:.2f}x")


if __name__ == "__main__":
    main()
