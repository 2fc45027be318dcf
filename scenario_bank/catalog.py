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
    "unknown_bank_name",
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


def _suggestions(bank: Bank, item: str) -> List[str]:
    """Bank names ``item`` may have meant, at most three: a ``.scenic`` path's entry name if the bank holds it,
    else names holding ``item`` as a part, then close spellings."""
    stem = item.strip()
    if stem.endswith(".scenic") or os.sep in stem or "/" in stem:
        path = Path(stem)
        stem = path.parent.name if path.name == "scenario.scenic" else path.stem
    names = bank.names()
    if stem in names:
        return [stem]
    lowered = stem.lower()
    near = [n for n in names if lowered in n.lower()] if len(lowered) >= 3 else []
    near += [n for n in difflib.get_close_matches(stem, names, n=3, cutoff=0.5) if n not in near]
    return near[:3]


def unknown_bank_name(bank: Bank, item: str, command: str, accepts: Optional[str] = None) -> UnknownScenarioError:
    """The error for ``item``, which ``command`` cannot select: what the command accepts (by default bank names and
    ``tag:<tag>`` for its ``--scenarios``; ``accepts`` says it otherwise), and the bank's names it may have meant."""
    near = _suggestions(bank, item)
    accepts = accepts or (f"{command} --scenarios takes bank names and 'tag:<tag>' selections (`dv2s bank list` "
                          "shows them with their tags)")
    if item in bank.problems:
        what = f"scenario {item!r} in the bank at {bank.root} is unusable: {bank.problems[item]}. {accepts}."
    elif item.strip().endswith(".scenic") or os.sep in item or "/" in item or "\n" in item:
        what = (f"{accepts}, not Scenic files or text: {item[:200]!r} is not a name in the bank at {bank.root}. "
                "Add a script to a bank first (`dv2s bank add PATH --description TEXT --bank FOLDER`), then pass "
                "its name and that --bank.")
    else:
        what = f"the bank at {bank.root} holds no scenario {item!r}; {accepts}."
    if near:
        return UnknownScenarioError(f"{what} Did you mean {', '.join(repr(n) for n in near)}?")
    shown = bank.names()[:3]
    more = f" and {len(bank) - len(shown)} more" if len(bank) > len(shown) else ""
    listing = f" The bank's scenarios: {', '.join(repr(n) for n in shown)}{more}." if shown else ""
    return UnknownScenarioError(f"{what}{listing}")


def select_scenarios(selector: Union[None, str, Sequence[str]], bank_dir: Optional[PathLike] = None,
                     command: Optional[str] = None) -> List[str]:
    """Bank names selected by ``None`` (all), a name, ``'tag:<tag>'`` or a list of those.

    ``command`` names a command that takes bank names and tags only (``"dv2s mine"``): an unknown item's error
    then says so (no ``.scenic`` paths or Scenic text) and suggests the bank's nearest names."""
    bank = open_bank(bank_dir)
    if not len(bank) and (selector is None or not bank.problems):  # no bank there: said before a name is looked up
        root = Path(bank.root)
        where = ("the folder does not exist" if not root.exists() else "it is a file" if not root.is_dir()
                 else "the folder holds no scenarios")
        raise UnknownScenarioError(f"there is no bank at {bank.root} ({where}); check the --bank path, or leave "
                                   "--bank out for the shipped bank")
    if selector is None:
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
            if command is not None and item not in bank:
                raise unknown_bank_name(bank, item, command)
            bank.get(item)
            selected.append(item)
    return list(dict.fromkeys(selected))
