"""A mined scenario's family: the bank scenario its failures go back to.

A mined or exact-replay bank entry names the scenario it came from in its provenance (``source.parent``);
that one may itself be mined. The family is the end of that chain: the first scenario with no parent in the
bank (a shipped or user scenario), joined with every lineage a near-duplicate script of the bank belongs to
(:func:`scenario_bank.families.content_families`: twins that differ in one range are one family). Failures are clustered and counted per family
(:mod:`dv2s_gym.mining.cluster`), so one behaviour found in two entries of one family is one behaviour.
"""

from __future__ import annotations

import os
from functools import lru_cache
from typing import Dict, Optional, Tuple

from dv2s_gym.mining.errors import MiningError
from scenario_bank.bank import Bank
from scenario_bank.errors import BankError
from scenario_bank.families import content_families
from scenario_bank.records import EpisodeRecord

__all__ = ["scenario_family", "record_family"]


def scenario_family(name: str, bank_dir: Optional[str] = None) -> str:
    """The family of bank scenario ``name`` in ``bank_dir`` (``None``: the shipped bank, :func:`content_families`);
    ``name`` itself when it has no parent nor near-duplicate, or when it is not a bank entry (a script path or
    source text)."""
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
    families = _families(bank_dir, stamp)
    return families.get(name, name) if families is not None else name


@lru_cache(maxsize=16)
def _families(bank_dir: Optional[str], stamp: Tuple[int, ...]) -> Optional[Dict[str, str]]:
    """:func:`scenario_bank.families.content_families` of a bank, computed once per state of the bank."""
    try:
        bank = Bank(bank_dir) if bank_dir else Bank()
    except (BankError, OSError):  # no readable bank: every scenario is its own family
        return None
    return content_families(bank)


def record_family(record: EpisodeRecord) -> str:
    """An episode record's family (its ``family`` field, which every mined episode records).

    Raises:
        MiningError: the record has none (a record no mining run of this dv2s-gym writes).
    """
    if not record.family:
        raise MiningError(f"episode {record.index} of {record.scenario} records no scenario family: it was not "
                          "written by a mining run of this version of dv2s-gym; start a new --out folder")
    return str(record.family)
