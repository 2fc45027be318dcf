"""What a policy spec *is*, by content: resume and baseline checks compare these, not the spec's text.

:func:`policy_fingerprint` turns a spec into the facts that decide how the policy drives:

- a checkpoint (``model.zip``, ``ppo:PATH``, a folder, the shipped ``dv2s-ppo``): the SHA-256 of
  its bytes (and of the model card beside it);
- ``module:attribute``: the SHA-256 of the module's source file;
- a registered driver (``rule``, ``idm``, ...): the SHA-256 of the module that implements it;
- the spec's options, typed and sorted.

A run's output folder records them (``run.json``); resuming with a changed checkpoint, module or
options under the same spec is refused, naming what changed.
"""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path
from typing import Any, Dict, Optional

from scenario_bank.atomic import file_sha256

__all__ = ["policy_fingerprint", "file_sha256"]


def _module_file(name: str) -> Optional[Path]:
    try:
        spec = importlib.util.find_spec(name)
    except (ImportError, ValueError):
        return None
    origin = getattr(spec, "origin", None) if spec is not None else None
    return Path(origin) if origin and Path(origin).is_file() else None


def _checkpoint(base: str) -> Optional[Path]:
    from policies.registry import SB3_ALGORITHMS, SHIPPED_CHECKPOINT

    if base == "dv2s-ppo":
        return SHIPPED_CHECKPOINT
    prefix, sep, rest = base.partition(":")
    if sep and prefix.lower() in SB3_ALGORITHMS:
        base = rest
    path = Path(base)
    if path.is_dir():
        path = path / "model.zip"
    return path if path.suffix == ".zip" or (sep and prefix.lower() in SB3_ALGORITHMS) else None


def policy_fingerprint(spec: str) -> Dict[str, Any]:
    """``{description: value}`` facts of a policy spec (see the module docstring); every key names what it is."""
    from policies.registry import _REGISTRY, parse_spec

    base, options = parse_spec(spec)
    facts: Dict[str, Any] = {"options": json.dumps(options, sort_keys=True, default=str)}
    checkpoint = _checkpoint(base)
    if checkpoint is not None:
        resolved = checkpoint.resolve()
        facts[f"checkpoint {checkpoint} (SHA-256)"] = file_sha256(resolved) if resolved.is_file() else "missing"
        card = resolved.parent / "model_card.json"
        if card.is_file():
            facts[f"model card {card} (SHA-256)"] = file_sha256(card)
    elif base in _REGISTRY:
        factory = _REGISTRY[base]
        module = getattr(factory, "__module__", None)
        closure = [c.cell_contents for c in (getattr(factory, "__closure__", None) or [])]
        paths = [c for c in closure if isinstance(c, str) and ":" in c]  # a state driver's class path
        if paths:
            module = paths[0].split(":")[0]
        found = _module_file(module) if module else None
        if found is not None:
            facts[f"module {module} source (SHA-256)"] = file_sha256(found)
    elif ":" in base:
        module = base.partition(":")[0]
        found = _module_file(module)
        facts[f"module {module} source (SHA-256)"] = file_sha256(found) if found else "not found"
    return facts
