"""The trained model's card: the run's settings, bank, sampler and segments, and its evaluation against the
baselines on held-out seeds."""

from __future__ import annotations

import json
from importlib import metadata
from pathlib import Path
from typing import Any, Callable, Dict, Mapping, Sequence

from envs.errors import Interrupted
from policies.card_record import ModelCard
from policies.evaluation import EVAL_SEED_BASE, TRAIN_SEED_LOW
from policies.model_card import bank_version, evaluate_for_card, write_card
from policies.training.config import TRAIN_SEED_HIGH, TrainConfig
from policies.training.run_record import TrainRun
from policies.training.scenario_envs import ScenarioSampler, evaluation_episodes

__all__ = ["trained_card", "with_card_evaluation"]


def _versions() -> Dict[str, str]:
    versions = {}
    for package in ("dv2s-gym", "stable-baselines3", "torch", "highway-env", "gymnasium", "scenic"):
        try:
            versions[package] = metadata.version(package)
        except metadata.PackageNotFoundError:
            versions[package] = "unknown"
    return versions


def _card_record(card: Mapping[str, Any]) -> ModelCard:
    """The record of a card's fields this module gathered (values JSON does not know written as text, as the file
    has them)."""
    return ModelCard.from_dict(json.loads(json.dumps(dict(card), default=str)))


def trained_card(config: TrainConfig, names: Sequence[str], env_config: Dict[str, Any], model: Any,
          sampler: ScenarioSampler, record: TrainRun) -> ModelCard:
    """The trained model's card, without its evaluation; ``record``: the run's ``run.json`` with its segments."""
    wall = sum(segment.wall_time_s for segment in record.segments)
    trained = sum(segment.steps for segment in record.segments)
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
            "segments": [segment.to_dict() for segment in record.segments],
            "train_seed_range": [TRAIN_SEED_LOW, TRAIN_SEED_HIGH],
        },
        "versions": _versions(),
    })


def with_card_evaluation(config: TrainConfig, names: Sequence[str], card: ModelCard, env_config: Mapping[str, Any],
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
