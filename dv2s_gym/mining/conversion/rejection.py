"""How a conversion of a failure stops: a rejection of the failure at one stage (:class:`ConversionRejected`,
recorded, never raised out of the conversion), or an error of the model backends' setup (:data:`SETUP_ERRORS`,
raised, so a run can be resumed once the endpoint works), or settings that are not a conversion's
(:func:`check_settings`).
"""

from __future__ import annotations

from typing import Any

from dv2s_gym.mining.conversion.settings import ConversionSettings
from dv2s_gym.mining.errors import MiningError
from dv2s_gym.pipeline.errors import (EndpointHTTPError, EndpointTimeoutError, EndpointUnreachableError,
                                      MissingAPIKeyError)
from scenario_bank.errors import WrongTypeError

__all__ = ["ConversionRejected", "SETUP_ERRORS", "stage_error", "check_settings"]


SETUP_ERRORS = (EndpointUnreachableError, EndpointTimeoutError, EndpointHTTPError, MissingAPIKeyError)
"""Errors of the model backends' setup (no connection, no answer, an HTTP error, no API key):
:func:`~dv2s_gym.mining.conversion.convert.convert_failure` raises them instead of rejecting the failure, so a run stops and can be
resumed when the endpoint works, rather than rejecting every cluster."""


class ConversionRejected(MiningError):
    """A failure's conversion rejected at ``stage`` (``"video"``, ``"check"``, ``"reproduction"``...) with ``message``;
    its text is the record's ``reason``, ``"<stage>: <message>"``. The conversion records it and never raises it to
    its caller."""

    def __init__(self, stage: str, message: str) -> None:
        super().__init__(f"{stage}: {message}")
        self.stage, self.message = stage, message


def stage_error(stage: str, error: BaseException) -> str:
    """A stage's failure as a rejection reason: ``"<stage>: <message>"``, an unexpected error named by its type."""
    if isinstance(error, ConversionRejected):
        return str(error)
    first = (str(error).strip().splitlines() or [""])[0]
    return f"{stage}: {type(error).__name__}: {first}"[:500]


def check_settings(settings: Any, function: str) -> None:
    """Refuse ``settings`` that are not a :class:`ConversionSettings` naming the policy that failed."""
    if not isinstance(settings, ConversionSettings):
        raise WrongTypeError(f"{function} takes its settings as one ConversionSettings, not {type(settings).__name__}")
    if settings.policy is None:
        raise WrongTypeError(f"{function} needs the policy that failed: pass ConversionSettings(policy=<its spec>)")
