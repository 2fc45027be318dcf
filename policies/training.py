"""Training driving policies on the scenario bank with stable-baselines3 (``dv2s train``).

A run lives in one folder (``out``)::

    run.json                        the run's settings (TrainConfig) and its segments (one per invocation)
    checkpoints/step_<n>.zip        periodic checkpoints, the last ``keep_checkpoints`` kept
    checkpoints/step_<n>.sampler.json   the scenario sampler's state at that step
    checkpoints/step_<n>.replay.pkl     the replay buffer (DQN, SAC) at that step
    tb/<ALGO>_1/events.out.tfevents.*   TensorBoard logs, one curve continued across resumes
    evaluations.jsonl               one line per periodic held-out evaluation
    model.zip, model_card.json, README.md   the final model and its card (:mod:`policies.model_card`)

**Environments.** ``n_envs`` DV2S-v0 envs run in ``SubprocVecEnv`` worker processes
(``OMP_NUM_THREADS=1``). Each is wrapped in a :class:`ScenarioSchedule`, which chooses
every training episode's scenario and reset seed from its own random stream: the
scenario from the probabilities the main process last sent it, the seed uniformly from
``[TRAIN_SEED_LOW, 2**31 - 1)``.

**Held-out seeds.** Evaluation episodes (periodic and for the card) are
``(scenario, EVAL_SEED_BASE + i)``; training reset seeds are never below
:data:`TRAIN_SEED_LOW`, so no training episode replays an evaluation scene (nor one of
the small seeds other tests use).

**Scenario sampling** (:class:`ScenarioSampler`, in the main process): ``uniform``;
``weighted`` (fixed weights); ``curriculum``, which mixes a uniform floor with each
scenario's failure rate (collision or off-road) over its last ``window`` training
episodes, so scenarios the policy fails are drawn more. :class:`CurriculumCallback`
reads each finished episode's outcome from the vectorized env's infos, updates the
sampler and sends the new probabilities to every worker with
``env_method("set_scenario_probabilities", ...)`` every ``update_every`` steps; the
probabilities are logged to TensorBoard (``curriculum/p_<scenario>``).

**Resume.** ``train(config, resume=True)`` loads the newest checkpoint in ``out``
through the policy registry (a checkpoint that does not load, or whose observation or
action space does not match the env, is refused naming which), restores the sampler
and replay buffer, and continues with ``reset_num_timesteps=False`` until the model has
``config.steps`` steps in total; the TensorBoard curve and the step counter continue.
An interrupted run (Ctrl-C) saves a checkpoint before it stops.
"""

from __future__ import annotations

import dataclasses
import functools
import inspect
import json
import os
import re
import shlex
import signal
import sys
import time
from collections import deque
from importlib import metadata
from pathlib import Path
from typing import Any, Callable, Deque, Dict, List, Mapping, Optional, Sequence, Tuple

import gymnasium as gym
import numpy as np
from stable_baselines3.common.callbacks import BaseCallback, CallbackList
from tqdm import tqdm

from envs.dv2s_env import DV2SEnv, check_env_config
from envs.errors import DV2SError, Interrupted
from policies.evaluation import EVAL_SEED_BASE, make_eval_env, run_episode, TRAIN_SEED_LOW
from policies.card_record import FineTune, ModelCard
from policies.model_card import bank_version, read_card, summarize_results, write_card, evaluate_for_card
from policies.registry import (SB3Policy, load_policy, read_model_card, SHIPPED_CHECKPOINT, parse_spec,
                               PolicySpaceError, check_card_observation)
from scenario_bank import select_scenarios
from scenario_bank.atomic import atomic_path, atomic_write_json
from scenario_bank.field_checks import (check_bool, check_choice, check_int, check_mapping, check_names,
                                        check_number, check_path)
from scenario_bank.bank import Bank
from scenario_bank.run_identity import (BANK_IDENTITY, RunIdentityError, bank_identity, check_bank_unchanged,
                                       check_format, check_identity, check_run_kind, record_format)
from policies.run_identity import CODE_IDENTITY, check_code_unchanged, code_identity
from scenario_bank.run_paths import as_read, read_paths, record_paths, resume_fix
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv
import stable_baselines3 as sb3

__all__ = [
    "ALGORITHMS",
    "SAMPLERS",
    "EVAL_SEED_BASE",
    "TRAIN_SEED_LOW",
    "DEFAULT_HYPERPARAMETERS",
    "TrainingError",
    "close_vec_env",
    "TrainConfig",
    "ScenarioSampler",
    "ScenarioSchedule",
    "CurriculumCallback",
    "HeldOutEvaluationCallback",
    "CheckpointSaver",
    "ProgressCallback",
    "make_train_env",
    "TrainEnvSpec",
    "make_vec_env",
    "evaluation_episodes",
    "latest_checkpoint",
    "load_run_config",
    "run_settings",
    "train",
    "resolve_checkpoint",
    "fine_tune",
    "fine_tune_scenarios",
    "with_reward_weights", "check_source_observation"]

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


# --------------------------------------------------------------------------- configuration
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
        unknown = set(self.hyperparameters) - _known_hyperparameters(self.algo)
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
        return {k: v for k, v in values.items() if not (k in _FINE_TUNING_ONLY and v is None)}

    @classmethod
    def from_json(cls, data: Mapping[str, Any]) -> "TrainConfig":
        """Inverse of :meth:`to_json` (unknown keys are refused)."""
        fields = {f.name for f in dataclasses.fields(cls)}
        unknown = set(data) - fields
        if unknown:
            raise TrainingError(f"run settings name unknown field(s) {', '.join(sorted(unknown))}; "
                                "was the run made by a newer dv2s-gym?")
        return cls(**dict(data))


_RUN_SCHEMA = "dv2s-train-run"
_RUN_VERSION = 2
"""The format of a training run's ``run.json`` (bumped when its fields change; a run folder of another format is
refused on resume)."""


def _new_run_record(config: TrainConfig, names: Sequence[str]) -> Dict[str, Any]:
    """A new run's ``run.json``: its format, its settings, the scripts of its scenarios ``names``
    (:func:`~scenario_bank.run_identity.bank_identity`), the code (:func:`~policies.run_identity.code_identity`) and
    no segment yet."""
    return {**record_format(_RUN_SCHEMA, _RUN_VERSION), "config": config.to_json(),
            BANK_IDENTITY: bank_identity(Bank(config.bank_dir), names), CODE_IDENTITY: code_identity(), "segments": []}


