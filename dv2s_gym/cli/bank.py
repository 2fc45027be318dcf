"""``dv2s bank``: list, show, add, remove, sample, export, import and count bank scenarios (validation:
:mod:`dv2s_gym.cli.bank_validate`)."""

from __future__ import annotations

import argparse
import json
import sys
import warnings
from typing import Any, List

from dv2s_gym.cli import bank_validate
from dv2s_gym.cli.errors import UsageError
from dv2s_gym.cli.inputs import (WEIGHTS, WEIGHTS_EXAMPLE, json_error, json_value, open_bank, read_input_file,
                                  seed_value)
from dv2s_gym.cli.output import emit
from dv2s_gym.cli.parser import bank_command, bank_option
from scenario_bank.admission import ON_DUPLICATE_OF
from scenario_bank.bank import MAX_SCRIPT_BYTES, MAX_SIDECAR_BYTES, Bank, Provenance, Sidecar
from scenario_bank.catalog import unknown_bank_name
from scenario_bank.errors import NearDuplicateWarning

__all__ = ["add_parser", "run_add", "run_export", "run_import", "run_list", "run_rm", "run_sample", "run_show",
           "run_stats"]

ELEMENTS_EXAMPLE = '\'{"participants": ["ego", "car"], "actions": [["car", "stop"]]}\''


def add_parser(subparsers) -> None:
    """Add ``bank`` and its subcommands to the ``dv2s`` subcommands."""
    bank = subparsers.add_parser("bank", help="list, add, validate, sample, export and import bank scenarios",
                                 description="The scenario bank: versioned, validated, searchable Scenic scenarios.")
    bank_option(bank)
    bank_sub = bank.add_subparsers(dest="bank_command", required=True, metavar="BANK_COMMAND")
    _add_read_commands(bank_sub)
    _add_write_commands(bank_sub)
    bank_validate.add_parser(bank_sub)
    _add_exchange_commands(bank_sub)


def _add_read_commands(bank_sub) -> None:
    p = bank_command(bank_sub, "list", "list scenarios, optionally filtered", run_list)
    p.add_argument("--tag", help="only scenarios with this tag")
    p.add_argument("--text", help="substring of the name or description")
    p.add_argument("--element", action="append", help="participant, action (car:cut_in), relation or road type")
    p.add_argument("--map", help="only scenarios on this map")
    p.add_argument("--source", choices=["hand-written", "generated", "mined"], help="only this source kind")
    p = bank_command(bank_sub, "show", "show one scenario: metadata and script", run_show)
    p.add_argument("name")


def _add_write_commands(bank_sub) -> None:
    p = bank_command(bank_sub, "add", "add a Scenic script with its description: safety-checked, then compiled, sampled and run once in the sandbox (atomic; duplicates and failures refused)", run_add)
    p.add_argument("script", help="path to the .scenic file")
    p.add_argument("--description", required=True, help="natural-language description")
    p.add_argument("--name", help="entry name (default: from the description)")
    p.add_argument("--elements", help="JSON file with the semantic elements")
    p.add_argument("--tag", action="append", help="tag (repeatable)")
    p.add_argument("--map", help="map name (default: read from `param map`)")
    p.add_argument("--kind", default="hand-written", choices=["hand-written", "generated", "mined"])
    p.add_argument("--video", help="source video (provenance)")
    p.add_argument("--parent", help="parent scenario (provenance)")
    p = bank_command(bank_sub, "rm", "remove scenarios", run_rm)
    p.add_argument("name", nargs="+")


def _add_exchange_commands(bank_sub) -> None:
    p = bank_command(bank_sub, "sample", "draw scenarios by weight", run_sample)
    p.add_argument("--count", type=int, default=1)
    p.add_argument("--seed", type=seed_value, default=0)
    p.add_argument("--tag", help="draw among scenarios with this tag")
    p.add_argument("--weights", help='JSON object name -> weight, e.g. \'{"a": 2, "b": 1}\'')
    p = bank_command(bank_sub, "export", "write scenarios to one .tar.gz archive", run_export)
    p.add_argument("archive")
    p.add_argument("--name", action="append", help="only this scenario (repeatable)")
    p = bank_command(bank_sub, "import", "import an archive (all or nothing; every new script verified in the sandbox like add)", run_import)
    p.add_argument("archive")
    p.add_argument("--on-duplicate", choices=ON_DUPLICATE_OF["import"], default="skip",
                   help="what to do with an archive entry the bank already holds (default: skip it)")
    bank_command(bank_sub, "stats", "counts by map, source, road type, tag and participant", run_stats)


def run_list(args: argparse.Namespace) -> int:
    """``dv2s bank list``: the (filtered) scenarios, and the bank's problems."""
    bank = open_bank(args)
    entries = bank.list(tag=args.tag, text=args.text, element=args.element, map=args.map, source=args.source)
    lines = _columns(["name", "map", "source", "tags"],
                     [[e.name, e.map or "", e.source.kind or "", ", ".join(e.tags)] for e in entries])
    lines += [f"! {name}: {message}" for name, message in sorted(bank.problems.items())]
    emit(args, {"scenarios": [e.summary() for e in entries], "problems": bank.problems},
         "\n".join(lines) + f"\n{len(entries)} scenario(s)")
    return 0


def _columns(header: List[str], rows: List[List[str]]) -> List[str]:
    """``rows`` under ``header`` in left-aligned columns as wide as their longest cell (the last one unpadded)."""
    if not rows:
        return []
    widths = [max(len(cell) for cell in column) for column in zip(header, *rows)]
    return ["  ".join(cell.ljust(width) for cell, width in zip(row[:-1], widths)) + "  " + row[-1]
            for row in [header, *rows]]


