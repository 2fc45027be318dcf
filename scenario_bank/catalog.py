"""Find scenarios in a bank by name or tag (thin functions over :class:`scenario_bank.bank.Bank`)."""

from __future__ import annotations

import difflib
import os
from pathlib import Path
from typing import Dict, List, Optional, Sequence, Union

__all__ = [
    "BANK_DIR",
    "UnknownScenarioError",
    "open_bank",
    "list_scenarios",
    "scenario_metadata",
    "scenario_path",
    "select_scenarios",
]

from scenario_bank.bank import BANK_DIR, Bank, UnknownScenarioError

PathLike = Union[str, os.PathLike]


def open_bank(bank_dir: Optional[PathLike] = None) -> Bank:
    """Open a bank (the shipped one by default), re-reading it from disk."""
    return Bank(bank_dir)


def list_scenarios(tag: Optional[str] = None, bank_dir: Optional[PathLike] = None) -> List[str]:
    """Names of the bank's scenarios, sorted; only those carrying ``tag`` if given."""
    return [e.name for e in open_bank(bank_dir).list(tag=tag)]


def scenario_path(name: str, bank_dir: Optional[PathLike] = None) -> Path:
    """Path of a bank scenario's script; :class:`UnknownScenarioError` with near matches otherwise."""
    return open_bank(bank_dir).get(name).script_path


def scenario_metadata(name: str, bank_dir: Optional[PathLike] = None) -> Dict:
    """The metadata sidecar of a scenario."""
    return open_bank(bank_dir).get(name).sidecar.to_dict()


def select_scenarios(selector: Union[None, str, Sequence[str]], bank_dir: Optional[PathLike] = None) -> List[str]:
    """Bank names selected by ``None`` (all), a name, ``'tag:<tag>'`` or a list of those."""
    bank = open_bank(bank_dir)
    if selector is None:
        if not len(bank):
            root = Path(bank.root)
            where = ("the folder does not exist" if not root.exists() else "it is a file" if not root.is_dir()
                     else "the folder holds no scenarios")
            raise UnknownScenarioError(f"there is no bank at {bank.root} ({where}); check the --bank path, or leave "
                                       "--bank out for the shipped bank")
        return bank.names()
    items = [selector] if isinstance(selector, str) else list(selector)
    selected: List[str] = []
    for item in items:
        if item.startswith("tag:"):
            tag = item[4:]
            tagged = [e.name for e in bank.list(tag=tag)]
            if not tagged:
                near = difflib.get_close_matches(tag, bank.tags(), n=3, cutoff=0.6)
                hint = f" Did you mean {', '.join(repr(t) for t in near)}?" if near else ""
                raise UnknownScenarioError(
                    f"no scenario carries tag {tag!r}.{hint} Tags in the bank: {', '.join(bank.tags()) or '(none)'}."
                )
            selected.extend(tagged)
        else:
            bank.get(item)
            selected.append(item)
    return list(dict.fromkeys(selected))
