"""DAgger checkpointing: what it costs an uninterrupted run, and what a killed run saves.

``python -m bench.bench_dagger_resume [--steps N]`` runs in one process, on the same settings
(DAgger's defaults: 4 iterations, 8 epochs, Adam 1e-3, the ``rule`` reference; ``dv2s-ppo`` on three
shipped scenarios, 2 subprocess envs, seed 7):

1. an uninterrupted run, timing the checkpoint writes (per-iteration commits and the partial
   commits every ``checkpoint_every`` steps) against its wall time;
2. the same run killed (``KeyboardInterrupt``) 80 % into iteration 3's collection, then resumed;
   the resumed run's wall time against the uninterrupted run's (what restarting from scratch,
   the behaviour before checkpoints, costs), and whether both end with identical weights.
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

SCENARIOS = {"highway_lead_vehicle_brakes": 1.0, "urban_pedestrian_crossing": 3.0, "highway_cut_in_from_left": 1.0}


def _run(out: Path, steps: int, **extra):
    from policies.imitation import DaggerConfig, dagger_fine_tune
    from policies.training import TrainConfig

    began = time.perf_counter()
    config = TrainConfig.fine_tuning(out, steps=steps, weights=SCENARIOS, seed=7, n_envs=2, progress_bar=False)
    path = dagger_fine_tune("dv2s-ppo", config, DaggerConfig(**extra), log=lambda _: None)
    return path, time.perf_counter() - began


def main() -> None:
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=12_000)
    args = parser.parse_args()
    import torch

    import policies.imitation as imitation
    from policies.dagger_checkpoint import DAggerCheckpoint
    from policies.registry import load_policy

    spent = {"save": 0.0, "save_partial": 0.0, "calls": 0}
    originals = {name: getattr(DAggerCheckpoint, name) for name in ("save", "save_partial")}

    def timed(name):
        def wrapper(self, *args, **kwargs):
            began = time.perf_counter()
            originals[name](self, *args, **kwargs)
            spent[name] += time.perf_counter() - began
            spent["calls"] += 1
        return wrapper

    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder)
        for name in originals:
            setattr(DAggerCheckpoint, name, timed(name))
        whole, wall = _run(root / "whole", args.steps)
        for name, original in originals.items():
            setattr(DAggerCheckpoint, name, original)
        writes = spent["save"] + spent["save_partial"]
        print(f"uninterrupted: {args.steps} steps in {wall:.1f} s; {spent['calls']} checkpoint commits took "
              f"{writes:.2f} s = {writes / wall:.1%} of the run (iterations {spent['save']:.2f} s, partial "
              f"{spent['save_partial']:.2f} s)")

        per_iteration = args.steps // 4
        kill_at = 2 * per_iteration + int(0.8 * per_iteration)
        original_collect, seen = imitation._collect, [0]

        class KillingBar:  # counts collected steps in place of the progress bar; the kill comes from it
            def update(self, n):
                seen[0] += n
                if seen[0] >= kill_at:
                    raise KeyboardInterrupt

        def killing_collect(venv, model, obs, budget, collected, every, commit, bar):
            return original_collect(venv, model, obs, budget, collected, every, commit, KillingBar())

        imitation._collect = killing_collect
        began = time.perf_counter()
        try:
            _run(root / "killed", args.steps)
        except KeyboardInterrupt:
            pass
        killed_wall = time.perf_counter() - began
        imitation._collect = original_collect
        resumed, resumed_wall = _run(root / "killed", args.steps)
        same = all(torch.equal(a, b) for a, b in zip(load_policy(f"ppo:{whole}").model.policy.state_dict().values(),
                                                      load_policy(f"ppo:{resumed}").model.policy.state_dict().values()))
        print(f"killed after {kill_at} of {args.steps} steps ({killed_wall:.1f} s in); resumed in {resumed_wall:.1f} s "
              f"= {resumed_wall / wall:.2f}x the uninterrupted run (restarting from scratch: 1.00x); "
              f"identical weights: {same}")


if __name__ == "__main__":
    main()
