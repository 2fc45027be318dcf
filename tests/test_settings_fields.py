"""Every field of every settings dataclass refuses bad values with the class's own error, naming the field (as
its command-line flag where it has one) and the bad value; and the shared checks they are built of."""

from __future__ import annotations

import dataclasses
import math

import pytest

from dv2s_gym.mining.conversion.settings import ConversionSettings
from dv2s_gym.mining.errors import MiningError
from dv2s_gym.loop.settings import LoopError, LoopSettings
from dv2s_gym.mining.settings import MineSettings
from dv2s_gym.regress.errors import RegressError
from dv2s_gym.regress.settings import RegressSettings
from dv2s_gym.workers.errors import WorkerError
from dv2s_gym.workers.settings import WorkerSettings
from policies.dagger_config import DaggerConfig
from policies.training import TrainConfig, TrainingError
from scenario_bank.errors import DV2SError
from scenario_bank.field_checks import check_int, check_names, check_number

NAN, INF = float("nan"), float("inf")
COUNT_FROM_1 = [0, -1, 1.5, True, "3", None]
COUNT_FROM_0 = [-1, 2.5, False, "3", None]
OPTIONAL_COUNT_FROM_1 = [-1, 1.5, True, "3"]
OPTIONAL_COUNT_FROM_0 = [-1, 1.5, True, "3"]
SEED = [-1, 1.5, True, "0", None]
POSITIVE = [0, -1.0, NAN, INF, True, "1", None]
SHARE_CLOSED = [-0.1, 1.5, NAN, INF, True, "0.5", None]  # [0, 1]
SHARE_OPEN = [0, 1, -0.1, NAN, True, "0.5", None]  # (0, 1)
MARGIN = [1, 1.5, -0.1, NAN, INF, True, "0.02", None]  # [0, 1)
NAMES = [0, [1], ["a", None], {"a": 1}]
MAPPING = [0, "x", [1], {1: 2}]
PATH = [0, "", ["a"]]
BOOL = ["yes", 1, 0, None]

BASE = {TrainConfig: {"out": "run"}}
ERRORS = {MineSettings: MiningError, ConversionSettings: MiningError, LoopSettings: LoopError, RegressSettings: RegressError,
          WorkerSettings: WorkerError, DaggerConfig: TrainingError, TrainConfig: TrainingError}

