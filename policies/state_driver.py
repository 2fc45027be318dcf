"""Base class of the drivers that read the simulator state instead of the observation."""

from __future__ import annotations

from typing import Any, Optional, Tuple

import numpy as np

__all__ = ["StateDriver", "LANE_LEFT", "IDLE", "LANE_RIGHT", "FASTER", "SLOWER"]

# highway-env DiscreteMetaAction indices
LANE_LEFT, IDLE, LANE_RIGHT, FASTER, SLOWER = 0, 1, 2, 3, 4


class StateDriver:
    """A driver bound to one env that picks a ``DiscreteMetaAction`` from its state (privileged).

    Subclasses implement :meth:`act`; this class checks the action type and gives them
    the SB3-style :meth:`predict` and the ``driver(obs, info)`` call interface.
    """

    def __init__(self, env) -> None:
        self.env = env
        action_type = env.unwrapped.config["action"]["type"]
        if action_type != "DiscreteMetaAction":
            raise ValueError(f"{type(self).__name__} drives with DiscreteMetaAction, not {action_type}; "
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