def _write_record(path: Path, record: Mapping[str, Any]) -> None:
    """Write ``run.json`` with the paths inside the run folder, or inside the loop folder holding it, relative to
    that folder (:mod:`scenario_bank.run_paths`: a moved run folder resumes where it is)."""
    atomic_write_json(path, record_paths(dict(record), path.parent))


_FINE_TUNING_ONLY = ("learning_rate", "reward_weights")
"""Fields only :func:`fine_tune` reads; it applies them (the rate saved in the first checkpoint, the reward terms
in the env config) and trains with them cleared, so :func:`train` refuses a config that sets them."""

_FINE_TUNE_DEFAULTS: Dict[str, Any] = {"env_config": None, "eval_freq": 0, "eval_seeds": 1, "card_seeds": 0,
                                       "baselines": []}
"""What a fine-tuning does unless told otherwise (:meth:`TrainConfig.fine_tuning`)."""


def _known_hyperparameters(algo: str) -> set:
    parameters = set(inspect.signature(getattr(sb3, algo.upper()).__init__).parameters)
    return (parameters - {"self", "env", "tensorboard_log", "verbose", "seed", "device", "_init_setup_model"}) | {"net_arch"}


# --------------------------------------------------------------------------- scenario sampling
class ScenarioSampler:
    """The probability of each scenario being a training episode's scenario.

    Args:
        names: the scenarios trained on.
        mode: ``uniform``; ``weighted`` (``weights``, scenario -> weight, absent = 0);
            ``curriculum``: ``p_i = floor / K + (1 - floor) * f_i / sum(f)`` where ``f_i``
            is scenario ``i``'s failure rate over its last ``window`` training episodes,
            smoothed as ``(failures + 1) / (episodes + 2)`` so an unseen scenario counts as
            0.5 and none ever drops to zero.
    """

    def __init__(self, names: Sequence[str], mode: str = "uniform", weights: Optional[Mapping[str, float]] = None,
                 floor: float = 0.25, window: int = 20) -> None:
        self.names = list(dict.fromkeys(names))
        if not self.names:
            raise TrainingError("the scenario selection is empty; name at least one bank scenario")
        if mode not in SAMPLERS:
            raise TrainingError(f"unknown sampler {mode!r}; use one of {', '.join(SAMPLERS)}")
        self.mode = mode
        self.floor = float(floor)
        self.window = int(window)
        self.weights = None
        if mode == "weighted":
            weights = dict(weights or {})
            stray = sorted(set(weights) - set(self.names))
            if stray:
                raise TrainingError(f"--weights names scenario(s) not trained on: {', '.join(stray)}; "
                                    f"weights are for {', '.join(self.names)}")
            values = [float(weights.get(name, 0.0)) for name in self.names]
            if any(v < 0 or not np.isfinite(v) for v in values) or sum(values) <= 0:
                raise TrainingError("--weights must be non-negative with a positive sum")
            self.weights = dict(zip(self.names, values))
        self.history: Dict[str, Deque[bool]] = {name: deque(maxlen=self.window) for name in self.names}
        self.episodes: Dict[str, int] = {name: 0 for name in self.names}

    def record(self, scenario: str, failed: bool) -> None:
        """Remember one finished training episode of ``scenario`` (others are ignored)."""
        if scenario in self.history:
            self.history[scenario].append(bool(failed))
            self.episodes[scenario] += 1

    def failure_rates(self) -> Dict[str, float]:
        """Smoothed failure rate of each scenario over its remembered episodes."""
        return {name: (sum(h) + 1.0) / (len(h) + 2.0) for name, h in self.history.items()}

    def probabilities(self) -> Dict[str, float]:
        """Scenario -> probability of being drawn next (sums to 1)."""
        k = len(self.names)
        if self.mode == "weighted":
            total = sum(self.weights.values())
            return {name: w / total for name, w in self.weights.items()}
        if self.mode == "uniform":
            return {name: 1.0 / k for name in self.names}
        rates = self.failure_rates()
        total = sum(rates.values())
        return {name: self.floor / k + (1.0 - self.floor) * rates[name] / total for name in self.names}

    def state_dict(self) -> Dict[str, Any]:
        """JSON-safe state (saved beside every checkpoint)."""
        return {"mode": self.mode, "history": {n: [bool(x) for x in h] for n, h in self.history.items()},
                "episodes": dict(self.episodes)}

    def load_state_dict(self, state: Mapping[str, Any]) -> None:
        """Restore :meth:`state_dict` (scenarios no longer trained on are dropped)."""
        for name, outcomes in state.get("history", {}).items():
            if name in self.history:
                self.history[name].clear()
                self.history[name].extend(bool(x) for x in outcomes)
        for name, count in state.get("episodes", {}).items():
            if name in self.episodes:
                self.episodes[name] = int(count)


class ScenarioSchedule(gym.Wrapper):
    """Chooses each episode's scenario and reset seed (training envs; see the module docstring).

    ``reset(seed=s)`` restarts the wrapper's stream from ``(s, stream)``; every reset then
    draws a scenario by the current probabilities and a reset seed in
    ``[TRAIN_SEED_LOW, 2**31 - 1)``, unless ``options`` names the scenario.
    """

    def __init__(self, env: gym.Env, probabilities: Mapping[str, float], seed: int = 0, stream: int = 0) -> None:
        super().__init__(env)
        self.stream = int(stream)
        self.rng = np.random.default_rng([int(seed), self.stream])
        self.set_scenario_probabilities(probabilities)

    def set_scenario_probabilities(self, probabilities: Mapping[str, float]) -> None:
        """Use these scenario -> probability weights from the next episode on."""
        names = list(probabilities)
        values = np.array([float(probabilities[n]) for n in names], dtype=float)
        if not names or np.any(values < 0) or values.sum() <= 0:
            raise TrainingError("scenario probabilities must be non-negative with a positive sum")
        self.names, self.probabilities = names, values / values.sum()

    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None):
        if seed is not None:
            self.rng = np.random.default_rng([int(seed), self.stream])
        options = dict(options or {})
        if "scenario" not in options:
            options["scenario"] = self.names[int(self.rng.choice(len(self.names), p=self.probabilities))]
        episode_seed = int(self.rng.integers(TRAIN_SEED_LOW, TRAIN_SEED_HIGH))
        return self.env.reset(seed=episode_seed, options=options)


