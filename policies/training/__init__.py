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

The package in modules: the run's settings (:mod:`.config`), the training envs and their scenario sampling
(:mod:`.scenario_envs`), the run folder and its resume (:mod:`.run_record`), the callbacks (:mod:`.callbacks`), the
model card (:mod:`.card`), the training loop (:mod:`.learning`) and fine-tuning (:mod:`.fine_tuning`). Import the
names below from here.
"""

from policies.evaluation import EVAL_SEED_BASE, TRAIN_SEED_LOW
from policies.training.callbacks import CheckpointSaver, CurriculumCallback, HeldOutEvaluationCallback, ProgressCallback
from policies.training.config import (ALGORITHMS, CARD_SEEDS, DEFAULT_HYPERPARAMETERS, SAMPLERS, SHORT_RUN_CARD_SEEDS,
                                      SHORT_RUN_STEPS, TRAIN_SEED_HIGH, TrainConfig, TrainingError)
from policies.training.fine_tuning import (check_source_observation, fine_tune, fine_tune_scenarios, resolve_checkpoint,
                                           with_reward_weights)
from policies.training.learning import planned_steps, train
from policies.training.run_record import latest_checkpoint, load_run_config, run_settings
from policies.training.scenario_envs import (ScenarioSampler, ScenarioSchedule, TrainEnvSpec, close_vec_env,
                                             evaluation_episodes, make_train_env, make_vec_env)

__all__ = [
    "ALGORITHMS",
    "SAMPLERS",
    "EVAL_SEED_BASE",
    "TRAIN_SEED_LOW",
    "TRAIN_SEED_HIGH",
    "CARD_SEEDS",
    "SHORT_RUN_STEPS",
    "SHORT_RUN_CARD_SEEDS",
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
    "planned_steps",
    "train",
    "resolve_checkpoint",
    "fine_tune",
    "fine_tune_scenarios",
    "with_reward_weights",
    "check_source_observation",
]
