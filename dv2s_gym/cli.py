"""The ``dv2s`` command: one CLI for the whole product."""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import asdict
from typing import List, Optional

__all__ = ["main", "build_parser"]


def _cmd_demo(args: argparse.Namespace) -> int:
    from dv2s_gym.demo import format_table, run_demo

    rows = run_demo(args.out, scenarios=args.scenario or None, episodes=args.episodes, seed=args.seed,
                    duration=args.duration)
    if args.json:
        print(json.dumps([asdict(r) for r in rows], indent=2, default=str))
    else:
        print(format_table(rows))
    return 0


def _cmd_run(args: argparse.Namespace) -> int:
    import gymnasium as gym

    import dv2s_gym  # noqa: F401
    from envs.recording import record_episode
    from policies import CautiousDriver

    config = {"ego_policy": args.ego_policy}
    if args.duration:
        config["duration"] = args.duration
    if args.map:
        config["map"] = args.map
    env = gym.make("DV2S-v0", scenario=args.scenario, config=config, render_mode="rgb_array")
    policy = None if args.ego_policy == "scenic" or args.random else CautiousDriver(env)
    result = record_episode(env, args.video, policy, seed=args.seed)
    if args.trace:
        env.unwrapped.save_trace(args.trace)
    info = result.pop("info")
    result.update({k: info[k] for k in ("scenario", "scene_seed", "collisions", "lane_changes", "min_ttc", "off_road")})
    result["params"] = info["params"]
    print(json.dumps(result, indent=2, default=str))
    env.close()
    return 0


def _cmd_replay(args: argparse.Namespace) -> int:
    from envs.trace import EpisodeTrace, replay_trace

    trace = EpisodeTrace.load(args.trace)
    env, replayed = replay_trace(trace)
    env.close()
    print(f"replayed {len(replayed.actions)} steps of {trace.scenario!r}: every actor state matches the trace")
    return 0


def _cmd_maps(args: argparse.Namespace) -> int:
    from scenario_bank.maps import MAPS_DIR, list_maps

    if args.build:
        from scenario_bank.maps import build_maps

        build_maps.main(["--out", str(MAPS_DIR)])
    for name in list_maps():
        print(f"{name}\t{MAPS_DIR / (name + '.xodr')}")
    return 0


def _cmd_bank_list(args: argparse.Namespace) -> int:
    from scenario_bank import list_scenarios, scenario_metadata

    rows = [{"name": n, **scenario_metadata(n)} for n in list_scenarios(tag=args.tag)]
    if args.json:
        print(json.dumps(rows, indent=2))
    else:
        for row in rows:
            print(f"{row['name']:<34} {row.get('map', ''):<18} {', '.join(row.get('tags', []))}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``dv2s`` (every subcommand has ``--help``)."""
    parser = argparse.ArgumentParser(prog="dv2s", description=__doc__.splitlines()[0] + " Turn driving videos "
                                     "into Scenic scenarios and run them as Gymnasium episodes in highway-env.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    demo = sub.add_parser("demo", help="run every bank scenario with a rule-based ego; one video each and a table",
                          description="Run DV2S-v0 episodes of every bank scenario with the rule-based "
                          "CautiousDriver, write one .webm per episode and print a summary table.")
    demo.add_argument("--out", default="out/demo", help="folder for the videos (default: out/demo)")
    demo.add_argument("--scenario", action="append", help="only this bank scenario (repeatable)")
    demo.add_argument("--episodes", type=int, default=1, help="episodes per scenario (default: 1)")
    demo.add_argument("--seed", type=int, default=0, help="seed of the first episode (default: 0)")
    demo.add_argument("--duration", type=float, default=None, help="episode length in seconds")
    demo.add_argument("--json", action="store_true", help="print JSON instead of a table")
    demo.set_defaults(func=_cmd_demo)

    run = sub.add_parser("run", help="run one episode of a scenario and record it",
                         description="Run one DV2S-v0 episode of a scenario (bank name, .scenic path or "
                         "tag:<tag>) and record it as a video; optionally save its trace.")
    run.add_argument("scenario", help="bank name, path to a .scenic file, or tag:<tag>")
    run.add_argument("--video", default="out/episode.webm", help="video path (.webm VP8; .mp4/.avi also work)")
    run.add_argument("--trace", default=None, help="also save the episode trace here (.json or .json.gz)")
    run.add_argument("--seed", type=int, default=0)
    run.add_argument("--duration", type=float, default=None, help="episode length in seconds")
    run.add_argument("--map", default=None, help="override the script's map (name or .xodr path)")
    run.add_argument("--ego-policy", choices=["agent", "scenic"], default="agent",
                     help="agent: rule-based driver; scenic: the script's ego behaviour")
    run.add_argument("--random", action="store_true", help="drive with random actions")
    run.set_defaults(func=_cmd_run)

    replay = sub.add_parser("replay", help="replay a saved episode trace and check it matches",
                            description="Re-run a saved trace with its seeds and actions; fails if any actor "
                            "state differs.")
    replay.add_argument("trace", help="trace file written by `dv2s run --trace` or env.save_trace()")
    replay.set_defaults(func=_cmd_replay)

    maps = sub.add_parser("maps", help="list the shipped OpenDRIVE maps (or rebuild them)",
                          description="List the shipped maps; --build regenerates them deterministically.")
    maps.add_argument("--build", action="store_true", help="regenerate the .xodr files first")
    maps.set_defaults(func=_cmd_maps)

    bank = sub.add_parser("bank", help="scenario bank commands", description="Inspect the scenario bank.")
    bank_sub = bank.add_subparsers(dest="bank_command", required=True, metavar="BANK_COMMAND")
    bank_list = bank_sub.add_parser("list", help="list scenarios", description="List bank scenarios.")
    bank_list.add_argument("--tag", default=None, help="only scenarios with this tag")
    bank_list.add_argument("--json", action="store_true", help="print JSON")
    bank_list.set_defaults(func=_cmd_bank_list)
    return parser


def main(argv: Optional[List[str]] = None) -> int:
    """Entry point of the ``dv2s`` console command."""
    parser = build_parser()
    args = parser.parse_args(argv)
    from envs.errors import DV2SError
    from scenario_bank import UnknownScenarioError

    try:
        return int(args.func(args) or 0)
    except (DV2SError, UnknownScenarioError, FileNotFoundError, ValueError) as error:
        print(f"dv2s: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
