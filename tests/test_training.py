"""`dv2s train`: a tiny run writes the model, its card, TensorBoard logs and checkpoints; a second
invocation resumes the step counter; the curriculum upweights what the policy fails; held-out
seeds never meet training; DQN and SAC train; bad input is refused with one clear line."""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

from cli_helpers import one_line_error, run
from policies.card_record import ModelCard
from policies.model_card import bank_version, read_card
from policies.registry import SB3Policy, load_policy
from policies.training import (
    EVAL_SEED_BASE,
    TRAIN_SEED_LOW,
    ScenarioSampler,
    ScenarioSchedule,
    TrainConfig,
    TrainEnvSpec,
    TrainingError,
    latest_checkpoint,
    make_vec_env,
    train,
)

SCENARIOS = ["highway_lead_vehicle_brakes", "urban_pedestrian_crossing"]
TINY = ["--hp", "n_steps=64", "--eval-freq", "128", "--eval-seeds", "1", "--card-seeds", "1", "--baselines",
        "keep_lane", "--eval-jobs", "1", "--checkpoint-freq", "128", "--no-progress"]


# --------------------------------------------------------------------------- sampler
def test_curriculum_upweights_the_scenario_the_policy_fails():
    sampler = ScenarioSampler(["a", "b", "c"], mode="curriculum", floor=0.25, window=10)
    assert sampler.probabilities() == pytest.approx({"a": 1 / 3, "b": 1 / 3, "c": 1 / 3})
    for _ in range(10):
        sampler.record("a", failed=True)
        sampler.record("b", failed=False)
        sampler.record("c", failed=False)
    p = sampler.probabilities()
    assert sum(p.values()) == pytest.approx(1.0)
    assert p["a"] > 1 / 3 > p["b"] == pytest.approx(p["c"])
    # (10+1)/12 against 1/12 failure rates: a takes the floor's share plus 11/13 of the rest
    assert p["a"] == pytest.approx(0.25 / 3 + 0.75 * 11 / 13)
    assert min(p.values()) >= 0.25 / 3  # the floor keeps every scenario in training
    # the window forgets: once a is solved its weight comes back down
    for _ in range(10):
        sampler.record("a", failed=False)
    assert sampler.probabilities()["a"] == pytest.approx(1 / 3)
    # state round trip (saved beside each checkpoint)
    again = ScenarioSampler(["a", "b", "c"], mode="curriculum", floor=0.25, window=10)
    again.load_state_dict(json.loads(json.dumps(sampler.state_dict())))
    assert again.probabilities() == sampler.probabilities() and again.episodes == sampler.episodes


def test_uniform_and_weighted_samplers_and_their_errors():
    assert ScenarioSampler(["a", "b"]).probabilities() == {"a": 0.5, "b": 0.5}
    uniform = ScenarioSampler(["a", "b"])
    uniform.record("a", True)
    assert uniform.probabilities() == {"a": 0.5, "b": 0.5}  # only the curriculum reacts
    assert ScenarioSampler(["a", "b"], "weighted", {"a": 3}).probabilities() == {"a": 1.0, "b": 0.0}
    with pytest.raises(TrainingError, match="not trained on: zzz"):
        ScenarioSampler(["a", "b"], "weighted", {"zzz": 1})
    with pytest.raises(TrainingError, match="non-negative"):
        ScenarioSampler(["a", "b"], "weighted", {"a": -1, "b": 2})
    with pytest.raises(TrainingError, match="empty"):
        ScenarioSampler([])


class _Recorder(gym.Env):
    """Stands in for DV2S-v0: records what each reset was asked for."""

    observation_space = gym.spaces.Box(-1, 1, (2,))
    action_space = gym.spaces.Discrete(2)

    def __init__(self):
        self.calls = []

    def reset(self, *, seed=None, options=None):
        self.calls.append((seed, dict(options or {})))
        return np.zeros(2, dtype=np.float32), {}


