"""A failed attempt of the Scenario Generator: the record an SG backend hands back for each script that failed
its checks (:attr:`dv2s_gym.pipeline.stages.Generation.failures`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Dict

__all__ = ["GenerationFailure"]


@dataclass(frozen=True)
class GenerationFailure:
    """One generated script that failed its checks: the ``attempt`` (from 1), its ``category`` in the paper's
    taxonomy (``undefined_symbol``, ``api_hallucination``, ``function_misuse``, ``geometric_infeasibility``,
    ``unsafe_code``, ``other``), the check's ``stage`` (``safety``, ``compile``, ``sample``, ``run``) and the
    checker's ``message``."""

    attempt: int
    category: str
    stage: str
    message: str

    def to_dict(self) -> Dict[str, Any]:
        """The failure as the reports write it: ``{"attempt", "category", "stage", "message"}``."""
        return {"attempt": self.attempt, "category": self.category, "stage": self.stage, "message": self.message}