@dataclasses.dataclass(frozen=True)
class TrainEnvSpec:
    """What every training env of a run is: DV2S-v0 on ``names`` with ``config`` (scenarios from ``bank_dir``,
    ``None``: the default bank), each episode's scenario drawn with ``probabilities``.

    ``wrap(env, seed, stream)``, a picklable callable, replaces SB3's Monitor as the outer wrapper
    (DAgger's reference labels, :mod:`policies.imitation`)."""

    names: Sequence[str]
    config: Mapping[str, Any]
    bank_dir: Optional[str]
    probabilities: Mapping[str, float]
    wrap: Optional[Callable[[gym.Env, int, int], gym.Env]] = None

    def __post_init__(self) -> None:  # plain containers: the spec is pickled into every worker process
        object.__setattr__(self, "names", list(self.names))
        object.__setattr__(self, "config", dict(self.config))
        object.__setattr__(self, "probabilities", dict(self.probabilities))


def _build_train_env(spec: TrainEnvSpec, seed: int, stream: int) -> gym.Env:
    os.environ["OMP_NUM_THREADS"] = "1"

    env = DV2SEnv(scenario=list(spec.names), config=dict(spec.config), bank_dir=spec.bank_dir)
    scheduled = ScenarioSchedule(env, spec.probabilities, seed=seed, stream=stream)
    return Monitor(scheduled) if spec.wrap is None else spec.wrap(scheduled, seed, stream)


def make_train_env(spec: TrainEnvSpec, seed: int, stream: int = 0) -> Callable[[], gym.Env]:
    """A picklable factory of one training env (DV2S-v0 in a :class:`ScenarioSchedule` and SB3's Monitor, or
    ``spec.wrap``)."""
    return functools.partial(_build_train_env, spec, int(seed), int(stream))


def make_vec_env(spec: TrainEnvSpec, n_envs: int, seed: int, stream: int = 0, vec_env: str = "subproc"):
    """``n_envs`` training envs in a ``SubprocVecEnv`` (or ``DummyVecEnv``); env ``i`` is seeded ``seed + i``."""
    os.environ["OMP_NUM_THREADS"] = "1"  # inherited by the worker processes
    factories = [make_train_env(spec, seed + rank, stream) for rank in range(n_envs)]
    if vec_env == "dummy":
        return DummyVecEnv(factories)
    return SubprocVecEnv([functools.partial(_worker_env, factory) for factory in factories])


def close_vec_env(venv: Any) -> None:
    """Close ``venv``; after Ctrl-C (an interrupt on its way out), without waiting for step results.

    Ctrl-C can cut a ``SubprocVecEnv`` step between two workers' answers; its own ``close`` then waits for an
    answer from every worker, and one that already answered sends none: the command would hang. Here the
    unread answers are dropped and every worker is told to stop (stopped by force if it does not)."""
    interrupted = isinstance(sys.exc_info()[1], KeyboardInterrupt)
    processes = getattr(venv, "processes", None)
    if interrupted and processes is not None and not venv.closed:
        venv.waiting = False
        for remote in venv.remotes:
            try:
                remote.send(("close", None))
            except OSError:
                pass
        for process in processes:
            process.join(5)
            if process.is_alive():
                process.terminate()
                process.join(5)
        for remote in venv.remotes:
            remote.close()
        venv.closed = True
        return
    venv.close()