def test_schedule_draws_scenarios_by_probability_and_seeds_outside_the_evaluation_range():
    inner = _Recorder()
    schedule = ScenarioSchedule(inner, {"a": 0.8, "b": 0.2}, seed=3)
    for _ in range(400):
        schedule.reset()
    names = [options["scenario"] for _, options in inner.calls]
    seeds = [seed for seed, _ in inner.calls]
    assert 0.72 < names.count("a") / len(names) < 0.88
    assert min(seeds) >= TRAIN_SEED_LOW > EVAL_SEED_BASE + 1000
    schedule.set_scenario_probabilities({"a": 0.0, "b": 1.0})
    schedule.reset()
    assert inner.calls[-1][1]["scenario"] == "b"
    schedule.reset(options={"scenario": "a"})  # an explicit scenario wins
    assert inner.calls[-1][1]["scenario"] == "a"
    # the same seed gives the same stream of episodes; another stream (a resumed run) another
    first, second, resumed = _Recorder(), _Recorder(), _Recorder()
    for env, stream in ((first, 0), (second, 0), (resumed, 512)):
        wrapped = ScenarioSchedule(env, {"a": 0.5, "b": 0.5}, stream=stream)
        wrapped.reset(seed=7)
        for _ in range(5):
            wrapped.reset()
    assert first.calls == second.calls != resumed.calls


def test_probabilities_reach_the_worker_envs():
    venv = make_vec_env(TrainEnvSpec(SCENARIOS, {}, None, {SCENARIOS[0]: 0.5, SCENARIOS[1]: 0.5}), n_envs=2, seed=0,
                        vec_env="dummy")
    try:
        venv.env_method("set_scenario_probabilities", {SCENARIOS[0]: 0.9, SCENARIOS[1]: 0.1})
        for probabilities in venv.get_attr("probabilities"):
            assert list(probabilities) == pytest.approx([0.9, 0.1])
    finally:
        venv.close()


# --------------------------------------------------------------------------- dv2s train
@pytest.mark.slow
def test_train_writes_model_card_logs_and_checkpoints_then_resumes(tmp_path, capsys):
    out = tmp_path / "run"
    code, _, err = run(capsys, "train", "--algo", "ppo", "--scenarios", *SCENARIOS, "--steps", 256, "--envs", 2,
                       "--seed", 1, "--sampler", "curriculum", "--curriculum-update", 64, "--out", out, *TINY)
    assert code == 0, err
    for name in ("model.zip", "model_card.json", "README.md", "run.json", "evaluations.jsonl"):
        assert (out / name).is_file(), name
    events = sorted((out / "tb").glob("PPO_1/events.out.tfevents.*"))
    assert len(events) == 1 and events[0].stat().st_size > 0
    first_checkpoint = latest_checkpoint(out)
    assert first_checkpoint is not None and first_checkpoint.with_suffix(".sampler.json").is_file()
    card = read_card(out)
    first_steps = card.training["steps"]
    assert card.algorithm == "ppo" and first_steps >= 256 and card.training["n_envs"] == 2
    assert card.bank["version"] == bank_version(SCENARIOS)["version"]
    assert sorted(card.bank["scenarios"]) == SCENARIOS
    assert card.hyperparameters["n_steps"] == 64 and card.hyperparameters["learning_rate"] == 5e-4
    assert card.training["command"].startswith("dv2s train --algo ppo --steps 256 --envs 2 --seed 1")
    assert card.training["wall_time_s"] > 0 and card.training["steps_per_s"] > 0
    evaluation = card.evaluation
    assert evaluation.seed_base == EVAL_SEED_BASE and evaluation.episodes_total == 2
    for label in ("ppo", "keep_lane"):
        for measure in ("collision", "success", "off_road"):
            rate = evaluation.policies[label].overall.measure(measure)
            assert rate["n"] == 2 and rate["lo"] <= rate["rate"] <= rate["hi"]
    assert 0 <= evaluation.comparisons["keep_lane"]["collision"]["p_two_sided"] <= 1
    assert evaluation.summary and evaluation.specs["ppo"] == "ppo:model.zip (beside this card)"
    lines = [json.loads(line) for line in (out / "evaluations.jsonl").read_text().splitlines()]
    assert lines and lines[0]["step"] >= 128 and lines[0]["episodes"] == 2

    # starting over the same folder is refused; --resume continues the step counter
    code, _, err = run(capsys, "train", "--scenarios", *SCENARIOS, "--steps", 512, "--out", out, *TINY)
    assert code == 2 and "already holds a training run" in one_line_error(err) and "--resume" in err
    code, _, err = run(capsys, "train", "--steps", 512, "--out", out, "--resume", *TINY)
    assert code == 0, err
    assert f"at step {first_steps}" in err
    card = read_card(out)
    segments = card.training["segments"]
    assert [s["start_step"] for s in segments] == [0, first_steps]
    assert segments[1]["resumed_from"] == first_checkpoint.name
    assert card.training["steps"] >= 512 and card.training["seed"] == 1  # settings came from run.json
    assert load_policy(out / "model.zip").model.num_timesteps == card.training["steps"]
    # one TensorBoard curve, continued (a second events file in the same run folder)
    assert len(list((out / "tb").glob("PPO_1/events.out.tfevents.*"))) == 2
    assert not (out / "tb" / "PPO_2").exists()
    # a resume with settings of another run is refused naming the setting
    code, _, err = run(capsys, "train", "--steps", 1024, "--seed", 5, "--out", out, "--resume", *TINY)
    assert code == 2 and "holds a training run with other settings (seed: run has 1, asked 5)" in one_line_error(err)


