"""highway-env side of dv2s-gym: the Scenic simulator interface, road conversion and ``DV2S-v0``."""

from envs.registration import register_envs

register_envs()

__all__ = ["register_envs"]
