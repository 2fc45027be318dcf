"""Render bird's-eye clips of bank scenarios (the evaluation videos of the ``bev`` DRA backend).

A clip is one ``DV2S-v0`` episode of a bank scenario, the ego driven by
:class:`policies.CautiousDriver`, rendered offscreen in highway-env's style and
written as VP8 ``.webm`` at the policy frequency (5 frames per second of
simulated time). Everything is seeded, so the same ``(scenario, seed, seconds,
size)`` gives the same frames.

Command line::

    python -m bench.evalsets.make_bev_clips OUT_DIR [--scenario NAME ...] [--seeds 0 1 2]
        [--seconds 10] [--size 400]

writes ``OUT_DIR/<scenario>_seed<seed>.webm`` (video only: no sidecar, no trace).
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import List, Optional, Sequence, Union

# highway-env's viewer draws nothing under SDL's "dummy" driver: render offscreen.
if os.environ.get("SDL_VIDEODRIVER", "dummy") == "dummy":
    os.environ["SDL_VIDEODRIVER"] = "offscreen"
os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")

__all__ = ["render_clip", "main"]


def render_clip(
    scenario: str,
    seed: int,
    path: Union[str, os.PathLike],
    seconds: float = 10,
    size: int = 400,
    ego_policy: str = "agent",
) -> dict:
    """Render one episode of ``scenario`` (a bank name or .scenic path) to ``path`` (.webm).

    ``ego_policy="agent"`` drives the ego with :class:`policies.CautiousDriver`;
    ``"scenic"`` lets the script's own ego behaviour drive it. The episode lasts
    ``seconds`` of simulated time (less if the ego crashes or
    leaves the road); the frames are ``size`` x ``size`` pixels with the ego at
    the centre, north up, at highway-env's default scale (5.5 px/m). Returns a
    summary: scenario, seed, frames, steps, fps, path, collisions, off_road,
    scenic_status and the episode ``trace`` (:class:`envs.trace.EpisodeTrace`).
    """
    from envs.dv2s_env import DV2SEnv
    from envs.recording import record_episode
    from policies import CautiousDriver

    config = {
        "duration": float(seconds),
        "screen_width": int(size),
        "screen_height": int(size),
        "offscreen_rendering": True,
        "show_trajectories": False,
        "ego_policy": ego_policy,
    }
    env = DV2SEnv(scenario=scenario, config=config, render_mode="rgb_array")
    try:
        result = record_episode(env, path, CautiousDriver(env), seed=int(seed))
        info = result["info"]
        return {"scenario": scenario, "seed": int(seed), "frames": result["frames"], "steps": result["steps"],
                "fps": env.config["policy_frequency"], "path": str(path),
                "collisions": list(info.get("collisions", [])), "off_road": bool(info.get("off_road")),
                "scenic_status": info.get("scenic_status"), "trace": env.trace}
    finally:
        env.close()


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("out", help="output folder")
    parser.add_argument("--scenario", action="append", help="bank scenario (repeatable; default: the whole bank)")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--seconds", type=float, default=10)
    parser.add_argument("--size", type=int, default=400)
    parser.add_argument("--ego-policy", choices=("agent", "scenic"), default="agent",
                        help="agent: the rule-based driver; scenic: the script's ego behaviour")
    args = parser.parse_args(argv)
    from scenario_bank import list_scenarios

    names: List[str] = args.scenario or list_scenarios()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    for name in names:
        for seed in args.seeds:
            result = render_clip(name, seed, out / f"{name}_seed{seed}.webm", args.seconds, args.size,
                                 args.ego_policy)
            print(f"{result['path']}: {result['frames']} frames")
    return 0


if __name__ == "__main__":
    sys.exit(main())
