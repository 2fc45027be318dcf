"""What a policy spec *is*, by content: resume and baseline checks compare these, not the spec's text.

:func:`policy_fingerprint` turns a spec into the facts that decide how the policy drives:

- a checkpoint (``model.zip``, ``ppo:PATH``, a folder, the shipped ``dv2s-ppo``): the SHA-256 of
  its bytes (and of the model card beside it);
- ``module:attribute``: the SHA-256 of the module's source file;
- a registered driver (``rule``, ``idm``, ...): the SHA-256 of the module that implements it;
- the spec's options, typed and sorted, and the bytes (SHA-256) of every option value that names an
  existing file (``?weights=weights.json``);
- the user's own modules the policy may use: every ``.py`` file beside a ``module:attribute``
  policy's module (its package's tree when it is in a package; at most
  :data:`~policies.run_identity.MAX_HELPER_FILES`), and every module loaded in this process from under that
  folder, leaving out the standard library, site-packages and dv2s's own packages;
- the dv2s version and one SHA-256 of dv2s's simulator, regression and policy sources (``envs/``,
  ``dv2s_gym/regress/``, ``policies/``), so an edited editable install is noticed.

All but that last SHA-256 are :func:`policies.run_identity.resume_fingerprint`, the policy half of every
resumable run's identity. A regression run's output folder records them all (``run.json``); resuming with a
changed checkpoint, module or options under the same spec, or with edited dv2s sources, is refused, naming what
changed.
"""

from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Any, Dict

from scenario_bank.atomic import file_sha256
from policies.run_identity import resume_fingerprint

__all__ = ["policy_fingerprint", "dv2s_sources_sha256"]

_DV2S_ROOT = Path(__file__).resolve().parents[2]
_DV2S_SOURCES = ("envs", "dv2s_gym/regress", "policies")


def dv2s_sources_sha256() -> str:
    """One SHA-256 over dv2s's simulator (``envs/``), regression (``dv2s_gym/regress/``) and ``policies/`` sources."""
    digest = hashlib.sha256()
    for folder in _DV2S_SOURCES:
        root = _DV2S_ROOT / folder
        for path in sorted(root.rglob("*.py")) if root.is_dir() else []:
            if "__pycache__" in path.parts:
                continue
            digest.update(str(path.relative_to(_DV2S_ROOT)).encode() + b"\0" + file_sha256(path).encode() + b"\n")
    return digest.hexdigest()


def policy_fingerprint(spec: str) -> Dict[str, Any]:
    """``{description: value}`` facts of a policy spec (see the module docstring); every key names what it is:
    :func:`~policies.run_identity.resume_fingerprint` with the one SHA-256 of dv2s's own sources."""
    facts = resume_fingerprint(spec)
    return {"options": facts.pop("options"), "dv2s version": facts.pop("dv2s version"),
            "dv2s sources (SHA-256)": dv2s_sources_sha256(), **facts}
