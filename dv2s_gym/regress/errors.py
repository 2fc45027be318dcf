"""Errors ``dv2s regress`` raises on bad input, each naming the problem and the fix."""

from __future__ import annotations

from envs.errors import DV2SError
from scenario_bank.run_identity import RunIdentityError

__all__ = ["RegressError", "ReportMismatchError", "ResumeMismatchError", "SequenceStoppedError"]


class RegressError(DV2SError, ValueError):
    """Bad input to a regression run (settings, scenario selection, reports, backends)."""


class ReportMismatchError(RegressError):
    """A baseline report that cannot be compared with this run (schema, bank or env config differ)."""


class ResumeMismatchError(RegressError, RunIdentityError):
    """An output folder holding a run with other settings than the one asked for (the resume check every
    resumable command shares, :mod:`scenario_bank.run_identity`; ``differences`` lists every setting that
    differs)."""


class SequenceStoppedError(DV2SError, RuntimeError):
    """A sequential test that has reached its verdict is fed more episodes. A :class:`RuntimeError`, so code
    catching that keeps working."""

    expected = False  # the caller's fault, not the user's input
