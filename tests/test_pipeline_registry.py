"""The stages pick their backends by name from a registry: the shipped ones, and any registered later."""

import pytest

from dv2s_gym.pipeline import stages
from dv2s_gym.pipeline.errors import BackendResultError, PipelineError, UnknownBackendError
from dv2s_gym.pipeline.evaluate import EVALSET_DIR
from dv2s_gym.pipeline.semantics.text import elements_from_text
from scenario_bank.errors import DV2SError
from scenario_bank.safety import UnsafeScenarioError

CLIP = EVALSET_DIR / "highway_lead_vehicle_brakes_seed0.webm"


@pytest.fixture
def registries(monkeypatch):
    """The registries as shipped, restored after the test."""
    monkeypatch.setattr(stages, "_DRA_REGISTRY", stages._DRA_REGISTRY.copy())
    monkeypatch.setattr(stages, "_SG_REGISTRY", stages._SG_REGISTRY.copy())


def test_the_shipped_backends_are_registered():
    assert stages.registered_dras() == sorted(stages.DRA_BACKENDS) == ["bev", "openai"]
    assert stages.registered_sgs() == sorted(stages.SG_BACKENDS) == ["openai", "rules"]


def test_an_unknown_backend_names_the_known_ones():
    with pytest.raises(UnknownBackendError, match=r"^unknown DRA backend 'bevv'; use one of \('bev', 'openai'\)$"):
        stages.describe(CLIP, backend="bevv")
    with pytest.raises(UnknownBackendError, match=r"^unknown SG backend 'rule'; use one of \('rules', 'openai'\)$"):
        stages.generate("A car brakes ahead of the ego.", backend="rule")


def test_an_unknown_backend_is_a_project_error_the_command_line_reports():
    with pytest.raises(DV2SError) as raised:
        stages.describe(CLIP, backend="bevv")
    assert isinstance(raised.value, PipelineError) and isinstance(raised.value, ValueError)


@pytest.mark.parametrize("returned, got", [
    (("a car brakes", {}, "extra"), "a tuple of 3 items"),
    ("a car brakes", "a str"),
    (None, "None"),
    ((b"a car brakes", {}), r"\(a bytes, a dict\)"),
    (("a car brakes", None), r"\(a str, None\)"),
])
def test_a_dra_backend_returning_the_wrong_shape_is_named(registries, returned, got):
    stages.register_dra("broken", lambda clip, **options: returned)
    with pytest.raises(BackendResultError, match=rf"^DRA backend 'broken' returned {got}; a DRA backend returns a "
                                                 r"pair \(text, provenance\): the description as a str and a dict"):
        stages.describe(CLIP, backend="broken", max_frames=2)


@pytest.mark.parametrize("returned, got", [
    ("param x = 1\n", "a str"),
    (("param x = 1\n", []), "a tuple of 2 items"),
    (stages.Generation(None, "broken"), "a Generation whose script is None"),
])
def test_an_sg_backend_returning_the_wrong_shape_is_named(registries, returned, got):
    stages.register_sg("broken", lambda description, **options: returned)
    with pytest.raises(BackendResultError, match=rf"^SG backend 'broken' returned {got}; an SG backend returns a "
                                                 r"dv2s_gym.pipeline.stages.Generation whose script"):
        stages.generate("anything", backend="broken")


def test_a_registered_dra_backend_describes_and_its_text_gives_the_elements(registries):
    text = "A car ahead of the ego brakes on a highway."
    calls = []

    def fixed(clip, *, camera, question, llm_config):
        calls.append((len(clip.frames), camera, question, llm_config))
        return text, {"model": "fixed-1", "prompt_hash": "abc"}

    stages.register_dra("fixed", fixed)
    description = stages.describe(CLIP, backend="fixed", camera="front", question="why?", llm_config={"k": 1},
                                  max_frames=4)
    assert calls == [(4, "front", "why?", {"k": 1})]
    assert (description.text, description.backend, description.model, description.prompt_hash,
            description.video) == (text, "fixed", "fixed-1", "abc", str(CLIP))
    assert description.elements == elements_from_text(text) and description.elements.road == "highway"
    with pytest.raises(UnknownBackendError, match=r"use one of \('bev', 'openai', 'fixed'\)"):
        stages.describe(CLIP, backend="nope")


def test_a_registered_sg_backend_generates_and_its_script_is_checked(registries):
    script = "param map = 'highway_straight'\nmodel scenic.domains.driving.model\nego = new Car\n"
    stages.register_sg("fixed", lambda description, *, seed, llm_config, max_attempts:
                       stages.Generation(script, "fixed", attempts=max_attempts))
    generation = stages.generate("anything", backend="fixed", max_attempts=2)
    assert (generation.script, generation.backend, generation.attempts) == (script, "fixed", 2)

    stages.register_sg("unsafe", lambda description, **options: stages.Generation(script + "import os\n", "unsafe"))
    with pytest.raises(UnsafeScenarioError, match="import"):
        stages.generate("anything", backend="unsafe")


def test_registering_a_taken_or_empty_name_is_refused(registries):
    with pytest.raises(PipelineError, match="a DRA backend named 'bev' is already registered; pass overwrite=True"):
        stages.register_dra("bev", lambda clip, **options: ("", {}))
    with pytest.raises(PipelineError, match="SG backend name '' must be a non-empty string"):
        stages.register_sg("", lambda description, **options: None)
    replacement = lambda description, **options: stages.Generation("", "rules")  # noqa: E731
    stages.register_sg("rules", replacement, overwrite=True)
    assert stages._SG_REGISTRY["rules"].call is replacement
