"""Errors the environment raises on bad input, each naming the problem and the fix."""

from __future__ import annotations

from scenario_bank.errors import DV2SError

__all__ = [
    "DV2SError",
    "ScenarioCompileError",
    "UnsupportedConstructError",
    "SceneSamplingError",
    "InvalidActionError",
    "InvalidSeedError",
    "UnknownConfigKeyError",
    "UnknownRenderModeError",
    "ResetNeededError",
    "StepTimeoutError",
    "Interrupted",
    "OBSERVATION_TYPES",
    "ACTION_TYPES", "ForeignConstructWarning", "SimulatorPropertiesError", "UntrustedScenarioError"]


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


class InvalidSeedError(DV2SError, ValueError):
    """A ``reset(seed=...)`` that is not an integer >= 0."""


class UnknownConfigKeyError(DV2SError, ValueError):
    """A ``config=`` key the env does not have, or a value it does not take (a typo would otherwise be ignored)."""


class UnknownRenderModeError(DV2SError, ValueError):
    """A ``render_mode=`` DV2S-v0 does not have."""


OBSERVATION_TYPES = ("Kinematics", "OccupancyGrid", "TimeToCollision", "LidarObservation", "GrayscaleObservation")
"""highway-env observation types DV2S-v0 supports."""

ACTION_TYPES = ("DiscreteMetaAction", "ContinuousAction", "DiscreteAction")
"""highway-env action types DV2S-v0 supports."""


class ForeignConstructWarning(UserWarning):
    """A construct of a script written for another simulator (CARLA, MetaDrive) was accepted
    but part of its meaning is dropped (a gear shift, a light state, traffic lights...)."""


__all__.append("ForeignConstructWarning")
__all__.append("UntrustedScenarioError")


class ResetNeededError(DV2SError, RuntimeError):
    """The env was asked for an episode's step or its trace before ``reset()`` started one (or after it ended);
    the fix is to call ``reset()``."""



class StepTimeoutError(DV2SError, RuntimeError):
    """One simulation step used more CPU time than the env's ``step_time_limit`` (a behaviour looping
    without taking an action never lets a time step end)."""


class UntrustedScenarioError(DV2SError, PermissionError):
    """Untrusted Scenic was about to be compiled outside the jail; run it through DV2SEnv or the sandbox."""


class SimulatorPropertiesError(DV2SError, RuntimeError):
    """The simulator reported an object's properties other than the ones Scenic declares for it (a fault of the
    simulator interface, not of the scenario). A :class:`RuntimeError`, so code catching that keeps working."""

    expected = False


__all__.append("SimulatorPropertiesError")