def _tiny_config(out: Path, algo: str, **kwargs) -> TrainConfig:
    return TrainConfig(out=str(out), algo=algo, scenarios=SCENARIOS[:1], steps=kwargs.pop("steps", 300), n_envs=1,
                       eval_freq=0, card_seeds=0, checkpoint_freq=0, progress_bar=False, vec_env="dummy", **kwargs)


def _after_start_up(err: str) -> str:
    """``err`` after the line saying the training envs start (the checkpoint is checked against their spaces)."""
    first, _, rest = err.partition("\n")
    assert first.startswith("starting 1 training env (subprocesses) on 1 scenario; "), err
    return rest


@pytest.mark.slow
def test_resume_refuses_a_broken_checkpoint_and_one_of_other_spaces(tmp_path, capsys):
    from stable_baselines3 import PPO

    out = tmp_path / "run"
    train(_tiny_config(out, "ppo", steps=64, hyperparameters={"n_steps": 64}), log=lambda line: None)
    newest = latest_checkpoint(out)
    # a checkpoint of a model made for a 5x7 observation (the env's is 8x7)
    other = PPO("MlpPolicy", _spaces_env((5, 7)), n_steps=64, device="cpu")
    other.save(out / "checkpoints" / "step_000099999.zip")
    code, _, err = run(capsys, "train", "--steps", 200000, "--out", out, "--resume", "--no-progress")
    line = one_line_error(_after_start_up(err))
    assert code == 2 and "observation space" in line and "Box(-inf, inf, (5, 7)" in line
    (out / "checkpoints" / "step_000099999.zip").write_bytes(b"not a zip")
    code, _, err = run(capsys, "train", "--steps", 200000, "--out", out, "--resume", "--no-progress")
    line = one_line_error(_after_start_up(err))
    assert code == 2 and "does not load as an SB3 model" in line and "step_000099999.zip" in line
    assert newest.is_file()


