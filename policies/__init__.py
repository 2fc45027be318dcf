"""Driving policies for DV2S-v0: rule-based baselines (and, later, trained SB3 policies)."""

from policies.baselines import IDMEgo, KeepLaneEgo
from policies.rule_based import CautiousDriver

__all__ = ["CautiousDriver", "IDMEgo", "KeepLaneEgo"]
