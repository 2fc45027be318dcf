"""The errors of the bottom layer: the one base class every dv2s-gym error derives from, and the bank's errors.

:class:`DV2SError` lives in the bottom layer (``scenario_bank``) so that every package can derive
from it; ``envs.errors`` re-exports it. The ``dv2s`` command catches it once and
prints its message as one line: a project error names the problem and the fix.
The bank's errors (:class:`BankError` and its kinds) are raised by :mod:`scenario_bank.bank` and the modules it
is built of, and re-exported there.
"""

from __future__ import annotations

import errno
from pathlib import Path
from typing import Any, List, Optional, Sequence

__all__ = ["DV2SError", "BankError", "BankVersionError", "UnsafeBankInputError", "NotABankError",
           "DuplicateScenarioError", "ScenarioRejectedError", "UnknownScenarioError", "BankOptionError",
           "MissingFileError", "WrongFileError", "SettingError", "WrongTypeError", "NearDuplicateWarning", "BuiltInReplacedWarning",
           "bank_write_error"]


class DV2SError(Exception):
    """Base class of dv2s-gym errors.

    ``expected`` is False for errors that signal a fault rather than bad input (a
    jailed worker that crashed); the command line then adds the ``--debug`` hint.
    """

    expected: bool = True


class MissingFileError(DV2SError, FileNotFoundError):
    """A file or folder the user named does not exist (or holds nothing the operation reads); the message names it
    and what to pass instead. A :class:`FileNotFoundError`, so code catching that keeps working."""


class WrongFileError(DV2SError, ValueError):
    """A file the user named is not of the kind the operation reads (not an OpenDRIVE map, ...)."""


class SettingError(DV2SError, ValueError):
    """A setting (an option, a keyword, an environment variable) holds a value that cannot be used; the message
    names the setting and the values it takes."""


class WrongTypeError(DV2SError, TypeError):
    """An argument of the public API holds a value of a type it does not take (or one it needs is missing); the
    message names the argument and what to pass. A :class:`TypeError`, so code catching that keeps working."""


class BankError(DV2SError):
    """A bank operation failed; the bank is unchanged."""


class BankVersionError(BankError):
    """The bank (or an entry) was written by a newer dv2s-gym."""


class UnsafeBankInputError(BankError, ValueError):
    """A bank folder, file, name or archive is malformed or hostile (a link, a FIFO, an unsafe name, too
    large or too deeply nested); the message names it and the fix, and nothing was written."""


class NotABankError(BankError, ValueError):
    """The folder holds other things than scenario entries."""


class DuplicateScenarioError(BankError):
    """The script is already in the bank (byte for byte or semantically)."""

    def __init__(self, message: str, existing: str) -> None:
        super().__init__(message)
        self.existing = existing


class NearDuplicateWarning(UserWarning):
    """A warning, not an error: an entry was added whose script is a near-duplicate of other entries (the same map
    and elements, overlapping parameter ranges; :func:`scenario_bank.dedup.near_duplicate`) or a near-copy of them
    (at most two lines of code apart; :func:`scenario_bank.families.twins`). Mining and the loop count them as one
    scenario family. ``name``: the new entry; ``twins``: the entries it is a near-duplicate of."""

    WHY = ("(same map and elements with overlapping parameter ranges, or at most two lines of code apart): mining and "
           "dv2s loop count them as one scenario family")

    def __init__(self, name: str, twins: Sequence[str]) -> None:
        super().__init__(f"{name} is a near-duplicate of bank entr{'y' if len(twins) == 1 else 'ies'} "
                         f"{', '.join(repr(t) for t in twins)} {self.WHY}")
        self.name = name
        self.twins = tuple(twins)

    def per_twin(self) -> List[str]:
        """The warning as one sentence per twin (what ``dv2s bank add`` prints)."""
        return [f"{self.name} is a near-duplicate of bank entry {twin!r} {self.WHY}" for twin in self.twins]


class BuiltInReplacedWarning(UserWarning):
    """A warning, not an error: a plug-in replaced or removed one of dv2s-gym's own entries in a registry (a
    policy, a failure detector, a backend), so what runs under that name is no longer the product's. ``what``:
    the kind of entry; ``name``: its name; ``module``: the module that replaced it (``None``: removed, or not
    known)."""

    def __init__(self, what: str, name: str, module: Optional[str], removed: bool = False) -> None:
        by = f" by {module}" if module else ""
        done = "removed" if removed else f"replaced{by}"
        super().__init__(f"the built-in {what} {name!r} was {done}: what runs as {name!r} is not dv2s-gym's own; "
                         "register yours under another name to keep both")
        self.what, self.name, self.module = what, name, module


class ScenarioRejectedError(BankError, ValueError):
    """The script failed verification: the safety check (``stage == "safety"``, ``findings``) or its
    compile, sample and run in the sandbox (``stage``; ``limit`` when a resource limit stopped it)."""

    def __init__(self, message: str, stage: str, findings: Sequence[Any] = (), limit: Optional[str] = None) -> None:
        super().__init__(message)
        self.stage, self.findings, self.limit = stage, list(findings), limit


class UnknownScenarioError(BankError, ValueError):
    """A scenario name or tag that the bank does not hold."""


class BankOptionError(BankError, ValueError):
    """A bank operation was given an option it does not take (an ``on_duplicate`` value it does not know, an option
    that only applies with another); the message names the values it takes."""


def bank_write_error(error: OSError, where: Path) -> BankError:
    """The :class:`BankError` for a write to ``where`` that failed with ``error`` (a full disk named as such)."""
    if error.errno == errno.ENOSPC:
        return BankError(f"the disk is full while writing to {where}; free some space and retry (the bank is unchanged)")
    return BankError(f"could not write to {where}: {error.strerror or error}; the bank is unchanged")
