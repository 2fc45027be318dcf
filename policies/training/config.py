"""A training run's settings: :class:`TrainConfig` with its checks, the algorithms and samplers, the default
hyperparameters, the seeds of the model card's evaluation, and the error of bad training input."""

from __future__ import annotations

import dataclasses
import inspect
import json
import os
import shlex
from typing import Any, Dict, List, Mapping, Optional

import stable_baselines3 as sb3

from envs.dv2s_env import check_env_config
from envs.errors import DV2SError
from scenario_bank.field_checks import (check_bool, check_choice, check_int, check_mapping, check_names, check_number,
                                        check_path)

__all__ = [
    "ALGORITHMS",
    "SAMPLERS",
    "TRAIN_SEED_HIGH",
    "SHORT_RUN_STEPS",
    "CARD_SEEDS",
    "SHORT_RUN_CARD_SEEDS",
    "DEFAULT_HYPERPARAMETERS",
    "TrainingError",
    "TrainConfig",
    "known_hyperparameters",
    "FINE_TUNING_ONLY",
]


ALGORITHMS = ("ppo", "dqn", "sac")
SAMPLERS = ("uniform", "weighted", "curriculum")
TRAIN_SEED_HIGH = 2**31 - 1
#: Seeds per scenario of the model card's evaluation, and for runs shorter than SHORT_RUN_STEPS.
CARD_SEEDS = 20
SHORT_RUN_STEPS = 100_000
SHORT_RUN_CARD_SEEDS = 3

DEFAULT_HYPERPARAMETERS: Dict[str, Dict[str, Any]] = {
    # highway-env's documented PPO settings for highway (batch 64, 10 epochs, lr 5e-4), with a
    # longer horizon (gamma 0.95: 4 s at 5 Hz) because the bank's hazards need braking seconds ahead
    # (with gamma 0.9 a 400k-step run learned to floor it on every highway scenario), 512 steps per
    # env per rollout, and [128, 128] layers so the checkpoint stays under 2 MB.
    "ppo": {"policy": "MlpPolicy", "net_arch": [128, 128], "n_steps": 512, "batch_size": 64, "n_epochs": 10,
            "learning_rate": 5e-4, "gamma": 0.95, "gae_lambda": 0.95, "clip_range": 0.2, "ent_coef": 0.0},
    # highway-env's documented DQN settings for highway
    "dqn": {"policy": "MlpPolicy", "net_arch": [256, 256], "learning_rate": 5e-4, "buffer_size": 15_000,
            "learning_starts": 200, "batch_size": 32, "gamma": 0.8, "train_freq": 1, "gradient_steps": 1,
            "target_update_interval": 50, "exploration_fraction": 0.7},
    "sac": {"policy": "MlpPolicy", "net_arch": [256, 256], "learning_rate": 3e-4, "buffer_size": 50_000,
            "learning_starts": 1000, "batch_size": 256, "gamma": 0.9},
}

_ACTION_TYPES = {"ppo": None, "dqn": ("DiscreteMetaAction", "DiscreteAction"), "sac": ("ContinuousAction",)}