def _worker_env(factory: Callable[[], gym.Env]) -> gym.Env:
    """``factory()`` in a vec-env worker process, which leaves Ctrl-C to the main process: a terminal's Ctrl-C
    reaches the whole process group, and a worker stopped by it would cut the main process off mid-step before
    it saves its checkpoint; the main process closes the workers itself."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    return factory()


def evaluation_episodes(names: Sequence[str], seeds: int) -> List[Tuple[str, int]]:
    """The held-out episodes: every scenario with seeds ``EVAL_SEED_BASE .. EVAL_SEED_BASE + seeds - 1``."""
    return [(name, EVAL_SEED_BASE + offset) for name in sorted(names) for offset in range(seeds)]


# --------------------------------------------------------------------------- callbacks
def _episode_failed(info: Mapping[str, Any]) -> bool:
    return bool(info.get("crashed") or info.get("collisions") or info.get("off_road"))


class CurriculumCallback(BaseCallback):
    """Feeds finished training episodes to the sampler and sends its probabilities to the workers.

    Every ``update_every`` env steps: ``env_method("set_scenario_probabilities", p)``
    (curriculum only) and TensorBoard scalars ``curriculum/p_<scenario>`` and
    ``train/failure_rate`` (over the episodes finished since the last update).
    """

    def __init__(self, sampler: ScenarioSampler, update_every: int = 1000) -> None:
        super().__init__()
        self.sampler = sampler
        self.update_every = int(update_every)
        self._last = 0
        self._finished: List[bool] = []

    def _on_training_start(self) -> None:
        self._last = self.num_timesteps

    def _on_step(self) -> bool:
        for done, info in zip(self.locals.get("dones", []), self.locals.get("infos", [])):
            if done and "scenario" in info:
                failed = _episode_failed(info)
                self.sampler.record(str(info["scenario"]), failed)
                self._finished.append(failed)
        if self.num_timesteps - self._last >= self.update_every:
            self.update()
        return True

    def update(self) -> Dict[str, float]:
        """Send the current probabilities to the workers and log them."""
        self._last = self.num_timesteps
        probabilities = self.sampler.probabilities()
        if self.sampler.mode == "curriculum":
            self.training_env.env_method("set_scenario_probabilities", probabilities)
        for name, p in probabilities.items():
            self.logger.record(f"curriculum/p_{name}", p)
        if self._finished:
            self.logger.record("train/failure_rate", float(np.mean(self._finished)))
            self._finished = []
        return probabilities

class HeldOutEvaluationCallback(BaseCallback):
    """Every ``every`` env steps, runs the model deterministically on held-out episodes.

    Logs ``eval/collision_rate``, ``eval/success_rate``, ``eval/off_road_rate``,
    ``eval/mean_return`` to TensorBoard and appends a line to ``log_path`` (JSON lines).
    """

    def __init__(self, episodes: Sequence[Tuple[str, int]], env_config: Mapping[str, Any],
                 bank_dir: Optional[str], every: int, log_path: Path) -> None:
        super().__init__()
        self.episodes = list(episodes)
        self.env_config = dict(env_config)
        self.bank_dir = bank_dir
        self.every = int(every)
        self.log_path = Path(log_path)
        self._last = 0
        self._env = None
        self.latest: Optional[Dict[str, Any]] = None

    def _on_training_start(self) -> None:
        self._last = self.num_timesteps

    def _on_step(self) -> bool:
        if self.every > 0 and self.episodes and self.num_timesteps - self._last >= self.every:
            self.run()
        return True

    def run(self) -> Dict[str, Any]:
        """Evaluate now; returns the overall rates."""
        self._last = self.num_timesteps
        if self._env is None:
            self._env = make_eval_env(sorted({s for s, _ in self.episodes}), config=self.env_config,
                                      bank_dir=self.bank_dir)
        policy = SB3Policy("training", self.model)
        policy.bind([self._env])
        results = [run_episode(self._env, policy, scenario, seed)[0] for scenario, seed in self.episodes]
        overall = summarize_results(results).overall
        for measure in ("collision", "success", "off_road"):
            self.logger.record(f"eval/{measure}_rate", overall.measure(measure)["rate"])
        self.logger.record("eval/mean_return", overall.mean_return)
        self.latest = {"step": int(self.num_timesteps), "episodes": len(results),
                       **{m: overall.measure(m) for m in ("collision", "success", "off_road", "failure")},
                       "mean_return": overall.mean_return}
        self.log_path.parent.mkdir(parents=True, exist_ok=True)
        with open(self.log_path, "a", encoding="utf-8") as handle:
            handle.write(json.dumps(self.latest, sort_keys=True) + "\n")
        return self.latest

    def _on_training_end(self) -> None:
        if self._env is not None:
            self._env.close()
            self._env = None

class CheckpointSaver(BaseCallback):
    """Saves ``checkpoints/step_<n>.zip`` (atomic) every ``every`` env steps with the sampler's
    state and, for off-policy algorithms, the replay buffer; keeps the newest ``keep``."""

    def __init__(self, directory: Path, every: int, sampler: ScenarioSampler, keep: int = 3) -> None:
        super().__init__()
        self.directory = Path(directory)
        self.every = int(every)
        self.sampler = sampler
        self.keep = int(keep)
        self._last = 0

    def _on_training_start(self) -> None:
        self._last = self.num_timesteps

    def _on_step(self) -> bool:
        if self.every > 0 and self.num_timesteps - self._last >= self.every:
            self.save()
        return True

    def save(self, model: Optional[Any] = None) -> Path:
        """Write a checkpoint of ``model`` (default: the model this callback is attached to) at its
        current step now; returns its path. ``model`` serves a run interrupted before SB3 attached
        the callbacks."""
        model = model if model is not None else self.model
        steps = int(model.num_timesteps)
        self._last = steps
        path = self.directory / f"step_{steps:09d}.zip"
        with atomic_path(path, keep_suffix=True) as tmp:
            model.save(tmp)
        atomic_write_json(path.with_suffix(".sampler.json"), self.sampler.state_dict())
        if getattr(model, "replay_buffer", None) is not None:
            with atomic_path(path.with_suffix(".replay.pkl"), keep_suffix=True) as tmp:
                model.save_replay_buffer(tmp)
        for old in _checkpoints(self.directory)[:-self.keep]:
            for companion in (old, old.with_suffix(".sampler.json"), old.with_suffix(".replay.pkl")):
                companion.unlink(missing_ok=True)
        return path

class ProgressCallback(BaseCallback):
    """A tqdm bar over the run's whole step budget (a resumed run starts where it stopped)."""

    def __init__(self, total: int, description: str, evaluation: Optional[Any] = None) -> None:
        super().__init__()
        self.total = int(total)
        self.description = description
        self.evaluation = evaluation
        self.bar = None
        self._shown = None

    def _on_training_start(self) -> None:
        self.bar = tqdm(total=self.total, initial=self.num_timesteps, unit="step", desc=self.description,
                        dynamic_ncols=True, smoothing=0.05)

    def _on_step(self) -> bool:
        if self.num_timesteps > self.bar.total:  # the last rollout may overshoot the budget
            self.bar.total = self.num_timesteps
        self.bar.update(self.num_timesteps - self.bar.n)
        latest = getattr(self.evaluation, "latest", None)
        if latest is not None and latest is not self._shown:
            self._shown = latest
            self.bar.set_postfix(collision=f"{latest['collision']['rate']:.2f}",
                                 success=f"{latest['success']['rate']:.2f}")
        return True

    def _on_training_end(self) -> None:
        if self.bar is not None:
            self.bar.close()


# --------------------------------------------------------------------------- run folder
_CHECKPOINT = re.compile(r"^step_(\d+)\.zip$")


def _checkpoints(directory: Path) -> List[Path]:
    if not directory.is_dir():
        return []
    found = [(int(m.group(1)), p) for p in directory.iterdir() if (m := _CHECKPOINT.match(p.name))]
    return [p for _, p in sorted(found)]


def latest_checkpoint(out: os.PathLike | str) -> Optional[Path]:
    """The newest ``checkpoints/step_<n>.zip`` in a run folder, or ``None``."""
    found = _checkpoints(Path(out) / "checkpoints")
    return found[-1] if found else None


def load_run_config(out: os.PathLike | str) -> Tuple[TrainConfig, Dict[str, Any]]:
    """The settings and the ``run.json`` record of the run in ``out`` (one of another format, :data:`_RUN_VERSION`,
    is refused)."""
    path = Path(out) / "run.json"
    check_run_kind(out, _RUN_SCHEMA, error=TrainingError)
    if not path.is_file():
        raise TrainingError(f"{out} holds no training run (no run.json); start one without --resume")
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as error:
        raise TrainingError(f"{path} is not a readable run record ({error}); start a new run in another --out") from error
    check_format(record, _RUN_SCHEMA, _RUN_VERSION, folder=out, what="a training run", file=path.name,
                 error=TrainingError)
    record = read_paths(record, out)  # paths in the run (or its loop) folder where they are now
    try:
        return TrainConfig.from_json(record["config"]), record
    except (KeyError, TypeError) as error:
        raise TrainingError(f"{path} is not a readable run record ({error}); start a new run in another --out") from error


