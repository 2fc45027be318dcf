"""A round's two fine-tuning arms: the fine-tuned policy's (the mined scenarios drawn with ``mined_share`` of the
probability) and the control's (the same fine-tuning less every mined scenario), each by PPO or DAgger on the
working bank less every held-out scenario and family (:func:`arm_weights`, :func:`fine_tune_arm`)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, Callable, Dict, Mapping, Sequence

from dv2s_gym.loop.record import FineTuneArm, recorded
from dv2s_gym.mining.family import scenario_family
from scenario_bank.bank import Bank
from policies.card_record import FineTune, FineTuneMethod
from policies.registry import read_model_card

__all__ = ["fine_tune_weights", "Arm", "arm_weights", "fine_tune_arm"]


def fine_tune_weights(names: Sequence[str], mined: Sequence[str], mined_share: float) -> Dict[str, float]:
    """Scenario -> sampling weight: the ``mined`` scenarios share ``mined_share`` of the probability
    equally, the other ``names`` share the rest (everything else in ``names`` stays in the mix)."""
    mined = sorted(set(mined) & set(names))
    rest = sorted(set(names) - set(mined))
    if not mined:
        return {name: 1.0 for name in rest}
    if not rest:
        return {name: 1.0 for name in mined}
    share = min(max(float(mined_share), 0.0), 1.0)
    weights = {name: (1.0 - share) / len(rest) for name in rest}
    weights.update({name: share / len(mined) for name in mined})
    return weights


@dataclasses.dataclass(frozen=True)
class Arm:
    """What the two fine-tuning arms of a round share (everything but the mined scenarios)."""

    bank: str
    method: str
    steps: int
    seed: int
    n_envs: int
    env_config: Dict[str, Any]
    fine_tune_config: Dict[str, Any]
    reward: Mapping[str, float]
    learning_rate: float
    beta_decay: float
    progress: bool
    log: Callable[[str], None]

    def config(self, out: Path, weights: Mapping[str, float]):
        """The arm's :class:`~policies.training.TrainConfig` into ``out``, drawing scenarios by ``weights``."""
        from policies.training import TrainConfig

        return TrainConfig.fine_tuning(out, steps=self.steps, weights=weights, bank_dir=self.bank, seed=self.seed,
                                       n_envs=self.n_envs, env_config=self.env_config, progress_bar=self.progress)


def arm_weights(bank_dir: str, excluded: set, mined_share: float, *,
                with_mined: bool) -> tuple:
    """The scenario sampling weights of one fine-tuning arm on the working bank ``bank_dir`` less ``excluded``
    (held-out scenarios and families): ``(weights, facts)``. ``with_mined``: the mined scenarios drawn with
    probability ``mined_share`` (the fine-tuned arm); otherwise left out (the control arm)."""
    # a held-out family's every member stays out too: exact replays of its failures and entries of earlier rounds,
    # at any depth (a member's family is the root of its provenance chain, not its immediate parent)
    bank = list(Bank(bank_dir))
    roots = {e.name: scenario_family(e.name, bank_dir) for e in bank}
    entries = [e for e in bank if e.name not in excluded and e.source.parent not in excluded
               and roots[e.name] not in excluded]
    mined = sorted(e.name for e in entries if e.source.mined)
    names = sorted(e.name for e in entries if with_mined or e.name not in mined)
    weights = fine_tune_weights(names, mined if with_mined else [], mined_share)
    return weights, {"scenarios": len(names), "mined_upweighted": len(mined) if with_mined else 0,
                     "mined_left_out": 0 if with_mined else len(mined),
                     "families": sorted({roots[e.name] for e in entries if e.name in names})}


def fine_tune_arm(current: str, out: Path, excluded: set, mined_share: float, arm: Arm, *, with_mined: bool,
                  label: str) -> FineTuneArm:
    """Fine-tune ``current`` into ``out`` on the working bank less ``excluded``: the mined scenarios upweighted
    (``with_mined``) or left out (the control arm); everything else identical between the two arms."""
    weights, facts = arm_weights(arm.bank, excluded, mined_share, with_mined=with_mined)
    common = dict(scenarios=facts["scenarios"], mined_upweighted=facts["mined_upweighted"], steps=arm.steps,
                  mined_left_out=facts["mined_left_out"], families=tuple(facts["families"]))
    if arm.method == FineTuneMethod.DAGGER:
        return FineTuneArm.from_dict(_dagger_arm(current, out, weights, arm, label)).replace(
            method=FineTuneMethod.DAGGER.value, **common)
    from policies.training import fine_tune

    config = dataclasses.replace(arm.config(out, weights), reward_weights=dict(arm.reward) or None,
                                 learning_rate=arm.learning_rate)
    path = fine_tune(current, config, log=arm.log)
    return FineTuneArm(model=str(path.resolve()), method=FineTuneMethod.PPO.value, **common, reward_weights=dict(arm.reward),
                       env_config=arm.fine_tune_config)


def _dagger_arm(current: str, out: Path, weights: Dict[str, float], arm: Arm, label: str) -> FineTuneArm:
    """A fine-tuning arm by DAgger (:func:`policies.imitation.dagger_fine_tune`); a killed one resumes."""
    from policies.imitation import DaggerConfig, dagger_fine_tune

    # a resumed run says so itself ("DAgger: resumed from ...", after the step's own line naming the arm)
    path = dagger_fine_tune(current, arm.config(out, weights), DaggerConfig(learning_rate=arm.learning_rate,
                                                                             beta_decay=arm.beta_decay), log=arm.log)
    dagger = read_model_card(path).fine_tune
    dagger = dagger if recorded(dagger) else FineTune()
    return FineTuneArm(model=str(path.resolve()), method=FineTuneMethod.DAGGER.value, reward_weights=None,
                       env_config=arm.env_config, reference=dagger.reference, agreement=dagger.agreement,
                       resumed=tuple(dagger.resumed or ()))