class TrainingError(DV2SError, ValueError):
    """Bad training input: names the problem and the fix."""


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """Everything a training run is made of (recorded in ``run.json`` and the model card).

    Args:
        out: the run folder.
        algo: ``ppo``, ``dqn`` or ``sac``.
        scenarios: bank names or ``tag:<tag>`` selectors; ``None`` is the whole bank.
        bank_dir: a bank folder other than the shipped one.
        steps: total env steps the model is trained to (across resumes).
        n_envs: environments in parallel worker processes.
        seed: seeds the model, the workers' scenario/seed streams and nothing else.
        sampler: ``uniform``, ``weighted`` (needs ``weights``) or ``curriculum``.
        weights: scenario -> weight for ``weighted`` (missing scenarios weigh 0).
        curriculum_floor / curriculum_window / curriculum_update: share of the uniform
            floor, episodes remembered per scenario, env steps between probability updates.
        env_config: DV2S-v0 config overrides (SAC gets ``ContinuousAction`` by default).
        hyperparameters: overrides of :data:`DEFAULT_HYPERPARAMETERS` (``net_arch`` goes to
            ``policy_kwargs``).
        eval_freq / eval_seeds: periodic held-out evaluation every ``eval_freq`` steps over
            ``eval_seeds`` seeds per scenario (0 turns it off).
        card_seeds / baselines / eval_jobs: the card's final evaluation: seeds per scenario
            (``None``: :data:`CARD_SEEDS` for runs of :data:`SHORT_RUN_STEPS` steps or more,
            :data:`SHORT_RUN_CARD_SEEDS` below, so a trial run is not followed by a long
            evaluation), baseline policies evaluated on the same episodes, parallel processes.
        checkpoint_freq / keep_checkpoints: checkpoint every that many steps, keep the newest.
        progress_bar: show a tqdm progress bar on stderr.
        vec_env: ``subproc`` (worker processes) or ``dummy`` (in this process).
        learning_rate: fine-tuning only (:func:`fine_tune`): a constant learning rate replacing the checkpoint's
            (``None``: the checkpoint's own). A training run takes its rate from ``hyperparameters``.
        reward_weights: fine-tuning only (:func:`fine_tune`): overrides of single reward terms of the env config
            (e.g. ``{"standing": -1.0}``; the other terms keep their weights).
    """

    out: str
    algo: str = "ppo"
    scenarios: Optional[List[str]] = None
    bank_dir: Optional[str] = None
    steps: int = 100_000
    n_envs: int = 2
    seed: int = 0
    sampler: str = "uniform"
    weights: Optional[Dict[str, float]] = None
    curriculum_floor: float = 0.25
    curriculum_window: int = 20
    curriculum_update: int = 1_000
    env_config: Dict[str, Any] = dataclasses.field(default_factory=dict)
    hyperparameters: Dict[str, Any] = dataclasses.field(default_factory=dict)
    eval_freq: int = 10_000
    eval_seeds: int = 2
    card_seeds: Optional[int] = None
    baselines: List[str] = dataclasses.field(default_factory=lambda: ["keep_lane", "rule"])
    eval_jobs: int = 2
    checkpoint_freq: int = 10_000
    keep_checkpoints: int = 3
    progress_bar: bool = True
    vec_env: str = "subproc"
    learning_rate: Optional[float] = None
    reward_weights: Optional[Dict[str, float]] = None

    # settings a resumed run must share with the run it continues
    IDENTITY = ("algo", "scenarios", "bank_dir", "seed", "sampler", "weights", "curriculum_floor",
                "curriculum_window", "env_config", "hyperparameters")

    def __post_init__(self) -> None:
        # each field's type and range, on construction (one line naming the flag); what needs the bank, the env
        # or the algorithm (the selection, the env config's keys, the hyperparameters) is :meth:`validate`'s
        check_path(TrainingError, "--out", self.out)
        check_choice(TrainingError, "--algo", self.algo, ALGORITHMS)
        if self.scenarios is not None:
            check_names(TrainingError, "--scenarios", self.scenarios)
        check_path(TrainingError, "--bank", self.bank_dir, optional=True)
        for flag, value, low in (("--steps", self.steps, 1), ("--envs", self.n_envs, 1), ("--seed", self.seed, 0),
                                 ("--curriculum-window", self.curriculum_window, 1),
                                 ("--curriculum-update", self.curriculum_update, 1),
                                 ("--eval-freq", self.eval_freq, 0), ("--eval-jobs", self.eval_jobs, 1),
                                 ("--checkpoint-freq", self.checkpoint_freq, 0),
                                 ("--keep-checkpoints", self.keep_checkpoints, 1)):
            check_int(TrainingError, flag, value, low=low)
        check_int(TrainingError, "--eval-seeds", self.eval_seeds, low=0)  # the 1000 cap: validate()'s, with its why
        check_int(TrainingError, "--card-seeds", self.card_seeds, low=0, optional=True,
                  none_means="the default for --steps")
        check_choice(TrainingError, "--sampler", self.sampler, SAMPLERS)
        check_mapping(TrainingError, "--weights", self.weights, optional=True,
                      what="a JSON object of scenario weights")
        for name, weight in (self.weights or {}).items():
            check_number(TrainingError, f"--weights {name!r}", weight, low=0)
        check_number(TrainingError, "--curriculum-floor", self.curriculum_floor, low=0, high=1)
        check_mapping(TrainingError, "--config", self.env_config, optional=True,  # None: a fine-tuning's source
                      what="a JSON object of DV2S-v0 config overrides")
        check_mapping(TrainingError, "--hp", self.hyperparameters, what="a JSON object of hyperparameters")
        check_names(TrainingError, "--baselines", self.baselines, optional=False)
        check_bool(TrainingError, "progress_bar (--no-progress)", self.progress_bar)
        check_choice(TrainingError, "--vec-env", self.vec_env, ("subproc", "dummy"))
        check_number(TrainingError, "learning_rate", self.learning_rate, low=0, interval="(]", optional=True,
                     example="e.g. 1e-4")
        check_mapping(TrainingError, "reward_weights", self.reward_weights, optional=True,
                      what="a JSON object of reward term weights")

    def validate(self) -> None:
        """Raise :class:`TrainingError` for settings that cannot train."""
        if self.algo not in ALGORITHMS:
            raise TrainingError(f"unknown algorithm {self.algo!r}; use one of {', '.join(ALGORITHMS)}")
        if self.scenarios is not None and not [s for s in self.scenarios if str(s).strip()]:
            raise TrainingError("the scenario selection is empty; name bank scenarios or tag:<tag> after "
                                "--scenarios, or leave --scenarios out to train on the whole bank")
        for name, value, low in (("steps", self.steps, 1), ("envs", self.n_envs, 1), ("eval-seeds", self.eval_seeds, 0),
                                 ("card-seeds", self.card_seed_count(), 0), ("eval-freq", self.eval_freq, 0),
                                 ("checkpoint-freq", self.checkpoint_freq, 0), ("eval-jobs", self.eval_jobs, 1),
                                 ("keep-checkpoints", self.keep_checkpoints, 1),
                                 ("curriculum-window", self.curriculum_window, 1),
                                 ("curriculum-update", self.curriculum_update, 1)):
            if not isinstance(value, int) or value < low:
                raise TrainingError(f"--{name} must be an integer >= {low}, not {value!r}")
        if self.eval_seeds > 1000 or self.card_seed_count() > 1000:
            raise TrainingError("at most 1000 evaluation seeds per scenario (seeds 10000..10999 are the held-out range)")
        if self.sampler not in SAMPLERS:
            raise TrainingError(f"unknown sampler {self.sampler!r}; use one of {', '.join(SAMPLERS)}")
        if self.sampler == "weighted" and not self.weights:
            raise TrainingError("--sampler weighted needs --weights '{\"scenario\": weight, ...}'")
        if not 0.0 <= self.curriculum_floor <= 1.0:
            raise TrainingError(f"the curriculum floor must be in [0, 1], not {self.curriculum_floor}")
        if self.vec_env not in ("subproc", "dummy"):
            raise TrainingError(f"vec_env must be 'subproc' or 'dummy', not {self.vec_env!r}")
        if not isinstance(self.env_config, dict):
            raise TrainingError("the env config must be a JSON object of DV2S-v0 config overrides")
        check_env_config(self.env_config)  # a misspelt key fails here, in one line, not in the env workers
        action = (self.env_config.get("action") or {}).get("type")
        allowed = _ACTION_TYPES[self.algo]
        if action is not None and allowed is not None and action not in allowed:
            raise TrainingError(f"{self.algo.upper()} needs a {' or '.join(allowed)} action space, not {action}; "
                                "change 'action' in --config or leave it out")
        unknown = set(self.hyperparameters) - known_hyperparameters(self.algo)
        if unknown:
            raise TrainingError(f"unknown {self.algo.upper()} hyperparameter(s) {', '.join(sorted(unknown))}; "
                                f"see stable-baselines3's {self.algo.upper()} arguments")

    def card_seed_count(self) -> int:
        """Seeds per scenario of the card's evaluation: ``card_seeds``, or the default for ``steps``."""
        if self.card_seeds is not None:
            return self.card_seeds
        return CARD_SEEDS if self.steps >= SHORT_RUN_STEPS else SHORT_RUN_CARD_SEEDS

    def effective_env_config(self) -> Dict[str, Any]:
        """The env config the policy trains on: ``env_config``, with ``ContinuousAction`` for SAC."""
        config = json.loads(json.dumps(self.env_config))
        if self.algo == "sac" and "action" not in config:
            config["action"] = {"type": "ContinuousAction"}
        return config

    def effective_hyperparameters(self) -> Dict[str, Any]:
        """Defaults of the algorithm updated with ``hyperparameters``."""
        merged = dict(DEFAULT_HYPERPARAMETERS[self.algo])
        merged.update(self.hyperparameters)
        return merged

    def command(self) -> str:
        """The ``dv2s train`` command line that makes this run."""
        default = TrainConfig(out=self.out)
        parts = ["dv2s", "train", "--algo", self.algo, "--steps", str(self.steps), "--envs", str(self.n_envs),
                 "--seed", str(self.seed)]
        if self.bank_dir:
            parts += ["--bank", self.bank_dir]
        if self.scenarios is not None:
            parts += ["--scenarios", *self.scenarios]
        if self.sampler != default.sampler:
            parts += ["--sampler", self.sampler]
        if self.weights:
            parts += ["--weights", json.dumps(self.weights, sort_keys=True)]
        if self.env_config:
            parts += ["--config", json.dumps(self.env_config, sort_keys=True)]
        for key in sorted(self.hyperparameters):
            parts += ["--hp", f"{key}={json.dumps(self.hyperparameters[key])}"]
        for flag, field in (("--eval-freq", "eval_freq"), ("--eval-seeds", "eval_seeds"), ("--card-seeds", "card_seeds"),
                            ("--checkpoint-freq", "checkpoint_freq"), ("--curriculum-floor", "curriculum_floor"),
                            ("--curriculum-window", "curriculum_window"), ("--curriculum-update", "curriculum_update")):
            if getattr(self, field) != getattr(default, field):
                parts += [flag, str(getattr(self, field))]
        if self.baselines != default.baselines:
            parts += ["--baselines", *self.baselines] if self.baselines else ["--baselines"]
        parts += ["--out", self.out]
        return shlex.join(parts)

    @classmethod
    def fine_tuning(cls, out: os.PathLike | str, *, steps: int, weights: Mapping[str, float],
                    **changes: Any) -> "TrainConfig":
        """The config of a fine-tuning (:func:`fine_tune`, :func:`policies.imitation.dagger_fine_tune`): ``steps``
        env steps on top of the checkpoint's, weighted sampling by ``weights``, the env config of the checkpoint's
        card (``env_config=None``), no periodic or card evaluation and no baselines, unless ``changes`` say
        otherwise (any other field: ``seed``, ``n_envs``, ``bank_dir``, ``scenarios``...)."""
        options = {**_FINE_TUNE_DEFAULTS, **changes}
        return cls(out=str(out), steps=steps, weights=dict(weights), sampler="weighted", **options)

    def to_json(self) -> Dict[str, Any]:
        """A JSON-safe dict of every field (the fine-tuning-only ones only when set)."""
        values = dataclasses.asdict(self)
        return {k: v for k, v in values.items() if not (k in FINE_TUNING_ONLY and v is None)}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> "TrainConfig":
        """Inverse of :meth:`to_json` (unknown keys are refused)."""
        fields = {f.name for f in dataclasses.fields(cls)}
        unknown = set(data) - fields
        if unknown:
            raise TrainingError(f"run settings name unknown field(s) {', '.join(sorted(unknown))}; "
                                "was the run made by a newer dv2s-gym?")
        return cls(**dict(data))


FINE_TUNING_ONLY = ("learning_rate", "reward_weights")
"""Fields only :func:`fine_tune` reads; it applies them (the rate saved in the first checkpoint, the reward terms
in the env config) and trains with them cleared, so :func:`train` refuses a config that sets them."""

_FINE_TUNE_DEFAULTS: Dict[str, Any] = {"env_config": None, "eval_freq": 0, "eval_seeds": 1, "card_seeds": 0,
                                       "baselines": []}
"""What a fine-tuning does unless told otherwise (:meth:`TrainConfig.fine_tuning`)."""


def known_hyperparameters(algo: str) -> set:
    """The hyperparameters ``algo``'s stable-baselines3 class takes (with ``net_arch``), less those the run sets
    itself (env, seed, device, logging)."""
    parameters = set(inspect.signature(getattr(sb3, algo.upper()).__init__).parameters)
    return (parameters - {"self", "env", "tensorboard_log", "verbose", "seed", "device", "_init_setup_model"}) | {"net_arch"}
