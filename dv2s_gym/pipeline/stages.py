"""The two D-V2S stages behind one interface each, whatever the backend.

* :func:`describe` (Driving Record Analyzer): video -> :class:`Description`.
  Backends: ``bev`` (embedded, offline: bird's-eye renders in highway-env style)
  and ``openai`` (any OpenAI-compatible VLM endpoint).
* :func:`generate` (Scenario Generator): description -> :class:`Generation`.
  Backends: ``rules`` (embedded, offline composer) and ``openai`` (any
  OpenAI-compatible LLM with the fixed context and compile-in-the-loop repair).
"""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass, field
from typing import Any, Dict, List, Optional

__all__ = ["Description", "Generation", "describe", "generate", "DRA_BACKENDS", "SG_BACKENDS"]

DRA_BACKENDS = ("bev", "openai")
SG_BACKENDS = ("rules", "openai")


@dataclass
class Description:
    """What the Driving Record Analyzer said about a video."""

    text: str
    elements: Dict[str, Any]
    backend: str
    model: Optional[str] = None
    prompt_hash: Optional[str] = None
    video: Optional[str] = None

    def as_dict(self) -> Dict[str, Any]:
        return asdict(self)


@dataclass
class Generation:
    """A Scenic script from the Scenario Generator, with what it could not place and how it got there."""

    script: str
    backend: str
    warnings: List[str] = field(default_factory=list)
    failures: List[Dict[str, Any]] = field(default_factory=list)
    attempts: int = 1
    model: Optional[str] = None
    context_hash: Optional[str] = None
    intended_elements: Dict[str, Any] = field(default_factory=dict)

    def failure_counts(self) -> Dict[str, int]:
        """Failures per category of the paper's taxonomy (plus unsafe code)."""
        counts: Dict[str, int] = {}
        for failure in self.failures:
            counts[failure["category"]] = counts.get(failure["category"], 0) + 1
        return counts

    def note_simulated(self, simulated: Dict[str, Any]) -> List[str]:
        """Add a warning for each element the script was composed to show (``intended_elements``, rules SG)
        that a simulated run of it (``simulated``, the trace's elements) did not show; returns the new ones."""
        if not self.intended_elements:
            return []
        from dv2s_gym.pipeline.sg_rules import unshown_warnings

        new = [w for w in unshown_warnings(self.intended_elements, simulated) if w not in self.warnings]
        self.warnings.extend(new)
        return new

    def as_dict(self) -> Dict[str, Any]:
        data = asdict(self)
        data["failure_counts"] = self.failure_counts()
        return data


def describe(
    video: str | os.PathLike,
    *,
    backend: str = "bev",
    camera: str = "bev",
    question: Optional[str] = None,
    fps: float = 2.0,
    max_frames: int = 16,
    max_pixels: int = 448 * 448,
    llm_config: Optional[Dict[str, Any]] = None,
) -> Description:
    """Describe a driving video (frames sampled at ``fps`` under ``max_frames`` and ``max_pixels``)."""
    from dv2s_gym.pipeline.semantics import elements_from_text
    from dv2s_gym.pipeline.video import read_video

    if backend not in DRA_BACKENDS:
        raise ValueError(f"unknown DRA backend {backend!r}; use one of {DRA_BACKENDS}")
    clip = read_video(video, fps=fps, max_frames=max_frames, max_pixels=max_pixels)
    if backend == "bev":
        from dv2s_gym.pipeline.dra_bev import analyze_bev

        analysis = analyze_bev(clip, question=question)
        return Description(analysis.description, elements_from_text(analysis.description), "bev", video=str(video))
    from dv2s_gym.pipeline.dra_openai import describe_with_vlm
    from dv2s_gym.pipeline.llm_client import ChatClient

    client = ChatClient.from_config(llm_config, kind="vlm")
    text, provenance = describe_with_vlm(clip.frames, client, camera=camera, question=question)
    return Description(text, elements_from_text(text), "openai", model=provenance.get("model"),
                       prompt_hash=provenance.get("prompt_hash"), video=str(video))


def generate(
    description: str,
    *,
    backend: str = "rules",
    seed: int = 0,
    llm_config: Optional[Dict[str, Any]] = None,
    max_attempts: int = 4,
) -> Generation:
    """Turn a description into a Scenic script that passed the safety check."""
    from scenario_bank.safety import assert_safe

    if backend not in SG_BACKENDS:
        raise ValueError(f"unknown SG backend {backend!r}; use one of {SG_BACKENDS}")
    if backend == "rules":
        from dv2s_gym.pipeline.sg_rules import generate_rules

        result = generate_rules(description, seed=seed)
        generation = Generation(result.script, "rules", warnings=list(result.warnings),
                                context_hash=getattr(result, "context_hash", None),
                                intended_elements=dict(getattr(result, "elements", {}) or {}))
    else:
        from dv2s_gym.pipeline.llm_client import ChatClient
        from dv2s_gym.pipeline.sg_openai import generate_with_llm
        from scenario_bank.bank import Bank

        client = ChatClient.from_config(llm_config)
        result = generate_with_llm(description, client, bank=Bank(), max_attempts=max_attempts)
        generation = Generation(result.script, "openai", failures=list(result.failures),
                                attempts=result.attempts, model=result.model, context_hash=result.context_hash)
    assert_safe(generation.script, "generated script")
    return generation
