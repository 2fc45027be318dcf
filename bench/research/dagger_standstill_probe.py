"""The DAgger standstill measurement of bench/RESULTS.md (the bank: DV2S_STANDSTILL_BANK, a loop round's working bank).

Standstill-before-left-turn probe: drive each policy on the two left-turn junction scenarios, seeds 10000..,
count the steps where the ego stands (speed < 0.5 m/s) with its left turn still ahead (route_turn obs > 0.25),
the rule's label there and the policy's greedy action; the episode's judged failure (detect_failure).
Usage: dagger_standstill_probe.py OUT.json NSEEDS SPEC [SPEC...]"""
import json, sys
from collections import Counter
import numpy as np
import torch
from policies import worker_cache
from policies.registry import load_policy
from policies.evaluation import run_episode
from dv2s_gym.mining.monitors import detect_failure

NAMES = ['L', 'I', 'R', 'F', 'S']
SCENARIOS = ['urban_t_junction_left_turn_oncoming', 'urban_left_turn_oncoming']
BANK = __import__('os').environ.get('DV2S_STANDSTILL_BANK')  # read by main(); Recorder needs no bank


class Recorder:
    """Wraps a policy: records standstill steps (obs, rule label, policy action, probs)."""
    def __init__(self, pol, rule, env):
        self.pol, self.rule, self.env = pol, rule, env
        self.rows = []
        self.all = []  # secondary: every standstill step, whatever the route feature
    def reset(self, i):
        self.pol.reset(i); self.rule.reset(i)
    def act(self, obs, deterministic=True):
        a = self.pol.act(obs, deterministic=deterministic)
        base = self.env.unwrapped
        r = int(self.rule.act(obs, deterministic=True)[0])  # asked at every step, as DAgger's labelling does
        if base.vehicle.speed < 0.5:
            self.all.append((r, int(a[0]), round(float(obs[0][0][7]), 2)))
        if base.vehicle.speed < 0.5 and float(obs[0][0][7]) > 0.25:
            model = self.pol.model
            t, _ = model.policy.obs_to_tensor(np.asarray(obs))
            with torch.no_grad():
                p = model.policy.get_distribution(t).distribution.probs.numpy()[0]
            self.rows.append((np.asarray(obs[0]).copy(), r, int(a[0]), p))
        return a


def main():
    out, nseeds, specs = sys.argv[1], int(sys.argv[2]), sys.argv[3:]
    cfg = json.load(open(__import__('os').path.join(BANK, '..', 'loop.json')))['settings']['env_config']
    key, env = worker_cache.env_for(BANK, cfg)
    rule = load_policy('rule'); rule.bind([env])
    report = {}
    dump = {}
    for spec in specs:
        pol = load_policy(spec); pol.bind([env])
        rec = Recorder(pol, rule, env)
        per = {}
        for scen in SCENARIOS:
            rec.rows = []; rec.all = []
            fails = Counter(); eps = 0
            for seed in range(10000, 10000 + nseeds):
                result, trace = run_episode(env, rec, scen, seed)
                f = detect_failure(result, trace)
                fails[f.type if f else 'none'] += 1; eps += 1
            labels = Counter(NAMES[r] for _, r, _, _ in rec.rows)
            acts = Counter(NAMES[a] for _, _, a, _ in rec.rows)
            fl = [row for row in rec.rows if row[1] == 3]
            per[scen] = {'episodes': eps, 'failed': eps - fails['none'], 'failures': dict(fails),
                         'standstill_steps': len(rec.rows), 'rule_labels': dict(labels), 'policy_actions': dict(acts),
                         'faster_share': (acts['F'] / len(rec.rows)) if rec.rows else None,
                         'faster_share_where_rule_faster': (sum(a == 3 for _, _, a, _ in fl) / len(fl)) if fl else None,
                         'all_standstill': {'steps': len(rec.all), 'rule_F': sum(r == 3 for r, _, _ in rec.all),
                                            'policy_F': sum(a == 3 for _, a, _ in rec.all),
                                            'policy_F_where_rule_F': sum(a == 3 and r == 3 for r, a, _ in rec.all),
                                            'route_turn_values': sorted(set(t for *_, t in rec.all))[:8]},
                         'mean_probs': np.mean([p for *_, p in rec.rows], axis=0).round(3).tolist() if rec.rows else None}
            dump[f'{spec}|{scen}'] = rec.rows
            print(spec, scen, json.dumps(per[scen]), flush=True)
        report[spec] = per
    json.dump(report, open(out, 'w'), indent=1)
    np.save(out + '.rows.npy', np.array([(k, o, r, a, p) for k, rows in dump.items() for o, r, a, p in rows], dtype=object), allow_pickle=True)

if __name__ == '__main__':
    main()
