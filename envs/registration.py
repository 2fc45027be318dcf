"""Gymnasium registration of ``DV2S-v0``."""

from __future__ import annotations

import gymnasium
from gymnasium.wrappers import RenderCollection

from envs.config_check import RENDER_MODES, check_render_mode

__all__ = ["register_envs", "make_env", "ENV_ID"]

ENV_ID = "DV2S-v0"


def register_envs() -> None:
    """Register ``DV2S-v0`` with Gymnasium (idempotent)."""
    if ENV_ID not in gymnasium.registry:
        gymnasium.register(id=ENV_ID, entry_point="envs.registration:make_env", disable_env_checker=False)


def make_env(**kwargs):
    """``DV2S-v0``'s entry point: :class:`envs.dv2s_env.DV2SEnv` with its render mode checked first.

    Given the class, ``gymnasium.make`` would print its own warning about an unknown ``render_mode`` before the
    env's error (with its did-you-mean) could say it; a function has no metadata for it to check. A
    ``<mode>_list`` render mode collects the frames (``gymnasium.wrappers.RenderCollection``), as Gymnasium does.
    """
    from envs.dv2s_env import DV2SEnv

    mode = kwargs.get("render_mode")
    collect = isinstance(mode, str) and mode.endswith("_list") and mode[: -len("_list")] in RENDER_MODES
    if collect:
        kwargs["render_mode"] = mode[: -len("_list")]
    else:
        check_render_mode(mode)
    env = DV2SEnv(**kwargs)
    if collect:
        env = RenderCollection(env)
    return env
