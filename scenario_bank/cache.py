"""Where dv2s-gym keeps what it derives: a user cache directory, never the installed package.

``cache_dir()`` is ``$DV2S_CACHE_DIR`` when set, else the platform's user cache
directory for ``dv2s-gym`` (``~/.cache/dv2s-gym`` on Linux). Everything in it can
be deleted at any time; it is rebuilt on demand:

    banks/<folder name>-<hash>/index.json   a bank's index (one folder per bank, keyed by its path)
    banks/<folder name>-<hash>/lock         the lock its writers take
    maps/<map name>-<hash>.snet             Scenic's parsed road networks

This module imports nothing else of dv2s-gym.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Union

from platformdirs import user_cache_dir

__all__ = ["CACHE_ENV", "cache_dir", "keyed_cache_dir", "keyed_cache_file"]

CACHE_ENV = "DV2S_CACHE_DIR"
"""Environment variable that overrides the cache directory."""


def cache_dir() -> Path:
    """The cache directory (not created)."""
    override = os.environ.get(CACHE_ENV)
    if override:
        return Path(override).expanduser()
    return Path(user_cache_dir("dv2s-gym", appauthor=False))


def _key(source: Union[str, os.PathLike]) -> str:
    resolved = Path(source).expanduser().resolve()
    digest = hashlib.sha256(str(resolved).encode("utf-8")).hexdigest()[:16]
    stem = "".join(c if c.isalnum() or c in "-_" else "_" for c in (resolved.stem or "root"))[:40]
    return f"{stem}-{digest}"


def keyed_cache_dir(kind: str, source: Union[str, os.PathLike]) -> Path:
    """``cache_dir()/<kind>/<name>-<hash of source's absolute path>``, created; two sources never share it."""
    folder = cache_dir() / kind / _key(source)
    folder.mkdir(parents=True, exist_ok=True)
    return folder


def keyed_cache_file(kind: str, source: Union[str, os.PathLike], suffix: str) -> Path:
    """``cache_dir()/<kind>/<name>-<hash of source's absolute path><suffix>``; its folder is created."""
    folder = cache_dir() / kind
    folder.mkdir(parents=True, exist_ok=True)
    return folder / f"{_key(source)}{suffix}"