def run_settings(out: os.PathLike | str, given: Mapping[str, Any], resume: bool = False) -> TrainConfig:
    """The settings of the run in ``out``: ``given`` (settings by :class:`TrainConfig` field; ``None`` values are
    not given) over, when resuming, the settings the run recorded (:func:`load_run_config`), so a resumed run
    keeps what it was started with unless told otherwise."""
    settings = {key: value for key, value in given.items() if value is not None}
    if resume:
        recorded, _ = load_run_config(out)
        settings = {**recorded.to_json(), **settings}
    return TrainConfig.from_json({**settings, "out": str(out) if isinstance(out, Path) else out})


def _resolve_names(config: TrainConfig) -> List[str]:
    names = select_scenarios(config.scenarios, config.bank_dir)
    if not names:
        raise TrainingError("the scenario selection is empty; name bank scenarios or tag:<tag> after --scenarios")
    return sorted(names)


def _check_resume(config: TrainConfig, record: Mapping[str, Any], names: Sequence[str]) -> None:
    """Refuse ``config`` unless it has the identity of the run's ``record`` (``run.json``): its settings
    (``config``, :meth:`TrainConfig.to_json`'s form: a fine-tuning setting it leaves out is ``None`` on both sides),
    the scripts of its scenarios ``names`` and the code."""
    run = f"{config.out} holds a training run"
    check_identity(record["config"], as_read(config.to_json(), config.out), TrainConfig.IDENTITY, run=run,
                   fix=resume_fix(config.out, "resume with the run's own settings (omit the option) or start a new "
                                              "run in another --out"))
    check_bank_unchanged(record.get(BANK_IDENTITY), bank_identity(Bank(config.bank_dir), names), run=run)
    check_code_unchanged(record, run=run, error=RunIdentityError)


def _new_model(config: TrainConfig, venv, tensorboard_log: str):
    hyperparameters = config.effective_hyperparameters()
    policy = hyperparameters.pop("policy", "MlpPolicy")
    policy_kwargs = dict(hyperparameters.pop("policy_kwargs", None) or {})
    if "net_arch" in hyperparameters:
        policy_kwargs["net_arch"] = list(hyperparameters.pop("net_arch"))
    cls = getattr(sb3, config.algo.upper())
    try:
        return cls(policy, venv, policy_kwargs=policy_kwargs, tensorboard_log=tensorboard_log, seed=config.seed,
                   device="cpu", verbose=0, **hyperparameters)
    except (TypeError, ValueError, AssertionError) as error:
        raise TrainingError(f"{config.algo.upper()} does not accept these hyperparameters ({error}); "
                            "fix the --hp values") from error


def _resume_model(config: TrainConfig, checkpoint: Path, venv, tensorboard_log: str):
    # The registry gives the clear errors: a checkpoint that does not load, or mismatched spaces.
    policy = load_policy(f"{config.algo}:{checkpoint}")
    policy.check_spaces(venv.observation_space, venv.action_space)
    model = getattr(sb3, config.algo.upper()).load(str(checkpoint), env=venv, device="cpu",
                                                     tensorboard_log=tensorboard_log)
    replay = checkpoint.with_suffix(".replay.pkl")
    if getattr(model, "replay_buffer", None) is not None and replay.is_file():
        model.load_replay_buffer(str(replay))
    model.set_random_seed(config.seed + int(model.num_timesteps))
    return model


