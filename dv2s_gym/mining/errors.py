"""Errors of failure mining, each naming the problem and the fix."""

from __future__ import annotations

from envs.errors import DV2SError

__all__ = ["MiningError"]


class MiningError(DV2SError, ValueError):
    """Bad mining settings or a run folder that cannot be resumed."""
