"""Is DAgger with ``beta_decay=0`` (the reference drives the first iteration alone, the student every later one)
worth making the loop's default?  A pre-declared measurement; the design below was committed before any run.

    python -m bench.research.dagger_beta0 run --bank BANK --start SPEC --out DIR [--steps 20000]
    python -m bench.research.dagger_beta0 analyse --out DIR

Design (fixed before running; see bench/RESULTS.md, "DAgger with beta_decay 0"):

* Start policy: the route-aware ``intent_start`` (``ppo:/work/exp/intent_start/model.zip`` on the machine it was
  run on); training bank: the loop round's 51-scenario working bank (``/work/exp/loop_intent/bank``), the three
  left-turn junction scenarios weighted 5, every other 1 (``dagger_standstill_finetune.fine_tune``, the
  earlier standstill measurement's fine-tuning, unchanged).
* Arms, all DAgger 4 iterations, SLOWER weight 3, 8 epochs, Adam 1e-3, ``STEPS`` env steps, 1 env:
  A = the defaults (beta_decay 0.5, disagreement_weight 1); C = beta_decay 0; D = beta_decay 0 and
  disagreement_weight 4.  Run with ``--steps 12000`` (scaled from the earlier measurement's 20,000: at the shared
  machine's load of 8-10 a 20k fine-tuning took about 11 minutes, six of them would not fit the time; decided
  after the start policy's evaluation and 2 iterations of A seed 2, before any trained arm was evaluated).  (The earlier, exploratory "D" of bench/RESULTS.md is this C.)
* Training seeds 2 and 3: new seeds, not the 0 and 1 whose runs suggested the hypothesis.
* Evaluation seeds fixed in advance: ``EVAL_SEED_BASE + 0 .. 19`` on each junction scenario
  (``urban_t_junction_left_turn_oncoming``, ``urban_left_turn_oncoming``): 40 episodes per trained policy, 80 per arm;
  the bank check ``EVAL_SEED_BASE + 0 .. 4`` on ``BANK_CHECK``: 8 other scenarios of the round's starting bank (its
  32 starting scenarios without the two junction ones, sorted, every 4th from the first; chosen by that rule, not by
  their outcomes), 40 episodes per trained policy, 80 per arm.  The start policy runs the same episodes once.
  Deterministic (greedy) actions, the round's env config.
* Failure: ``detect_failure`` (collision, off road, low TTC, stall), as in the loop's mining.
* Primary metric: junction episodes judged failed, per arm (of 80).  Primary test: exact two-sided McNemar on the
  pairs (training seed, scenario, eval seed), C against A and D against A, Holm-adjusted over these two.
  Secondary: Fisher exact two-sided on the same counts; D against C (McNemar, exploratory); failure types; the
  share of FASTER at standstill-before-turn steps (``dagger_standstill_probe.Recorder``).
* Bank check: failures (of 80) and mean speed per arm; exact McNemar against A on the paired bank episodes; the
  paired mean-speed difference against A with a normal 95 % interval.
* An arm is a candidate for the loop's default only if (1) it fails fewer junction episodes than A with
  Holm-adjusted McNemar p < 0.05, (2) on the bank check it fails at most 3 more episodes than A (of 80) and not
  significantly more (two-sided McNemar p >= 0.05), and (3) its bank mean speed is not more than 10 % below A's.
  With fewer junction failures but (1) not met it is a lead, not a candidate.
* Order of the run (so a stop leaves whole pairs): start, then seed 2 A, C, D, then seed 3 A, C, D; each policy
  trained and then evaluated; every result written to ``OUT`` (a rerun continues where it stopped).  Nothing is
  rerun or dropped after seeing results.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from collections import Counter
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

JUNCTION_EVAL = ["urban_t_junction_left_turn_oncoming", "urban_left_turn_oncoming"]
JUNCTION_SEEDS = 20
BANK_SEEDS = 5
TRAIN_SEEDS = [2, 3]
ARMS = {"A": {"beta_decay": 0.5, "disagreement_weight": 1.0},
        "C": {"beta_decay": 0.0, "disagreement_weight": 1.0},
        "D": {"beta_decay": 0.0, "disagreement_weight": 4.0}}
START_SCENARIOS_LOOP = "/work/exp/loop_intent/loop.json"


def bank_check_scenarios(start_scenarios):
    """The bank check's 8 scenarios: the starting scenarios without the junction ones, sorted, every 4th."""
    rest = sorted(s for s in start_scenarios if s not in JUNCTION_EVAL)
    return rest[0::4][:8]


