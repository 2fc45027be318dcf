"""A plug-in failure type, as a user writes one (docs/mining.md, "Adding a failure type"): ``hard_brake``, the ego
slowing by more than :data:`DROP` m/s in one step. It registers its row and detector when it is imported, so the
worker processes of ``dv2s mine`` and ``dv2s regress`` (which import the plug-in modules of the process that
started them) detect it too. :func:`unregister` undoes it (tests)."""

from __future__ import annotations

import sys

from dv2s_gym.mining.monitors import Detector, Failure, register_detector, unregister_detector
from scenario_bank.failure_types import FAILURE_TABLE, FailureType, register_failure_type, unregister_failure_type

NAME = "hard_brake"
DROP = 1.8
"""m/s the ego's speed falls in one step for a hard brake."""


def detect_hard_brake(result, trace, settings):
    """The first step where the ego slowed by more than :data:`DROP` m/s, as a failure; else ``None``."""
    speeds = [float(step["ego"][3]) for step in trace.states if "ego" in step]
    period = 1.0 / float(trace.config.get("policy_frequency", 5))
    for step in range(1, len(speeds)):
        if speeds[step - 1] - speeds[step] > DROP:
            return Failure(NAME, step * period, step, speed=speeds[step])
    return None


def score_hard_brake(result, failure, settings):
    """A hard brake's robustness: always -0.25."""
    return -0.25


register_failure_type(FailureType(NAME, severity=len(FAILURE_TABLE), result_field="hard_braked",
                                  regress_default=False, with_actor=False, label="hard brake"))
register_detector(Detector(NAME, detect_hard_brake, score_hard_brake))


def unregister() -> None:
    """Undo the registration and forget this module, so that importing it again registers again."""
    unregister_detector(NAME)
    unregister_failure_type(NAME)
    sys.modules.pop(__name__, None)