def _keys_sorted(value: Any) -> Any:
    """``value`` with the keys of every mapping in it sorted, as the bank writes a sidecar."""
    if isinstance(value, dict):
        return {key: _keys_sorted(value[key]) for key in sorted(value)}
    if isinstance(value, list):
        return [_keys_sorted(item) for item in value]
    return value


def run_show(args: argparse.Namespace) -> int:
    """``dv2s bank show``: one scenario's metadata, files and script."""
    bank = open_bank(args)
    entry = bank.get(_bank_name(bank, args.name, "dv2s bank show"))
    missing = set(entry.missing_files())
    files = [str(f) + (" (missing)" if str(f.relative_to(entry.folder)) in missing else "") for f in entry.files]
    # the sidecar's fields in the order its file holds them (the bank writes sidecars with sorted keys)
    sidecar = _keys_sorted(entry.sidecar.to_dict())
    data = {**sidecar, "path": str(entry.script_path), "script": entry.script, "files": files}
    human = (f"{entry.name}  ({entry.map}, {entry.source.kind})\n{entry.description}\n"
             f"tags: {', '.join(entry.tags)}\nelements: {json.dumps(entry.elements.to_dict())}\n"
             f"source: {json.dumps(sidecar['source'])}\npath: {entry.script_path}\n"
             + "".join(f"file: {f}\n" for f in files) + f"\n{entry.script}")
    emit(args, data, human)
    return 0


def _bank_name(bank: Bank, name: str, command: str) -> str:
    """``name``, which ``command`` takes as a name of ``bank``'s scenarios (a usable one or one the bank lists as
    unusable); otherwise the error saying that this command takes bank names, with the names meant."""
    if name in bank or name in bank.problems:
        return name
    raise unknown_bank_name(bank, name, command, accepts=f"`{command}` takes the name of a scenario in the bank "
                            "(`dv2s bank list` shows them)")


def run_add(args: argparse.Namespace) -> int:
    """``dv2s bank add``: a Scenic script (Scenic 2 upgraded, the rewrites printed) with its description."""
    try:
        script = read_input_file(args.script, "script", MAX_SCRIPT_BYTES).decode("utf-8")
    except UnicodeDecodeError as error:
        raise UsageError(f"the script {args.script} is not UTF-8 text ({error.reason}); save it as UTF-8") from None
    elements = (json_value(read_input_file(args.elements, "elements file", MAX_SIDECAR_BYTES),
                           f"the elements file {args.elements}", "the scenario's elements as JSON",
                           ELEMENTS_EXAMPLE) if args.elements else None)
    provenance = Provenance(kind=args.kind, video=args.video, parent=args.parent)
    # Bank.add upgrades Scenic 2 syntax to Scenic 3 (recording the rewrites and notes in the provenance), then its
    # allowlist + sandbox checks
    fields = Sidecar(description=args.description, name=args.name, elements=elements, tags=tuple(args.tag or ()),
                     map=args.map or "", source=provenance)
    bank = open_bank(args)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", NearDuplicateWarning)
        entry = bank.add(script, fields, upgrade_scenic2=True)
    for warning in caught:
        if isinstance(warning.message, NearDuplicateWarning):
            for line in warning.message.per_twin():
                print(f"warning: {line}", file=sys.stderr)
        else:
            warnings.warn_explicit(warning.message, warning.category, warning.filename, warning.lineno)
    rewrites = list(entry.source.scenic2_rewrites or ())
    for line in [f"scenic2: {r}" for r in rewrites] + [f"scenic2 note: {n}" for n in entry.source.scenic2_notes or ()]:
        print(line, file=sys.stderr)
    summary = dict(entry.summary(), scenic2_rewrites=rewrites)
    emit(args, summary, f"added {entry.name} ({entry.script_path})")
    return 0


def run_rm(args: argparse.Namespace) -> int:
    """``dv2s bank rm``: remove the named scenarios."""
    bank = open_bank(args)
    for name in args.name:
        bank.remove(_bank_name(bank, name, "dv2s bank rm"))
    emit(args, {"removed": args.name}, f"removed {', '.join(args.name)}")
    return 0


def run_sample(args: argparse.Namespace) -> int:
    """``dv2s bank sample``: scenario names drawn by weight."""
    bank = open_bank(args)
    candidates = [e.name for e in bank.list(tag=args.tag)] if args.tag else None
    weights = json_value(args.weights, "--weights", WEIGHTS, WEIGHTS_EXAMPLE, mapping=True) if args.weights else None
    if weights is not None and not all(isinstance(v, (int, float)) for v in weights.values()):
        raise json_error("--weights", WEIGHTS, WEIGHTS_EXAMPLE, "a weight is not a number")
    picks = [bank.sample(args.seed + k, weights=weights, candidates=candidates).name for k in range(args.count)]
    emit(args, picks, "\n".join(picks))
    return 0


def run_export(args: argparse.Namespace) -> int:
    """``dv2s bank export``: scenarios into one archive."""
    path = open_bank(args).export(args.archive, names=args.name or None)
    emit(args, {"archive": str(path)}, f"wrote {path}")
    return 0


def run_import(args: argparse.Namespace) -> int:
    """``dv2s bank import``: an archive's scenarios, all or nothing."""
    result = open_bank(args).import_archive(args.archive, on_duplicate=args.on_duplicate)
    emit(args, result, f"added {len(result['added'])}: {', '.join(result['added']) or '-'}; "
         f"skipped {len(result['skipped'])} duplicate(s): {', '.join(result['skipped']) or '-'}")
    return 0


def run_stats(args: argparse.Namespace) -> int:
    """``dv2s bank stats``: counts by map, source, road type, tag and participant."""
    stats = open_bank(args).stats()
    human = "\n".join(f"{k}: {v}" for k, v in stats.items())
    emit(args, stats, human)
    return 0
