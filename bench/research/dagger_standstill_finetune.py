"""The DAgger standstill measurement of bench/RESULTS.md: fine-tune a start policy by DAgger, with or without the
disagreement weight (equal steps), on a loop round's working bank with the left-turn junction scenarios weighted 5.

Usage: python -m bench.research.dagger_standstill_finetune BANK START_SPEC OUT DISAGREEMENT_WEIGHT [SLOWER_WEIGHT]
(environment: FT_SEED the training seed, default 0; FT_BETA_DECAY DAgger's beta_decay, default 0.5).
:func:`fine_tune` is the same run for other scripts (``bench/research/dagger_beta0.py``)."""
import os
import sys
from policies.dagger_config import DaggerConfig
from policies.imitation import dagger_fine_tune
from policies.training import TrainConfig
from scenario_bank.bank import Bank

JUNCTION = ['urban_t_junction_left_turn_oncoming', 'urban_left_turn_oncoming',
            'replay_urban_t_junction_left_turn_oncoming_stall']
STEPS = 20000


def fine_tune(bank, start, out, disagreement_weight=1.0, *, seed=0, beta_decay=0.5, slower_weight=None,
              steps=STEPS, log=lambda line: print(line, flush=True)):
    """DAgger from ``start`` on every scenario of ``bank`` (the JUNCTION ones weighted 5), 1 env; the other DAgger
    settings are the defaults (``slower_weight`` None: the default). Returns the model's path."""
    names = sorted(e.name for e in Bank(bank))
    weights = {n: (5.0 if n in JUNCTION else 1.0) for n in names}
    config = TrainConfig.fine_tuning(out, steps=steps, weights=weights, bank_dir=bank, seed=seed, n_envs=1,
                                     vec_env='dummy', progress_bar=False)
    extra = {} if slower_weight is None else {"slower_weight": float(slower_weight)}
    return dagger_fine_tune(start, config, DaggerConfig(disagreement_weight=float(disagreement_weight),
                                                        beta_decay=float(beta_decay), **extra), log=log)


def main():
    bank, start, out, weight = sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4])
    path = fine_tune(bank, start, out, weight, seed=int(os.environ.get('FT_SEED', 0)),
                     beta_decay=float(os.environ.get("FT_BETA_DECAY", 0.5)),
                     slower_weight=float(sys.argv[5]) if len(sys.argv) > 5 else None)
    print('done', path)


if __name__ == '__main__':
    main()
