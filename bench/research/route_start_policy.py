"""A starting policy for ``dv2s loop`` that observes the ego's route (``route_turn``, ``route_bearing``,
docs/envs.md): a short PPO run only to make a checkpoint whose card carries the env config, then DAgger toward the
``rule`` driver on every scenario of the shipped bank with that config.

    python -m bench.research.route_start_policy --out out/route_start --steps 60000
    dv2s loop --profile evidence --workers 2 --policy ppo:out/route_start/policy/model.zip --out out/loop-route

``--steps`` DAgger env steps (4 iterations, the loop's DAgger defaults: Adam 1e-3, 8 epochs, SLOWER labels
weighted 3x), 2 subprocess envs, seed ``--seed``. The initialisation is ``dv2s train --algo ppo --steps 1024``
(one rollout of 512 steps x 2 envs) with the same config, no evaluation and no baselines.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

ROUTE_CONFIG = {
    "observation": {"type": "Kinematics", "vehicles_count": 8,
                    "features": ["presence", "x", "y", "vx", "vy", "cos_h", "sin_h", "route_turn", "route_bearing"],
                    "absolute": False, "normalize": True, "see_behind": True},
    # the shipped policy's reward (only the PPO initialisation uses it; DAgger imitates)
    "reward_weights": {"collision": -2.0, "high_speed": 0.4, "lane_change": -0.05, "low_ttc": -0.4, "off_road": -1.0},
}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", required=True)
    parser.add_argument("--steps", type=int, default=60000, help="DAgger env steps (default 60000)")
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    from policies.dagger_config import DaggerConfig
    from policies.imitation import dagger_fine_tune
    from policies.training import TrainConfig
    from scenario_bank import select_scenarios

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "config.json").write_text(json.dumps(ROUTE_CONFIG, indent=1))
    init = out / "init"
    began = time.perf_counter()
    if not (init / "model.zip").is_file():
        subprocess.run([sys.executable, "-m", "dv2s_gym.cli", "train", "--algo", "ppo", "--steps", "1024", "--envs",
                        "2", "--seed", str(args.seed), "--config", str(out / "config.json"), "--eval-freq", "0",
                        "--card-seeds", "0", "--baselines", "--checkpoint-freq", "0", "--no-progress",
                        "--out", str(init)], check=True)
    names = sorted(select_scenarios(None))
    config = TrainConfig.fine_tuning(out / "policy", steps=args.steps, weights={name: 1.0 for name in names},
                                     seed=args.seed, n_envs=2, progress_bar=False)
    path = dagger_fine_tune(f"ppo:{init / 'model.zip'}", config, DaggerConfig(), log=lambda line: print(line, flush=True))
    print(f"wrote {path} in {time.perf_counter() - began:.0f} s", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
