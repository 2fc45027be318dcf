"""The settings of an LLM/VLM endpoint, as one typed record: what the command line, the conversion settings and the
stages hand to the chat client (:meth:`~dv2s_gym.pipeline.llm_client.ChatClient.from_config`).

A mapping of the same keys (``base_url``, ``model``, ``api_key``, ``timeout``, ``retries``, and per-kind sections
``llm``/``vlm``) is read once, where it enters (:meth:`LLMConfig.of`): its keys are checked there and nowhere after.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Mapping, Optional, Union

from dv2s_gym.pipeline.errors import LLMConfigError

__all__ = ["CONFIG_KEYS", "LLMConfig", "LLMConfigLike"]

CONFIG_KEYS = ("base_url", "model", "api_key", "timeout", "retries")
"""The settings of an endpoint (the fields of :class:`LLMConfig` besides its per-kind sections)."""
KINDS = ("llm", "vlm")
"""The per-kind sections: ``llm`` for the Scenario Generator, ``vlm`` for the Driving Record Analyzer."""


@dataclass(frozen=True)
class LLMConfig:
    """An endpoint's settings; a field left ``None`` (or empty) is read from the environment by the client
    (``DV2S_LLM_*``, ``DV2S_VLM_*``, ``OPENAI_API_KEY``) or takes its default. ``llm``/``vlm``: settings of one kind
    of model that win over these (a VLM at another endpoint than the LLM)."""

    base_url: Optional[str] = None
    model: Optional[str] = None
    api_key: Optional[str] = None
    timeout: Optional[Any] = None
    retries: Optional[Any] = None
    llm: Optional["LLMConfig"] = None
    vlm: Optional["LLMConfig"] = None

    @classmethod
    def of(cls, config: "LLMConfigLike") -> Optional["LLMConfig"]:
        """``config`` as a record: ``None`` stays ``None``, a record is itself, a mapping has its keys checked
        (:data:`CONFIG_KEYS`, and sections :data:`KINDS` that are mappings of them; :class:`LLMConfigError`
        otherwise)."""
        if config is None or isinstance(config, cls):
            return config
        if not isinstance(config, Mapping):
            raise LLMConfigError(f"the LLM config must be a mapping of {', '.join(CONFIG_KEYS)}, not "
                                 f"{type(config).__name__}")
        flat = {key: value for key, value in config.items() if not (key in KINDS and isinstance(value, Mapping))}
        unknown = sorted(set(flat) - set(CONFIG_KEYS))
        if unknown:
            raise LLMConfigError(f"unknown LLM config keys {unknown}; allowed: {', '.join(CONFIG_KEYS)}")
        sections = {kind: config[kind] for kind in KINDS if isinstance(config.get(kind), Mapping)}
        unknown = sorted({f"{kind}.{key}" for kind, section in sections.items() for key in section
                          if key not in CONFIG_KEYS})
        if unknown:
            raise LLMConfigError(f"unknown LLM config keys {unknown}; allowed: {', '.join(CONFIG_KEYS)}")
        return cls(**flat, **{kind: cls(**section) for kind, section in sections.items()})

    def for_kind(self, kind: str) -> "LLMConfig":
        """The settings one kind of model (``llm``, ``vlm``) uses: these, with its section's given values on top."""
        section = getattr(self, kind)
        given = {} if section is None else {key: getattr(section, key) for key in CONFIG_KEYS
                                            if getattr(section, key) is not None}
        return dataclasses.replace(self, llm=None, vlm=None, **given)


LLMConfigLike = Union[None, LLMConfig, Mapping[str, Any]]
"""What the stages take as an endpoint's settings: a record, a mapping of its keys (read by :meth:`LLMConfig.of`)
or ``None`` (the environment's)."""
