"""The two D-V2S stages behind one interface each, whatever the backend.

* :func:`describe` (Driving Record Analyzer): video -> :class:`Description`.
  Backends (:mod:`dv2s_gym.pipeline.dra`): ``bev`` (embedded, offline: bird's-eye
  renders in highway-env style) and ``openai`` (any OpenAI-compatible VLM endpoint).
* :func:`generate` (Scenario Generator): description -> :class:`Generation`.
  Backends (:mod:`dv2s_gym.pipeline.sg`): ``rules`` (embedded, offline composer) and
  ``openai`` (any OpenAI-compatible LLM with the fixed context and compile-in-the-loop repair).

Each stage picks its backend by name from a registry (:func:`register_dra`, :func:`register_sg`);
a backend module is imported only when its backend runs.
"""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass, field, fields
from typing import Any, Callable, Dict, List, Mapping, Optional, Tuple

from dv2s_gym.pipeline.attempts import GenerationFailure
from dv2s_gym.pipeline.errors import BackendResultError, PipelineError, UnknownBackendError
from dv2s_gym.pipeline.llm_config import LLMConfigLike
from scenario_bank.elements import Elements
from scenario_bank.named_registry import Registry
from scenario_bank.plugins import registering_module, remember_code
from scenario_bank.bank import Bank
from scenario_bank.safety import assert_safe

__all__ = ["Description", "Generation", "describe", "generate", "DRA_BACKENDS", "SG_BACKENDS",
           "register_dra", "register_sg", "registered_dras", "registered_sgs", "reads_model", "StageBackend"]

@dataclass
class Description:
    """What the Driving Record Analyzer said about a video."""

    text: str
    elements: Elements
    backend: str
    model: Optional[str] = None
    prompt_hash: Optional[str] = None
    video: Optional[str] = None

    def as_dict(self) -> Dict[str, Any]:
        data = asdict(self)
        data["elements"] = self.elements.to_dict()
        return data

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "Description":
        """The description :meth:`as_dict` wrote (a conversion's ``report.json``); keys it does not know are left."""
        values = {key: data[key] for key in _field_names(cls) if key in data}
        if "elements" in values:
            values["elements"] = Elements.from_dict(values["elements"])
        return cls(**values)


@dataclass
class Generation:
    """A Scenic script from the Scenario Generator, with what it could not place and how it got there."""

    script: str
    backend: str
    warnings: List[str] = field(default_factory=list)
    failures: List[GenerationFailure] = field(default_factory=list)
    attempts: int = 1
    model: Optional[str] = None
    context_hash: Optional[str] = None
    intended_elements: Optional[Elements] = None
    """What the script was composed to show (the rules SG's :attr:`~dv2s_gym.pipeline.sg.rules.SGResult.elements`;
    ``None`` from a backend that does not say: written as ``{}``)."""

    def failure_counts(self) -> Dict[str, int]:
        """Failures per category of the paper's taxonomy (plus unsafe code)."""
        counts: Dict[str, int] = {}
        for failure in self.failures:
            counts[failure.category] = counts.get(failure.category, 0) + 1
        return counts

    def note_simulated(self, simulated: Elements) -> List[str]:
        """Add a warning for each element the script was composed to show (``intended_elements``, rules SG)
        that a simulated run of it (``simulated``, the trace's elements) did not show; returns the new ones."""
        if self.intended_elements is None:
            return []
        from dv2s_gym.pipeline.sg.rules import unshown_warnings

        new = [w for w in unshown_warnings(self.intended_elements, simulated) if w not in self.warnings]
        self.warnings.extend(new)
        return new

    def as_dict(self) -> Dict[str, Any]:
        data = asdict(self)
        data["intended_elements"] = self.intended_elements.to_dict() if self.intended_elements is not None else {}
        data["failure_counts"] = self.failure_counts()
        return data

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> "Generation":
        """The generation :meth:`as_dict` wrote (a conversion's ``report.json``); the counts it adds are left."""
        values = {key: data[key] for key in _field_names(cls) if key in data}
        intended = values.get("intended_elements")
        values["intended_elements"] = Elements.from_dict(intended) if intended else None
        return cls(**values)


def _field_names(record: type) -> List[str]:
    return [f.name for f in fields(record)]


