"""highway-env side of dv2s-gym: the Scenic simulator interface, road conversion and ``DV2S-v0``.

Importing it registers ``DV2S-v0`` with Gymnasium and names :mod:`envs.jail_worker` as the worker the
bank's script checks run in (:mod:`scenario_bank.simulator_worker`).
"""

from envs.registration import register_envs
from scenario_bank.simulator_worker import use_simulator_worker

register_envs()
use_simulator_worker("envs.jail_worker")

__all__ = ["register_envs"]