# class -> field -> (what the message names, bad values)
BAD = {
    MineSettings: {
        "budget": ("--budget", COUNT_FROM_1),
        "sampler": ("sampler", ["x", 0, None]),
        "sampler_options": ("--sampler-options", MAPPING),
        "feedback": ("feedback", ["curious", 0, ["novelty"]]),
        "scenarios": ("--scenarios", NAMES),
        "bank_dir": ("--bank", PATH),
        "seed": ("--seed", SEED),
        "reference": ("--reference", [0, "", ["rule"]]),
        "batch": ("--batch", [-1, 1.5, True, "4"]),
        "env_config": ("--config", MAPPING),
        "ttc_threshold": ("--ttc-threshold", POSITIVE),
        "stall_seconds": ("--stall-seconds", POSITIVE),
        "convert": ("convert", BOOL),
        "conversion": ("conversion", MAPPING + [None]),
        "max_conversions": ("--max-conversions", OPTIONAL_COUNT_FROM_0),
    },
    ConversionSettings: {
        "policy": ("conversion policy", ["", " "]),
        "dra": ("conversion dra", ["", 0, None]),
        "sg": ("conversion sg", ["", 0, None]),
        "llm_config": ("llm_config", []),  # its keys are the LLM client's to check (LLMConfigError)
        "k": ("conversion k", [-1, 1.5, True, "3", None]),
        "threshold": ("conversion threshold", [NAN, INF, True, "0.3", None]),
        "seed": ("conversion seed", SEED),
        "env_config": ("conversion env_config", MAPPING),
        "bank_dir": ("conversion bank_dir", PATH),
        "monitor": ("conversion monitor", MAPPING + [{"ttc_threshold": "x"}]),
        "before": ("conversion before", [-1.0, NAN, True, "4", None]),
        "after": ("conversion after", [-1.0, NAN, True, "1", None]),
        "reference": ("conversion reference", ["", " "]),
        "describe_events": ("conversion describe_events", BOOL),
    },
    LoopSettings: {
        "rounds": ("--rounds", COUNT_FROM_1),
        "bank_dir": ("--bank", PATH),
        "scenarios": ("--scenarios", NAMES),
        "budget": ("--budget", COUNT_FROM_1),
        "sampler": ("--sampler", ["x", 0, None]),
        "max_conversions": ("--max-conversions", OPTIONAL_COUNT_FROM_0),
        "max_replays": ("--max-replays", OPTIONAL_COUNT_FROM_0),
        "holdout_fraction": ("--holdout-fraction", SHARE_CLOSED),
        "fine_tune_method": ("--fine-tune-method", ["sgd", 0, None]),
        "fine_tune_steps": ("--fine-tune-steps", COUNT_FROM_1),
        "fine_tune_lr": ("--fine-tune-lr", [0, -1e-4, NAN, INF, True, "1e-4"]),
        "fine_tune_reward": ("--fine-tune-reward", [0, "x", [1], {"standing": "x"}, {"standing": NAN}]),
        "mined_share": ("--mined-share", SHARE_OPEN),
        "dagger_beta_decay": ("--dagger-beta-decay", SHARE_CLOSED),
        "control": ("control", BOOL),
        "k_eval": ("--k-eval", COUNT_FROM_1),
        "min_heldout_episodes": ("--min-heldout-episodes", COUNT_FROM_0),
        "min_heldout_families": ("--min-heldout-families", COUNT_FROM_0),
        "untouched_seeds": ("--untouched-seeds", COUNT_FROM_0),
        "regress_episodes": ("--regress-episodes", COUNT_FROM_1),
        "margin": ("--margin", MARGIN),
        "seed": ("--seed", SEED),
        "workers": ("--workers", OPTIONAL_COUNT_FROM_0),
        "n_envs": ("--envs", COUNT_FROM_1),
    },
    RegressSettings: {
        "scenarios": ("--scenarios", NAMES),
        "bank_dir": ("--bank", PATH),
        "episodes": ("--episodes", OPTIONAL_COUNT_FROM_1 + [0]),
        "seed": ("--seed", SEED),
        "margin": ("--margin", MARGIN),
        "alpha": ("--alpha", SHARE_OPEN),
        "mde": ("--mde", [0, 1, NAN, True, "0.3"]),
        "power": ("--power", [0, 1, NAN, True, "0.8"]),
        "sequential": ("--sequential", BOOL),
        "batch": ("--batch", OPTIONAL_COUNT_FROM_1 + [0]),
        "env_config": ("--config", MAPPING),
        "failure": ("--failure", [0, "crash", [1], "", []]),
        "stall_seconds": ("--stall-seconds", POSITIVE),
    },
    WorkerSettings: {
        "backend": ("--backend", ["x", 0, None]),
        "workers": ("--workers", OPTIONAL_COUNT_FROM_1),
        "address": ("--address", [0, "", ["a"]]),
        "timeout": ("--timeout", [0, -1, NAN, INF, True, "5"]),
    },
    DaggerConfig: {
        "iterations": ("DAgger iterations", COUNT_FROM_1),
        "beta": ("DAgger beta", SHARE_CLOSED),
        "beta_decay": ("DAgger beta_decay", SHARE_CLOSED),
        "epochs": ("DAgger epochs", COUNT_FROM_0),
        "batch_size": ("DAgger batch_size", COUNT_FROM_1),
        "learning_rate": ("DAgger learning_rate", [0, -1e-3, NAN, INF, True, "1e-3", None]),
        "reference": ("DAgger reference", [-1, 0, "", None]),
        "slower_weight": ("DAgger slower_weight", POSITIVE),
        "disagreement_weight": ("DAgger disagreement_weight", POSITIVE),
        "checkpoint_every": ("DAgger checkpoint_every", COUNT_FROM_0),
    },
    TrainConfig: {
        "out": ("--out", PATH + [None]),
        "algo": ("--algo", ["a2c", 0, None]),
        "scenarios": ("--scenarios", NAMES),
        "bank_dir": ("--bank", PATH),
        "steps": ("--steps", COUNT_FROM_1),
        "n_envs": ("--envs", COUNT_FROM_1),
        "seed": ("--seed", SEED),
        "sampler": ("--sampler", ["x", 0, None]),
        "weights": ("--weights", MAPPING + [{"a": -1.0}, {"a": NAN}, {"a": "1"}]),
        "curriculum_floor": ("--curriculum-floor", SHARE_CLOSED),
        "curriculum_window": ("--curriculum-window", COUNT_FROM_1),
        "curriculum_update": ("--curriculum-update", COUNT_FROM_1),
        "env_config": ("--config", MAPPING),
        "hyperparameters": ("--hp", MAPPING + [None]),
        "eval_freq": ("--eval-freq", COUNT_FROM_0),
        "eval_seeds": ("--eval-seeds", COUNT_FROM_0),
        "card_seeds": ("--card-seeds", OPTIONAL_COUNT_FROM_0),
        "baselines": ("--baselines", NAMES + [None]),
        "eval_jobs": ("--eval-jobs", COUNT_FROM_1),
        "checkpoint_freq": ("--checkpoint-freq", COUNT_FROM_0),
        "keep_checkpoints": ("--keep-checkpoints", COUNT_FROM_1),
        "progress_bar": ("--no-progress", BOOL),
        "vec_env": ("--vec-env", ["fork", 0, None]),
        "learning_rate": ("learning_rate", [0, -1.0, NAN, INF, True, "1e-4"]),
        "reward_weights": ("reward_weights", MAPPING),
    },
}

