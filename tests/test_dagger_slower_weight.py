"""DAgger's cross-entropy weights the reference's SLOWER labels (``slower_weight``, default 3)."""

import gymnasium as gym
import numpy as np
import pytest
import torch
from stable_baselines3.common.policies import ActorCriticPolicy

import policies.imitation as imitation
from policies.state_driver import FASTER, IDLE, SLOWER


class _Model:  # the part of an SB3 model imitation_step reads
    def __init__(self):
        space = gym.spaces.Box(-1.0, 1.0, shape=(8, 7), dtype=np.float32)
        self.policy = ActorCriticPolicy(space, gym.spaces.Discrete(5), lambda _: 1e-3)


@pytest.mark.slow
def test_slower_labels_weigh_more_in_the_loss():
    torch.manual_seed(0)
    model = _Model()
    with torch.no_grad():  # a policy that prefers IDLE, so SLOWER labels cost more than IDLE ones
        model.policy.action_net.bias.copy_(torch.tensor([0.0, 3.0, 0.0, 0.0, -2.0]))
    obs = np.random.default_rng(0).uniform(-1, 1, size=(6, 8, 7)).astype(np.float32)
    labels = np.array([IDLE, SLOWER, FASTER, SLOWER, IDLE, IDLE])
    with torch.no_grad():
        nll = -model.policy.get_distribution(torch.as_tensor(obs)).log_prob(torch.as_tensor(labels)).numpy()
    weights = np.where(labels == SLOWER, 3.0, 1.0)
    optimizer = torch.optim.SGD(model.policy.parameters(), lr=0.0)  # a step that changes nothing
    loss = imitation.imitation_step(model, optimizer, obs, labels,
                                   weights=imitation.loss_weights(labels, np.zeros(len(labels), bool), 3.0))
    assert loss == pytest.approx(float((weights * nll).sum() / weights.sum()), rel=1e-5)
    assert loss != pytest.approx(float(nll.mean()), rel=1e-3)  # not the unweighted mean
    unweighted = imitation.imitation_step(model, optimizer, obs, labels)
    assert unweighted == pytest.approx(float(nll.mean()), rel=1e-5)


def test_dagger_defaults_weight_slower_labels_and_refuse_a_bad_weight(tmp_path):
    assert imitation.DAGGER_DEFAULTS["slower_weight"] == 3.0
    with pytest.raises(imitation.TrainingError, match="slower_weight"):
        imitation.DaggerConfig(slower_weight=0)
