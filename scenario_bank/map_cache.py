"""Scenic road networks, parsed once and cached in the user cache directory.

Scenic's ``Network.fromFile`` pickles a parsed map as ``<map>.snet`` beside the
``.xodr`` file, which would write into the installed package. :func:`load_network`
keeps the same pickle (same digest checks, so an edited map or changed map
options invalidate it) under :func:`scenario_bank.cache.cache_dir` instead, keyed
by the map's absolute path. :func:`install_network_cache` routes Scenic's own
``Network.fromFile`` (which the driving domain's world model calls) through it.

This module imports nothing else of dv2s-gym but :mod:`scenario_bank`.
"""

from __future__ import annotations

import hashlib
import os
import pickle
from pathlib import Path
from typing import Any, Union

from scenario_bank.atomic import atomic_path
from scenario_bank.cache import keyed_cache_file

__all__ = ["load_network", "install_network_cache", "network_cache_path"]


def network_cache_path(map_path: Union[str, os.PathLike]) -> Path:
    """Where the parsed network of ``map_path`` is cached."""
    return keyed_cache_file("maps", map_path, ".snet")


def load_network(path: Union[str, os.PathLike], use_cache: bool = True, write_cache: bool = True, **options: Any):
    """Scenic ``Network`` of an OpenDRIVE map, through the user-cache pickle.

    ``options`` are Scenic's map options (``tolerance``, ``ref_points``...). A
    cache that is stale, corrupt or unwritable is ignored: the map is parsed again.
    Paths that are not ``.xodr`` files go to Scenic unchanged (without its cache).
    """
    from scenic.core.serialization import deterministicHash
    from scenic.domains.driving.roads import Network

    path = Path(path)
    if path.suffix != ".xodr":
        return _original_from_file(Network)(path, useCache=use_cache, writeCache=False, **options)
    data = path.read_bytes()
    digest = hashlib.blake2b(data).digest()
    options_digest = deterministicHash(options, digest_size=8)
    cached = network_cache_path(path)
    if use_cache and cached.is_file():
        try:
            return Network.fromPickle(cached, originalDigest=digest, optionsDigest=options_digest)
        except (Network.DigestMismatchError, pickle.UnpicklingError, EOFError, OSError, ValueError, AttributeError):
            pass  # stale or damaged: parse the map again
    network = Network.fromOpenDrive(path, **options)
    if write_cache:
        try:
            with atomic_path(cached) as tmp:
                network.dumpPickle(tmp, digest, optionsDigest=options_digest)
        except OSError:
            pass  # the cache is only a speed-up
    return network


def _original_from_file(network_class):
    return getattr(network_class.fromFile, "dv2s_original", network_class.fromFile)


def install_network_cache() -> None:
    """Make Scenic's ``Network.fromFile`` use :func:`load_network` (idempotent).

    After this, compiling a scenario never writes ``.snet`` files beside its map.
    """
    from scenic.domains.driving.roads import Network

    if getattr(Network.fromFile, "dv2s_original", None) is not None:
        return
    original = Network.fromFile

    def from_file(cls, path, useCache: bool = True, writeCache: bool = True, **kwargs):
        return load_network(path, use_cache=useCache, write_cache=writeCache, **kwargs)

    from_file.dv2s_original = original
    Network.fromFile = classmethod(from_file)
