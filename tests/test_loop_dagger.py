"""DAgger fine-tuning (`dv2s loop --fine-tune-method dagger`): the labelling wrapper, the policy's actions
moving toward the reference driver's, a loadable checkpoint with its card, and the loop using it."""

from __future__ import annotations

import json

import numpy as np
import pytest

from scenario_bank.run_identity import RunIdentityError
from dv2s_gym.loop.settings import LoopError
from envs.dv2s_env import DV2SEnv
from cli_helpers import run
from loop_helpers import FakeMiner, run_loop
from policies.imitation import ReferenceLabels, agreement
from fine_tune_helpers import dagger_fine_tune
from policies.model_card import read_card
from policies.registry import SHIPPED_CHECKPOINT, load_policy
from policies.rule_based import CautiousDriver
from policies.training import TrainingError, resolve_checkpoint

SOURCES = ["highway_lead_vehicle_brakes", "urban_pedestrian_crossing"]
SHIPPED_CONFIG = read_card(SHIPPED_CHECKPOINT).env_config


def _labelled_states(spec, scenario, seeds, beta=0.0):
    """Roll ``spec`` out (greedy) on ``scenario`` with the labelling wrapper: (observations, reference labels)."""
    env = ReferenceLabels(DV2SEnv(scenario=scenario, config=dict(SHIPPED_CONFIG)), beta=beta, seed=1)
    model = load_policy(spec).model
    observations, labels = [], []
    try:
        for seed in seeds:
            obs, _ = env.reset(seed=seed)
            done = False
            while not done:
                action, _ = model.predict(obs, deterministic=True)
                observations.append(np.asarray(obs, dtype=np.float32))
                obs, _, terminated, truncated, info = env.step(action)
                labels.append(info["reference_action"])
                done = terminated or truncated
    finally:
        env.close()
    return np.stack(observations), np.asarray(labels)


def test_labels_are_the_reference_drivers_actions_and_beta_mixes_them_in():
    config = dict(SHIPPED_CONFIG)
    plain = DV2SEnv(scenario=SOURCES[1], config=config)
    driver = CautiousDriver(plain)
    expected = []
    obs, _ = plain.reset(seed=3)
    for _ in range(25):  # the rule driver driving alone
        action = driver.act()
        expected.append(action)
        plain.step(action)
    plain.close()
    # beta 1: the wrapper executes the reference whatever it is given, and labels match a lone driver's actions
    wrapped = ReferenceLabels(DV2SEnv(scenario=SOURCES[1], config=config), beta=1.0)
    wrapped.reset(seed=3)
    seen = []
    for _ in range(25):
        _, _, _, _, info = wrapped.step(0)  # LANE_LEFT asked every step, never executed
        assert info["executed_action"] == info["reference_action"]
        seen.append(info["reference_action"])
    assert seen == expected
    # beta 0: the given action runs, the label still comes from the reference
    wrapped.set_beta(0.0)
    wrapped.reset(seed=3)
    infos = [wrapped.step(3)[4] for _ in range(10)]
    assert all(i["executed_action"] == 3 for i in infos)
    assert {i["reference_action"] for i in infos} <= set(range(5))
    wrapped.close()
    with pytest.raises(TrainingError, match=r"beta must be in \[0, 1\]"):
        wrapped.set_beta(1.5)
    with pytest.raises(TrainingError, match="reads the simulator state"):
        ReferenceLabels(DV2SEnv(scenario=SOURCES[0], config=config), reference="random")


@pytest.mark.slow
def test_dagger_moves_the_policy_toward_the_reference_and_saves_a_loadable_checkpoint(tmp_path):
    out = tmp_path / "dagger"
    weights = {SOURCES[0]: 1.0, SOURCES[1]: 3.0}
    # plain DAgger (SLOWER not up-weighted): the claim checked is agreement with the reference, which the
    # default weighting trades for caution; three iterations, so the last one's states are mostly the student's
    path = dagger_fine_tune("dv2s-ppo", bank_dir=None, out=out, steps=3600, weights=weights, n_envs=1,
                            vec_env="dummy", iterations=3, epochs=8, learning_rate=1e-3, slower_weight=1.0,
                            progress_bar=False, log=lambda _: None)
    # a normal SB3 checkpoint: loads through the registry and the loop's resolver, acts in Discrete(5)
    assert resolve_checkpoint(str(path))[0] == "ppo"
    policy = load_policy(f"ppo:{path}")
    assert type(policy.model).__name__ == "PPO"
    card = read_card(path)
    tuned = card.fine_tune.to_dict()
    assert tuned["method"] == "dagger" and tuned["reference"] == "rule" and tuned["steps"] == 3600
    assert [h["beta"] for h in tuned["history"]] == [1.0, 0.5, 0.25]
    assert sum(h["steps"] for h in tuned["history"]) == tuned["agreement"]["states"] == 3600
    assert card.env_config == SHIPPED_CONFIG and card.evaluation is None and not card.evaluation_interrupted
    assert "DAgger" in (out / "README.md").read_text()
    # on the states it was trained on, the greedy action agrees with the reference far more often than before
    assert tuned["agreement"]["fine_tuned"] >= tuned["agreement"]["source"] + 0.2
    # and on fresh states (new reset seeds, each policy driving itself), measured here, not read from the card
    fresh = [(scenario, list(range(50, 53))) for scenario in SOURCES]
    before = [agreement(load_policy("dv2s-ppo").model, *_labelled_states("dv2s-ppo", s, seeds)) for s, seeds in fresh]
    after = [agreement(policy.model, *_labelled_states(f"ppo:{path}", s, seeds)) for s, seeds in fresh]
    assert np.mean(after) >= np.mean(before) + 0.15, (before, after)
    # finished: called again it returns the same file without training
    stamp = path.stat().st_mtime_ns
    assert dagger_fine_tune("dv2s-ppo", bank_dir=None, out=out, steps=3600, weights=weights, n_envs=1,
                            vec_env="dummy", progress_bar=False, log=lambda _: None) == path
    assert path.stat().st_mtime_ns == stamp


