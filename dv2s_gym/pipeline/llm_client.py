"""A client for OpenAI-compatible chat-completion endpoints, on the ``openai`` package.

It speaks ``POST <base_url>/chat/completions`` as served by OpenAI (GPT-4o),
vLLM, Ollama, llama.cpp's server and most other local model servers::

    client = ChatClient("http://localhost:11434/v1", "qwen2.5vl:7b")
    reply = client.chat([{"role": "user", "content": "Hello"}])
    reply.text, reply.model, reply.usage

Messages may carry images as content parts
(``{"type": "image_url", "image_url": {"url": "data:image/jpeg;base64,..."}}``).

Transport, timeouts and retries are the ``openai`` package's: connection errors,
timeouts, HTTP 408/409/429 and 5xx answers are retried with its exponential
backoff (0.5 s doubling, at most 8 s, honouring ``Retry-After``); other 4xx
answers fail at once. This module keeps the project's contract on top of it:
every failure raises a :class:`~dv2s_gym.pipeline.errors.PipelineError`
subclass whose message names the endpoint and the fix, and a 2xx answer that is
not a chat completion is a :class:`MalformedResponseError`. The client makes no
request of its own (no telemetry, nothing at construction): only ``chat()`` talks
to the configured endpoint.

Configuration (:meth:`ChatClient.from_config`): keys ``base_url``, ``model``,
``api_key``, ``timeout``, ``retries`` of a dict, else environment variables
``DV2S_LLM_BASE_URL``, ``DV2S_LLM_MODEL``, ``DV2S_LLM_API_KEY`` /
``OPENAI_API_KEY``, ``DV2S_LLM_TIMEOUT``, ``DV2S_LLM_RETRIES`` (``kind="vlm"``
reads ``DV2S_VLM_*`` first and falls back to ``DV2S_LLM_*``), else GPT-4o on
api.openai.com.
"""

from __future__ import annotations

import ipaddress
import json
import logging
import os
import ssl
import urllib.parse
from dataclasses import dataclass, field
from typing import Any, Dict, Mapping, Optional, Sequence

import openai

from dv2s_gym.pipeline.errors import (
    EndpointHTTPError,
    EndpointTimeoutError,
    EndpointUnreachableError,
    MalformedResponseError,
    MissingAPIKeyError,
)
from dv2s_gym.pipeline.errors import LLMConfigError
from dv2s_gym.pipeline.llm_config import CONFIG_KEYS, LLMConfig, LLMConfigLike
from scenario_bank.errors import SettingError

__all__ = ["ChatClient", "ChatReply", "DEFAULT_BASE_URL", "DEFAULT_MODEL", "CONFIG_KEYS"]

log = logging.getLogger(__name__)

DEFAULT_BASE_URL = "https://api.openai.com/v1"
"""Endpoint used when neither the config nor the environment names one."""
DEFAULT_MODEL = "gpt-4o"
"""Model used when neither the config nor the environment names one (the paper's choice)."""
_KEY_HOSTS = ("api.openai.com",)
_NO_KEY = "no-key"  # sent to servers that need none: the openai package always sends a bearer token
_EXCERPT = 300
_COMPLETIONS = "/chat/completions"


@dataclass
class ChatReply:
    """One chat completion: the assistant's text, the model that answered, token usage, the raw JSON."""

    text: str
    model: str
    usage: Dict[str, Any] = field(default_factory=dict)
    raw: Dict[str, Any] = field(default_factory=dict)
    finish_reason: Optional[str] = None


def _excerpt(text: str, limit: int = _EXCERPT) -> str:
    text = " ".join(text.split())
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _endpoint_url(base_url: str) -> str:
    url = base_url.strip().rstrip("/")
    if url.endswith(_COMPLETIONS):
        return url
    if url.endswith("/v1") or "/v1/" in url + "/" or url.endswith("/openai"):
        return url + _COMPLETIONS
    return url + "/v1" + _COMPLETIONS


def _is_loopback(host: str) -> bool:
    if host in ("localhost", "localhost.localdomain"):
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


