"""``dv2s run``: one episode of a scenario, recorded as a video (and optionally its trace)."""

from __future__ import annotations

import argparse
from typing import Any, Mapping, Optional

from dv2s_gym.cli.output import json_text
from dv2s_gym.cli.inputs import output_file, seed_value
from dv2s_gym.cli.parser import bank_option
from scenario_bank.jail.output import printable

__all__ = ["add_parser", "run"]


def add_parser(subparsers) -> None:
    """Add ``run`` to the ``dv2s`` subcommands."""
    p = subparsers.add_parser("run", help="run one episode of a scenario and record it",
                              description="Run one DV2S-v0 episode of a scenario (bank name, .scenic path or "
                              "tag:<tag>) and record it as a video; optionally save its trace.")
    p.add_argument("scenario", help="bank name, path to a .scenic file, or tag:<tag>")
    bank_option(p)
    p.add_argument("--video", default="out/episode.webm", type=output_file, help="video path (.webm VP8; .mp4/.avi also work)")
    p.add_argument("--trace", default=None, help="also save the episode trace here (.json or .json.gz)")
    p.add_argument("--seed", type=seed_value, default=0,
                   help="episode seed: it chooses the scene (and the actions of --random); the same seed gives the "
                   "same episode (default: 0)")
    p.add_argument("--duration", type=float, default=None, help="episode length in seconds")
    p.add_argument("--map", default=None, help="override the script's map (name or .xodr path)")
    p.add_argument("--ego-policy", choices=["agent", "scenic"], default="agent",
                   help="agent: rule-based driver; scenic: the script's ego behaviour")
    p.add_argument("--random", action="store_true", help="drive with random actions")
    p.add_argument("--trusted", action="store_true",
                   help="run the script in this process, skipping the jail (the operating-system sandbox): only for "
                   "a script you wrote or reviewed; it does not skip the allowlist check of what a script may use "
                   "(imports, file access, ...), which every script passes (scripts that ship with dv2s-gym always "
                   "run in process)")
    p.add_argument("--json", action="store_true",
                   help="print the episode's summary as strict JSON (for programs; a number that is not finite, such "
                   "as min_ttc with no vehicle on a collision course, is null)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Record the episode and print its summary (as JSON with ``--json``)."""
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
    if args.json:
        print(json_text(result))
    else:
        print(printable(summary(result, seed=args.seed, trace=args.trace)))  # names and values come from the script
    return 0


DRIVERS = {"rule-based": "the rule-based driver", "random": "random actions",
           "scenic": "the script's ego behaviour"}
"""How the summary names the ``driver`` of :func:`dv2s_gym.demo.record_scenario`'s result."""


def summary(result: Mapping[str, Any], *, seed: int, trace: Optional[str] = None) -> str:
    """A recorded episode in a few lines for people: where it went, how it ended, the scene's parameters."""
    ending = "ended early (terminated)" if result.get("terminated") else "ran to its time limit"
    collisions = result.get("collisions") or []
    ttc = result.get("min_ttc")
    ttc_text = "none (no vehicle on a collision course)" if ttc is None or ttc == float("inf") else f"{float(ttc):.2f} s"
    outcome = [("collision with " + ", ".join(map(str, collisions))) if collisions else "no collision",
               "off the road" if result.get("off_road") else "on the road",
               f"{result.get('lane_changes', 0)} lane change{'s' if result.get('lane_changes') != 1 else ''}",
               f"min TTC {ttc_text}"]
    driver = DRIVERS.get(result.get("driver"), str(result.get("driver")))
    lines = [f"wrote {result.get('path')} ({result.get('frames')} frames)",
             f"{result.get('scenario')}, seed {seed} (scene seed {result.get('scene_seed')}), driven by {driver}: "
             f"{result.get('steps')} steps, {ending}, return {float(result.get('return') or 0):.2f}",
             "outcome: " + ", ".join(outcome)]
    params = {k: v for k, v in (result.get("params") or {}).items() if isinstance(v, (int, float, str))
              and not isinstance(v, bool) and k != "map"}
    if params:
        lines.append("scene: " + ", ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}"
                                           for k, v in params.items()))
    if trace:
        lines.append(f"trace: {trace}")
    return "\n".join(lines)