# --------------------------------------------------------------------------- registries
DRABackend = Callable[..., Tuple[str, Dict[str, Any]]]
"""``backend(clip, *, camera, question, llm_config) -> (text, provenance)``: ``clip`` is a
:class:`~dv2s_gym.pipeline.video.VideoClip`; ``provenance`` may name the ``model`` and ``prompt_hash``."""
SGBackend = Callable[..., Generation]
"""``backend(description, *, seed, llm_config, max_attempts) -> Generation``."""


@dataclass(frozen=True)
class StageBackend:
    """A registered DRA or SG backend: the callable, and whether it calls a model and so reads the model settings
    it is given (``reads_model``)."""

    call: Callable[..., Any]
    reads_model: bool = True


def _unknown_backend(stage: str) -> Callable[[str, List[str]], Exception]:
    return lambda name, names: UnknownBackendError(f"unknown {stage} backend {name!r}; use one of {tuple(names)}")


_DRA_REGISTRY: Registry[StageBackend] = Registry("DRA backend", PipelineError, unknown=_unknown_backend("DRA"))
_SG_REGISTRY: Registry[StageBackend] = Registry("SG backend", PipelineError, unknown=_unknown_backend("SG"))


def register_dra(name: str, backend: DRABackend, overwrite: bool = False, *, reads_model: bool = True) -> None:
    """Make ``describe(video, backend=name)`` call ``backend(clip, camera=..., question=..., llm_config=...)``
    (see :data:`DRABackend`); the description's elements are read from the text it returns. A name registered
    already needs ``overwrite=True``. ``reads_model``: whether the backend calls a model and so reads the model
    settings it is given (``llm_config``; the command line's ``--base-url``, ``--model``, ``--api-key``); a
    command refuses those options for a backend that does not. The calling module (``__main__`` too) is part of a
    run's code identity (:func:`scenario_bank.plugins.remember_code`); the workers need nothing of it."""
    _DRA_REGISTRY.register(name, StageBackend(backend, reads_model), overwrite=overwrite)
    remember_code(f"DRA backend {name!r}", registering_module())


def register_sg(name: str, backend: SGBackend, overwrite: bool = False, *, reads_model: bool = True) -> None:
    """Make ``generate(description, backend=name)`` call
    ``backend(description, seed=..., llm_config=..., max_attempts=...)`` (see :data:`SGBackend`);
    the script of the :class:`Generation` it returns must pass the safety check. ``overwrite`` and
    ``reads_model`` and the calling module: as for :func:`register_dra`."""
    _SG_REGISTRY.register(name, StageBackend(backend, reads_model), overwrite=overwrite)
    remember_code(f"SG backend {name!r}", registering_module())


def reads_model(stage: str, name: str) -> bool:
    """Whether the ``stage`` (``"DRA"`` or ``"SG"``) backend ``name`` reads model settings: registered with
    ``reads_model`` true (the default, so a plug-in's backend is given them), or a name not registered."""
    entry = {"DRA": _DRA_REGISTRY, "SG": _SG_REGISTRY}[stage].get(name, None)
    return entry is None or entry.reads_model


def registered_dras() -> List[str]:
    """The DRA backend names :func:`describe` knows, sorted."""
    return sorted(_DRA_REGISTRY)


def registered_sgs() -> List[str]:
    """The SG backend names :func:`generate` knows, sorted."""
    return sorted(_SG_REGISTRY)


def _describe_bev(clip: Any, *, camera: str, question: Optional[str],
                  llm_config: LLMConfigLike) -> Tuple[str, Dict[str, Any]]:
    from dv2s_gym.pipeline.dra.bev import analyze_bev

    return analyze_bev(clip, question=question).description, {}


def _describe_openai(clip: Any, *, camera: str, question: Optional[str],
                     llm_config: LLMConfigLike) -> Tuple[str, Dict[str, Any]]:
    from dv2s_gym.pipeline.dra.openai import describe_with_vlm
    from dv2s_gym.pipeline.llm_client import ChatClient

    client = ChatClient.from_config(llm_config, kind="vlm")
    return describe_with_vlm(clip.frames, client, camera=camera, question=question)


def _generate_rules(description: str, *, seed: int, llm_config: LLMConfigLike,
                    max_attempts: int) -> Generation:
    from dv2s_gym.pipeline.sg.rules import generate_rules

    result = generate_rules(description, seed=seed)
    return Generation(result.script, "rules", warnings=list(result.warnings),
                      context_hash=getattr(result, "context_hash", None),
                      intended_elements=result.elements)