class ChatClient:
    """Client of one OpenAI-compatible ``/v1/chat/completions`` endpoint.

    Args:
        base_url: the server's OpenAI-compatible root, e.g. ``https://api.openai.com/v1``,
            ``http://localhost:8000/v1`` (vLLM), ``http://localhost:11434/v1`` (Ollama),
            ``http://localhost:8080/v1`` (llama.cpp). A URL without ``/v1`` gets it
            appended; a full ``.../chat/completions`` URL is used as is.
        model: the model name the server knows (``gpt-4o``, ``Qwen/Qwen2.5-VL-7B-Instruct``...).
        api_key: sent as ``Authorization: Bearer``; required for api.openai.com,
            optional for local servers.
        timeout: seconds to wait for the connection and for each read.
        retries: extra attempts after the first on connection errors, timeouts, 408/409/429 and 5xx.
    """

    def __init__(
        self,
        base_url: str,
        model: str,
        api_key: Optional[str] = None,
        timeout: float = 60,
        retries: int = 3,
        *,
        kind: str = "llm",
    ) -> None:
        if not base_url or not isinstance(base_url, str):
            raise LLMConfigError("base_url must be the endpoint's URL, e.g. 'http://localhost:8000/v1'")
        parsed = urllib.parse.urlsplit(base_url.strip())
        if parsed.scheme not in ("http", "https") or not parsed.hostname:
            raise LLMConfigError(
                f"base_url {base_url!r} is not an http(s) URL; use e.g. 'http://localhost:8000/v1' "
                "or 'https://api.openai.com/v1'"
            )
        if not model or not isinstance(model, str):
            raise LLMConfigError(f"model must name a model served at {base_url} (e.g. 'gpt-4o')")
        if timeout <= 0:
            raise LLMConfigError("timeout must be a positive number of seconds")
        if retries < 0:
            raise LLMConfigError("retries must not be negative")
        self.base_url = base_url.strip()
        self.endpoint = _endpoint_url(self.base_url)
        self.model = model
        self.api_key = api_key or None
        self.timeout = float(timeout)
        self.retries = int(retries)
        self.kind = kind
        self.host = parsed.hostname
        if self.api_key is None and any(self.host == h or self.host.endswith("." + h) for h in _KEY_HOSTS):
            prefix = self._prefix()
            raise MissingAPIKeyError(
                f"the endpoint {self.endpoint} needs an API key and none was given. Set OPENAI_API_KEY "
                f"(or {prefix}_API_KEY, or config['api_key']), or point {prefix}_BASE_URL / "
                "config['base_url'] at a local OpenAI-compatible server (vLLM, Ollama, llama.cpp) that needs none."
            )
        self._client = openai.OpenAI(
            base_url=self.endpoint[: -len(_COMPLETIONS)],
            api_key=self.api_key or _NO_KEY,
            timeout=self.timeout,
            max_retries=self.retries,
            # a local server is reached directly, whatever proxy the environment names
            http_client=openai.DefaultHttpxClient(trust_env=False) if _is_loopback(self.host) else None,
        )

    # ------------------------------------------------------------ configuration
    @classmethod
    def from_config(cls, config: LLMConfigLike = None, kind: str = "llm") -> "ChatClient":
        """A client configured from ``config`` (an :class:`~dv2s_gym.pipeline.llm_config.LLMConfig`, or a mapping of
        its keys, :data:`CONFIG_KEYS`, read by :meth:`LLMConfig.of`), then the environment.

        ``kind="llm"`` (Scenario Generator) reads ``DV2S_LLM_*`` variables; ``kind="vlm"``
        (Driving Record Analyzer) reads ``DV2S_VLM_*`` first and falls back to ``DV2S_LLM_*``.
        The API key falls back to ``OPENAI_API_KEY``. ``config`` may also hold a nested
        ``{"llm": {...}, "vlm": {...}}`` section per kind, which wins over its top level.
        """
        if kind not in ("llm", "vlm"):
            raise SettingError(f"kind must be 'llm' (the scenario generator) or 'vlm' (the record analyzer), "
                               f"not {kind!r}")
        settings = (LLMConfig.of(config) or LLMConfig()).for_kind(kind)
        config = {key: getattr(settings, key) for key in CONFIG_KEYS}
        prefixes = ["DV2S_VLM_", "DV2S_LLM_"] if kind == "vlm" else ["DV2S_LLM_"]

        def env(name: str) -> Optional[str]:
            for prefix in prefixes:
                value = os.environ.get(prefix + name)
                if value:
                    return value
            return None

        def pick(key: str, default: Any) -> Any:
            value = config.get(key)
            return value if value not in (None, "") else (env(key.upper()) or default)

        api_key = config.get("api_key") or env("API_KEY") or os.environ.get("OPENAI_API_KEY") or None
        try:
            timeout = float(pick("timeout", 60))
            retries = int(pick("retries", 3))
        except (TypeError, ValueError) as error:
            raise LLMConfigError(f"timeout and retries must be numbers: {error}") from None
        return cls(pick("base_url", DEFAULT_BASE_URL), pick("model", DEFAULT_MODEL), api_key=api_key,
                   timeout=timeout, retries=retries, kind=kind)

    def __repr__(self) -> str:
        key = "set" if self.api_key else "none"
        return f"ChatClient(endpoint={self.endpoint!r}, model={self.model!r}, api_key={key}, timeout={self.timeout})"

    # -------------------------------------------------------------------- chat
    def chat(
        self,
        messages: Sequence[Mapping[str, Any]],
        temperature: float = 0,
        max_tokens: int = 1024,
        **params: Any,
    ) -> ChatReply:
        """Send one chat-completion request; returns the first choice as a :class:`ChatReply`.

        Extra keyword arguments (``seed``, ``stop``, ``top_p``...) are added to the request body.
        """
        _check_messages(messages)
        tries = f"{self.retries + 1} attempt{'s' if self.retries else ''}"
        try:
            raw = self._client.chat.completions.with_raw_response.create(
                model=self.model,
                messages=list(messages),
                temperature=temperature,
                max_tokens=int(max_tokens),
                stream=False,
                extra_body=params or None,
            )
        except openai.APITimeoutError:
            raise self._timeout_error(tries) from None
        except openai.APIConnectionError as error:
            raise self._connection_error(error, tries) from None
        except openai.APIStatusError as error:
            raise self._http_error(error.status_code, error.response.text, tries) from None
        return self._parse(raw.content, raw.status_code)

    # ---------------------------------------------------------------- errors
    def _prefix(self) -> str:
        return "DV2S_VLM" if self.kind == "vlm" else "DV2S_LLM"

    def _timeout_error(self, tries: str) -> EndpointTimeoutError:
        return EndpointTimeoutError(
            f"the chat endpoint {self.endpoint} (model {self.model!r}) did not answer within "
            f"{self.timeout:g} s ({tries}). Raise the timeout (timeout=, config['timeout'] or "
            f"{self._prefix()}_TIMEOUT), ask for fewer tokens or images, or use a faster model or server.",
            endpoint=self.endpoint,
        )

    def _connection_error(self, error: Exception, tries: str) -> EndpointUnreachableError:
        reason = error.__cause__ or error.__context__ or error
        while reason.__cause__ is not None or reason.__context__ is not None:
            if isinstance(reason, ssl.SSLCertVerificationError):
                break
            reason = reason.__cause__ or reason.__context__
        if isinstance(reason, ssl.SSLCertVerificationError) or "CERTIFICATE_VERIFY_FAILED" in str(reason):
            return EndpointUnreachableError(
                f"TLS certificate check failed for {self.endpoint}: {reason}. Use the server's correct "
                "https URL, or http:// for a local server without TLS.",
                endpoint=self.endpoint,
            )
        what = getattr(reason, "strerror", None) or str(reason) or type(reason).__name__
        return EndpointUnreachableError(
            f"could not connect to the chat endpoint {self.endpoint} ({what}; {tries}). Start the model "
            "server (e.g. `vllm serve MODEL`, `ollama serve`, `llama-server -m MODEL.gguf`) or set "
            f"{self._prefix()}_BASE_URL / config['base_url'] to a reachable OpenAI-compatible endpoint.",
            endpoint=self.endpoint,
        )

    def _http_error(self, status: int, text: str, tries: str) -> EndpointHTTPError:
        detail = _error_detail(text)
        where = f"the chat endpoint {self.endpoint} answered HTTP {status}"
        if status in (401, 403):
            fix = (f"it rejected the credentials. Set OPENAI_API_KEY (or {self._prefix()}_API_KEY, or "
                   "config['api_key']) to a valid key for this endpoint")
        elif status == 404:
            fix = (f"the path or the model was not found. Check that base_url {self.base_url!r} is the "
                   f"server's OpenAI-compatible root (usually ending in /v1) and that model {self.model!r} "
                   "is served there (GET <base_url>/models lists them)")
        elif status == 413:
            fix = "the request is too large. Send fewer or smaller frames, or a shorter prompt"
        elif status == 429:
            fix = (f"it is rate-limiting ({tries}). Wait and retry, lower the request rate, or raise "
                   "retries")
        elif status >= 500:
            fix = f"the server failed ({tries}). Check the model server's log; it may be overloaded or still loading"
        else:
            fix = (f"it rejected the request. Check that model {self.model!r} exists and accepts this input "
                   "(image parts need a vision model), and lower max_tokens if it is above the model's limit")
        return EndpointHTTPError(
            f"{where}: {fix}. Server said: {_excerpt(detail) or '(empty body)'}",
            endpoint=self.endpoint,
            status=status,
            body=_excerpt(text, 2000),
        )

    def _malformed(self, what: str, raw: bytes | str) -> MalformedResponseError:
        text = raw.decode("utf-8", "replace") if isinstance(raw, bytes) else raw
        return MalformedResponseError(
            f"the chat endpoint {self.endpoint} answered, but {what}: {_excerpt(text) or '(empty body)'}. "
            "Check that base_url points at an OpenAI-compatible server's /v1 root (not a web page or "
            "another API) and that the server supports non-streaming chat completions.",
            endpoint=self.endpoint,
        )

    # ----------------------------------------------------------------- parse
    def _parse(self, raw: bytes, status: int) -> ChatReply:
        try:
            data = json.loads(raw.decode("utf-8"))
        except (UnicodeDecodeError, ValueError):
            raise self._malformed("not with JSON", raw) from None
        if not isinstance(data, dict):
            raise self._malformed("not with a JSON object", raw)
        choices = data.get("choices")
        if not choices:
            if data.get("error"):
                raise self._malformed(f"with an error instead of a completion ({_error_detail(raw.decode())})", raw)
            raise self._malformed("with no choices", raw)
        if not isinstance(choices, list) or not isinstance(choices[0], dict):
            raise self._malformed("with choices that are not a list of objects", raw)
        first = choices[0]
        message = first.get("message")
        if not isinstance(message, dict):
            raise self._malformed("with a choice that has no message", raw)
        content = message.get("content")
        if content is None:
            refusal = message.get("refusal")
            if refusal:
                raise self._malformed(f"the model refused: {refusal!r}", raw)
            raise self._malformed("with a message that has no content", raw)
        if isinstance(content, list):  # some servers answer with content parts
            content = "".join(part.get("text", "") for part in content if isinstance(part, dict))
        if not isinstance(content, str):
            raise self._malformed("with message content that is not text", raw)
        usage = data.get("usage") if isinstance(data.get("usage"), dict) else {}
        return ChatReply(
            text=content,
            model=str(data.get("model") or self.model),
            usage=dict(usage),
            raw=data,
            finish_reason=first.get("finish_reason"),
        )


def _check_messages(messages: Sequence[Mapping[str, Any]]) -> None:
    if isinstance(messages, (str, bytes)) or not messages:
        raise SettingError("messages must be a non-empty list of {'role': ..., 'content': ...} dicts")
    for i, message in enumerate(messages):
        if not isinstance(message, Mapping) or "role" not in message or "content" not in message:
            raise SettingError(f"message {i} must be a dict with 'role' and 'content', got {message!r:.120}")
        if message["role"] not in ("system", "user", "assistant", "developer", "tool"):
            raise SettingError(f"message {i} has unknown role {message['role']!r}; the roles are system, user, "
                               "assistant, developer and tool")


def _error_detail(text: str) -> str:
    """The ``error.message`` of an OpenAI-style error body, else the body itself."""
    try:
        data = json.loads(text)
    except (ValueError, TypeError):
        return text
    if isinstance(data, dict):
        error = data.get("error", data.get("detail"))
        if isinstance(error, dict):
            return str(error.get("message") or error)
        if error:
            return str(error)
    return text