def evaluate(spec, bank, env_config, bank_check):
    """Every fixed episode of ``spec``: junction ones through the standstill Recorder, then the bank check's."""
    from policies import worker_cache
    from policies.evaluation import EVAL_SEED_BASE, run_episode
    from policies.registry import load_policy
    from dv2s_gym.mining.monitors import detect_failure
    from bench.research.dagger_standstill_probe import Recorder

    key, env = worker_cache.env_for(bank, env_config)
    rule = load_policy("rule")
    rule.bind([env])
    pol = load_policy(spec)
    pol.bind([env])
    rec = Recorder(pol, rule, env)
    episodes = []
    for part, scenarios, nseeds in (("junction", JUNCTION_EVAL, JUNCTION_SEEDS), ("bank", bank_check, BANK_SEEDS)):
        for scen in scenarios:
            for seed in range(EVAL_SEED_BASE, EVAL_SEED_BASE + nseeds):
                rec.rows = []
                result, trace = run_episode(env, rec if part == "junction" else pol, scen, seed)
                failure = detect_failure(result, trace)
                episodes.append({"part": part, "scenario": scen, "seed": seed,
                                 "failure": failure.type if failure else None,
                                 "mean_speed": result.mean_speed, "steps": result.steps,
                                 "standstill_steps": len(rec.rows) if part == "junction" else None,
                                 "standstill_rule_F": sum(r == 3 for _, r, _, _ in rec.rows) if part == "junction" else None,
                                 "standstill_policy_F": sum(a == 3 for _, _, a, _ in rec.rows) if part == "junction" else None,
                                 "standstill_policy_F_where_rule_F": sum(a == 3 and r == 3 for _, r, a, _ in rec.rows)
                                 if part == "junction" else None})
    return episodes


def run(args):
    from bench.research.dagger_standstill_finetune import fine_tune

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    loop = json.loads(Path(args.loop).read_text())
    env_config = loop["settings"]["env_config"]
    bank_check = bank_check_scenarios(loop["start"]["scenarios"])
    (out / "design.json").write_text(json.dumps({"bank": args.bank, "start": args.start, "steps": args.steps,
                                                 "arms": ARMS, "train_seeds": TRAIN_SEEDS,
                                                 "junction": JUNCTION_EVAL, "junction_seeds": JUNCTION_SEEDS,
                                                 "bank_check": bank_check, "bank_seeds": BANK_SEEDS}, indent=1))
    jobs = [("start", None, None)] + [(f"{arm}_s{seed}", arm, seed) for seed in TRAIN_SEEDS for arm in ARMS]
    for name, arm, seed in jobs:
        result = out / f"eval_{name}.json"
        if result.is_file():
            continue
        timing = {"start_utc": time.strftime("%H:%M:%S", time.gmtime())}
        spec = args.start
        if arm is not None:
            t0 = time.time()
            path = fine_tune(args.bank, args.start, out / name, ARMS[arm]["disagreement_weight"], seed=seed,
                             beta_decay=ARMS[arm]["beta_decay"], steps=args.steps)
            timing["train_s"] = round(time.time() - t0, 1)
            spec = f"ppo:{path}"
        t0 = time.time()
        episodes = evaluate(spec, args.bank, env_config, bank_check)
        timing["eval_s"] = round(time.time() - t0, 1)
        timing["load"] = os.getloadavg()
        result.write_text(json.dumps({"name": name, "arm": arm, "seed": seed, "spec": spec, "timing": timing,
                                      "episodes": episodes}, indent=1))
        print(name, json.dumps(timing), summary_line(episodes), flush=True)


