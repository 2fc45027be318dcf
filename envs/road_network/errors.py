"""The errors of loading a road network map: one that cannot be read, one that does not exist."""

from __future__ import annotations

from envs.errors import DV2SError

__all__ = ["MapLoadError", "MapNotFoundError"]


class MapLoadError(DV2SError, ValueError):
    """A road network map could not be loaded (parse error, no drivable lanes...)."""


class MapNotFoundError(MapLoadError, FileNotFoundError):
    """The road network map file does not exist (also a ``FileNotFoundError``)."""
