"""A mined scenario's family: the bank scenario its failures go back to.

A mined or exact-replay bank entry names the scenario it came from in its provenance (``source.parent``);
that one may itself be mined. The family is the end of that chain: the first scenario with no parent in the
bank (a shipped or user scenario). Failures are clustered and counted per family
(:mod:`dv2s_gym.mining.cluster`), so one behaviour found in two entries of one family is one behaviour.
"""

from __future__ import annotations

import os
from functools import lru_cache
from typing import Optional, Tuple

from scenario_bank.bank import Bank
from scenario_bank.records import EpisodeRecord

__all__ = ["scenario_family", "record_family"]


def scenario_family(name: str, bank_dir: Optional[str] = None) -> str:
    """The family of bank scenario ``name`` in ``bank_dir`` (``None``: the shipped bank); ``name`` itself
    when it has no parent, or when it is not a bank entry (a script path or source text)."""
    return _family(name, bank_dir, _bank_stamp(bank_dir))


def _bank_stamp(bank_dir: Optional[str]) -> Tuple[int, ...]:
    """Modification times of a writable bank's folders: an entry added, replaced or removed changes them, so a
    family cached before is not reused after (the shipped bank never changes)."""
    if not bank_dir:
        return ()
    stamps = []
    try:
        with os.scandir(bank_dir) as children:
            stamps = [child.stat().st_mtime_ns for child in children if child.is_dir()]
        stamps.append(os.stat(bank_dir).st_mtime_ns)
    except OSError:
        return (-1,)
    return tuple(sorted(stamps))


@lru_cache(maxsize=4096)
def _family(name: str, bank_dir: Optional[str], stamp: Tuple[int, ...]) -> str:
    try:
        bank = Bank(bank_dir) if bank_dir else Bank()
    except Exception:  # noqa: BLE001 - no readable bank: every scenario is its own family
        return name
    current, seen = name, {name}
    while current in bank:
        parent = bank.get(current).source.parent
        if not parent or str(parent) in seen:
            break
        current = str(parent)
        seen.add(current)
    return current


def record_family(record: EpisodeRecord) -> str:
    """An episode record's family: its ``family`` field, or its scenario for records written without one."""
    return str(record.family or record.scenario)
