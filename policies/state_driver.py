"""Base class of the drivers that read the simulator state instead of the observation."""

from __future__ import annotations

from typing import Any, Optional, Tuple

import numpy as np
from scenario_bank.errors import DV2SError

__all__ = ["DriverConfigError", "StateDriver", "LANE_LEFT", "IDLE", "LANE_RIGHT", "FASTER", "SLOWER"]

# highway-env DiscreteMetaAction indices
LANE_LEFT, IDLE, LANE_RIGHT, FASTER, SLOWER = 0, 1, 2, 3, 4


class DriverConfigError(DV2SError, ValueError):
    """A driver was given an env whose settings it cannot drive with (its action type); the message names the
    setting to use."""


class StateDriver:
    """A driver bound to one env that picks a ``DiscreteMetaAction`` from its state (privileged).

    Subclasses implement :meth:`act`; this class checks the action type and gives them
    the SB3-style :meth:`predict` and the ``driver(obs, info)`` call interface.
    """

    def __new__(cls, env=None, *args: Any, **kwargs: Any):
        # A jailed simulation's state stays in the jail: the driver is built there, next to it.
        if env is not None and getattr(env.unwrapped, "runs_in_jail", False) and cls is not RemoteStateDriver:
            return RemoteStateDriver(env, cls, args, kwargs)
        return super().__new__(cls)

    def __init__(self, env) -> None:
        self.env = env
        action_type = env.unwrapped.config["action"]["type"]
        if action_type != "DiscreteMetaAction":
            raise DriverConfigError(f"{type(self).__name__} drives with DiscreteMetaAction, not {action_type}; "
                             "set config['action'] = {'type': 'DiscreteMetaAction'}")

    def act(self) -> int:  # pragma: no cover - overridden
        """The next action for the env's current state."""
        raise NotImplementedError

    def predict(
        self, observation: Any, state: Optional[Any] = None, episode_start: Optional[Any] = None,
        deterministic: bool = True,
    ) -> Tuple[np.ndarray, Optional[Any]]:
        """SB3-compatible: ``(action, state)`` for the env's current state."""
        return np.array(self.act()), state

    def __call__(self, observation: Any = None, info: Optional[dict] = None) -> int:
        return self.act()


class RemoteStateDriver(StateDriver):
    """A :class:`StateDriver` of a jailed env: the driver runs in the jail, only its action comes back.

    ``CautiousDriver(env)`` returns one of these when ``env`` is a
    :class:`~envs.jailed_env.JailedDV2SEnv`; it acts like the driver it stands for.
    """

    def __init__(self, env, driver_class: type, args: Tuple[Any, ...] = (), kwargs: Optional[dict] = None) -> None:
        super().__init__(env)
        self.driver_class = driver_class
        self._handle = env.unwrapped.driver_new(driver_class, args, dict(kwargs or {}))

    def act(self) -> int:
        """The remote driver's action for the simulation's current state."""
        return self.env.unwrapped.driver_act(self._handle)
