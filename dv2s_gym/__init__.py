"""dv2s-gym: driving videos to simulatable Scenic scenarios, served as Gymnasium envs.

``import dv2s_gym`` registers ``DV2S-v0``; Gymnasium's ``"module:id"`` form does the import
itself, so no import is needed::

    import gymnasium as gym
    env = gym.make("dv2s_gym:DV2S-v0", scenario="highway_lead_vehicle_brakes")

The env classes below are imported on first use, so that importing a light submodule
(``dv2s_gym.regress.stats``, the pytest plugin, ``dv2s --help``) does not load Scenic.
"""

from importlib import import_module
from typing import Any

from envs import register_envs

register_envs()

__version__ = "0.1.0"

_LAZY = {
    "DV2SEnv": "envs.dv2s_env",
    "EpisodeTrace": "envs.trace",
    "VideoWriter": "envs.recording",
    "record_episode": "envs.recording",
    "replay_trace": "envs.replay",
}

__all__ = ["DV2SEnv", "EpisodeTrace", "VideoWriter", "record_episode", "replay_trace", "register_envs"]


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        value = getattr(import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'dv2s_gym' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
