"""How a mined failure is converted and judged: :class:`ConversionSettings` (one record, handed from the command
line and the miner to :func:`dv2s_gym.mining.conversion.convert.convert_failure` and
:func:`~dv2s_gym.mining.conversion.replay.replay_failure_entry`)."""

from __future__ import annotations

import dataclasses
import os
from typing import Any, Mapping, Optional, Union

from dv2s_gym.mining.errors import MiningError
from dv2s_gym.mining.monitors import MonitorSettings
from dv2s_gym.pipeline.llm_config import LLMConfig
from scenario_bank.field_checks import check_bool, check_int, check_mapping, check_number, check_path, check_text

__all__ = ["ConversionSettings"]

PathLike = Union[str, os.PathLike]


@dataclasses.dataclass(frozen=True)
class ConversionSettings:
    """How :func:`~dv2s_gym.mining.conversion.convert.convert_failure` converts and judges a failure (and how
    :func:`~dv2s_gym.mining.conversion.replay.replay_failure_entry` keeps its exact replay); ``dv2s mine``'s conversion
    options are these. Every field is checked when the settings are made (:class:`MiningError` names the field and
    the bad value); a ``k`` below 1 or a ``threshold`` outside [0, 1] is not refused here but makes each conversion
    a rejection at its ``input`` stage. Not recorded in a run folder (a resumed run may convert otherwise)."""

    policy: Any = None
    """The deterministic policy that failed (a spec or a :class:`~policies.registry.Policy`); the miner sets its
    run's. A conversion without one is refused."""
    dra: str = "bev"
    """The Driving Record Analyzer backend (``bev``, ``openai``...)."""
    sg: str = "rules"
    """The Scenario Generator backend (``rules``, ``openai``...)."""
    llm_config: Optional[LLMConfig] = None
    """Model settings of the LLM/VLM backends (a mapping of their keys is read into the record, its keys checked)."""
    k: int = 10
    """Episodes of the reproduction check (and of the reference driver's avoidability check)."""
    threshold: float = 0.3
    """The smallest reproduction rate (and share of episodes showing the interaction) that keeps the script."""
    seed: int = 0
    """The SG's seed and the reproduction seeds' salt."""
    env_config: Optional[Mapping[str, Any]] = None
    """The mining run's DV2S-v0 config overrides (the miner sets its run's)."""
    bank_dir: Optional[PathLike] = None
    """The bank holding the record's scenario (``None``: the bank converted into when it holds it, else the
    shipped bank)."""
    monitor: Optional[MonitorSettings] = None
    """The failure monitors' settings (a mapping of them is read into the record; ``None``: those of the run's
    ``settings.json``, else the monitors' defaults)."""
    before: float = 4.0
    """Seconds of video before the failure."""
    after: float = 1.0
    """Seconds of video after the failure."""
    reference: Optional[Any] = "rule"
    """The driver that must avoid the failure on the new script (``None``: not checked)."""
    describe_events: bool = True
    """Add the trace's account of the failure to the description."""

    def __post_init__(self) -> None:
        object.__setattr__(self, "llm_config", LLMConfig.of(self.llm_config))  # a mapping's keys checked once, here
        check_text(MiningError, "conversion dra", self.dra, what="a DRA backend's name (e.g. bev)")
        check_text(MiningError, "conversion sg", self.sg, what="an SG backend's name (e.g. rules)")
        check_int(MiningError, "conversion k", self.k, low=0)
        check_number(MiningError, "conversion threshold", self.threshold, example="a reproduction rate, e.g. 0.3")
        check_int(MiningError, "conversion seed", self.seed, low=0)
        check_mapping(MiningError, "conversion env_config", self.env_config, optional=True,
                      what="a JSON object of DV2S-v0 config overrides")
        check_path(MiningError, "conversion bank_dir", self.bank_dir, optional=True)
        check_number(MiningError, "conversion before", self.before, low=0, example="seconds")
        check_number(MiningError, "conversion after", self.after, low=0, example="seconds")
        check_bool(MiningError, "conversion describe_events", self.describe_events)
        for name in ("policy", "reference"):
            if isinstance(getattr(self, name), str):
                check_text(MiningError, f"conversion {name}", getattr(self, name), what="a policy spec (e.g. rule)")
        self._read_monitor()

    def _read_monitor(self) -> None:
        if self.monitor is None or isinstance(self.monitor, MonitorSettings):
            return
        check_mapping(MiningError, "conversion monitor", self.monitor, what="monitor settings (ttc_threshold, "
                      "stall_seconds)")
        for key in ("ttc_threshold", "stall_seconds"):
            if self.monitor.get(key) is not None:  # a setting left out or None takes its default
                check_number(MiningError, f"conversion monitor {key!r}", self.monitor[key])
        object.__setattr__(self, "monitor", MonitorSettings.of(self.monitor))

    def replace(self, **changes: Any) -> "ConversionSettings":
        """A copy with ``changes`` (checked again)."""
        return dataclasses.replace(self, **changes)