def test_dagger_refuses_bad_settings(tmp_path):
    with pytest.raises(TrainingError, match="steps must be an integer >= 1"):
        dagger_fine_tune("dv2s-ppo", bank_dir=None, out=tmp_path / "a", steps=0, weights={SOURCES[0]: 1.0})
    with pytest.raises(TrainingError, match="positive weight"):
        dagger_fine_tune("dv2s-ppo", bank_dir=None, out=tmp_path / "b", steps=10, weights={SOURCES[0]: 0.0})
    with pytest.raises(TrainingError, match="stable-baselines3 checkpoint"):
        dagger_fine_tune("rule", bank_dir=None, out=tmp_path / "c", steps=10, weights={SOURCES[0]: 1.0})
    assert not any(tmp_path.iterdir())


@pytest.mark.slow
def test_the_loop_runs_end_to_end_with_dagger(tmp_path):
    out = tmp_path / "loop"
    miner = FakeMiner(SOURCES, failures_per_round=4)
    tiny = dict(budget=6, fine_tune_steps=200, k_eval=2, regress_episodes=1, workers=1, n_envs=1, progress=False,
                scenarios=SOURCES, min_heldout_episodes=1, untouched_seeds=0, log=lambda _: None)
    report = run_loop("dv2s-ppo", out=out, miner=miner, fine_tune_method="dagger", **tiny)
    steps = report.rounds[0].to_dict()["steps"]
    assert set(steps) == {"mine", "split", "reference", "before", "fine_tune", "control", "after", "regress"}
    assert steps["control"]["method"] == "dagger" and steps["control"]["steps"] == tiny["fine_tune_steps"]
    tuned = steps["fine_tune"]
    assert tuned["method"] == "dagger" and tuned["reward_weights"] is None and tuned["env_config"] == SHIPPED_CONFIG
    card = read_card(tuned["model"])
    assert card.fine_tune.method == "dagger"
    held = steps["split"]["held_out"]
    assert held and not set(held) & set(card.sampler["weights"])  # never trained on a held-out scenario
    assert steps["after"]["pairs"] == 2 * len(held)
    assert steps["regress"]["verdict"] in ("PASS", "FAIL", "INCONCLUSIVE")
    assert report.policy.startswith("ppo:") and report.policy.endswith("model.zip")
    state = json.loads((out / "loop.json").read_text())
    assert state["settings"]["fine_tune_method"] == "dagger"
    assert "DAgger" in report.paths["md"].read_text()
    assert "(dagger)" in report.paths["html"].read_text()
    assert state["settings"]["fine_tune_lr"] == 1e-3  # DAgger's own learning rate when none is given
    # the method is part of the loop's identity
    with pytest.raises(RunIdentityError, match="fine_tune_method: run has 'dagger', asked 'ppo'"):
        run_loop("dv2s-ppo", out=out, miner=miner, fine_tune_method="ppo", fine_tune_lr=1e-3, **tiny)


def test_cli_refuses_an_unknown_method_in_one_line(tmp_path, capsys):
    with pytest.raises(SystemExit):
        run(capsys, "loop", "--out", tmp_path / "loop", "--no-progress", "--fine-tune-method", "bc")
    assert "invalid choice: 'bc'" in capsys.readouterr().err
    assert not (tmp_path / "loop").exists()
    with pytest.raises(LoopError, match="--fine-tune-method must be one of ppo, dagger"):
        run_loop("dv2s-ppo", out=tmp_path / "loop2", miner=FakeMiner(SOURCES), fine_tune_method="bc")
