"""``dv2s maps``: the shipped OpenDRIVE maps (``--build --out DIR`` writes a fresh copy of them elsewhere)."""

from __future__ import annotations

import argparse
from pathlib import Path

from dv2s_gym.cli.errors import UsageError
from dv2s_gym.cli.inputs import output_folder

__all__ = ["add_parser", "run"]

MAINTAINER_REBUILD = "python -m scenario_bank.maps.build_maps"
"""The maintainer's command that rewrites the maps shipped in the package's own folder."""


def add_parser(subparsers) -> None:
    """Add ``maps`` to the ``dv2s`` subcommands."""
    maps = subparsers.add_parser("maps", help="list the shipped OpenDRIVE maps (or build a copy of them)",
                                 description="List the shipped maps; --build --out DIR writes them, built afresh and "
                                 "deterministically, into DIR (never into the installed package).")
    maps.add_argument("--build", action="store_true", help="build the .xodr files into --out")
    maps.add_argument("--out", type=output_folder, help="folder --build writes the maps into (required with "
                      "--build; not the package's own maps folder)")
    maps.set_defaults(func=run)


def _build_folder(out: str | None) -> Path:
    """The folder ``--build`` writes into: ``--out``, which must be given and must not be the shipped maps."""
    from scenario_bank.maps import MAPS_DIR

    if out is None:
        raise UsageError("--build needs --out DIR, the folder to write the maps into; the shipped maps are part of "
                         f"the package and stay as they are (a maintainer rebuilds them with `{MAINTAINER_REBUILD}`)")
    folder = Path(out)
    if folder.resolve() == Path(MAPS_DIR).resolve():
        raise UsageError(f"--out {out} is the installed package's own maps folder, which --build does not rewrite: "
                         f"pass another folder (a maintainer rebuilds the shipped maps with `{MAINTAINER_REBUILD}`)")
    return folder


def run(args: argparse.Namespace) -> int:
    """Print each shipped map's name and file, or with ``--build`` each map built into ``--out``."""
    from scenario_bank.maps import MAPS_DIR, list_maps

    if args.out is not None and not args.build:
        raise UsageError("--out is where --build writes the maps; add --build, or leave --out out to list them")
    if args.build:
        from scenario_bank.maps import build_maps

        for path in build_maps.write_maps(_build_folder(args.out)):
            print(f"{path.stem}\t{path}")
        return 0
    for name in list_maps():
        print(f"{name}\t{MAPS_DIR / (name + '.xodr')}")
    return 0
