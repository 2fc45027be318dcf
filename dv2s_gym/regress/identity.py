"""What a regression run *is*, by content: resume and baseline checks compare these, not the specs' text.

:func:`policy_fingerprint` turns a policy spec into the facts that decide how the policy drives
(:func:`policies.run_identity.resume_fingerprint`: a checkpoint's bytes, a module's source and the user's modules
beside it, a registered driver's module, the spec's options and the files they name, the dv2s version), and
:func:`dv2s_sources_sha256` is the one SHA-256 of dv2s's own sources (all four packages) of
:func:`policies.run_identity.code_identity`, which a regression run records with its plug-in modules, what they
registered and the built-ins they replaced. A regression run's output folder records them all (``run.json``);
resuming with a changed checkpoint, module or options under the same spec, with edited dv2s sources, or with other
or changed plug-ins is refused, naming what changed.
"""

from __future__ import annotations

from typing import Any, Dict

from policies.run_identity import dv2s_sources_sha256, resume_fingerprint

__all__ = ["policy_fingerprint", "dv2s_sources_sha256"]


def policy_fingerprint(spec: str) -> Dict[str, Any]:
    """``{description: value}`` facts of a policy spec (:func:`~policies.run_identity.resume_fingerprint`); every
    key names what it is."""
    return resume_fingerprint(spec)
