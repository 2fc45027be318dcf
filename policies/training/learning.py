"""The training loop (:func:`train`): the model built or resumed, stable-baselines3's learning with the run's
callbacks, the segment recorded (also when stopped with Ctrl-C), the model and its card written."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Callable, List, Mapping, Optional, Sequence, Tuple

import stable_baselines3 as sb3
from stable_baselines3.common.callbacks import BaseCallback, CallbackList

from envs.errors import Interrupted
from policies.card_record import ModelCard
from policies.model_card import read_card, write_card
from policies.registry import load_policy
from policies.training.callbacks import CheckpointSaver, CurriculumCallback, HeldOutEvaluationCallback, ProgressCallback
from policies.training.card import trained_card, with_card_evaluation
from policies.training.config import FINE_TUNING_ONLY, TrainConfig, TrainingError
from policies.training.run_record import (TrainSegment, open_run_record, resolve_scenario_names, restored_sampler,
                                         write_run_record)
from policies.training.scenario_envs import (ScenarioSampler, TrainEnvSpec, close_vec_env, evaluation_episodes,
                                             make_vec_env)
from scenario_bank.atomic import atomic_path

__all__ = ["planned_steps", "train"]


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


def train(config: TrainConfig, resume: bool = False, log: Callable[[str], None] = print) -> ModelCard:
    """Train (or resume) a run as described in the module docstring; returns the model card.

    Raises :class:`TrainingError` (and the registry's/bank's errors) for bad input.
    """
    config.validate()
    ignored = [name for name in FINE_TUNING_ONLY if getattr(config, name) is not None]
    if ignored:
        raise TrainingError(f"{' and '.join(ignored)} are fine-tuning settings (fine_tune applies them); to train "
                            "with another learning rate pass hyperparameters={'learning_rate': ...}, and change the "
                            "reward with env_config")
    out = Path(config.out)
    if out.exists() and not out.is_dir():
        raise TrainingError(f"--out {out} is a file; choose a folder for the run")
    names = resolve_scenario_names(config)
    run_path = out / "run.json"
    resume, record, checkpoint = open_run_record(config, names, resume, log)

    import torch

    torch.set_num_threads(1)
    env_config = config.effective_env_config()
    sampler, stream = restored_sampler(config, names, checkpoint if resume else None)
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
        write_run_record(run_path, record)
        callbacks, saver = _callbacks(config, names, env_config, sampler, planned)
        began = time.perf_counter()
        remaining = config.steps - start

        def close_segment(status: str) -> TrainSegment:
            nonlocal record
            segment = TrainSegment(start_step=start, end_step=int(model.num_timesteps), status=status,
                                   wall_time_s=round(time.perf_counter() - began, 3),
                                   resumed_from=checkpoint.name if resume else None)
            record = record.with_segment(segment)
            write_run_record(run_path, record)
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
    card = with_card_evaluation(config, names, trained_card(config, names, env_config, model, sampler, record),
                                env_config, model_path, log)
    card_path = write_card(out, card)
    log(f"wrote {model_path} and {out / 'model_card.json'} (step {model.num_timesteps}, last segment "
        f"{segment.wall_time_s:.0f} s)")
    return read_card(card_path)


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
