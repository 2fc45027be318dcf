"""Values the user gives on the command line: JSON options, input files, the bank folder, LLM settings."""

from __future__ import annotations

import argparse
import json
import os
import tempfile
from pathlib import Path
from typing import Any, Optional, Union

from dv2s_gym.cli.errors import UsageError
from dv2s_gym.pipeline.llm_config import LLMConfig
from dv2s_gym.pipeline.stages import reads_model
from scenario_bank.bank import Bank, BankError, MAX_JSON_DEPTH, MAX_SIDECAR_BYTES, UnsafeBankInputError
from scenario_bank.safe_files import nests_deeper_than, read_regular_file, UnsafeInputError

__all__ = ["CONFIG_EXAMPLE", "WEIGHTS", "WEIGHTS_EXAMPLE", "env_config_option", "json_error", "json_option",
           "json_value", "llm_config", "open_bank", "read_input_file", "input_file", "output_file", "output_folder",
           "description_text", "seed_value"]


def open_bank(args: argparse.Namespace):
    """The :class:`~scenario_bank.bank.Bank` of ``--bank`` (the shipped one by default); a ``--bank`` folder that
    does not exist is an error unless the command writes to it."""
    writes = getattr(args, "bank_command", None) in ("add", "import") or getattr(args, "add_to_bank", False)
    if args.bank is not None and not writes and not Path(args.bank).exists():
        raise BankError(f"there is no bank at {args.bank} (the folder does not exist); check the path, or create "
                        "a bank there with `dv2s bank add` or `dv2s bank import`")
    return Bank(args.bank)


def read_input_file(path: str, what: str, max_bytes: int) -> bytes:
    """A file named on the command line: a regular file (a FIFO or device is refused, never waited on) of at
    most ``max_bytes``."""
    try:
        return read_regular_file(path, max_bytes, follow_symlinks=True)
    except UnsafeInputError as error:
        raise UnsafeBankInputError(f"the {what} {error}") from None


def llm_config(args: argparse.Namespace) -> Optional[LLMConfig]:
    """The model endpoint settings given (``--base-url``, ``--model``, ``--api-key``), or None; a
    :class:`UsageError` when they are given but none of the command's backends (``--dra``, ``--sg``) calls a
    model, so they would be ignored."""
    config = {k: getattr(args, k, None) for k in ("base_url", "model", "api_key")}
    given = [f"--{k.replace('_', '-')}" for k, v in config.items() if v]
    if not given:
        return None
    chosen = [(stage, getattr(args, stage.lower())) for stage in ("DRA", "SG") if getattr(args, stage.lower(), None)]
    if chosen and not any(reads_model(stage, name) for stage, name in chosen):
        backends = " and ".join(f"--{stage.lower()} {name}" for stage, name in chosen)
        raise UsageError(f"{', '.join(given)} set{'s' if len(given) == 1 else ''} the model a backend calls, and "
                         f"{backends} call{'s' if len(chosen) == 1 else ''} none: drop "
                         f"{'it' if len(given) == 1 else 'them'}, or choose a backend that calls a model "
                         f"({' or '.join(f'--{stage.lower()} openai' for stage, _ in chosen)})")
    return LLMConfig.of({k: v for k, v in config.items() if v})


CONFIG_EXAMPLE = "'{\"duration\": 10}'"
WEIGHTS = "a JSON object of scenario name -> number"
WEIGHTS_EXAMPLE = '\'{"a": 2, "b": 1}\''


def json_error(what: str, wanted: str, example: str, why: str) -> UsageError:
    """The one shape of the error of a JSON value given on the command line: ``{what} must be {wanted}, e.g.
    {example}; {why}`` (without the example when there is none)."""
    return UsageError(f"{what} must be {wanted}{f', e.g. {example}' if example else ''}; {why}")


def json_value(source: Union[str, bytes], what: str, wanted: str, example: str = "", *, mapping: bool = False) -> Any:
    """The command line's one JSON parser: a value given inline (or the bytes of a file named on the command line),
    at most :data:`~scenario_bank.bank.MAX_SIDECAR_BYTES` of UTF-8 nested at most
    :data:`~scenario_bank.bank.MAX_JSON_DEPTH` deep, and with ``mapping`` a JSON object; anything else is a
    :class:`UsageError` of one shape (:func:`json_error`)."""
    data = source.encode("utf-8", "surrogateescape") if isinstance(source, str) else source
    if len(data) > MAX_SIDECAR_BYTES:
        raise json_error(what, wanted, example, f"it is larger than {MAX_SIDECAR_BYTES} bytes")
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as error:
        raise json_error(what, wanted, example, f"it is not UTF-8 text ({error.reason})") from None
    if nests_deeper_than(text, MAX_JSON_DEPTH):
        raise json_error(what, wanted, example, f"it nests arrays and objects deeper than {MAX_JSON_DEPTH} levels")
    try:
        value = json.loads(text)
    except (ValueError, RecursionError) as error:
        raise json_error(what, wanted, example, f"it is not valid JSON ({error})") from None
    if mapping and not isinstance(value, dict):
        raise json_error(what, wanted, example, f"it is a JSON {_JSON_KINDS.get(type(value), 'value')}")
    return value