def summary_line(episodes):
    j = [e for e in episodes if e["part"] == "junction"]
    b = [e for e in episodes if e["part"] == "bank"]
    return (f"junction failed {sum(e['failure'] is not None for e in j)}/{len(j)} "
            f"{dict(Counter(e['failure'] for e in j if e['failure']))}; bank failed "
            f"{sum(e['failure'] is not None for e in b)}/{len(b)}, mean speed "
            f"{sum(e['mean_speed'] for e in b) / max(len(b), 1):.2f}")


def mcnemar(pairs):
    """Exact two-sided McNemar on (x failed, y failed) pairs: (only x, only y, p)."""
    from scipy.stats import binomtest
    only_x = sum(1 for x, y in pairs if x and not y)
    only_y = sum(1 for x, y in pairs if y and not x)
    n = only_x + only_y
    return only_x, only_y, (1.0 if n == 0 else binomtest(only_x, n, 0.5).pvalue)


def holm(pvalues):
    order = sorted(range(len(pvalues)), key=lambda i: pvalues[i])
    adjusted, running = [0.0] * len(pvalues), 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (len(pvalues) - rank) * pvalues[i]))
        adjusted[i] = running
    return adjusted


def analyse(args):
    from scipy.stats import fisher_exact

    out = Path(args.out)
    evals = {json.loads(p.read_text())["name"]: json.loads(p.read_text()) for p in sorted(out.glob("eval_*.json"))}

    def keyed(name, part):
        return {(e["scenario"], e["seed"]): e for e in evals[name]["episodes"] if e["part"] == part}

    def arm_eps(arm, part):
        """(training seed, scenario, eval seed) -> episode, over the training seeds this arm finished."""
        rows = {}
        for seed in TRAIN_SEEDS:
            if f"{arm}_s{seed}" in evals:
                rows.update({(seed, *k): e for k, e in keyed(f"{arm}_s{seed}", part).items()})
        return rows

    lines = ["| policy | junction failed | T-junction | crossroads | failure types | FASTER at standstill where rule FASTER | bank failed | bank mean speed (m/s) | train s | eval s |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    names = ["start"] + [f"{a}_s{s}" for a in ARMS for s in TRAIN_SEEDS]
    for name in names + list(ARMS):
        if name in evals:
            eps = evals[name]["episodes"]
            t = evals[name]["timing"]
        elif name in ARMS:
            eps = [e for s in TRAIN_SEEDS if f"{name}_s{s}" in evals for e in evals[f"{name}_s{s}"]["episodes"]]
            t = {}
            if not eps:
                continue
        else:
            continue
        j = [e for e in eps if e["part"] == "junction"]
        b = [e for e in eps if e["part"] == "bank"]
        per = [sum(e["failure"] is not None for e in j if e["scenario"] == s) for s in JUNCTION_EVAL]
        n_per = [sum(1 for e in j if e["scenario"] == s) for s in JUNCTION_EVAL]
        rule_f = sum(e["standstill_rule_F"] for e in j)
        pol_f = sum(e["standstill_policy_F_where_rule_F"] for e in j)
        types = Counter(e["failure"] for e in eps if e["part"] == "junction" and e["failure"])
        label = f"**{name} (pooled)**" if name in ARMS else name
        lines.append(f"| {label} | {sum(per)}/{len(j)} | {per[0]}/{n_per[0]} | {per[1]}/{n_per[1]} | "
                     f"{', '.join(f'{k} {v}' for k, v in sorted(types.items())) or '-'} | "
                     f"{pol_f}/{rule_f} ({(100 * pol_f / rule_f) if rule_f else float('nan'):.0f} %) | "
                     f"{sum(e['failure'] is not None for e in b)}/{len(b)} | "
                     f"{sum(e['mean_speed'] for e in b) / max(len(b), 1):.2f} | {t.get('train_s', '-')} | {t.get('eval_s', '-')} |")
    print("\n".join(lines))

    print("\nPrimary (junction, paired on training seed x scenario x eval seed):")
    a_j = arm_eps("A", "junction")
    tests, raw = [], []
    for arm in ("C", "D"):
        x = arm_eps(arm, "junction")
        shared = sorted(set(x) & set(a_j))
        if not shared:
            continue
        only_arm, only_a, p = mcnemar([(x[k]["failure"] is not None, a_j[k]["failure"] is not None) for k in shared])
        fa = sum(a_j[k]["failure"] is not None for k in shared)
        fx = sum(x[k]["failure"] is not None for k in shared)
        fisher = fisher_exact([[fx, len(shared) - fx], [fa, len(shared) - fa]])[1]
        tests.append((arm, len(shared), fx, fa, only_arm, only_a, fisher))
        raw.append(p)
    for (arm, n, fx, fa, only_arm, only_a, fisher), p, ph in zip(tests, raw, holm(raw)):
        print(f"  {arm} vs A: {fx}/{n} vs {fa}/{n}; only {arm} failed {only_arm}, only A {only_a}; "
              f"McNemar p = {p:.3g}, Holm p = {ph:.3g}; Fisher p = {fisher:.3g}")
    c_j, d_j = arm_eps("C", "junction"), arm_eps("D", "junction")
    shared = sorted(set(c_j) & set(d_j))
    if shared:
        od, oc, p = mcnemar([(d_j[k]["failure"] is not None, c_j[k]["failure"] is not None) for k in shared])
        print(f"  (exploratory) D vs C: only D failed {od}, only C {oc}; McNemar p = {p:.3g}")

    print("\nBank check (paired on training seed x scenario x eval seed), against A:")
    a_b = arm_eps("A", "bank")
    for arm in ("C", "D"):
        x = arm_eps(arm, "bank")
        shared = sorted(set(x) & set(a_b))
        if not shared:
            continue
        only_arm, only_a, p = mcnemar([(x[k]["failure"] is not None, a_b[k]["failure"] is not None) for k in shared])
        diffs = [x[k]["mean_speed"] - a_b[k]["mean_speed"] for k in shared]
        mean = sum(diffs) / len(diffs)
        sd = math.sqrt(sum((d - mean) ** 2 for d in diffs) / max(len(diffs) - 1, 1))
        half = 1.96 * sd / math.sqrt(len(diffs))
        a_speed = sum(a_b[k]["mean_speed"] for k in shared) / len(shared)
        print(f"  {arm}: failed {sum(x[k]['failure'] is not None for k in shared)}/{len(shared)} vs A "
              f"{sum(a_b[k]['failure'] is not None for k in shared)}/{len(shared)} (only {arm} {only_arm}, only A "
              f"{only_a}, McNemar p = {p:.3g}); mean speed {mean:+.2f} m/s [{mean - half:+.2f}, {mean + half:+.2f}] "
              f"({100 * mean / a_speed:+.1f} % of A's {a_speed:.2f})")
    print("\nBank check per scenario (failures of 5 per policy):")
    bank_names = sorted({e["scenario"] for ev in evals.values() for e in ev["episodes"] if e["part"] == "bank"})
    print("| scenario | " + " | ".join(n for n in names if n in evals) + " |")
    print("|---|" + "---|" * sum(n in evals for n in names))
    for scen in bank_names:
        cells = []
        for n in names:
            if n in evals:
                eps = [e for e in evals[n]["episodes"] if e["part"] == "bank" and e["scenario"] == scen]
                kinds = Counter(e["failure"] for e in eps if e["failure"])
                cells.append(f"{sum(kinds.values())}" + (f" ({', '.join(f'{k} {v}' for k, v in sorted(kinds.items()))})" if kinds else ""))
        print(f"| {scen} | " + " | ".join(cells) + " |")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run")
    r.add_argument("--bank", required=True, help="the training bank (a loop round's working bank)")
    r.add_argument("--start", required=True, help="the start policy's spec")
    r.add_argument("--loop", default=START_SCENARIOS_LOOP, help="the round's loop.json (env config, starting scenarios)")
    r.add_argument("--out", required=True)
    r.add_argument("--steps", type=int, default=20000, help="DAgger env steps per fine-tuning (default 20000)")
    a = sub.add_parser("analyse")
    a.add_argument("--out", required=True)
    args = parser.parse_args()
    run(args) if args.command == "run" else analyse(args)


if __name__ == "__main__":
    main()
