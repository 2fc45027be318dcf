"""``dv2s run``: one episode of a scenario, recorded as a video (and optionally its trace)."""

from __future__ import annotations

import argparse
import json

from dv2s_gym.cli.parser import bank_option

__all__ = ["add_parser", "run"]


def add_parser(subparsers) -> None:
    """Add ``run`` to the ``dv2s`` subcommands."""
    p = subparsers.add_parser("run", help="run one episode of a scenario and record it",
                              description="Run one DV2S-v0 episode of a scenario (bank name, .scenic path or "
                              "tag:<tag>) and record it as a video; optionally save its trace.")
    p.add_argument("scenario", help="bank name, path to a .scenic file, or tag:<tag>")
    bank_option(p)
    p.add_argument("--video", default="out/episode.webm", help="video path (.webm VP8; .mp4/.avi also work)")
    p.add_argument("--trace", default=None, help="also save the episode trace here (.json or .json.gz)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--duration", type=float, default=None, help="episode length in seconds")
    p.add_argument("--map", default=None, help="override the script's map (name or .xodr path)")
    p.add_argument("--ego-policy", choices=["agent", "scenic"], default="agent",
                   help="agent: rule-based driver; scenic: the script's ego behaviour")
    p.add_argument("--random", action="store_true", help="drive with random actions")
    p.add_argument("--trusted", action="store_true",
                   help="run the script in this process, without the jail: only for a script you wrote or "
                   "reviewed (scripts that ship with dv2s-gym always run in process)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Record the episode and print its summary as JSON."""
    from dv2s_gym.cli.name_checks import check_names

    check_names(scenarios=args.scenario, bank=args.bank)  # a typo is reported before the slow imports
    from dv2s_gym.demo import record_scenario

    config = {"ego_policy": args.ego_policy}
    if args.duration:
        config["duration"] = args.duration
    if args.map:
        config["map"] = args.map
    result = record_scenario(args.scenario, args.video, config=config, seed=args.seed, drive=not args.random,
                             trusted=args.trusted, bank_dir=args.bank, trace=args.trace)
    print(json.dumps(result, indent=2, default=str))
    return 0
