"""Errors of the D-V2S pipeline's model backends.

Every error raised while talking to a chat endpoint names the endpoint it was
talking to and says what to change to make it work.

Hierarchy::

    PipelineError
    ├── EndpointError                    (has .endpoint)
    │   ├── EndpointUnreachableError     connection refused / DNS / reset
    │   ├── EndpointTimeoutError         no answer within the timeout
    │   ├── EndpointHTTPError            non-2xx answer (has .status and .body)
    │   └── MalformedResponseError       2xx answer that is not a chat completion
    ├── MissingAPIKeyError               api.openai.com without a key
    ├── UnknownBackendError              a stage asked for a backend no one registered (also a ValueError)
    ├── BackendResultError               a registered backend returned something of the wrong shape
    ├── GenerationFailedError            no generated script passed the checks (has .result)
    ├── GenerationError                  the rules SG cannot place the ego or the main event (also a DV2SError)
    └── ConversionFolderError            the output folder holds a run of another kind (also a ValueError)
"""

from __future__ import annotations

from typing import Any, Optional

from envs.errors import DV2SError

__all__ = [
    "PipelineError",
    "EndpointError",
    "EndpointUnreachableError",
    "EndpointTimeoutError",
    "EndpointHTTPError",
    "MalformedResponseError",
    "MissingAPIKeyError",
    "LLMConfigError",
    "EmptyDescriptionError",
    "UnknownBackendError",
    "BackendResultError",
    "GenerationFailedError",
    "GenerationError",
    "FrameEncodeError",
    "ConversionFolderError",
]


class PipelineError(DV2SError):
    """Base class of the pipeline's errors."""


class EndpointError(PipelineError):
    """A chat endpoint could not be used; ``endpoint`` is the URL that was called."""

    def __init__(self, message: str, *, endpoint: str) -> None:
        super().__init__(message)
        self.endpoint = endpoint


class EndpointUnreachableError(EndpointError):
    """No connection could be made to the endpoint (refused, unknown host, reset)."""


class EndpointTimeoutError(EndpointError):
    """The endpoint did not answer within the client's timeout."""


class EndpointHTTPError(EndpointError):
    """The endpoint answered with an HTTP error status."""

    def __init__(self, message: str, *, endpoint: str, status: int, body: str = "") -> None:
        super().__init__(message, endpoint=endpoint)
        self.status = status
        self.body = body


class MalformedResponseError(EndpointError):
    """The endpoint answered 2xx, but not with a usable chat completion."""


class UnknownBackendError(PipelineError, ValueError):
    """A stage was asked for a backend name that is not registered; the message lists the registered ones."""


class BackendResultError(PipelineError):
    """A registered backend returned something its stage cannot use; the message names the backend and what it
    must return."""


class LLMConfigError(PipelineError, ValueError):
    """The LLM/VLM endpoint's settings (base URL, model, timeout, retries, config keys) hold a value that cannot be
    used; the message names the setting and an example."""


class EmptyDescriptionError(PipelineError, ValueError):
    """The description to turn into a scenario is empty."""


class MissingAPIKeyError(PipelineError):
    """An endpoint that needs an API key (api.openai.com) was configured without one."""


class GenerationFailedError(PipelineError):
    """The Scenario Generator's attempts all failed; ``result`` holds every failure."""

    def __init__(self, message: str, result: Optional[Any] = None) -> None:
        super().__init__(message)
        self.result = result


class FrameEncodeError(PipelineError, RuntimeError):
    """A video frame could not be encoded as an image for the vision-language model (a broken OpenCV build). A
    :class:`RuntimeError`, so code catching that keeps working."""

    expected = False


class GenerationError(PipelineError, ValueError):
    """The rules SG cannot place the ego or the main event of a description (the message names the phrase
    and what to write instead)."""


class ConversionFolderError(PipelineError, ValueError):
    """The output folder of a conversion holds a run of another kind (a mining, regression or training run, a
    loop), whose ``report.json`` the conversion would write over; the message names the folder, what it holds and
    the fix (another ``--out``)."""
