"""The DAgger standstill measurement of bench/RESULTS.md: fine-tune a start policy by DAgger, with or without the
disagreement weight (equal steps), on a loop round's working bank with the left-turn junction scenarios weighted 5.

Usage: python -m bench.research.dagger_standstill_finetune BANK START_SPEC OUT DISAGREEMENT_WEIGHT [SLOWER_WEIGHT]
(environment: FT_SEED the training seed, default 0; FT_BETA_DECAY DAgger's beta_decay, default 0.5)."""
import os
import sys
from policies.dagger_config import DaggerConfig
from policies.imitation import dagger_fine_tune
from policies.training import TrainConfig
from scenario_bank.bank import Bank

JUNCTION = ['urban_t_junction_left_turn_oncoming', 'urban_left_turn_oncoming',
            'replay_urban_t_junction_left_turn_oncoming_stall']
BANK, START, out, weight = sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4])
names = sorted(e.name for e in Bank(BANK))
weights = {n: (5.0 if n in JUNCTION else 1.0) for n in names}
config = TrainConfig.fine_tuning(out, steps=20000, weights=weights, bank_dir=BANK, seed=int(os.environ.get('FT_SEED', 0)), n_envs=1,
                                 vec_env='dummy', progress_bar=False)
path = dagger_fine_tune(START, config, DaggerConfig(disagreement_weight=weight, beta_decay=float(os.environ.get("FT_BETA_DECAY", 0.5)), **({"slower_weight": float(sys.argv[5])} if len(sys.argv) > 5 else {})),
                        log=lambda line: print(line, flush=True))
print('done', path)
