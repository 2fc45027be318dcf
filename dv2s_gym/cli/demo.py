"""``dv2s demo``: every bank scenario with a rule-based ego, a video each and a summary table."""

from __future__ import annotations

import argparse
from dataclasses import asdict

from dv2s_gym.cli.inputs import output_folder, seed_value
from dv2s_gym.cli.output import json_text
from scenario_bank.catalog import open_bank, unknown_bank_name

__all__ = ["add_parser", "run"]


def add_parser(subparsers) -> None:
    """Add ``demo`` to the ``dv2s`` subcommands."""
    demo = subparsers.add_parser("demo", help="run every bank scenario with a rule-based ego; one video each and a table",
                                 description="Run DV2S-v0 episodes of every bank scenario with the rule-based "
                                 "CautiousDriver, write one .webm per episode and print a summary table.")
    demo.add_argument("--out", default="out/demo", type=output_folder, help="folder for the videos (default: out/demo)")
    demo.add_argument("--scenario", action="append", help="only this bank scenario (repeatable)")
    demo.add_argument("--episodes", type=int, default=1, help="episodes per scenario (default: 1)")
    demo.add_argument("--seed", type=seed_value, default=0, help="seed of the first episode (default: 0)")
    demo.add_argument("--duration", type=float, default=None, help="episode length in seconds")
    demo.add_argument("--json", action="store_true", help="print JSON instead of a table")
    demo.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the demo episodes and print their table (or JSON)."""
    from dv2s_gym.demo import format_table, run_demo

    bank = open_bank()
    for name in args.scenario or ():
        if name not in bank:
            raise unknown_bank_name(bank, name, "dv2s demo", accepts="`dv2s demo --scenario` takes the name of a "
                                    "scenario in the shipped bank (`dv2s bank list` shows them)")
    rows = run_demo(args.out, scenarios=args.scenario or None, episodes=args.episodes, seed=args.seed,
                    duration=args.duration)
    if args.json:
        print(json_text([asdict(r) for r in rows]))
    else:
        print(format_table(rows))
    return 0
