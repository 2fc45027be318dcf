"""Errors ``dv2s regress`` raises on bad input, each naming the problem and the fix."""

from __future__ import annotations

from envs.errors import DV2SError
from scenario_bank.run_identity import RunIdentityError

__all__ = ["RegressError", "ReportMismatchError", "ResumeMismatchError"]


class RegressError(DV2SError, ValueError):
    """Bad input to a regression run (settings, scenario selection, reports, backends)."""


class ReportMismatchError(RegressError):
    """A baseline report that cannot be compared with this run (schema, bank or env config differ)."""


class ResumeMismatchError(RegressError, RunIdentityError):
    """An output folder holding a run with other settings than the one asked for (the resume check every
    resumable command shares, :mod:`scenario_bank.run_identity`; ``differences`` lists every setting that
    differs)."""
