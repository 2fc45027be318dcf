"""Driving policies for DV2S-v0 behind one interface: rule-based baselines, SB3 checkpoints, callables.

``load_policy(spec)`` (see :mod:`policies.registry`) returns a batched :class:`Policy`.
The names below load on first use, so checking a policy spec (:func:`policies.registry.check_policy_spec`)
does not import highway-env.
"""

import importlib

_HOMES = {
    "CautiousDriver": "policies.rule_based",
    "IDMEgo": "policies.baselines",
    "KeepLaneEgo": "policies.baselines",
    **{name: "policies.registry" for name in ("Policy", "PolicyError", "PolicySpaceError", "load_policy",
                                                "register_policy", "registered_policies")},
}

__all__ = sorted(_HOMES)


def __getattr__(name):
    if name not in _HOMES:
        raise AttributeError(f"module 'policies' has no attribute {name!r}")
    return getattr(importlib.import_module(_HOMES[name]), name)


def __dir__():
    return sorted(set(globals()) | set(_HOMES))