def planned_steps(model: Any, start: int, target: int) -> Tuple[int, Optional[str]]:
    """``(the step count training to ``target`` from ``start`` ends at, a line saying so)``.

    Stable-baselines3 stops at the first whole rollout that reaches ``target``: ``n_steps x n_envs`` env steps
    for PPO/A2C, ``train_freq x n_envs`` for DQN/SAC with a step-counted ``train_freq``. The line is ``None``
    when nothing is left to train or the rollout is counted in episodes (its end is not known ahead)."""
    remaining = int(target) - int(start)
    n_envs = int(getattr(model, "n_envs", 1) or 1)
    if remaining <= 0:
        return int(start), None
    if getattr(model, "n_steps", None):
        per_env, unit = int(model.n_steps), "rollouts"
    else:
        frequency = getattr(model, "train_freq", None)
        if getattr(getattr(frequency, "unit", None), "value", "step") != "step":
            return int(target), None
        per_env, unit = int(getattr(frequency, "frequency", 1) or 1), "collection rounds"
    rollout = per_env * n_envs
    final = int(start) + -(-remaining // rollout) * rollout
    origin = f" from step {start:,}" if start else ""
    if final == int(target):
        return final, (f"training {remaining:,} steps{origin}: {remaining // rollout:,} {unit} of {rollout:,} "
                       f"({per_env} steps x {n_envs} env{'s' if n_envs != 1 else ''})")
    return final, (f"{target:,} steps asked: trains to {final:,}{origin} (stable-baselines3 trains whole {unit} "
                   f"of {rollout:,} = {per_env} steps x {n_envs} env{'s' if n_envs != 1 else ''})")


def _versions() -> Dict[str, str]:
    versions = {}
    for package in ("dv2s-gym", "stable-baselines3", "torch", "highway-env", "gymnasium", "scenic"):
        try:
            versions[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            versions[package] = "unknown"
    return versions


def train(config: TrainConfig, resume: bool = False, log: Callable[[str], None] = print) -> ModelCard:
    """Train (or resume) a run as described in the module docstring; returns the model card.

    Raises :class:`TrainingError` (and the registry's/bank's errors) for bad input.
    """
    config.validate()
    ignored = [name for name in _FINE_TUNING_ONLY if getattr(config, name) is not None]
    if ignored:
        raise TrainingError(f"{' and '.join(ignored)} are fine-tuning settings (fine_tune applies them); to train "
                            "with another learning rate pass hyperparameters={'learning_rate': ...}, and change the "
                            "reward with env_config")
    out = Path(config.out)
    if out.exists() and not out.is_dir():
        raise TrainingError(f"--out {out} is a file; choose a folder for the run")
    names = _resolve_names(config)
    run_path = out / "run.json"
    resume, record, checkpoint = _open_record(config, names, resume, log)

    import torch

    torch.set_num_threads(1)
    env_config = config.effective_env_config()
    sampler, stream = _restored_sampler(config, names, checkpoint if resume else None)
    out.mkdir(parents=True, exist_ok=True)
    tensorboard_log = str(out / "tb")
    log(_starting(config, names))
    venv = make_vec_env(TrainEnvSpec(names, env_config, config.bank_dir, sampler.probabilities()), config.n_envs,
                        config.seed, stream=stream, vec_env=config.vec_env)
    try:
        if resume:
            model = _resume_model(config, checkpoint, venv, tensorboard_log)
            log(f"resuming {checkpoint} at step {model.num_timesteps}")
        else:
            model = _new_model(config, venv, tensorboard_log)
        start = int(model.num_timesteps)
        planned, plan = planned_steps(model, start, config.steps)
        if plan:
            log(plan)
        _write_record(run_path, record)
        callbacks, saver = _callbacks(config, names, env_config, sampler, planned)
        began = time.perf_counter()
        remaining = config.steps - start

        def close_segment(status: str) -> Dict[str, Any]:
            segment = {"start_step": start, "end_step": int(model.num_timesteps), "status": status,
                       "wall_time_s": round(time.perf_counter() - began, 3),
                       "resumed_from": checkpoint.name if resume else None}
            record["segments"].append(segment)
            _write_record(run_path, record)
            return segment

        if remaining > 0:
            try:
                model.learn(remaining, callback=CallbackList(callbacks), reset_num_timesteps=not resume,
                            tb_log_name=config.algo.upper(), progress_bar=False)
            except KeyboardInterrupt:
                saved = saver.save(model)
                close_segment("interrupted")
                if getattr(model, "_logger", None) is not None:  # set once learning has started
                    model.logger.close()  # TensorBoard's last events written now: an interrupted dv2s exits at once
                raise Interrupted(f"training stopped at step {model.num_timesteps}: checkpoint {saved} is kept; "
                                  "rerun the same command with --resume to continue") from None
            saver.save(model)
        else:
            log(f"the model already has {start} steps (>= --steps {config.steps}); nothing to train")
        segment = close_segment("finished")
    finally:
        close_vec_env(venv)
    model_path = out / "model.zip"
    with atomic_path(model_path, keep_suffix=True) as tmp:
        model.save(tmp)
    card = _evaluate_for_card(config, names, _card(config, names, env_config, model, sampler, record), env_config,
                              model_path, log)
    card_path = write_card(out, card)
    log(f"wrote {model_path} and {out / 'model_card.json'} (step {model.num_timesteps}, last segment "
        f"{segment['wall_time_s']:.0f} s)")
    return read_card(card_path)


def _card_record(card: Mapping[str, Any]) -> ModelCard:
    """The record of a card's fields this module gathered (values JSON does not know written as text, as the file
    has them)."""
    return ModelCard.from_dict(json.loads(json.dumps(dict(card), default=str)))


def _starting(config: TrainConfig, names: Sequence[str]) -> str:
    """The line that says what starts (the first reset takes a while)."""
    return (f"starting {config.n_envs} training env{'s' if config.n_envs != 1 else ''} "
            f"({'subprocesses' if config.vec_env != 'dummy' else 'in this process'}) on {len(names)} scenario"
            f"{'s' if len(names) != 1 else ''}; the first reset compiles their first scenarios (up to a minute) ...")


def _callbacks(config: TrainConfig, names: Sequence[str], env_config: Mapping[str, Any], sampler: "ScenarioSampler",
               planned: int) -> Tuple[List[BaseCallback], "CheckpointSaver"]:
    """The training callbacks (curriculum, held-out evaluation, checkpoints, progress bar) and the checkpoint
    saver among them."""
    out = Path(config.out)
    curriculum = CurriculumCallback(sampler, config.curriculum_update)
    evaluation = HeldOutEvaluationCallback(evaluation_episodes(names, config.eval_seeds), env_config,
                                           config.bank_dir, config.eval_freq, out / "evaluations.jsonl")
    saver = CheckpointSaver(out / "checkpoints", config.checkpoint_freq, sampler, config.keep_checkpoints)
    callbacks: List[BaseCallback] = [curriculum, evaluation, saver]
    if config.progress_bar:
        callbacks.append(ProgressCallback(max(planned, config.steps), f"{config.algo} {out.name}", evaluation))
    return callbacks, saver


def _open_record(config: TrainConfig, names: Sequence[str], resume: bool, log: Callable[[str], None]
                 ) -> Tuple[bool, Dict[str, Any], Optional[Path]]:
    """``(resume, run.json's record, the newest checkpoint)`` of the run of the scenarios ``names`` in
    ``config.out``: a resumed run's record (checked against ``config``, the scripts and the code), or a new one
    (refused over an existing run)."""
    out = Path(config.out)
    check_run_kind(out, _RUN_SCHEMA, error=TrainingError)
    checkpoint = latest_checkpoint(out)
    record: Dict[str, Any] = _new_run_record(config, names)
    if resume:
        _, record = load_run_config(out)
        _check_resume(config, record, names)
        if checkpoint is None:
            # stopped before its first checkpoint: nothing was kept, so the run starts over in place
            log(f"{out} holds no checkpoint yet (the run stopped before its first one): starting from step 0")
            resume, record = False, _new_run_record(config, names)
        else:
            record["config"] = config.to_json()
    elif checkpoint is not None or (out / "run.json").exists():
        at = f" (checkpoint at step {int(_CHECKPOINT.match(checkpoint.name).group(1))})" if checkpoint else ""
        raise TrainingError(f"{out} already holds a training run{at}; pass --resume to continue it, "
                            "or choose another --out")
    return resume, record, checkpoint


def _restored_sampler(config: TrainConfig, names: Sequence[str],
                      checkpoint: Optional[Path]) -> Tuple[ScenarioSampler, int]:
    """The run's scenario sampler and the workers' seed stream: fresh, or as saved beside ``checkpoint``."""
    sampler = ScenarioSampler(names, config.sampler, config.weights, config.curriculum_floor, config.curriculum_window)
    if checkpoint is None:
        return sampler, 0
    sampler_state = checkpoint.with_suffix(".sampler.json")
    if sampler_state.is_file():
        sampler.load_state_dict(json.loads(sampler_state.read_text(encoding="utf-8")))
    return sampler, int(_CHECKPOINT.match(checkpoint.name).group(1))


def _card(config: TrainConfig, names: Sequence[str], env_config: Dict[str, Any], model: Any,
          sampler: ScenarioSampler, record: Mapping[str, Any]) -> ModelCard:
    """The trained model's card, without its evaluation."""
    wall = sum(s["wall_time_s"] for s in record["segments"])
    trained = sum(s["end_step"] - s["start_step"] for s in record["segments"])
    return _card_record({
        "name": Path(config.out).name,
        "algorithm": config.algo,
        "policy": config.effective_hyperparameters()["policy"],
        "hyperparameters": config.effective_hyperparameters(),
        "env_id": "DV2S-v0",
        "env_config": env_config,
        "observation_space": str(model.observation_space),
        "action_space": str(model.action_space),
        "bank": {**bank_version(names, config.bank_dir), "dir": config.bank_dir},
        "sampler": {"mode": config.sampler, "weights": config.weights, "final_probabilities": sampler.probabilities(),
                    "training_episodes": dict(sampler.episodes)},
        "training": {
            "command": config.command(),
            "steps": int(model.num_timesteps),
            "n_envs": config.n_envs,
            "seed": config.seed,
            "wall_time_s": round(wall, 1),
            "steps_per_s": round(trained / wall, 1) if wall > 0 else 0.0,
            "segments": record["segments"],
            "train_seed_range": [TRAIN_SEED_LOW, TRAIN_SEED_HIGH],
        },
        "versions": _versions(),
    })


def _evaluate_for_card(config: TrainConfig, names: Sequence[str], card: ModelCard, env_config: Mapping[str, Any],
                       model_path: Path, log: Callable[[str], None]) -> ModelCard:
    """``card`` with its ``evaluation``: the model (in ``env_config``, the card's) and the baselines on held-out seeds
    (none when ``card_seeds`` is 0); Ctrl-C writes the card without it."""
    card_seeds = config.card_seed_count()
    if card_seeds <= 0:
        return card

    specs = {config.algo: f"{config.algo}:{model_path.resolve()}", **{b: b for b in config.baselines}}
    log(f"model card evaluation: {len(names)} scenarios x {card_seeds} held-out seeds x "
        f"{len(specs)} policies ({', '.join(specs)}) = {len(names) * card_seeds * len(specs)} episodes; "
        "--card-seeds N shortens it (0 skips it), Ctrl-C writes the card without it")
    baseline_config = {k: v for k, v in env_config.items() if k != "action"}
    configs = {label: (env_config if label == config.algo else baseline_config) for label in specs}
    try:
        evaluation = evaluate_for_card(specs, evaluation_episodes(names, card_seeds), configs,
                                       bank_dir=config.bank_dir, candidate=config.algo, seed_base=EVAL_SEED_BASE,
                                       seeds=card_seeds, jobs=config.eval_jobs, progress=config.progress_bar, log=log)
    except KeyboardInterrupt:
        write_card(Path(config.out), card.replace(evaluation=None,
                                                  null_fields=(card.null_fields or frozenset()) | {"evaluation"}))
        raise Interrupted(f"stopped during the card's evaluation: {model_path} and "
                          f"{Path(config.out) / 'model_card.json'} are written without it; rerun the same command "
                          "with --resume to evaluate") from None
    specs_written = {**evaluation.specs, config.algo: f"{config.algo}:model.zip (beside this card)"}
    return card.replace(evaluation=evaluation.replace(specs=specs_written))


# --------------------------------------------------------------------------- fine-tuning
def resolve_checkpoint(spec: str) -> Tuple[str, Path, ModelCard]:
    """``(algorithm, checkpoint path, model card)`` of an SB3 policy spec.

    ``spec`` is ``dv2s-ppo`` (the shipped checkpoint), ``ppo:PATH`` / ``dqn:PATH`` /
    ``sac:PATH``, a ``model.zip`` or the run folder holding one. The card is the empty card when
    none lies beside the checkpoint; the algorithm then comes from loading it.
    """
    base, options = parse_spec(str(spec))
    if options:
        raise TrainingError(f"cannot fine-tune {spec!r}: policy options ({', '.join(options)}) change how it acts, "
                            "not its weights; name the checkpoint without '?...'")
    prefix, sep, rest = base.partition(":")
    if base == "dv2s-ppo":
        path, algorithm = SHIPPED_CHECKPOINT, "ppo"
    elif sep and prefix.lower() in ALGORITHMS:
        path, algorithm = Path(rest), prefix.lower()
    else:
        path, algorithm = Path(base), None
    if path.is_dir():
        path = path / "model.zip"
    if path.suffix != ".zip" or not path.is_file():
        raise TrainingError(f"cannot fine-tune {spec!r}: it names no stable-baselines3 checkpoint (model.zip); "
                            "give dv2s-ppo, ppo:PATH or a run folder written by `dv2s train`")
    card = read_model_card(path)
    algorithm = algorithm or (card.algorithm or "").lower() or None
    if algorithm is None:
        policy = load_policy(str(path))
        algorithm = type(policy.model).__name__.lower() if isinstance(policy, SB3Policy) else None
    if algorithm not in ALGORITHMS:
        raise TrainingError(f"cannot fine-tune {spec!r}: its algorithm {algorithm!r} is not one of "
                            f"{', '.join(ALGORITHMS)}")
    return algorithm, path.resolve(), card


def check_source_observation(source_card: ModelCard, env_config: Mapping[str, Any], spec: str) -> None:
    """Refuse to fine-tune a checkpoint in envs that observe otherwise than the ones it was trained in (its card's
    ``env_config``; a card without one is checked by the observation space's shape only)."""
    try:
        check_card_observation(str(spec), source_card, env_config)
    except PolicySpaceError as error:
        raise TrainingError(f"cannot fine-tune here: {error}") from None


def with_reward_weights(env_config: Mapping[str, Any], reward_weights: Optional[Mapping[str, float]]) -> Dict[str, Any]:
    """A copy of ``env_config`` whose ``reward_weights`` are updated term by term with ``reward_weights``.

    Terms not named keep their weight from ``env_config`` (or, when it names no
    ``reward_weights``, DV2S-v0's defaults). Unknown terms and non-finite weights are refused.
    """
    config = json.loads(json.dumps(dict(env_config)))
    if not reward_weights:
        return config

    defaults = DV2SEnv.default_config()["reward_weights"]
    unknown = sorted(set(reward_weights) - set(defaults))
    if unknown:
        raise TrainingError(f"unknown reward term(s) {', '.join(unknown)}; DV2S-v0's terms are "
                            f"{', '.join(sorted(defaults))}")
    for name, value in reward_weights.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
            raise TrainingError(f"the weight of reward term {name!r} must be a finite number, not {value!r}")
    weights = dict(config.get("reward_weights") or defaults)
    weights.update({name: float(value) for name, value in reward_weights.items()})
    config["reward_weights"] = weights
    return config


def fine_tune_scenarios(weights: Optional[Mapping[str, float]],
                        scenarios: Optional[Sequence[str]]) -> Tuple[Dict[str, float], List[str]]:
    """The sampling weights (``str -> float``) and the scenarios a fine-tuning draws from: ``scenarios``,
    or by default every scenario with a positive weight (sorted); :class:`TrainingError` if there are none."""
    weights = {str(k): float(v) for k, v in dict(weights or {}).items()}
    if scenarios is None:
        scenarios = sorted(name for name, w in weights.items() if w > 0)
    if not scenarios:
        raise TrainingError("fine-tuning needs at least one scenario with a positive weight")
    return weights, list(scenarios)


def fine_tune(checkpoint_or_spec: str, config: TrainConfig, *, log: Callable[[str], None] = print) -> Path:
    """Continue training an SB3 checkpoint on a bank with weighted scenario sampling; returns ``config.out/model.zip``.

    ``config`` (:meth:`TrainConfig.fine_tuning`) says what to train on: ``steps`` env steps of fine-tuning (on
    top of the checkpoint's own), ``weights`` scenario -> sampling weight, the scenarios trained on
    (``scenarios``, default every scenario with a positive weight, so scenarios left out, held-out ones, are
    never drawn), ``env_config`` (``None``: the one on the checkpoint's model card, same reward), the seed,
    the environments, the evaluations and checkpoints. Its ``algo``, ``sampler`` and ``hyperparameters`` are
    the checkpoint's (weighted sampling).

    The checkpoint is copied into ``out/checkpoints/step_<n>.zip`` (``n``: its own step
    counter) and :func:`train` resumes from it with the ``weighted`` sampler, so the step
    counter, the optimizer state saved in the zip and the reset-seed ranges (training
    seeds >= :data:`TRAIN_SEED_LOW`, evaluation seeds :data:`EVAL_SEED_BASE`...) are those of
    ``dv2s train``. The card (``model_card.json``, ``README.md``) gets a ``fine_tune`` section naming the
    source checkpoint and its step.
    ``config.learning_rate`` (constant) replaces the checkpoint's own for the fine-tuning.
    ``config.reward_weights`` overrides single reward terms of that env config (e.g.
    ``{"standing": -1.0}``; the other terms keep their weights): the training env's
    config is recorded as the card's ``env_config`` and the overrides in its
    ``fine_tune`` section. Only training uses it; evaluating the result is up to the caller.

    Restartable: called again with the same ``out`` it resumes from the newest checkpoint
    there, and returns at once when ``out/model.zip`` and its card are already written.
    """
    steps = config.steps
    if isinstance(steps, bool) or not isinstance(steps, int) or steps < 1:
        raise TrainingError(f"fine-tuning steps must be a positive integer, not {steps!r}")
    out = Path(config.out)
    learning_rate, reward_weights = config.learning_rate, config.reward_weights
    weights, scenarios = fine_tune_scenarios(config.weights, config.scenarios)
    algorithm, source, source_card = resolve_checkpoint(checkpoint_or_spec)
    env_config = dict(source_card.env_config or {}) if config.env_config is None else config.env_config
    env_config = with_reward_weights(env_config, reward_weights)
    check_source_observation(source_card, env_config, checkpoint_or_spec)
    hyperparameters = {k: v for k, v in (source_card.hyperparameters or {}).items()
                       if k != "policy" and k in _known_hyperparameters(algorithm)}

    model_path = out / "model.zip"
    if model_path.is_file() and read_model_card(model_path).fine_tune is not None:
        return model_path

    start_step = int(getattr(sb3, algorithm.upper()).load(str(source), device="cpu").num_timesteps)
    run_config = dataclasses.replace(
        config, out=str(out), algo=algorithm, scenarios=sorted(scenarios), steps=start_step + steps,
        sampler="weighted", weights={name: weights.get(name, 0.0) for name in sorted(scenarios)},
        env_config=dict(env_config), hyperparameters=hyperparameters, baselines=list(config.baselines),
        learning_rate=None, reward_weights=None)
    run_config.validate()
    if latest_checkpoint(out) is None:
        _first_checkpoint(run_config, source, start_step, learning_rate)
    card = train(run_config, resume=True, log=log)
    section = FineTune.from_dict(json.loads(json.dumps({
        "source": str(checkpoint_or_spec), "source_checkpoint": str(source), "source_steps": start_step,
        "steps": int(card.training["steps"]) - start_step, "weights": run_config.weights,
        "learning_rate": learning_rate, "reward_weights": dict(reward_weights) if reward_weights else None})))
    description = (f"Fine-tuned from {checkpoint_or_spec} (step {start_step}) for {section.steps} steps on "
                   f"{len(run_config.scenarios)} scenarios with weighted sampling (see sampler.weights).")
    write_card(out, card.replace(fine_tune=section, description=description, name=out.name))
    return model_path


def _first_checkpoint(config: TrainConfig, source: Path, start_step: int, learning_rate: Optional[float]) -> None:
    """Start a fine-tuning run in ``config.out``: the source checkpoint as its first checkpoint (with
    ``learning_rate`` saved in it when given) and a ``run.json`` with no segment yet."""
    out = Path(config.out)
    if (out / "run.json").exists():
        raise TrainingError(f"{out} holds a training run without a checkpoint; remove it or choose another out")
    first = out / "checkpoints" / f"step_{start_step:09d}.zip"
    first.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(first, keep_suffix=True) as tmp:
        if learning_rate is None:
            Path(tmp).write_bytes(source.read_bytes())
        else:  # saved with the model: every resume of this run keeps it
            model = getattr(sb3, config.algo.upper()).load(str(source), device="cpu")
            model.learning_rate = float(learning_rate)
            model._setup_lr_schedule()
            model.save(tmp)
    _write_record(out / "run.json", _new_run_record(config, _resolve_names(config)))