@pytest.mark.slow
def test_resume_of_a_finished_run_rewrites_its_card_and_one_stopped_before_its_first_checkpoint_starts_over(
        tmp_path):
    out = tmp_path / "run"
    lines = []
    first = train(_tiny_config(out, "ppo", steps=64, hyperparameters={"n_steps": 64}), log=lines.append)
    # what the CLI advises after Ctrl-C in the card evaluation: the same command with --resume
    again = train(_tiny_config(out, "ppo", steps=64, hyperparameters={"n_steps": 64}), resume=True,
                  log=lines.append)
    assert any("nothing to train" in line for line in lines)
    assert again.to_dict()["training"]["steps"] == first.to_dict()["training"]["steps"] == 64
    assert [s["status"] for s in again.to_dict()["training"]["segments"]] == ["finished", "finished"]
    assert read_card(out).training["steps"] == 64
    # a run folder with run.json but no checkpoint (interrupted while starting): --resume trains from step 0
    for path in (out / "checkpoints").iterdir():
        path.unlink()
    (out / "model.zip").unlink()
    lines.clear()
    card = train(_tiny_config(out, "ppo", steps=64, hyperparameters={"n_steps": 64}), resume=True,
                 log=lines.append)
    assert any("holds no checkpoint yet" in line and "step 0" in line for line in lines)
    assert [s["start_step"] for s in card.training["segments"]] == [0] and card.training["steps"] == 64
    assert latest_checkpoint(out) is not None


def _spaces_env(shape):
    class Env(gym.Env):
        observation_space = gym.spaces.Box(-np.inf, np.inf, shape, dtype=np.float32)
        action_space = gym.spaces.Discrete(5)

        def reset(self, *, seed=None, options=None):
            return np.zeros(shape, dtype=np.float32), {}

        def step(self, action):
            return np.zeros(shape, dtype=np.float32), 0.0, True, False, {}

    return Env()


@pytest.mark.slow
@pytest.mark.parametrize("algo", ["dqn", "sac"])
def test_dqn_and_sac_train_tiny_and_load_through_the_registry(tmp_path, algo):
    out = tmp_path / algo
    hyperparameters = {"learning_starts": 50, "buffer_size": 1000, "batch_size": 16}
    card = train(_tiny_config(out, algo, steps=200, hyperparameters=hyperparameters), log=lambda line: None)
    assert card.algorithm == algo and card.training["steps"] >= 200
    policy = load_policy(out / "model.zip")
    assert isinstance(policy, SB3Policy) and policy.card.algorithm == algo
    if algo == "sac":  # SAC needs a continuous action space: train sets it
        assert card.env_config["action"] == {"type": "ContinuousAction"}
        assert isinstance(policy.action_space, gym.spaces.Box)
    else:
        assert "action" not in card.env_config and isinstance(policy.action_space, gym.spaces.Discrete)
    # the replay buffer is checkpointed so a resumed off-policy run keeps its experience
    assert latest_checkpoint(out).with_suffix(".replay.pkl").is_file()
    from policies.evaluation import evaluate

    result = evaluate(policy, [(SCENARIOS[0], EVAL_SEED_BASE)], config=card.env_config)[0]
    assert result.steps > 0 and result.error is None


def _train_on_defaults(capsys, tmp_path: Path, algo: str) -> Path:
    """`dv2s train --algo ALGO` for 64 steps without --hp; the run folder."""
    out = tmp_path / algo
    code, _, err = run(capsys, "train", "--algo", algo, "--scenarios", SCENARIOS[0], "--steps", 64, "--envs", 1,
                       "--seed", 0, "--vec-env", "dummy", "--eval-freq", 0, "--card-seeds", 0, "--checkpoint-freq", 0,
                       "--no-progress", "--out", out)
    assert code == 0, err
    return out


