"""Fine-tuning a checkpoint (:func:`fine_tune`): the source checkpoint resolved and checked against the envs,
the reward terms overridden, the first checkpoint written at the source's step count, and the run trained on."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple

import numpy as np
import stable_baselines3 as sb3

from envs.dv2s_env import DV2SEnv
from policies.card_record import FineTune, ModelCard
from policies.model_card import write_card
from policies.registry import (PolicySpaceError, SB3Policy, SHIPPED_CHECKPOINT, check_card_observation, load_policy,
                               parse_spec, read_model_card)
from policies.training.config import ALGORITHMS, TrainConfig, TrainingError, known_hyperparameters
from policies.training.learning import train
from policies.training.run_record import (latest_checkpoint, new_run_record, resolve_scenario_names,
                                          write_run_record)
from scenario_bank.atomic import atomic_path

__all__ = ["resolve_checkpoint", "check_source_observation", "with_reward_weights", "fine_tune_scenarios", "fine_tune"]


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
                       if k != "policy" and k in known_hyperparameters(algorithm)}

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
    write_run_record(out / "run.json", new_run_record(config, resolve_scenario_names(config)))
