"""Find scenarios in a bank folder by name or tag."""

from __future__ import annotations

import difflib
import json
import os
from pathlib import Path
from typing import Dict, Iterable, List, Optional, Sequence, Union

__all__ = [
    "BANK_DIR",
    "UnknownScenarioError",
    "list_scenarios",
    "scenario_metadata",
    "scenario_path",
    "select_scenarios",
]

BANK_DIR = Path(__file__).resolve().parent / "scenarios"
"""Folder of the bank shipped with dv2s-gym."""


class UnknownScenarioError(ValueError):
    """A scenario name or tag that the bank does not hold."""


def _bank(bank_dir: Optional[Union[str, os.PathLike]]) -> Path:
    return Path(bank_dir) if bank_dir is not None else BANK_DIR


def list_scenarios(tag: Optional[str] = None, bank_dir: Optional[Union[str, os.PathLike]] = None) -> List[str]:
    """Names of the bank's scenarios, sorted; only those carrying ``tag`` if given."""
    names = sorted(p.stem for p in _bank(bank_dir).glob("*.scenic"))
    if tag is None:
        return names
    return [n for n in names if tag in scenario_metadata(n, bank_dir).get("tags", [])]


def scenario_path(name: str, bank_dir: Optional[Union[str, os.PathLike]] = None) -> Path:
    """Path of a bank scenario's script; :class:`UnknownScenarioError` with near matches otherwise."""
    path = _bank(bank_dir) / f"{name}.scenic"
    if path.is_file():
        return path
    known = list_scenarios(bank_dir=bank_dir)
    near = difflib.get_close_matches(name, known, n=3, cutoff=0.5)
    hint = f" Did you mean {', '.join(repr(n) for n in near)}?" if near else ""
    raise UnknownScenarioError(
        f"unknown scenario {name!r}.{hint} Known scenarios: {', '.join(known) or '(none)'}. "
        "Pass a bank name, a path to a .scenic file, Scenic source text, or 'tag:<tag>'."
    )


def scenario_metadata(name: str, bank_dir: Optional[Union[str, os.PathLike]] = None) -> Dict:
    """The metadata sidecar of a scenario (empty dict if it has none)."""
    sidecar = scenario_path(name, bank_dir).with_suffix(".json")
    if not sidecar.is_file():
        return {}
    return json.loads(sidecar.read_text(encoding="utf-8"))


def all_tags(bank_dir: Optional[Union[str, os.PathLike]] = None) -> List[str]:
    """Every tag used in the bank."""
    tags = set()
    for name in list_scenarios(bank_dir=bank_dir):
        tags.update(scenario_metadata(name, bank_dir).get("tags", []))
    return sorted(tags)


def select_scenarios(
    selector: Union[None, str, Sequence[str]], bank_dir: Optional[Union[str, os.PathLike]] = None
) -> List[str]:
    """Bank names selected by ``None`` (all), a name, ``'tag:<tag>'`` or a list of those."""
    if selector is None:
        names = list_scenarios(bank_dir=bank_dir)
        if not names:
            raise UnknownScenarioError(f"the bank at {_bank(bank_dir)} holds no scenarios")
        return names
    items: Iterable[str] = [selector] if isinstance(selector, str) else selector
    selected: List[str] = []
    for item in items:
        if item.startswith("tag:"):
            tag = item[4:]
            tagged = list_scenarios(tag=tag, bank_dir=bank_dir)
            if not tagged:
                tags = all_tags(bank_dir)
                near = difflib.get_close_matches(tag, tags, n=3, cutoff=0.5)
                hint = f" Did you mean {', '.join(repr(t) for t in near)}?" if near else ""
                raise UnknownScenarioError(
                    f"no scenario carries tag {tag!r}.{hint} Tags in the bank: {', '.join(tags) or '(none)'}."
                )
            selected.extend(tagged)
        else:
            scenario_path(item, bank_dir)
            selected.append(item)
    return list(dict.fromkeys(selected))