@pytest.mark.slow
def test_dqn_trains_with_its_default_learning_rate_and_exploration(tmp_path, capsys):
    """`dv2s train --algo dqn` without --hp: the saved model's optimiser steps at 5e-4 and its exploration rate
    falls linearly from 1 to 0.05 over the first 70 % of the run (highway-env's documented DQN settings for highway),
    and its card says so."""
    from stable_baselines3 import DQN

    out = _train_on_defaults(capsys, tmp_path, "dqn")
    model = DQN.load(out / "model.zip", device="cpu")
    assert model.learning_rate == 5e-4 and model.exploration_fraction == 0.7
    assert [group["lr"] for group in model.policy.optimizer.param_groups] == [5e-4]
    # the schedule the model explores with: 35 % into the run it is half-way down from 1 to 0.05; at 70 % down
    assert model.exploration_schedule(1 - 0.35) == pytest.approx(1 - 0.95 * 0.5)
    assert model.exploration_schedule(1 - 0.7) == pytest.approx(0.05)
    assert model.exploration_schedule(1 - 0.3) > 0.05
    assert (model.exploration_initial_eps, model.exploration_final_eps) == (1.0, 0.05)
    hyperparameters = read_card(out).hyperparameters
    assert hyperparameters["learning_rate"] == 5e-4 and hyperparameters["exploration_fraction"] == 0.7


@pytest.mark.slow
def test_sac_trains_with_its_default_hyperparameters(tmp_path, capsys):
    """`dv2s train --algo sac` without --hp: the saved model learns at 3e-4 (actor, critics and entropy coefficient)
    from a 50 000-transition replay buffer, starting after 1000 steps, in batches of 256, with gamma 0.9 and
    [256, 256] layers, on ContinuousAction; its card says so."""
    from stable_baselines3 import SAC

    out = _train_on_defaults(capsys, tmp_path, "sac")
    model = SAC.load(out / "model.zip", device="cpu")
    assert model.learning_rate == 3e-4 and model.lr_schedule(0.5) == 3e-4
    optimizers = (model.actor.optimizer, model.critic.optimizer, model.ent_coef_optimizer)
    assert [group["lr"] for optimizer in optimizers for group in optimizer.param_groups] == [3e-4] * 3
    assert (model.buffer_size, model.learning_starts, model.batch_size, model.gamma) == (50_000, 1000, 256, 0.9)
    assert model.policy.net_arch == [256, 256]
    card = read_card(out)
    assert card.hyperparameters == {"policy": "MlpPolicy", "net_arch": [256, 256], "learning_rate": 3e-4,
                                       "buffer_size": 50_000, "learning_starts": 1000, "batch_size": 256,
                                       "gamma": 0.9}
    assert card.env_config["action"] == {"type": "ContinuousAction"}


def test_a_short_run_gets_a_short_card_evaluation_unless_told_otherwise():
    from policies.training import CARD_SEEDS, SHORT_RUN_CARD_SEEDS, SHORT_RUN_STEPS, TrainConfig

    assert TrainConfig(out="o", steps=2_000).card_seed_count() == SHORT_RUN_CARD_SEEDS < CARD_SEEDS
    assert TrainConfig(out="o", steps=SHORT_RUN_STEPS).card_seed_count() == CARD_SEEDS
    assert TrainConfig(out="o", steps=2_000, card_seeds=20).card_seed_count() == 20
    assert TrainConfig(out="o", steps=400_000, card_seeds=0).card_seed_count() == 0
    # the command line names the seeds only when they were set
    assert "--card-seeds" not in TrainConfig(out="o", steps=2_000).command()
    assert "--card-seeds 20" in TrainConfig(out="o", steps=2_000, card_seeds=20).command()
    with pytest.raises(TrainingError, match="--card-seeds must be an integer >= 0"):
        TrainConfig(out="o", card_seeds=-1).validate()


