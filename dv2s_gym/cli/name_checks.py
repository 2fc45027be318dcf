"""Names on the command line checked before a command's slow start-up (Scenic, highway-env, worker pools):
a misspelt scenario or policy is reported in a second, with a suggestion, rather than after the imports."""

from __future__ import annotations

import os
from typing import Iterable, Optional, Sequence, Union

from scenario_bank import select_scenarios
from policies.registry import check_policy_spec

__all__ = ["check_names"]


def _is_bank_selector(item: str) -> bool:
    """A bank name or ``tag:<tag>``, not a ``.scenic`` path or Scenic text (the env checks those itself)."""
    return bool(item) and not (item.endswith(".scenic") or os.sep in item or "\n" in item or len(item) > 4096)


def check_names(*, policies: Iterable[Optional[str]] = (), scenarios: Union[None, str, Sequence[str]] = None,
                bank: Optional[str] = None, bank_names_only: Optional[str] = None) -> None:
    """Raise the error the command would raise later for an unknown policy name or bank scenario/tag (the
    scenarios of a ``bank`` folder that does not exist yet are left to the command). ``bank_names_only`` names
    a command whose --scenarios are bank names and tags only (``"dv2s mine"``): every item is checked, and an
    unknown one's error says what the command accepts."""
    for spec in policies:
        if spec:
            check_policy_spec(spec)
    items = [scenarios] if isinstance(scenarios, str) else list(scenarios or [])
    names = [item.strip() for item in items
             if isinstance(item, str) and (bank_names_only or _is_bank_selector(item.strip()))]
    if names and (bank is None or os.path.isdir(bank)):  # a new --bank folder is made by the command (mine)
        select_scenarios(names, bank, command=bank_names_only)
