"""Errors of the jail; each says what happened and what to do."""

from __future__ import annotations

from typing import Optional

from scenario_bank.errors import DV2SError

__all__ = ["JailError", "JailUnavailableError", "BwrapMissingError", "JailLimitError", "JailCrashError", "JailProtocolError"]


class JailError(DV2SError, RuntimeError):
    """Something went wrong with a jailed worker; ``output`` holds the tail of what it printed."""

    expected = False

    def __init__(self, message: str, output: str = "") -> None:
        if output:
            message = f"{message}\n--- the script's output (last {len(output)} characters) ---\n{output}"
        super().__init__(message)
        self.output = output


class JailUnavailableError(JailError):
    """The jail cannot be created on this machine (no bubblewrap, no user namespaces, no seccomp)."""

    expected = True


class BwrapMissingError(JailUnavailableError, FileNotFoundError):
    """bubblewrap (``bwrap``) is not installed. A :class:`FileNotFoundError`, so code catching that keeps working."""


class JailLimitError(JailError):
    """A jailed worker hit a limit: ``limit`` is ``"cpu"``, ``"memory"``, ``"wall"``, ``"output"`` or ``"file"``."""

    expected = True  # a script that hits a limit is an outcome its message explains

    def __init__(self, message: str, limit: str, stage: Optional[str] = None, output: str = "") -> None:
        super().__init__(message, output)
        self.limit = limit
        self.stage = stage


class JailCrashError(JailError):
    """A jailed worker died without answering (killed by a signal, exited)."""


class JailProtocolError(JailError):
    """A jailed worker sent something that is not a valid message (too large, wrong types)."""