def _generate_openai(description: str, *, seed: int, llm_config: LLMConfigLike,
                     max_attempts: int) -> Generation:
    from dv2s_gym.pipeline.llm_client import ChatClient
    from dv2s_gym.pipeline.sg.openai import generate_with_llm
    client = ChatClient.from_config(llm_config)
    result = generate_with_llm(description, client, bank=Bank(), max_attempts=max_attempts)
    return Generation(result.script, "openai", failures=list(result.failures),
                      attempts=result.attempts, model=result.model, context_hash=result.context_hash)


register_dra("bev", _describe_bev, reads_model=False)
register_dra("openai", _describe_openai)
register_sg("rules", _generate_rules, reads_model=False)
register_sg("openai", _generate_openai)
_DRA_REGISTRY.mark_built_in()
_SG_REGISTRY.mark_built_in()

DRA_BACKENDS: Tuple[str, ...] = tuple(_DRA_REGISTRY)
"""The Driving Record Analyzer backends that ship with dv2s-gym, in the order registered above (the order
``--help`` lists them in)."""
SG_BACKENDS: Tuple[str, ...] = tuple(_SG_REGISTRY)
"""The Scenario Generator backends that ship with dv2s-gym, in the order registered above."""


# --------------------------------------------------------------------------- the stages
def describe(
    video: str | os.PathLike,
    *,
    backend: str = "bev",
    camera: str = "bev",
    question: Optional[str] = None,
    fps: float = 2.0,
    max_frames: int = 16,
    max_pixels: int = 448 * 448,
    llm_config: LLMConfigLike = None,
) -> Description:
    """Describe a driving video (frames sampled at ``fps`` under ``max_frames`` and ``max_pixels``)."""
    from dv2s_gym.pipeline.semantics.text import elements_from_text
    from dv2s_gym.pipeline.video import read_video

    call = _DRA_REGISTRY.get(backend).call
    clip = read_video(video, fps=fps, max_frames=max_frames, max_pixels=max_pixels)
    text, provenance = _description_of(backend, call(clip, camera=camera, question=question, llm_config=llm_config))
    return Description(text, elements_from_text(text), backend, model=provenance.get("model"),
                       prompt_hash=provenance.get("prompt_hash"), video=str(video))


def generate(
    description: str,
    *,
    backend: str = "rules",
    seed: int = 0,
    llm_config: LLMConfigLike = None,
    max_attempts: int = 4,
) -> Generation:
    """Turn a description into a Scenic script that passed the safety check."""
    call = _SG_REGISTRY.get(backend).call
    generation = call(description, seed=seed, llm_config=llm_config, max_attempts=max_attempts)
    if not isinstance(generation, Generation) or not isinstance(generation.script, str):
        got = (f"a Generation whose script is {_kind(generation.script)}" if isinstance(generation, Generation)
               else _kind(generation))
        raise BackendResultError(f"SG backend {backend!r} returned {got}; an SG backend returns a "
                                 "dv2s_gym.pipeline.stages.Generation whose script is the Scenic text (a str)")
    assert_safe(generation.script, "generated script")
    return generation


def _description_of(backend: str, returned: Any) -> Tuple[str, Mapping[str, Any]]:
    """A DRA backend's ``(text, provenance)``; :class:`BackendResultError` naming the backend for any other shape."""
    if (isinstance(returned, (tuple, list)) and len(returned) == 2 and isinstance(returned[0], str)
            and isinstance(returned[1], Mapping)):
        return returned[0], returned[1]
    got = (f"({_kind(returned[0])}, {_kind(returned[1])})"
           if isinstance(returned, (tuple, list)) and len(returned) == 2 else _kind(returned))
    raise BackendResultError(f"DRA backend {backend!r} returned {got}; a DRA backend returns a pair (text, "
                             "provenance): the description as a str and a dict, which may name 'model' and "
                             "'prompt_hash' (or is empty)")


def _kind(value: Any) -> str:
    """How an error names a value a backend returned: its type, and its length when it is a tuple or list."""
    if isinstance(value, (tuple, list)):
        return f"a {type(value).__name__} of {len(value)} items"
    return "None" if value is None else f"a {type(value).__name__}"