def test_bad_training_input_is_one_clear_line(tmp_path, capsys):
    out = tmp_path / "run"
    code, _, err = run(capsys, "train", "--scenarios", "nonexistent_scenario", "--out", out)
    assert code == 2 and "nonexistent_scenario" in one_line_error(err)
    code, _, err = run(capsys, "train", "--scenarios", "--out", out)
    assert code == 2 and "scenario selection is empty" in one_line_error(err)
    code, _, err = run(capsys, "train", "--scenarios", "tag:no_such_tag", "--out", out)
    assert code == 2 and "no_such_tag" in one_line_error(err)
    code, _, err = run(capsys, "train", "--algo", "dqn", "--config", '{"action": {"type": "ContinuousAction"}}',
                       "--out", out)
    assert code == 2 and "DQN needs a DiscreteMetaAction or DiscreteAction action space" in one_line_error(err)
    code, _, err = run(capsys, "train", "--hp", "learning_rat=0.1", "--out", out)
    assert code == 2 and "unknown PPO hyperparameter(s) learning_rat" in one_line_error(err)
    code, _, err = run(capsys, "train", "--steps", 0, "--out", out)
    assert code == 2 and "--steps must be an integer >= 1" in one_line_error(err)
    code, _, err = run(capsys, "train", "--sampler", "weighted", "--out", out)
    assert code == 2 and "--weights" in one_line_error(err)
    code, _, err = run(capsys, "train", "--resume", "--out", out)
    assert code == 2 and "holds no training run" in one_line_error(err)
    assert not out.exists() or not any(out.iterdir())


# --------------------------------------------------------------------------- model card statistics
def test_card_statistics_agree_with_the_regression_stats_module():
    from dv2s_gym.regress.stats import PairedTable, mcnemar_exact, wilson_interval
    from policies.model_card import compare_paired, rate

    assert (rate(7, 40).low, rate(7, 40).high) == pytest.approx(wilson_interval(7, 40))
    candidate = "CSSSSSSSS-OSSSSSSSSS" * 2
    baseline = "CCCCCSSSCCSSSSSSSSS-" * 2
    comparison = compare_paired(candidate, baseline, "collision")
    table = PairedTable.from_outcomes([c == "C" for c in candidate], [b == "C" for b in baseline])
    assert comparison["table"]["candidate_only"] == table.candidate_only == 0
    assert comparison["table"]["baseline_only"] == table.baseline_only == 12
    assert comparison["p_candidate_better"] == pytest.approx(mcnemar_exact(table, alternative="less"))
    assert comparison["p_two_sided"] == pytest.approx(mcnemar_exact(table, alternative="two-sided"))
    assert comparison["p_candidate_better"] < 0.001 < comparison["p_candidate_worse"]
    success = compare_paired(candidate, baseline, "success")  # more successes is better
    assert (success["table"]["candidate_only"], success["table"]["baseline_only"]) == (12, 2)
    assert success["p_candidate_better"] == pytest.approx(mcnemar_exact(
        PairedTable.from_outcomes([c != "S" for c in candidate], [b != "S" for b in baseline]), alternative="less"))
    assert success["p_candidate_better"] < 0.01


def test_card_summary_says_where_the_policy_is_worse():
    from policies.evaluation import EpisodeResult
    from policies.model_card import evaluation_section

    def result(scenario, seed, collided):
        return EpisodeResult(scenario=scenario, seed=seed, scene_seed=seed, params={}, collided=collided,
                             collisions=["car"] if collided else [], off_road=False, success=not collided,
                             min_ttc=1.0, mean_speed=10.0, distance=50.0, episode_return=1.0, steps=10,
                             trajectory_hash="")

    episodes = [(name, seed) for name in ("a", "b") for seed in range(10)]
    candidate = [result(s, seed, s == "a" and seed < 8) for s, seed in episodes]
    baseline = [result(s, seed, False) for s, seed in episodes]
    section = evaluation_section({"ppo": candidate, "rule": baseline}, episodes, candidate="ppo")
    assert section.policies["ppo"].outcomes == {"a": "CCCCCCCC" + "SS", "b": "S" * 10}
    assert section.policies["ppo"].overall.collision["k"] == 8 and section.policies["rule"].overall.errors == 0
    assert section.scenarios == ("a", "b") and section.to_dict()["seed_base"] is None  # written as null
    text = " ".join(section.summary)
    assert "On collision rate the ppo does NOT beat (it is significantly worse than) rule" in text
    assert "collides more often than rule on 1 scenario(s): a (8/10 collisions against 0/10)" in text


