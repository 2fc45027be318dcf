"""Reading a road network map: Scenic parses the file (its parse cached in the user cache), the OpenDRIVE speed
limits are read beside it, and the conversion is cached in-process by path, modification time and size."""

from __future__ import annotations

import math
import os
import threading
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import TYPE_CHECKING, Dict, Tuple, Union

from envs.road_network.conversion import ConvertedNetwork, convert_network
from envs.road_network.errors import MapLoadError, MapNotFoundError
from scenario_bank.map_cache import load_network

if TYPE_CHECKING:  # pragma: no cover - typing only
    from scenic.domains.driving.roads import Network

__all__ = ["load_road_network"]


# ---------------------------------------------------------------------------
# Loading
# ---------------------------------------------------------------------------

_CACHE: Dict[Tuple[str, int, int], ConvertedNetwork] = {}
_CACHE_LOCK = threading.Lock()

_SPEED_UNITS = {"m/s": 1.0, "km/h": 1.0 / 3.6, "mph": 0.44704}


def _read_speed_limits(path: Path) -> Dict[str, float]:
    """OpenDRIVE road id -> first ``<type><speed max=...>`` of the road [m/s]."""
    limits: Dict[str, float] = {}
    try:
        root = ET.parse(path).getroot()
    except (ET.ParseError, OSError):
        return limits
    for road in root.iter("road"):
        for road_type in road.findall("type"):
            speed = road_type.find("speed")
            if speed is None:
                continue
            try:
                value = float(speed.get("max", "nan"))
            except ValueError:
                continue
            factor = _SPEED_UNITS.get(speed.get("unit", "m/s"), None)
            if factor is not None and math.isfinite(value) and value > 0:
                limits[str(road.get("id"))] = value * factor
                break
    return limits


def _load_scenic_network(path: Path) -> "Network":
    return load_network(path)


def load_road_network(map_path: Union[str, Path]) -> ConvertedNetwork:
    """Load a map through Scenic and convert it, caching the result in-process.

    Scenic's parsed network is cached in the user cache directory
    (:mod:`scenario_bank.map_cache`), never beside the map. The conversion is cached by resolved path, modification
    time and size, so resetting an environment does not reconvert; the same
    :class:`ConvertedNetwork` object is returned each time.

    :param map_path: path to an OpenDRIVE ``.xodr`` file (anything
        ``Network.fromFile`` accepts).
    :raises MapNotFoundError: (a ``FileNotFoundError``) the file does not exist.
    :raises MapLoadError: (a ``ValueError``) Scenic could not parse the file, or
        it has no drivable lanes.
    """
    path = Path(map_path).expanduser()
    try:
        resolved = path.resolve(strict=True)
        stat = resolved.stat()
    except FileNotFoundError:
        raise MapNotFoundError(
            f"road network map not found: {str(map_path)!r} (looked for {path.absolute()}). "
            "Check the path; relative paths are resolved against the current working "
            f"directory ({os.getcwd()})."
        ) from None
    if not resolved.is_file():
        raise MapLoadError(f"road network map {str(map_path)!r} is not a file ({resolved})")

    where = repr(str(map_path)) if Path(str(map_path)) == resolved else f"{str(map_path)!r} ({resolved})"
    key = (str(resolved), stat.st_mtime_ns, stat.st_size)
    with _CACHE_LOCK:
        cached = _CACHE.get(key)
    if cached is not None:
        return cached

    try:
        network = _load_scenic_network(resolved)
    except FileNotFoundError as exc:
        raise MapNotFoundError(f"road network map {str(map_path)!r} could not be read: {exc}") from exc
    except Exception as exc:  # Scenic raises all sorts of things on bad input
        detail = f"{type(exc).__name__}: {exc}".strip()
        raise MapLoadError(
            f"Scenic could not load the road network {where}: {detail}. Check that the "
            "file is a complete, valid OpenDRIVE (.xodr) map, e.g. open it in an "
            "OpenDRIVE viewer or regenerate it with the tool that wrote it."
        ) from exc

    if not network.lanes:
        raise MapLoadError(
            f"road network {where} contains no drivable lanes. "
            "Check that it is the intended OpenDRIVE map and that its roads have lanes "
            'of type "driving".'
        )
    speed_limits = _read_speed_limits(resolved) if resolved.suffix == ".xodr" else {}
    converted = convert_network(network, speed_limits=speed_limits, source=resolved)
    with _CACHE_LOCK:
        # keep only the newest version of a given file
        for old in [k for k in _CACHE if k[0] == key[0]]:
            del _CACHE[old]
        _CACHE[key] = converted
    return converted
