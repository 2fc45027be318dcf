"""``dv2s bank validate``: every scenario safety-checked, compiled, sampled and run; with ``--story``, how often
each one plays its story."""

from __future__ import annotations

import argparse
from typing import Dict, List

from dv2s_gym.cli.inputs import open_bank
from dv2s_gym.cli.output import emit
from dv2s_gym.cli.parser import bank_command
from scenario_bank.bank import UnsafeBankInputError
from scenario_bank.safe_files import UnsafeInputError, validate_entry_name

__all__ = ["add_parser", "run"]


def add_parser(bank_sub) -> None:
    """Add ``validate`` to the ``dv2s bank`` subcommands."""
    p = bank_command(bank_sub, "validate", "safety-check, compile, sample and run every scenario; exit 1 if any is broken",
                     run)
    p.add_argument("name", nargs="*", help="only these scenarios")
    p.add_argument("--samples", type=int, default=3, help="scenes sampled and run per scenario (default 3)")
    p.add_argument("--seconds", type=float, default=3.0, help="simulated seconds per run (default 3)")
    p.add_argument("--jobs", type=int, default=1, help="parallel processes")
    p.add_argument("--story", action="store_true",
                   help="instead: measure how often each scenario plays its story (see dv2s_gym/story.py)")
    p.add_argument("--seeds", type=int, default=20, help="with --story: seeds per scenario and ego (default 20)")
    p.add_argument("--threshold", type=float, default=0.9,
                   help="with --story: lowest acceptable story rate (default 0.9); exit 1 below it")
    p.add_argument("--egos", nargs="+",
                   help="with --story: egos to drive, space- or comma-separated (default: scenic, rule, keep_lane, "
                        "idm); the probe egos hangback, rush, surge and weave drive unlike traffic on purpose")


def run(args: argparse.Namespace) -> int:
    """Validate the (named) scenarios and print a line each; exit 1 if any is broken."""
    if args.story:
        return _run_story(args)
    from dv2s_gym.bank_validate import validate_bank

    bank = open_bank(args)  # a --bank that does not exist is an error, not "0/0 scenarios valid"
    for name in args.name or []:
        if name not in bank.problems:
            try:
                validate_entry_name(name, "scenario name")
            except UnsafeInputError as error:
                raise UnsafeBankInputError(str(error)) from None
    reports = validate_bank(args.bank, args.name or None, samples=args.samples, seconds=args.seconds,
                            jobs=args.jobs, progress=not args.json)
    lines = []
    for r in reports:
        rate = f"{r.acceptance_rate:.2f}" if r.acceptance_rate is not None else "-"
        compile_s = f"{r.compile_seconds:.2f}s" if r.compile_seconds is not None else "-"
        outcomes = ",".join(e["outcome"] for e in r.episodes) or "-"
        lines.append(f"{'ok  ' if r.ok else 'FAIL'} {r.name:<40} compile {compile_s:>7}  accept {rate:>5}  "
                     f"runs {outcomes}" + (f"\n     {r.error}" if r.error else ""))
    broken = [r.name for r in reports if not r.ok]
    lines.append(f"{len(reports) - len(broken)}/{len(reports)} scenarios valid" +
                 (f"; broken: {', '.join(broken)}" if broken else ""))
    emit(args, [r.as_dict() for r in reports], "\n".join(lines))
    return 1 if broken else 0


def _run_story(args: argparse.Namespace) -> int:
    from dv2s_gym.story import EGOS, check_stories

    open_bank(args)  # a --bank that does not exist is an error
    egos = [e for item in args.egos or [] for e in item.split(",") if e] or list(EGOS)
    result = check_stories(args.name, egos, args.seeds, args.threshold, bank_root=args.bank, jobs=args.jobs,
                           progress=not args.json)
    emit(args, result.as_dict(), "\n".join(_story_lines(args, result.names, result.table, egos, result.under)))
    return 0 if result.ok else 1


def _story_lines(args: argparse.Namespace, names: List[str], table: Dict[str, Dict[str, dict]], egos: List[str],
                 under: List[str]) -> List[str]:
    """The story table as text: a rate per scenario and ego, then what the scenarios under the threshold missed."""
    width = max(len(n) for n in names)
    lines = [f"story rate over {args.seeds} seeds (threshold {args.threshold:.2f})",
             f"{'scenario':<{width}}  " + "  ".join(f"{e:>9}" for e in egos)]
    for name, row in table.items():
        cells = [f"{row[e]['rate']:>8.2f}" + ("*" if row[e]["rate"] < args.threshold else " ") for e in egos]
        lines.append(f"{name:<{width}}  " + "  ".join(cells))
    crashes = sum(cell["by_collision"] for row in table.values() for cell in row.values())
    lines.append(f"({crashes} of {len(names) * len(egos) * args.seeds} episodes count because the ego hit an "
                 "actor of the story before the trace showed all of it)")
    for name in under:
        for ego in egos:
            cell = table[name][ego]
            if cell["rate"] >= args.threshold:
                continue
            lines.append(f"  {name} / {ego}: rate {cell['rate']:.2f}")
            for step, miss in cell.get("missed", {}).items():
                lines.append(f"    missed {step!s} in {miss['count']}/{args.seeds} seeds, e.g. seed {miss['seed']}"
                             + (f": {miss['why']}" if miss["why"] else ""))
    lines.append(f"{len(names) - len(under)}/{len(names)} scenarios play their story in at least "
                 f"{args.threshold:.0%} of seeds with every ego" + (f"; under: {', '.join(under)}" if under else ""))
    return lines
