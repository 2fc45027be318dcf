"""``dv2s maps``: the shipped OpenDRIVE maps (``--build`` regenerates them)."""

from __future__ import annotations

import argparse

__all__ = ["add_parser", "run"]


def add_parser(subparsers) -> None:
    """Add ``maps`` to the ``dv2s`` subcommands."""
    maps = subparsers.add_parser("maps", help="list the shipped OpenDRIVE maps (or rebuild them)",
                                 description="List the shipped maps; --build regenerates them deterministically.")
    maps.add_argument("--build", action="store_true", help="regenerate the .xodr files first")
    maps.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Print each map's name and file (after rebuilding them with ``--build``)."""
    from scenario_bank.maps import MAPS_DIR, list_maps

    if args.build:
        from scenario_bank.maps import build_maps

        build_maps.main(["--out", str(MAPS_DIR)])
    for name in list_maps():
        print(f"{name}\t{MAPS_DIR / (name + '.xodr')}")
    return 0