_JSON_KINDS = {list: "array", str: "string", int: "number", float: "number", bool: "boolean", type(None): "null"}


def json_option(text: Optional[str], what: str, wanted: str, example: str = "", *, mapping: bool = False) -> Any:
    """An option holding a JSON value inline or, when it ends in ``.json``, the path of a file holding one (``None``
    when not given); parsed by :func:`json_value`."""
    if text is None:
        return None
    if text.endswith(".json"):
        if not Path(text).is_file():
            raise json_error(what, wanted, example, f"there is no file {text}")
        return json_value(read_input_file(text, f"{what} file", MAX_SIDECAR_BYTES), what, wanted, example,
                          mapping=mapping)
    return json_value(text, what, wanted, example, mapping=mapping)


def env_config_option(text: Optional[str], what: str = "--config") -> Optional[dict]:
    """``--config``: DV2S-v0 config overrides, a JSON object given inline or as a path to a .json file holding
    one (``None`` when not given); every command that takes one reads it here."""
    return json_option(text, what, "a JSON object of DV2S-v0 config overrides (or a .json file holding one)",
                       CONFIG_EXAMPLE, mapping=True)


def _cannot_write_in(folder: Path) -> Optional[str]:
    """Why a folder (or a file) cannot be made at ``folder``, or None: its nearest existing ancestor must be a
    folder a trial folder can be made (and removed) in, so that the command fails before any work, not after."""
    place = folder
    while not place.exists() and place != place.parent:
        place = place.parent
    if place.exists() and not place.is_dir():
        return f"{place} is a file, not a folder"
    try:
        os.rmdir(tempfile.mkdtemp(prefix=".dv2s-probe-", dir=place))
    except OSError as error:
        return f"cannot create anything in {place} ({error.strerror or error})"
    return None


def seed_value(text: str) -> int:
    """``--seed``: an integer >= 0 (episodes and samplers are seeded with it); else an
    :class:`argparse.ArgumentTypeError` naming the value and the fix."""
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a seed: give an integer >= 0 (e.g. --seed 0; the same "
                                         "seed gives the same scenes)")
    return value


def output_folder(text: str) -> str:
    """``--out``: a folder that exists or can be created (checked while the options are read, see
    :func:`_cannot_write_in`); else an :class:`argparse.ArgumentTypeError` naming the path, the problem and the fix."""
    path = Path(text)
    why = f"{text} is a file, not a folder" if path.is_file() else _cannot_write_in(path)
    if why:
        raise argparse.ArgumentTypeError(f"{text}: the output folder cannot be made: {why}; "
                                         "pass a folder in a writable place (e.g. --out out/run)")
    return text


def output_file(text: str) -> str:
    """``--video``: a file whose folder exists or can be created; else an :class:`argparse.ArgumentTypeError` naming
    the path, the problem and the fix."""
    path = Path(text)
    why = f"{text} is a folder" if path.is_dir() else _cannot_write_in(path.parent)
    if why:
        raise argparse.ArgumentTypeError(f"{text}: the output file cannot be written: {why}; "
                                         "pass a path in a writable folder (e.g. out/episode.webm)")
    return text


def input_file(text: str) -> str:
    """``--from``: an existing file; else an :class:`argparse.ArgumentTypeError` naming the path and the fix."""
    path = Path(text)
    if not path.is_file():
        why = "it is a folder" if path.is_dir() else "there is no such file"
        raise argparse.ArgumentTypeError(f"{text}: {why}; pass the path of an existing text file "
                                         "(or give the description itself in quotes, without --from)")
    return text


_PATH_SUFFIXES = (".txt", ".md", ".json")


def description_text(text: str) -> str:
    """The description given as the one positional argument; a missing file given there by mistake (it ends in
    .txt/.md/.json, or holds a path separator and no space) is a :class:`UsageError` suggesting ``--from FILE``."""
    looks_like_a_path = text.strip().lower().endswith(_PATH_SUFFIXES) or (
        (os.sep in text or "/" in text) and not any(c.isspace() for c in text.strip()))
    if looks_like_a_path and not Path(text).exists():
        raise UsageError(f"{text!r} looks like a file path, but there is no such file; to read a description from a "
                         "file pass --from FILE with an existing file, or if it really is the description, put it "
                         "in quotes with spaces (e.g. 'a car brakes')")
    return text