@pytest.mark.slow
def test_the_same_settings_train_the_same_model(tmp_path):
    """What makes a card reproducible from its command: same seed, same settings, same weights
    (two subprocess envs, as `dv2s train` runs them)."""
    import torch

    weights = []
    for run_name in ("first", "second"):
        config = TrainConfig(out=str(tmp_path / run_name), scenarios=SCENARIOS, steps=128, n_envs=2, seed=3,
                             sampler="curriculum", curriculum_update=32, hyperparameters={"n_steps": 64},
                             eval_freq=0, card_seeds=0, checkpoint_freq=0, progress_bar=False)
        train(config, log=lambda line: None)
        weights.append(load_policy(tmp_path / run_name / "model.zip").model.policy.state_dict())
    assert weights[0].keys() == weights[1].keys()
    assert all(torch.equal(weights[0][key], weights[1][key]) for key in weights[0])


def test_the_steps_a_run_really_trains_are_said_before_it_starts():
    from types import SimpleNamespace

    from policies.training import planned_steps

    ppo = SimpleNamespace(n_steps=512, n_envs=2)
    assert planned_steps(ppo, 0, 2000) == (2048, "2,000 steps asked: trains to 2,048 (stable-baselines3 trains "
                                                  "whole rollouts of 1,024 = 512 steps x 2 envs)")
    assert planned_steps(ppo, 908, 2000)[0] == 2956 and "from step 908" in planned_steps(ppo, 908, 2000)[1]
    assert planned_steps(ppo, 0, 2048) == (2048, "training 2,048 steps: 2 rollouts of 1,024 (512 steps x 2 envs)")
    assert planned_steps(ppo, 4096, 2048) == (4096, None)  # nothing left to train


@pytest.mark.slow
def test_train_logs_its_start_up_and_the_steps_it_trains_to(tmp_path):
    lines = []
    card = train(_tiny_config(tmp_path / "run", "ppo", steps=300, hyperparameters={"n_steps": 128}), log=lines.append)
    assert card.training["steps"] == 384
    assert any(line.startswith("starting 1 training env (in this process) on 1 scenario") for line in lines), lines
    assert "300 steps asked: trains to 384 (stable-baselines3 trains whole rollouts of 128 = 128 steps x 1 env)" \
        in lines


def test_a_card_whose_evaluation_was_interrupted_says_so_and_how_to_complete_it():
    from policies.model_card import render_markdown

    card = {"name": "run", "algorithm": "ppo", "evaluation": None,
            "training": {"command": "dv2s train --steps 2000 --out out/train/run"}}
    text = render_markdown(ModelCard.from_dict(card))
    assert "Not evaluated: the held-out evaluation was interrupted" in text
    assert "`dv2s train --steps 2000 --out out/train/run --resume`" in text
    skipped = ModelCard.from_dict({k: v for k, v in card.items() if k != "evaluation"})
    assert "Not evaluated" not in render_markdown(skipped)


def test_the_card_evaluation_says_how_long_it_has_left_once_its_first_episodes_are_done(monkeypatch):
    import time

    from policies.model_card import TimeLeft

    now = [100.0]
    monkeypatch.setattr(time, "perf_counter", lambda: now[0])
    lines = []
    left = TimeLeft(288, lines.append, "model card evaluation")
    for _ in range(3):
        now[0] += 20.0
        left.update(4)  # 12 episodes in 60 s: 14 of them (a twentieth) needed first
    assert lines == []
    now[0] += 10.0
    left.update(4)
    now[0] += 10.0
    left.update(4)
    assert lines == ["model card evaluation: 16 of 288 episodes in 70 s; about 20 min left"]
