"""Values the user gives on the command line: JSON options, input files, the bank folder, LLM settings."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Optional

from dv2s_gym.cli.errors import UsageError
from scenario_bank.bank import Bank, BankError, MAX_JSON_DEPTH, MAX_SIDECAR_BYTES, UnsafeBankInputError
from scenario_bank.safe_files import load_json_bounded, read_regular_file, UnsafeInputError

__all__ = ["env_config_option", "json_argument", "json_option", "llm_config", "open_bank", "read_input_file"]


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


def json_argument(text: str, what: str):
    """A JSON value given on the command line (or in a file), size and nesting capped."""
    data = text.encode("utf-8", "surrogateescape") if isinstance(text, str) else text
    if len(data) > MAX_SIDECAR_BYTES:
        raise UnsafeBankInputError(f"{what} is larger than {MAX_SIDECAR_BYTES} bytes; shorten it")
    try:
        return load_json_bounded(data, MAX_JSON_DEPTH, what)
    except UnsafeInputError as error:
        raise UnsafeBankInputError(str(error)) from None


def llm_config(args: argparse.Namespace):
    """The LLM endpoint settings given (``--base-url``, ``--model``, ``--api-key``), or None."""
    config = {k: getattr(args, k, None) for k in ("base_url", "model", "api_key")}
    return {k: v for k, v in config.items() if v} or None


CONFIG_EXAMPLE = "'{\"duration\": 10}'"


def env_config_option(text: Optional[str], what: str = "--config") -> Optional[dict]:
    """``--config``: DV2S-v0 config overrides, a JSON object given inline or as a path to a .json file holding
    one (``None`` when not given); every command that takes one reads it here."""
    if text is None:
        return None
    if text.endswith(".json") and not Path(text).is_file():
        raise UsageError(f"{what}: there is no file {text}; pass a JSON object of DV2S-v0 config overrides, e.g. "
                         f"{CONFIG_EXAMPLE}, or the path of a .json file holding one")
    source = Path(text).read_text(encoding="utf-8") if text.endswith(".json") else text
    try:
        value = json.loads(source)
    except ValueError as error:
        raise UsageError(f"{what} must be a JSON object of DV2S-v0 config overrides (or a .json file), e.g. "
                         f"{CONFIG_EXAMPLE}; {error}") from None
    if not isinstance(value, dict):
        raise UsageError(f"{what} must be a JSON object of DV2S-v0 config overrides, e.g. {CONFIG_EXAMPLE}")
    return value


def json_option(text: Optional[str], what: str):
    """A JSON value given inline or as a path to a .json file."""
    if text is None:
        return None
    source = Path(text).read_text(encoding="utf-8") if text.endswith(".json") and Path(text).is_file() else text
    try:
        return json.loads(source)
    except ValueError as error:
        raise UsageError(f"{what} is not valid JSON ({error}); pass a JSON object or a path to a .json file") from None
