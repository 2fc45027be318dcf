"""``dv2s eval``: a D-V2S stage's scores (SCS/HR, SP, E2E-SC) over a labeled folder."""

from __future__ import annotations

import argparse

from dv2s_gym.cli.backend_options import dra_option, sg_option
from dv2s_gym.cli.errors import UsageError
from dv2s_gym.cli.inputs import llm_config
from dv2s_gym.cli.output import emit
from dv2s_gym.cli.parser import llm_options

__all__ = ["add_parser", "run"]


def add_parser(subparsers) -> None:
    """Add ``eval`` to the ``dv2s`` subcommands."""
    p = subparsers.add_parser("eval", help="SCS/HR (dra), SP (sg) or E2E-SC (e2e) over a labeled folder",
                              description="Evaluate a stage over a folder of videos/descriptions with <name>.label.json "
                              "files; prints mean ± sd per use case and overall.")
    p.add_argument("stage", choices=["dra", "sg", "e2e"])
    p.add_argument("folder", nargs="?", default=None,
                   help="labeled folder (default: the shipped in-house set, as --set in-house)")
    p.add_argument("--set", dest="evalset", default=None, metavar="NAME",
                   choices=["in-house", "in-house-descriptions"],
                   help="a shipped evaluation set instead of a folder: in-house (bird's-eye clips of the bank's "
                        "scenarios) or in-house-descriptions (descriptions written by hand from public sources)")
    dra_option(p)
    sg_option(p)
    p.add_argument("--jobs", type=int, default=1)
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--json", action="store_true")
    llm_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Evaluate the stage and print its table (or JSON)."""
    from dv2s_gym.pipeline.evaluate import evalset_folder, evaluate, format_results

    if args.folder is not None and args.evalset is not None:
        raise UsageError(f"give a labeled folder or --set {args.evalset}, not both")
    folder = args.folder if args.folder is not None else evalset_folder(args.evalset or "in-house")
    report = evaluate(args.stage, folder, dra=args.dra, sg=args.sg, llm_config=llm_config(args),
                      jobs=args.jobs, seconds=args.seconds, progress=not args.json)
    emit(args, report, format_results(report))
    return 0