CASES = [pytest.param(cls, field, named, value, id=f"{cls.__name__}.{field}={value!r}")
         for cls, fields in BAD.items() for field, (named, values) in fields.items() for value in values]


def test_every_field_of_every_settings_class_has_bad_values_here():
    for cls, fields in BAD.items():
        assert sorted(fields) == sorted(field.name for field in dataclasses.fields(cls)), cls.__name__


@pytest.mark.parametrize("cls, field, named, value", CASES)
def test_a_bad_value_is_refused_naming_the_field_and_the_value(cls, field, named, value):
    with pytest.raises(ERRORS[cls]) as caught:
        cls(**{**BASE.get(cls, {}), field: value})
    message = str(caught.value)
    assert named in message
    if field not in ("failure", "sampler", "feedback"):  # these name the unknown kind, or the value's type fails
        shown = [repr(value)] + ([f"{key!r} must be a {what}, not {item!r}" for key, item in value.items()
                                  for what in ("finite number", "number >= 0")] if isinstance(value, dict) else [])
        assert any(text in message for text in shown) or (isinstance(value, list) and "is not a name" in message), \
            message


@pytest.mark.parametrize("cls", list(BAD))
def test_the_defaults_and_the_edges_of_each_range_stay_valid(cls):
    base = BASE.get(cls, {})
    cls(**base)
    edges = {MineSettings: dict(budget=1, seed=0, batch=0, max_conversions=0, reference=None, feedback="novelty",
                                scenarios="one", env_config=None, ttc_threshold=0.5, stall_seconds=1),
             LoopSettings: dict(margin=0, holdout_fraction=1.0, seed=0, workers=0, max_replays=None,
                                fine_tune_reward={}, min_heldout_episodes=0),
             RegressSettings: dict(margin=0.0, episodes=1, batch=1, failure=["stall"], mde=0.5, power=0.9,
                                   env_config={}, scenarios=("a", "tag:b")),
             ConversionSettings: dict(policy="keep_lane", k=0, threshold=2.0, seed=0, env_config={}, bank_dir="b",
                                      monitor={"ttc_threshold": 1.0}, before=0, after=0, reference=None,
                                      describe_events=False),
             WorkerSettings: dict(backend="ray", workers=1, address="auto", timeout=0.5),
             DaggerConfig: dict(beta=0, beta_decay=1, epochs=0, checkpoint_every=0, slower_weight=1,
                                disagreement_weight=1),
             TrainConfig: dict(card_seeds=0, eval_freq=0, eval_seeds=0, curriculum_floor=1, baselines=[],
                               env_config=None, weights={"a": 0}, sampler="weighted", seed=0)}
    settings = cls(**{**base, **edges[cls]})
    for name, value in edges[cls].items():
        if name not in ("scenarios", "env_config", "batch", "failure", "workers", "fine_tune_reward", "monitor"):
            assert getattr(settings, name) == value, name


def test_the_settings_normalise_what_they_accept():
    assert MineSettings(scenarios="one").scenarios == ("one",)  # one name, not its letters
    assert RegressSettings(scenarios=["a", "b"]).scenarios == ("a", "b")
    assert WorkerSettings(workers=0).workers is None  # 0 reads as every core, as the miner reads it
    assert MineSettings(batch=0).batch is None


def test_the_shared_checks_name_the_field_the_value_and_what_is_allowed():
    class Bad(DV2SError):
        pass

    with pytest.raises(Bad, match=r"^--budget must be an integer >= 1, not 0$"):
        check_int(Bad, "--budget", 0, low=1)
    with pytest.raises(Bad, match=r"^--n must be an integer in \[2, 3\] or left out \(all\), not 4$"):
        check_int(Bad, "--n", 4, low=2, high=3, optional=True, none_means="all")
    with pytest.raises(Bad, match=r"^--margin must be a number in \[0, 1\), e\.g\. 0\.05, not 1$"):
        check_number(Bad, "--margin", 1, low=0, high=1, interval="[)", example="e.g. 0.05")
    with pytest.raises(Bad, match=r"^--t must be a positive number, not nan$"):
        check_number(Bad, "--t", NAN, low=0, interval="(]")
    with pytest.raises(Bad, match=r"--s must be a list of names or left out; 3 in \['a', 3\] is not a name"):
        check_names(Bad, "--s", ["a", 3])
    assert check_number(Bad, "--x", 0.5, low=0, high=1, interval="()") == 0.5
    assert check_int(Bad, "--x", None, optional=True) is None
    assert math.isclose(check_number(Bad, "--x", 1e-9, low=0, interval="(]"), 1e-9)
    with pytest.raises(ValueError, match="interval must be one of"):
        check_number(Bad, "--x", 0.5, interval="<>")
