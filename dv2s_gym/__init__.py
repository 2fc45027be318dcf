"""dv2s-gym: driving videos to simulatable Scenic scenarios, served as Gymnasium envs.

``import dv2s_gym`` registers ``DV2S-v0``; Gymnasium's ``"module:id"`` form does the import
itself, so no import is needed::

    import gymnasium as gym
    env = gym.make("dv2s_gym:DV2S-v0", scenario="highway_lead_vehicle_brakes")
"""

from envs import register_envs
from envs.dv2s_env import DV2SEnv
from envs.recording import VideoWriter, record_episode
from envs.replay import replay_trace
from envs.trace import EpisodeTrace

register_envs()

__version__ = "0.1.0"

__all__ = ["DV2SEnv", "EpisodeTrace", "VideoWriter", "record_episode", "replay_trace", "register_envs"]
