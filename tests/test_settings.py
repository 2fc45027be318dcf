"""The run settings objects: one place for each default (the command line reads it), checked on construction."""

from __future__ import annotations

import argparse
import dataclasses

import pytest

from dv2s_gym.cli.parser import Parser
from dv2s_gym.mining.errors import MiningError
from dv2s_gym.cli.loop import loop_settings
from dv2s_gym.loop.settings import DEFAULTS, EVIDENCE, LoopError, LoopSettings
from dv2s_gym.mining.settings import MineSettings
from dv2s_gym.regress.errors import RegressError
from dv2s_gym.regress.settings import RegressSettings
from policies.dagger_config import DAGGER_DEFAULTS, DaggerConfig
from policies.training import TrainConfig, TrainingError


def _defaults(command: str) -> dict:
    from dv2s_gym.cli import loop, mine

    parser = Parser(prog="dv2s")
    sub = parser.add_subparsers()
    {"mine": mine, "loop": loop}[command].add_parser(sub)
    args = parser.parse_args([command] + (["--policy", "rule"] if command == "mine" else []))
    return vars(args)


def test_the_command_line_defaults_are_the_settings_defaults():
    mine, loop = _defaults("mine"), _defaults("loop")
    settings = MineSettings()
    for key in ("budget", "sampler", "seed", "reference", "ttc_threshold", "stall_seconds", "batch", "max_conversions"):
        assert mine[key] == getattr(settings, key), key
    assert loop["profile"] == "quick" and loop_settings(argparse.Namespace(**loop)) == LoopSettings()
    for key in ("rounds", "budget", "sampler", "fine_tune_steps", "holdout_fraction", "k_eval", "min_heldout_episodes",
                "min_heldout_families", "untouched_seeds", "regress_episodes", "mined_share", "fine_tune_method",
                "margin", "seed", "max_conversions", "max_replays"):
        assert DEFAULTS[key] == getattr(LoopSettings, key), key
    assert loop["envs"] == LoopSettings().n_envs and DAGGER_DEFAULTS["iterations"] == DaggerConfig().iterations


def _loop_args(*argv: str):
    from dv2s_gym.cli import loop

    parser = Parser(prog="dv2s")
    loop.add_parser(parser.add_subparsers())
    return loop_settings(parser.parse_args(["loop", *argv]))


def test_a_loop_profile_sets_the_defaults_and_explicit_options_override_it():
    evidence = _loop_args("--profile", "evidence")
    assert evidence == LoopSettings.evidence() == LoopSettings(**EVIDENCE) != LoopSettings()
    assert evidence.budget > LoopSettings().budget and evidence.k_eval > LoopSettings().k_eval
    given = _loop_args("--profile", "evidence", "--budget", "7", "--max-replays", "all", "--no-control")
    assert given == LoopSettings.evidence(budget=7, max_replays=None, control=False)
    assert (given.budget, given.max_replays, given.control, given.fine_tune_steps) == (
        7, None, False, EVIDENCE["fine_tune_steps"])
    assert _loop_args("--k-eval", "9") == LoopSettings(k_eval=9)
    with pytest.raises(LoopError, match="--profile must be one of quick, evidence, not 'huge'"):
        LoopSettings.from_profile("huge")


def test_settings_are_frozen_and_resolve_their_derived_defaults():
    settings = MineSettings(sampler="split", scenarios=["a"])
    assert settings.feedback == "novelty" and settings.scenarios == ("a",)
    with pytest.raises(dataclasses.FrozenInstanceError):
        settings.budget = 5  # type: ignore[misc]
    assert LoopSettings(fine_tune_method="ppo").fine_tune_lr == 1e-4
    assert LoopSettings(fine_tune_reward=None).fine_tune_reward == {"standing": -0.3}
    assert RegressSettings(failure="stall,collision").failure == ("collision", "stall")
    config = TrainConfig.fine_tuning("out", steps=10, weights={"a": 1.0})
    assert (config.sampler, config.eval_freq, config.card_seeds, config.baselines, config.env_config) == \
        ("weighted", 0, 0, [], None)
    for frozen in (LoopSettings(), RegressSettings(), DaggerConfig(), config):
        with pytest.raises(dataclasses.FrozenInstanceError):
            setattr(frozen, dataclasses.fields(frozen)[0].name, None)


@pytest.mark.parametrize("make, error, match", [
    (lambda: MineSettings(budget=0), MiningError, "--budget must be an integer >= 1"),
    (lambda: MineSettings(feedback="curious"), MiningError, "unknown feedback 'curious'"),
    (lambda: MineSettings(convert=True), MiningError, "pass --bank DIR"),
    (lambda: MineSettings(ttc_threshold=float("nan")), MiningError, "--ttc-threshold must be a positive number"),
    (lambda: MineSettings(stall_seconds=-5.0), MiningError, "--stall-seconds must be a positive number"),
    (lambda: MineSettings(stall_seconds="5"), MiningError, "--stall-seconds must be a positive number"),
    (lambda: LoopSettings(k_eval=0), LoopError, "--k-eval must be an integer >= 1"),
    (lambda: LoopSettings(mined_share=1.0), LoopError, r"--mined-share must be a number in \(0, 1\)"),
    (lambda: LoopSettings(max_replays=-1), LoopError, "--max-replays must be an integer >= 0"),
    (lambda: LoopSettings(margin=2.0), LoopError, r"--margin must be a number in \[0, 1\), a failure-rate difference"),
    (lambda: LoopSettings(margin=float("nan")), LoopError, "--margin must be a number in"),
    (lambda: LoopSettings(n_envs=0), LoopError, "--envs must be an integer >= 1"),
    (lambda: LoopSettings(workers=-3), LoopError, "--workers must be an integer >= 0"),
    (lambda: LoopSettings(seed="7"), LoopError, "--seed must be an integer"),
    (lambda: RegressSettings(margin=1.5), RegressError, r"--margin must be a number in \[0, 1\)"),
    (lambda: RegressSettings(stall_seconds=0), RegressError, "--stall-seconds must be a positive number"),
    (lambda: DaggerConfig(beta=2.0), TrainingError, r"DAgger beta must be a number in \[0, 1\], not 2.0"),
    (lambda: DaggerConfig(batch_size=0), TrainingError, "batch_size must be an integer >= 1"),
])
def test_bad_settings_are_refused_naming_the_setting(make, error, match):
    with pytest.raises(error, match=match):
        make()
