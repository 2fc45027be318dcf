"""Driving policies for DV2S-v0 behind one interface: rule-based baselines, SB3 checkpoints, callables.

``load_policy(spec)`` (see :mod:`policies.registry`) returns a batched :class:`Policy`.
"""

from policies.baselines import IDMEgo, KeepLaneEgo
from policies.registry import Policy, PolicyError, PolicySpaceError, load_policy, register_policy, registered_policies
from policies.rule_based import CautiousDriver

__all__ = ["CautiousDriver", "IDMEgo", "KeepLaneEgo", "Policy", "PolicyError", "PolicySpaceError", "load_policy",
           "register_policy", "registered_policies"]
