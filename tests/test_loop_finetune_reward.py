"""The fine-tuning env config of `dv2s loop`: reward-term overrides reach the training env and the model
card, and never the envs that mine, evaluate the held-out scenarios or regression-test."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

import policies.training as training
import policies.training.scenario_envs as scenario_envs
from cli_helpers import one_line_error, run
from scenario_bank.records import HeldOutEpisode
from scenario_bank.run_identity import RunIdentityError
from dv2s_gym.loop.settings import DEFAULTS, LoopError
from loop_helpers import FakeMiner, run_loop
from policies.model_card import read_card
from policies.registry import SHIPPED_CHECKPOINT
from policies.training import TrainingError, with_reward_weights
from fine_tune_helpers import fine_tune

SOURCES = ["highway_lead_vehicle_brakes", "urban_pedestrian_crossing"]
SHIPPED_CONFIG = read_card(SHIPPED_CHECKPOINT).env_config


def test_reward_overrides_change_only_the_named_terms():
    config = with_reward_weights(SHIPPED_CONFIG, {"standing": -1.0, "low_ttc": -0.8})
    weights = config["reward_weights"]
    assert weights["standing"] == -1.0 and weights["low_ttc"] == -0.8
    for name, value in SHIPPED_CONFIG["reward_weights"].items():
        if name not in ("standing", "low_ttc"):
            assert weights[name] == value
    assert "standing" not in SHIPPED_CONFIG["reward_weights"]  # the source config is not modified
    assert with_reward_weights(SHIPPED_CONFIG, {}) == SHIPPED_CONFIG
    # a config without reward weights starts from DV2S-v0's defaults
    from envs.dv2s_env import DV2SEnv

    defaults = DV2SEnv.default_config()["reward_weights"]
    assert with_reward_weights({}, {"standing": -0.5})["reward_weights"] == {**defaults, "standing": -0.5}
    with pytest.raises(TrainingError, match="unknown reward term.*stall"):
        with_reward_weights(SHIPPED_CONFIG, {"stall": -1.0})
    with pytest.raises(TrainingError, match="finite number"):
        with_reward_weights(SHIPPED_CONFIG, {"standing": float("nan")})


@pytest.mark.slow
def test_fine_tune_trains_with_the_overridden_reward_and_records_it(tmp_path, monkeypatch):
    seen = []
    build = scenario_envs._build_train_env

    def recording_build(*args, **kwargs):
        env = build(*args, **kwargs)
        seen.append(dict(env.unwrapped.config["reward_weights"]))
        return env

    monkeypatch.setattr(scenario_envs, "_build_train_env", recording_build)
    path = fine_tune("dv2s-ppo", bank_dir=None, out=tmp_path / "ft", steps=10, weights={SOURCES[0]: 1.0}, n_envs=1,
                     vec_env="dummy", progress_bar=False, reward_weights={"standing": -1.0}, log=lambda _: None)
    assert seen and all(w["standing"] == -1.0 for w in seen)  # the env the policy trained in
    assert all(w["collision"] == SHIPPED_CONFIG["reward_weights"]["collision"] for w in seen)
    card = read_card(path)
    assert card.env_config["reward_weights"] == {**SHIPPED_CONFIG["reward_weights"], "standing": -1.0}
    assert card.fine_tune.reward_weights == {"standing": -1.0}
    assert '"standing": -1.0' in (tmp_path / "ft" / "README.md").read_text()


def _stub_fine_tune(calls):
    def stub(spec, config, **kwargs):
        out, env_config, reward_weights = config.out, config.env_config, config.reward_weights
        calls.append({"env_config": env_config, "reward_weights": reward_weights, "training_config":
                      with_reward_weights(env_config, reward_weights)})
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        shutil.copy(SHIPPED_CHECKPOINT, out / "model.zip")
        card = read_card(SHIPPED_CHECKPOINT).to_dict()
        card.update(env_config=with_reward_weights(env_config, reward_weights), fine_tune={"source": spec})
        (out / "model_card.json").write_text(json.dumps(card))
        return out / "model.zip"
    return stub


def test_loop_fine_tunes_with_its_reward_but_evaluates_with_the_policys_config(tmp_path, monkeypatch):
    import dv2s_gym.loop.heldout as heldout
    import dv2s_gym.regress.runner as runner

    fine_tunes, evaluations, regressions = [], [], []
    monkeypatch.setattr(training, "fine_tune", _stub_fine_tune(fine_tunes))

    def fake_evaluate(role, policy, episodes, *, env_config=None, **kwargs):
        evaluations.append((role, env_config))
        return [HeldOutEpisode(role=role, scenario=s, seed=seed, failed=role == "before")
                for s, seed in episodes]

    def fake_regression(candidate, baseline, settings, **kwargs):
        regressions.append(settings.env_config)
        return {"verdict": "PASS", "overall": {}}

    monkeypatch.setattr(heldout, "evaluate_heldout", fake_evaluate)
    monkeypatch.setattr(runner, "run_regression", fake_regression)
    miner = FakeMiner(SOURCES, failures_per_round=4)
    reward = {"standing": -0.7, "low_ttc": -0.5}
    report = run_loop("dv2s-ppo", out=tmp_path / "loop", miner=miner, fine_tune_method="ppo", budget=6,
                      fine_tune_steps=100, k_eval=3, regress_episodes=1, workers=1, n_envs=1, progress=False,
                      scenarios=SOURCES, fine_tune_reward=reward, min_heldout_episodes=1, min_heldout_families=1,
                      untouched_seeds=0,
                      log=lambda _: None)
    expected = with_reward_weights(SHIPPED_CONFIG, reward)
    assert len(fine_tunes) == 2  # the fine-tuning and its control arm, with the same reward
    assert all(call["training_config"] == expected for call in fine_tunes)
    # everything that counts failures runs the policy's own env config
    assert miner.calls[0]["env_config"] == SHIPPED_CONFIG
    assert evaluations and all(config == SHIPPED_CONFIG for _, config in evaluations)
    assert regressions == [SHIPPED_CONFIG]
    steps = report.rounds[0].to_dict()["steps"]
    assert steps["fine_tune"]["reward_weights"] == reward and steps["fine_tune"]["env_config"] == expected
    assert steps["after"]["relative_drop"] == 1.0
    state = json.loads((tmp_path / "loop" / "loop.json").read_text())
    assert state["settings"]["fine_tune_reward"] == reward
    assert state["settings"]["fine_tune_env_config"] == expected
    assert state["settings"]["env_config"] == SHIPPED_CONFIG
    assert "low_ttc -0.5, standing -0.7" in report.paths["md"].read_text()
    assert "low_ttc -0.5, standing -0.7" in report.paths["html"].read_text()
    # the reward is part of the loop's identity: resuming with another one is refused
    with pytest.raises(RunIdentityError, match="fine_tune_reward: run has"):
        run_loop("dv2s-ppo", out=tmp_path / "loop", miner=miner, fine_tune_method="ppo", budget=6,
                 fine_tune_steps=100, k_eval=2, regress_episodes=1, workers=1, n_envs=1, progress=False,
                 scenarios=SOURCES, min_heldout_episodes=1, untouched_seeds=0, log=lambda _: None)


def test_the_default_fine_tune_reward_penalises_the_stall():
    assert DEFAULTS["fine_tune_reward"]["standing"] < 0


@pytest.mark.parametrize("value, needle", [
    ('{"stall": -1}', "unknown reward term(s) stall"),
    ("[1]", "--fine-tune-reward must be a JSON object"),
    ("{standing", "--fine-tune-reward must be a JSON object"),
])
def test_cli_refuses_a_bad_fine_tune_reward_in_one_line(tmp_path, capsys, value, needle):
    code, _, err = run(capsys, "loop", "--out", tmp_path / "loop", "--no-progress", "--fine-tune-reward", value)
    assert code == 2 and needle in one_line_error(err)
    assert not (tmp_path / "loop").exists()


@pytest.mark.parametrize("field, value", [("learning_rate", 1e-4), ("reward_weights", {"standing": -1.0})])
def test_train_refuses_a_fine_tuning_setting_it_would_ignore(tmp_path, field, value):
    config = training.TrainConfig(out=str(tmp_path / "run"), steps=10, **{field: value})
    with pytest.raises(TrainingError, match=f"{field}.*fine-tuning settings"):
        training.train(config, log=lambda _: None)
    assert not (tmp_path / "run").exists()


def test_a_fine_tuning_config_records_its_own_settings_only_when_set(tmp_path):
    plain = training.TrainConfig.fine_tuning(tmp_path, steps=10, weights={SOURCES[0]: 1.0})
    assert "learning_rate" not in plain.to_json() and "reward_weights" not in plain.to_json()
    tuned = training.TrainConfig.fine_tuning(tmp_path, steps=10, weights={SOURCES[0]: 1.0}, learning_rate=1e-4)
    assert training.TrainConfig.from_json(tuned.to_json()) == tuned
    with pytest.raises(TrainingError, match="learning_rate"):
        training.TrainConfig.fine_tuning(tmp_path, steps=10, weights={SOURCES[0]: 1.0}, learning_rate=-1.0)
