"""Errors the environment raises on bad input, each naming the problem and the fix."""

from __future__ import annotations

from scenario_bank.errors import DV2SError

__all__ = [
    "DV2SError",
    "ScenarioCompileError",
    "UnsupportedConstructError",
    "SceneSamplingError",
    "InvalidActionError",
    "UnknownConfigKeyError",
    "check_config_keys",
    "StepTimeoutError",
    "Interrupted",
    "OBSERVATION_TYPES",
    "ACTION_TYPES",
]


class Interrupted(KeyboardInterrupt):
    """Ctrl-C, carrying one line on what the interrupted run kept and how to resume it."""

    def __init__(self, note: str) -> None:
        super().__init__(note)
        self.note = note


class ScenarioCompileError(DV2SError, ValueError):
    """A Scenic script does not compile; carries Scenic's message, file and line."""

    def __init__(self, message: str, *, path: str | None = None, line: int | None = None) -> None:
        super().__init__(message)
        self.path = path
        self.line = line


class UnsupportedConstructError(ScenarioCompileError):
    """A script uses something our highway-env model does not provide."""


class SceneSamplingError(DV2SError, RuntimeError):
    """No scene satisfying the script's requirements was found in the iteration budget."""


class InvalidActionError(DV2SError, ValueError):
    """An action outside the environment's action space."""


class UnknownConfigKeyError(DV2SError, ValueError):
    """A ``config=`` key the env does not have (a typo would otherwise be ignored)."""


OBSERVATION_TYPES = ("Kinematics", "OccupancyGrid", "TimeToCollision", "LidarObservation", "GrayscaleObservation")
"""highway-env observation types DV2S-v0 supports."""

REQUIRED_OBSERVATION_KEYS = {
    "GrayscaleObservation": {"observation_shape": (128, 64), "stack_size": 4, "weights": [0.2989, 0.5870, 0.1140]},
}
"""Keys an observation type cannot do without, each with an example value (highway-env has no default)."""

ACTION_TYPES = ("DiscreteMetaAction", "ContinuousAction", "DiscreteAction")
"""highway-env action types DV2S-v0 supports."""


def _check_type(config, key: str, choices) -> None:
    import difflib

    section = (config or {}).get(key)
    if section is None:
        return
    if not isinstance(section, dict) or "type" not in section:
        raise UnknownConfigKeyError(f"config[{key!r}] must be a dict with a 'type' (one of {', '.join(choices)}), "
                                    f"e.g. {{'type': {choices[0]!r}}}; got {section!r}")
    if section["type"] not in choices:
        close = difflib.get_close_matches(str(section["type"]), choices, n=1)
        raise UnknownConfigKeyError(f"unknown {key} type {section['type']!r}"
                                    + (f" (did you mean {close[0]!r}?)" if close else "")
                                    + f"; DV2S-v0 supports {', '.join(choices)}")


def check_config_keys(config, defaults) -> None:
    """Raise :class:`UnknownConfigKeyError` naming each key of ``config`` not in ``defaults`` (with a
    suggestion), or an observation or action type DV2S-v0 does not support (with the choices)."""
    import difflib

    _check_type(config, "observation", OBSERVATION_TYPES)
    _check_type(config, "action", ACTION_TYPES)
    observation = (config or {}).get("observation") or {}
    needed = REQUIRED_OBSERVATION_KEYS.get(observation.get("type"), {})
    missing = [key for key in needed if key not in observation]
    if missing:
        example = {"type": observation["type"], **needed}
        raise UnknownConfigKeyError(f"the {observation['type']} observation needs {', '.join(map(repr, missing))}; "
                                    f"e.g. config['observation'] = {example!r}")
    unknown = sorted(set(config or {}) - set(defaults))
    if not unknown:
        return
    hints = []
    for key in unknown:
        close = difflib.get_close_matches(str(key), [str(k) for k in defaults], n=1)
        hints.append(f"{key!r}" + (f" (did you mean {close[0]!r}?)" if close else ""))
    raise UnknownConfigKeyError(f"unknown config key(s) {', '.join(hints)}; DV2SEnv.default_config() lists the keys")


class ForeignConstructWarning(UserWarning):
    """A construct of a script written for another simulator (CARLA, MetaDrive) was accepted
    but part of its meaning is dropped (a gear shift, a light state, traffic lights...)."""


__all__.append("ForeignConstructWarning")
__all__.append("UntrustedScenarioError")


class StepTimeoutError(DV2SError, RuntimeError):
    """One simulation step used more CPU time than the env's ``step_time_limit`` (a behaviour looping
    without taking an action never lets a time step end)."""


class UntrustedScenarioError(DV2SError, PermissionError):
    """Untrusted Scenic was about to be compiled outside the jail; run it through DV2SEnv or the sandbox."""
