"""Episode traces: everything needed to look at an episode again or replay it exactly.

A trace holds the scenario (name, source text), the seeds, the sampled scene
parameters, the env config, the agent's actions, the state of every actor after
every step (highway-env frame: x, y, heading, speed) and the events.
Replaying (:mod:`envs.replay`) re-runs the same scene with the same actions and
checks that every state matches.
"""

from __future__ import annotations

import gzip
import json
import os
import zlib
from dataclasses import MISSING, asdict, dataclass, field, fields
from pathlib import Path
from typing import Any, Dict, List, Optional, Union

from scenario_bank.atomic import atomic_write_bytes
from scenario_bank.errors import DV2SError, MissingFileError

__all__ = ["EpisodeTrace", "actor_state", "TraceFileError", "TraceMismatchError", "TRACE_VERSION", "saved_file_schema"]

TRACE_VERSION = 1


def actor_state(vehicle) -> List[float]:
    """``[x, y, heading, speed]`` of a highway-env object (full precision)."""
    return [float(vehicle.position[0]), float(vehicle.position[1]), float(vehicle.heading), float(vehicle.speed)]


class TraceFileError(DV2SError, ValueError):
    """A file given as an episode trace is not one (missing fields, corrupt, too large, damaged settings, written by
    a newer dv2s-gym); the message names the file and the fix."""


class TraceMismatchError(DV2SError, AssertionError):
    """A replay diverged from its trace."""


MAX_TRACE_BYTES = 64 * 2**20


@dataclass
class EpisodeTrace:
    """One episode, step by step."""

    scenario: str
    source: str
    seed: Optional[int]
    scene_seed: int
    params: Dict[str, Any]
    config: Dict[str, Any]
    scenario_path: Optional[str] = None
    actions: List[Any] = field(default_factory=list)
    states: List[Dict[str, List[float]]] = field(default_factory=list)
    events: List[Dict[str, Any]] = field(default_factory=list)
    kinds: Dict[str, str] = field(default_factory=dict)
    """Actor name -> element-vocabulary type (``scenario_bank.elements.PARTICIPANTS``)."""
    fixed_params: Dict[str, Any] = field(default_factory=dict)
    """Global parameters the reset fixed (``options={"params": ...}``, failure mining); a replay fixes them again."""
    version: int = TRACE_VERSION

    def ego_collision(self) -> Optional[Dict[str, Any]]:
        """The first ``collision`` event the ego is part of (``{"kind", "time", "actors", ...}``), or ``None``."""
        return next((event for event in self.events
                     if event.get("kind") == "collision" and "ego" in event.get("actors", [])), None)

    def first_failure_event(self) -> Optional[Dict[str, Any]]:
        """The first event that ends the ego's episode as a failure: a collision the ego is part of, or the ego
        leaving the road (``off_road``); ``None`` when there is neither."""
        return next((event for event in self.events
                     if event.get("kind") == "off_road"
                     or (event.get("kind") == "collision" and "ego" in event.get("actors", []))), None)

    @staticmethod
    def other_actor(event: Dict[str, Any]) -> Optional[str]:
        """The first actor of ``event`` that is not the ego, or ``None``."""
        return next((actor for actor in event.get("actors", []) if actor != "ego"), None)

    def save(self, path: Union[str, os.PathLike]) -> Path:
        """Write the trace as JSON (gzip-compressed when ``path`` ends in ``.gz``); atomic."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        data = json.dumps(asdict(self)).encode("utf-8")
        if path.suffix == ".gz":
            data = gzip.compress(data, mtime=0)
        return atomic_write_bytes(path, data)

    @classmethod
    def from_dict(cls, data: Any, source: str = "trace") -> "EpisodeTrace":
        """The trace a :meth:`save`-d dict describes; ``ValueError`` naming ``source`` when it is not one."""
        names = {f.name for f in fields(cls)}
        required = {f.name for f in fields(cls) if f.default is MISSING and f.default_factory is MISSING}
        if not isinstance(data, dict) or not required <= data.keys():
            missing = sorted(required - data.keys()) if isinstance(data, dict) else sorted(required)
            raise TraceFileError(
                f"{source} is not a dv2s episode trace: missing fields {', '.join(missing)}; "
                "traces are written by env.save_trace()"
            )
        version = data.get("version", 0)
        if version > TRACE_VERSION:
            raise TraceFileError(
                f"{source} was written by a newer dv2s-gym (trace version {version} > {TRACE_VERSION}); upgrade"
            )
        return cls(**{k: v for k, v in data.items() if k in names})

    @classmethod
    def load(cls, path: Union[str, os.PathLike]) -> "EpisodeTrace":
        """Read a trace written by :meth:`save` (at most ``MAX_TRACE_BYTES``, compressed or not)."""
        try:
            with open(path, "rb") as handle:
                raw = handle.read(MAX_TRACE_BYTES + 1)
                if raw[:2] == b"\x1f\x8b":
                    handle.seek(0)
                    with gzip.GzipFile(fileobj=handle) as unzipped:  # streamed: a small bomb stays small
                        raw = unzipped.read(MAX_TRACE_BYTES + 1)
        except FileNotFoundError:
            raise MissingFileError(f"no trace file {path}; check the path (`dv2s run --trace FILE` and "
                                       "`dv2s regress` write episode traces)") from None
        except (OSError, EOFError, zlib.error) as error:
            raise TraceFileError(f"{path} is not a dv2s episode trace (corrupt or truncated file: {error}); "
                             "save it again with env.save_trace()") from None
        if len(raw) > MAX_TRACE_BYTES:
            raise TraceFileError(f"{path}: a trace over {MAX_TRACE_BYTES // 2**20} MiB (uncompressed) is refused; "
                             "a dv2s episode trace is far smaller: is this the right file?")
        try:
            data = json.loads(raw.decode("utf-8"))
        except (OSError, EOFError, zlib.error, UnicodeDecodeError, json.JSONDecodeError) as error:
            raise TraceFileError(
                f"{path} is not a dv2s episode trace (corrupt or truncated file: {error}); "
                "save it again with env.save_trace()"
            ) from None
        return cls.from_dict(data, str(path))


def saved_file_schema(path: Union[str, os.PathLike]) -> Optional[str]:
    """The ``schema`` a saved dv2s JSON file names (a regression report's, a mining run's report), or ``None`` for
    an episode trace (gzip-compressed, or JSON without one) and for anything else (not JSON, unreadable): which
    kind of file ``dv2s replay`` was given."""
    try:
        with open(path, "rb") as handle:
            if handle.read(2) == b"\x1f\x8b":
                return None
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return None
    schema = data.get("schema") if isinstance(data, dict) else None
    return schema if isinstance(schema, str) else None
