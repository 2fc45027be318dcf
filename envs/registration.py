"""Gymnasium registration of ``DV2S-v0``."""

from __future__ import annotations

__all__ = ["register_envs", "ENV_ID"]

ENV_ID = "DV2S-v0"


def register_envs() -> None:
    """Register ``DV2S-v0`` with Gymnasium (idempotent)."""
    import gymnasium

    if ENV_ID not in gymnasium.registry:
        gymnasium.register(id=ENV_ID, entry_point="envs.dv2s_env:DV2SEnv", disable_env_checker=False)

