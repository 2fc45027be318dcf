"""DAgger's ``disagreement_weight``: the labelled states where the collecting student's greedy action was not the
reference's label weigh more in the imitation loss, so a rare label the student keeps missing is learnt."""

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3.common.policies import ActorCriticPolicy

import policies.imitation as imitation
from policies.dagger_checkpoint import DAggerCheckpoint, LabelledBatch
from policies.state_driver import FASTER, IDLE, SLOWER


class _Model:  # the parts of an SB3 model that DAgger's training and agreement read
    def __init__(self, idle_bias: float = 0.0):
        space = gym.spaces.Box(-1.0, 1.0, shape=(8, 7), dtype=np.float32)
        self.policy = ActorCriticPolicy(space, gym.spaces.Discrete(5), lambda _: 1e-3)
        with torch.no_grad():  # a student that starts out preferring IDLE, as one that stands and waits
            self.policy.action_net.bias.copy_(torch.tensor([0.0, idle_bias, 0.0, 0.0, 0.0]))

    def predict(self, observations, deterministic=True):
        with torch.no_grad():
            distribution = self.policy.get_distribution(torch.as_tensor(observations))
            return distribution.get_actions(deterministic=deterministic).numpy(), None


def _states(seed: int, n: int):
    """One varying feature; the label is FASTER on its top tenth (the rare class), IDLE elsewhere."""
    rng = np.random.default_rng(seed)
    observations = np.zeros((n, 8, 7), dtype=np.float32)
    observations[:, 0, 0] = rng.uniform(-1.0, 1.0, n)
    return observations, np.where(observations[:, 0, 0] > 0.8, FASTER, IDLE)


def _fit(disagreement_weight: float):
    """Collect-then-train as a DAgger iteration does: the student's disagreements with the labels are taken
    before training, then 4 epochs of Adam on the weighted loss. Returns (recall of the rare label, accuracy on
    the common one) on fresh states."""
    torch.manual_seed(0)
    model = _Model(idle_bias=1.0)
    observations, labels = _states(0, 1000)
    disagreed = imitation._greedy(model, observations) != labels
    optimizer = torch.optim.Adam(model.policy.parameters(), lr=1e-3)
    imitation._train(model, optimizer, observations, labels, 4, 64, np.random.default_rng(0),
                     imitation.loss_weights(labels, disagreed, 1.0, disagreement_weight))
    test_obs, test_labels = _states(100, 1000)
    actions = model.predict(test_obs)[0]
    rare = test_labels == FASTER
    return float(np.mean(actions[rare] == FASTER)), float(np.mean(actions[~rare] == IDLE))


@pytest.mark.slow
def test_a_rare_label_the_student_misses_is_learnt_with_the_disagreement_weight():
    plain_recall, plain_common = _fit(1.0)
    weighted_recall, weighted_common = _fit(4.0)
    assert plain_recall <= 0.5 and plain_common == 1.0  # the plain mean leaves the rare label to the common one
    assert weighted_recall >= 0.9  # weighted, the student presses the rare action where it is labelled
    assert weighted_common >= 0.6  # at the price of some common states next to the rare ones, not of all


def test_the_weights_multiply_the_slower_weight_in_the_loss():
    torch.manual_seed(0)
    model = _Model()
    observations = np.random.default_rng(0).uniform(-1, 1, size=(6, 8, 7)).astype(np.float32)
    labels = np.array([IDLE, SLOWER, FASTER, SLOWER, IDLE, FASTER])
    disagreed = np.array([False, True, True, False, False, False])
    with torch.no_grad():
        nll = -model.policy.get_distribution(torch.as_tensor(observations)).log_prob(torch.as_tensor(labels)).numpy()
    weights = np.where(labels == SLOWER, 3.0, 1.0) * np.where(disagreed, 4.0, 1.0)
    optimizer = torch.optim.SGD(model.policy.parameters(), lr=0.0)  # a step that changes nothing
    loss = imitation.imitation_step(model, optimizer, observations, labels,
                                    weights=imitation.loss_weights(labels, disagreed, 3.0, 4.0))
    assert loss == pytest.approx(float((weights * nll).sum() / weights.sum()), rel=1e-5)
    assert imitation.loss_weights(labels, disagreed, 1.0, 1.0) is None  # both 1: the plain mean, as before
    assert imitation.loss_weights(labels, disagreed, 3.0, 1.0).tolist() == [1, 3, 1, 3, 1, 1]  # SLOWER alone
    assert imitation.DAGGER_DEFAULTS["disagreement_weight"] == 1.0
    with pytest.raises(imitation.TrainingError, match="disagreement_weight"):
        imitation.DaggerConfig(disagreement_weight=0)


def test_the_checkpoint_keeps_which_states_the_student_disagreed_on(tmp_path):
    model = _Model()
    optimizer = torch.optim.Adam(model.policy.parameters(), lr=1e-3)
    checkpoint = DAggerCheckpoint(tmp_path / "ckpt", {"steps": 4})
    observations = np.zeros((4, 8, 7), dtype=np.float32)
    labels = np.array([IDLE, FASTER, IDLE, SLOWER])
    disagreed = np.array([False, True, False, True])
    common = dict(model=model, optimizer=optimizer, rng=np.random.default_rng(0), history=[], envs=[],
                  wall_time_s=0.0, resumes=[])
    checkpoint.save(LabelledBatch(1, observations, labels, observations[:1], disagreed), **common)
    checkpoint.save(LabelledBatch(2, observations, labels, observations[:1]), **common)  # not recorded
    saved = DAggerCheckpoint(tmp_path / "ckpt", {"steps": 4}).load()
    assert saved.iteration == 2
    assert [d.tolist() for d in saved.disagreed] == [disagreed.tolist(), [False] * 4]


@pytest.mark.slow
def test_a_killed_run_with_the_disagreement_weight_resumes_to_the_same_model(tmp_path, monkeypatch):
    from fine_tune_helpers import dagger_fine_tune
    from policies.model_card import read_card
    from test_dagger_resume import RUN, _kill_on_train_call, _same_model, _stats

    run = {**RUN, "disagreement_weight": 4.0}
    whole = dagger_fine_tune("dv2s-ppo", out=tmp_path / "whole", log=lambda _: None, **run)
    assert read_card(whole).fine_tune.disagreement_weight == 4.0
    plain = dagger_fine_tune("dv2s-ppo", out=tmp_path / "plain", log=lambda _: None, **RUN)
    with pytest.raises(AssertionError):  # the weight changes the training
        _same_model(whole, plain)
    out = tmp_path / "killed"
    _kill_on_train_call(monkeypatch, 2)  # iteration 2 collected, killed while training on it
    with pytest.raises(KeyboardInterrupt):
        dagger_fine_tune("dv2s-ppo", out=out, log=lambda _: None, **run)
    monkeypatch.undo()
    resumed = dagger_fine_tune("dv2s-ppo", out=out, log=lambda _: None, **run)  # iteration 1's flags read back
    _same_model(whole, resumed)
    assert _stats(resumed) == _stats(whole)
