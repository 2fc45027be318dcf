"""Samplers are records in one registry: what make_sampler builds, what options it checks, what feedback and
schedule a run gives it, how the failure-rate estimate weighs its scenes, and what ``--sampler`` accepts."""

from __future__ import annotations

import pytest

from dv2s_gym.cli import build_parser
from dv2s_gym.mining.sampling import samplers
from dv2s_gym.mining.errors import MiningError
from dv2s_gym.mining.sampling.rate import failure_rate
from dv2s_gym.mining.sampling.samplers import (SAMPLER_OPTIONS, SAMPLERS, SamplerRecord, default_feedback, is_adaptive,
                                      is_uniform, make_sampler, register_sampler, registered_samplers, sampler_params)
from dv2s_gym.mining.settings import MineSettings
from dv2s_gym.mining.sampling.space import SceneSpace
from scenario_bank.records import EpisodeRecord


@pytest.fixture
def registry(monkeypatch):
    """The registry as shipped, restored after the test."""
    monkeypatch.setattr(samplers, "_REGISTRY", samplers._REGISTRY.copy())


def test_the_shipped_samplers_and_what_each_record_says():
    assert SAMPLERS == ("random", "halton", "cross-entropy", "bandit", "split", "novelty-bandit")
    assert registered_samplers() == list(SAMPLERS)
    assert [name for name in SAMPLERS if is_uniform(name)] == ["random", "halton"]
    assert [name for name in SAMPLERS if is_adaptive(name)] == ["cross-entropy", "bandit", "split", "novelty-bandit"]
    assert {name: default_feedback(name) for name in ("halton", "split", "novelty-bandit", "nope")} == {
        "halton": "robustness", "split": "novelty", "novelty-bandit": "state-novelty", "nope": "robustness"}
    assert set(SAMPLER_OPTIONS) == {"cross-entropy", "bandit", "split", "novelty-bandit"}


def test_a_registered_sampler_is_built_checked_and_accepted_everywhere(registry):
    built = []

    def build(space, feature_space, params):
        built.append(params)
        return samplers._REGISTRY["halton"].build(space, feature_space, None)

    register_sampler("sweep", SamplerRecord(build, lambda options: {"step": float(options.get("step", 1))},
                                            ("step",), default_feedback="novelty", adaptive=False, uniform=True))
    space = SceneSpace(["highway_lead_vehicle_brakes"])
    sampler = make_sampler("sweep", space, 3, {"step": 2})
    assert built == [{"step": 2.0}] and len(sampler.draw(4)) == 4
    assert sampler_params("sweep", None) == {"step": 1.0}
    with pytest.raises(MiningError, match=r"sampler 'sweep' has no option 'alpha'; it takes step"):
        sampler_params("sweep", {"alpha": 0.5})
    assert is_uniform("sweep") and not is_adaptive("sweep") and default_feedback("sweep") == "novelty"
    assert MineSettings(sampler="sweep").feedback == "novelty"
    # its scenes weigh 1 in the failure-rate estimate without a proposal recorded, as a uniform sampler's do
    records = [EpisodeRecord(index=i, scenario="s", seed=i, failure={"type": "collision"} if i < 2 else None)
               for i in range(4)]
    assert failure_rate(records, sampler="sweep") == failure_rate(records, sampler="random")
    assert failure_rate(records, sampler="sweep").available and not failure_rate(records, sampler="bandit").available
    assert build_parser().parse_args(["mine", "--policy", "rule", "--sampler", "sweep"]).sampler == "sweep"
    # a uniform sampler's draws carry the uniform proposal density, read off the record, not the name
    assert sampler.proposal(0) == {"scenario": 1.0, "coords": [1.0] * len(space.feature_space.featureNamed["u"]
                                                                         .domain.intervals),
                                   "floor": 1.0, "floors": [1.0] * len(space.feature_space.featureNamed["u"]
                                                                        .domain.intervals)}


def test_a_registered_sampler_s_density_is_its_records(registry):
    """``SamplerRecord.density`` tells the proposal density of a plug-in sampler; without it (and not uniform) there
    is none, and ``density`` wins over ``uniform``."""
    halton = samplers._REGISTRY["halton"].build
    seen = []

    def density(sampler, point):
        seen.append(point)
        return {"scenario": 0.25, "coords": [2.0], "floor": 0.5, "floors": [0.5]}

    register_sampler("told", SamplerRecord(halton, density=density, uniform=True))
    register_sampler("untold", SamplerRecord(halton))
    space = SceneSpace(["highway_lead_vehicle_brakes"])
    told, untold = make_sampler("told", space, 1), make_sampler("untold", space, 1)
    (point, _), = told.draw(1)
    untold.draw(1)
    assert told.proposal(0) == {"scenario": 0.25, "coords": [2.0], "floor": 0.5, "floors": [0.5]} and seen == [point]
    assert untold.proposal(0) is None and samplers.proposal_density("nope", None, point) is None


def test_an_unknown_or_taken_sampler_name_is_refused(registry):
    with pytest.raises(MiningError, match="unknown sampler 'haltn': use one of random, halton, cross-entropy"):
        make_sampler("haltn", SceneSpace(["highway_lead_vehicle_brakes"]), 0)
    with pytest.raises(MiningError, match="a sampler named 'halton' is already registered; pass overwrite=True"):
        register_sampler("halton", samplers._REGISTRY["random"])
    with pytest.raises(MiningError, match="sampler name '' must be a non-empty string"):
        register_sampler("", samplers._REGISTRY["random"])


def test_a_built_sampler_without_the_methods_the_miner_calls_is_refused_naming_them(registry):
    class NextSampleOnly:  # the name VerifAI's samplers do not use
        def nextSample(self):
            return None

        def update(self, point, info, rho):
            pass

    class Neither:
        pass

    space = SceneSpace(["highway_lead_vehicle_brakes"])
    register_sampler("next-only", SamplerRecord(lambda space, feature_space, params: NextSampleOnly()))
    with pytest.raises(MiningError) as error:
        make_sampler("next-only", space, 0)
    assert str(error.value) == (
        "sampler 'next-only' built a NextSampleOnly without getSample() -> (point, info), which the miner calls: "
        "the object its build returns needs both, getSample() -> (point, info) and update(point, info, rho), as "
        "VerifAI's samplers have them (SamplerRecord.build says what each does)")
    register_sampler("neither", SamplerRecord(lambda space, feature_space, params: Neither()))
    with pytest.raises(MiningError, match=r"^sampler 'neither' built a Neither without getSample\(\) -> \(point, "
                                          r"info\) and update\(point, info, rho\), which the miner calls: "):
        make_sampler("neither", space, 0)
