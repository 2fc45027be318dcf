"""As run for the DAgger standstill measurement in bench/RESULTS.md (paths are those of that machine; FT_SEED the
training seed, default 0; FT_BETA_DECAY the DAgger beta_decay, default 0.5).

Fine-tune the route-aware start policy by DAgger, with or without the disagreement weight (equal steps).
Usage: dagger_standstill_finetune.py OUT DISAGREEMENT_WEIGHT [SLOWER_WEIGHT]"""
import sys, json
from pathlib import Path
from policies.dagger_config import DaggerConfig
from policies.imitation import dagger_fine_tune
from policies.training import TrainConfig
from scenario_bank.bank import Bank

BANK = '/work/exp/loop_ev4/bank'
JUNCTION = ['urban_t_junction_left_turn_oncoming', 'urban_left_turn_oncoming',
            'replay_urban_t_junction_left_turn_oncoming_stall']
out, weight = sys.argv[1], float(sys.argv[2])
names = sorted(e.name for e in Bank(BANK))
weights = {n: (5.0 if n in JUNCTION else 1.0) for n in names}
config = TrainConfig.fine_tuning(out, steps=20000, weights=weights, bank_dir=BANK, seed=int(__import__('os').environ.get('FT_SEED', 0)), n_envs=1,
                                 vec_env='dummy', progress_bar=False)
path = dagger_fine_tune('ppo:/work/exp/intent_start/model.zip', config, DaggerConfig(disagreement_weight=weight, beta_decay=float(__import__("os").environ.get("FT_BETA_DECAY", 0.5)), **({"slower_weight": float(sys.argv[3])} if len(sys.argv) > 3 else {})),
                        log=lambda line: print(line, flush=True))
print('done', path)
