"""`dv2s demo`: every bank scenario driven by the rule-based ego, a video of each and a table of how each went."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import List, Optional, Sequence

import gymnasium as gym
from tqdm import tqdm

from envs.recording import record_episode
from scenario_bank import list_scenarios
from policies import CautiousDriver

__all__ = ["EpisodeSummary", "run_demo", "format_table", "record_scenario"]


@dataclass
class EpisodeSummary:
    """What one demo episode did."""

    scenario: str
    seed: int
    steps: int
    sim_seconds: float
    episode_return: float
    outcome: str
    min_ttc: float
    collisions: List[str]
    lane_changes: int
    video: str


def _outcome(info: dict, terminated: bool, truncated: bool) -> str:
    if info.get("crashed"):
        return "collision"
    if info.get("off_road"):
        return "off_road"
    if info.get("scenic_status") == "finished":
        return "scenario_end"
    if info.get("scenic_status") == "rejected":
        return "rejected"
    return "time_limit" if truncated else ("terminated" if terminated else "running")


def run_demo(
    out_dir: str | os.PathLike = "out/demo",
    scenarios: Optional[Sequence[str]] = None,
    episodes: int = 1,
    seed: int = 0,
    duration: Optional[float] = None,
) -> List[EpisodeSummary]:
    """Run ``episodes`` episodes of each scenario with :class:`policies.CautiousDriver`.

    Writes ``<out_dir>/<scenario>_seed<seed>.webm`` per episode, returns the summaries.
    """
    names = list(scenarios) if scenarios else list_scenarios()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    config = {} if duration is None else {"duration": duration}
    summaries: List[EpisodeSummary] = []
    jobs = [(name, seed + k) for name in names for k in range(episodes)]
    for name, episode_seed in tqdm(jobs, desc="episodes", unit="ep"):
        env = gym.make("dv2s_gym:DV2S-v0", scenario=name, config=config, render_mode="rgb_array")
        driver = CautiousDriver(env)
        video = out / f"{name}_seed{episode_seed}.webm"
        result = record_episode(env, video, driver, seed=episode_seed)
        info = result["info"]
        base = env.unwrapped
        summaries.append(
            EpisodeSummary(
                scenario=name,
                seed=episode_seed,
                steps=result["steps"],
                sim_seconds=round(base.time, 2),
                episode_return=round(result["return"], 3),
                outcome=_outcome(info, result["terminated"], result["truncated"]),
                min_ttc=info.get("min_ttc", math.inf),
                collisions=info.get("collisions", []),
                lane_changes=info.get("lane_changes", 0),
                video=str(video),
            )
        )
        env.close()
    return summaries


def format_table(rows: Sequence[EpisodeSummary]) -> str:
    """A plain-text table of demo summaries."""
    header = ["scenario", "seed", "steps", "sim s", "return", "outcome", "min TTC", "collided with", "video"]
    lines = [
        [r.scenario, str(r.seed), str(r.steps), f"{r.sim_seconds:.1f}", f"{r.episode_return:.2f}", r.outcome,
         "inf" if math.isinf(r.min_ttc) else f"{r.min_ttc:.2f}", ",".join(r.collisions) or "-", r.video]
        for r in rows
    ]
    widths = [max(len(h), *(len(line[i]) for line in lines)) if lines else len(h) for i, h in enumerate(header)]
    fmt = "  ".join(f"{{:<{w}}}" for w in widths)
    out = [fmt.format(*header), fmt.format(*("-" * w for w in widths))]
    out += [fmt.format(*line) for line in lines]
    return "\n".join(out)


def record_scenario(scenario: str, video: str | os.PathLike, *, config: dict, seed: int = 0, drive: bool = True,
                    trusted: bool = False, bank_dir: Optional[str | os.PathLike] = None,
                    trace: Optional[str | os.PathLike] = None) -> dict:
    """Run one DV2S-v0 episode of ``scenario`` (bank name, .scenic path or ``tag:<tag>``) and record it to ``video``.

    ``config`` is the env config (its ``ego_policy`` ``scenic`` lets the script drive the ego); otherwise the ego
    is :class:`policies.CautiousDriver` when ``drive``, random actions when not. With ``trace``, the episode's
    trace is saved there. Returns the recording summary with the episode's scenario, seed, collisions, lane
    changes, minimum TTC, off-road flag, parameters and ``driver``: ``rule-based``, ``random`` or ``scenic``.
    """
    env = gym.make("dv2s_gym:DV2S-v0", scenario=scenario, config=config, render_mode="rgb_array",
                   trusted=trusted, bank_dir=bank_dir)
    policy = CautiousDriver(env) if drive and config.get("ego_policy") != "scenic" else None
    result = record_episode(env, video, policy, seed=seed)
    if trace:
        env.unwrapped.save_trace(trace)
    info = result.pop("info")
    result.update({k: info[k] for k in ("scenario", "scene_seed", "collisions", "lane_changes", "min_ttc", "off_road")})
    result["params"] = info["params"]
    result["driver"] = "scenic" if config.get("ego_policy") == "scenic" else "rule-based" if drive else "random"
    env.close()
    return result
