"""Monte Carlo calibration of the ``dv2s regress`` statistics (dv2s_gym/regress/stats.py and family.py).

    python -m bench.calibrate_regress            # full run (a few minutes on 2 cores)
    python -m bench.calibrate_regress --quick    # fewer repetitions
    python -m bench.calibrate_regress --only gate  # one section (fixed, sizes, sequential, gate, gate-sequential)

Synthetic paired outcomes from the shared-difficulty model (a per-episode latent difficulty
shared by both policies, latent correlation rho; bench/research/regress_montecarlo.py), fed through the
actual decision rules. It prints:

* the false-alarm rate (FAIL with identical policies) of ``compare`` at the documented episode
  count, with its Wilson interval, and at a few other designs;
* P(PASS) when the true difference equals the non-inferiority margin;
* the power (FAIL rate) at +3 percentage points from a 5 % baseline at the documented count,
  and what the same count gives unpaired;
* the episodes needed for 80 % power, paired against unpaired, analytic and simulated, for a
  few correlations;
* the same checks for ``SequentialTest`` (5 looks, O'Brien-Fleming spending);
* the gate over the bank's 21 scenarios (``compare_scenarios``: every scenario a test, the pooled test in
  the same family) at the default, power-planned, episodes and at 20: false alarms with identical
  policies, a single scenario going 0 % -> 30 % (with and without fixes elsewhere) and +20 pp, a
  regression of +3 pp everywhere; and the power the reports state.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np
from scipy import stats

from bench.research.regress_montecarlo import (
    DOCUMENTED_BASELINE_RATE,
    DOCUMENTED_DELTA,
    DOCUMENTED_EPISODES,
    DOCUMENTED_POWER,
    MonteCarloRate,
    discordant_probability,
    paired_cell_probabilities,
    paired_sample_size,
    simulate_false_alarm,
    simulate_paired_outcomes,
    simulate_unpaired_power,
    simulate_verdict_rates,
    simulated_sample_size,
    unpaired_sample_size,
)
from dv2s_gym.regress.family import DEFAULT_POOLED_WEIGHT, gate_rejections
from dv2s_gym.regress.power import plan_episodes, run_power
from dv2s_gym.regress.stats import (
    DEFAULT_ALPHA,
    DEFAULT_CORRELATION,
    DEFAULT_MARGIN,
    PairedTable,
    SequentialTest,
    Verdict,
    _newcombe_bounds,
    compare_scenarios,
)

P0 = DOCUMENTED_BASELINE_RATE
P1 = DOCUMENTED_BASELINE_RATE + DOCUMENTED_DELTA
CORRELATIONS = (0.0, 0.3, 0.5, 0.7, 0.9)


def phi_of(p_baseline: float, p_candidate: float, rho: float) -> float:
    """Phi correlation of the paired outcomes under the shared-difficulty model."""
    both, cand_only, base_only, neither = paired_cell_probabilities(p_baseline, p_candidate, rho)
    spread = p_baseline * (1 - p_baseline) * p_candidate * (1 - p_candidate)
    return (both * neither - cand_only * base_only) / spread**0.5


def fixed_design(reps: int, rng: np.random.Generator) -> None:
    n = DOCUMENTED_EPISODES
    print(f"== compare() on one pooled table, {n} paired episodes (DOCUMENTED_EPISODES), {reps} repetitions each")
    same = simulate_verdict_rates(n, P0, P0, repetitions=reps, rng=rng)
    print(f"false alarm (FAIL), identical policies at {P0:.0%}: {same[Verdict.FAIL]}")
    print(f"    (PASS {same[Verdict.PASS].rate:.3f}, INCONCLUSIVE {same[Verdict.INCONCLUSIVE].rate:.3f})")
    at_margin = simulate_verdict_rates(n, P0, P0 + DEFAULT_MARGIN, repetitions=reps, rng=rng)
    print(f"P(PASS) when candidate - baseline = margin ({P0:.0%} vs {P0 + DEFAULT_MARGIN:.0%}): "
          f"{at_margin[Verdict.PASS]}   (nominal alpha/2 = {DEFAULT_ALPHA / 2:g}, must be <= {DEFAULT_ALPHA:g})")
    worse = simulate_verdict_rates(n, P0, P1, repetitions=reps, rng=rng)
    print(f"power (FAIL) at +{DOCUMENTED_DELTA * 100:.0f} pp ({P0:.0%} vs {P1:.0%}): {worse[Verdict.FAIL]}   "
          f"(target >= {DOCUMENTED_POWER:g}; PASS {worse[Verdict.PASS].rate:.4f})")
    unpaired = simulate_unpaired_power(n, P0, DOCUMENTED_DELTA, repetitions=reps, rng=rng)
    print(f"    the same {n} episodes per policy unpaired (each on its own scenes, one-sided Fisher exact): {unpaired}")
    print("false alarm at other designs (n paired episodes, failure rate p, latent correlation rho):")
    for n_other, p, rho in ((30, 0.2, 0.5), (100, 0.05, 0.5), (300, 0.02, 0.5), (400, 0.1, 0.0), (2000, 0.05, 0.8)):
        rate = simulate_false_alarm(n_other, p, correlation=rho, repetitions=reps, rng=rng)
        print(f"    n={n_other:5d} p={p:.2f} rho={rho:.1f}: {rate}")


def sample_sizes(reps: int, seed: int) -> None:
    print(f"\n== episodes per policy for {DOCUMENTED_POWER:.0%} power to FAIL {P0:.0%} -> {P1:.0%} "
          f"(one-sided alpha {DEFAULT_ALPHA:g}; simulated: {reps} repetitions per count, step 10)")
    unpaired_analytic = unpaired_sample_size(P0, DOCUMENTED_DELTA)
    unpaired_simulated = simulated_sample_size(correlation=None, repetitions=reps, seed=seed)
    print("  rho  phi   discordant  paired analytic  paired simulated  unpaired analytic  unpaired simulated")
    print("                         (Connor)         (compare: exact   (normal)           (Fisher exact)")
    print("                                          McNemar)")
    for rho in CORRELATIONS:
        psi = discordant_probability(P0, P1, rho)
        analytic = paired_sample_size(P0, DOCUMENTED_DELTA, correlation=rho)
        simulated = simulated_sample_size(correlation=rho, repetitions=reps, seed=seed)
        mark = "  <- default" if rho == DEFAULT_CORRELATION else ""
        print(f"  {rho:.1f}  {phi_of(P0, P1, rho):.2f}  {psi:.4f}      {analytic:6d}           {simulated:6d}"
              f"            {unpaired_analytic:6d}             {unpaired_simulated:6d}{mark}")


def run_sequential(p_candidate: float, reps: int, rng: np.random.Generator, looks: int = 5) -> tuple[dict, float]:
    n_max = DOCUMENTED_EPISODES
    counts = {verdict: 0 for verdict in Verdict}
    used = 0
    for start in range(0, reps, 500):
        size = min(500, reps - start)
        cand, base = simulate_paired_outcomes(n_max, P0, p_candidate, DEFAULT_CORRELATION, size, rng)
        cells = np.stack([cand & base, cand & ~base, ~cand & base, ~cand & ~base], axis=-1).cumsum(axis=1)
        for r in range(size):
            test = SequentialTest(DEFAULT_MARGIN, max_episodes=n_max)
            for k in range(1, looks + 1):
                n = n_max * k // looks
                verdict = test.update(PairedTable(*map(int, cells[r, n - 1])))
                if verdict is not None:
                    break
            counts[verdict] += 1
            used += n
    return counts, used / reps


def sequential(reps: int, rng: np.random.Generator) -> None:
    print(f"\n== SequentialTest (O'Brien-Fleming spending), 5 looks every {DOCUMENTED_EPISODES // 5} paired episodes up to "
          f"{DOCUMENTED_EPISODES}, {reps} repetitions each")
    for label, p_candidate, verdict in (("false alarm (FAIL), identical", P0, Verdict.FAIL),
                                        ("P(PASS) at the margin", P0 + DEFAULT_MARGIN, Verdict.PASS),
                                        (f"power (FAIL) at +{DOCUMENTED_DELTA * 100:.0f} pp", P1, Verdict.FAIL)):
        counts, mean_used = run_sequential(p_candidate, reps, rng)
        print(f"    {label:<32} {MonteCarloRate(counts[verdict], reps)}   "
              f"mean episodes {mean_used:5.0f}   (PASS/FAIL/INCONCLUSIVE "
              f"{counts[Verdict.PASS]}/{counts[Verdict.FAIL]}/{counts[Verdict.INCONCLUSIVE]})")


def simulate_scenario(n: int, p_baseline: float, p_candidate: float, reps: int, rng: np.random.Generator,
                      rho: float = DEFAULT_CORRELATION) -> np.ndarray:
    """Paired tables (reps, 4) of one scenario; a rate of 0 means that policy never fails there."""
    difficulty = rng.standard_normal((reps, n))
    shared, own = np.sqrt(rho), np.sqrt(1 - rho)
    threshold = lambda p: stats.norm.isf(p) if p > 0 else np.inf  # noqa: E731
    cand = shared * difficulty + own * rng.standard_normal((reps, n)) > threshold(p_candidate)
    base = shared * difficulty + own * rng.standard_normal((reps, n)) > threshold(p_baseline)
    return np.stack([(cand & base).sum(1), (cand & ~base).sum(1), (~cand & base).sum(1), (~cand & ~base).sum(1)],
                    axis=1)


def gate_outcomes(tables: np.ndarray, margin: float = DEFAULT_MARGIN, alpha: float = DEFAULT_ALPHA
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The gate's decisions for simulated runs, ``tables`` of shape (reps, scenarios, 4): (overall FAIL per run,
    scenario FAIL per run and scenario, overall PASS per run). The same rule as ``compare_scenarios`` (checked against it in ``gate``),
    vectorised where it can be: the p-values, intervals and PASS checks; the family procedure per run."""
    reps, count, _ = tables.shape
    a, b, c, d = (tables[..., i] for i in range(4))
    z = stats.norm.ppf(1 - alpha / 2)
    _, upper = _newcombe_bounds(a, b, c, d, z)
    p = np.where(b + c > 0, stats.binom.sf(b - 1, b + c, 0.5), 1.0)
    pooled = tables.sum(axis=1)
    pa, pb, pc, pd = (pooled[:, i] for i in range(4))
    _, pooled_upper = _newcombe_bounds(pa, pb, pc, pd, z)
    pooled_p = np.where(pb + pc > 0, stats.binom.sf(pb - 1, pb + pc, 0.5), 1.0)
    scenario_fail = np.zeros((reps, count), dtype=bool)
    overall = np.zeros(reps, dtype=bool)
    for r in range(reps):
        decision = gate_rejections(p[r], b[r] + c[r], float(pooled_p[r]), alpha)
        scenario_fail[r] = np.array(decision.scenarios) & (b[r] > c[r]) & (upper[r] >= margin)
        pooled_fail = decision.pooled and pb[r] > pc[r] and pooled_upper[r] >= margin
        overall[r] = scenario_fail[r].any() or pooled_fail
    worse_alone = ((p < alpha) & (b > c)).any(axis=1)
    passed = ~overall & (pooled_upper < margin) & ~worse_alone
    return overall, scenario_fail, passed


BANK_SCENARIOS = 21
"""Scenarios of the shipped bank (the default run)."""


def bank_rates(count: int = BANK_SCENARIOS) -> np.ndarray:
    """Failure rates of the simulated bank: from 2 % to 25 %, evenly (both policies alike unless stated)."""
    return np.linspace(0.02, 0.25, count)


def simulate_run(n: int, rates: np.ndarray, reps: int, rng: np.random.Generator,
                 changes: dict[int, tuple[float, float]] | None = None) -> np.ndarray:
    """(reps, scenarios, 4) tables: every scenario at its rate for both policies, except ``changes``
    (index -> (baseline rate, candidate rate))."""
    changes = changes or {}
    return np.stack([simulate_scenario(n, *changes.get(i, (p, p)), reps, rng) for i, p in enumerate(rates)], axis=1)


def gate(reps: int, rng: np.random.Generator) -> None:
    names = [f"s{i}" for i in range(BANK_SCENARIOS)]
    planned = plan_episodes(names)
    rates = bank_rates()
    check = simulate_run(20, rates, 50, rng, {0: (0.0, 0.3)})
    check = np.concatenate([check, simulate_run(1000, rates, 50, rng, {2: (0.05, 0.08)})])  # PASSes among them
    overall, scenario_fail, passed = gate_outcomes(check)
    for r in range(check.shape[0]):  # the vectorised rule is compare_scenarios'
        tables = {name: PairedTable(*map(int, check[r, i])) for i, name in enumerate(names)}
        per, whole = compare_scenarios(tables, DEFAULT_MARGIN)
        assert (whole.verdict is Verdict.FAIL) == overall[r] and (whole.verdict is Verdict.PASS) == passed[r]
        assert [per[name].verdict is Verdict.FAIL for name in names] == list(scenario_fail[r])
    print(f"\n== the gate (compare_scenarios: every scenario a test, pooled test in the family), {BANK_SCENARIOS} "
          f"scenarios with failure rates 2-25 % (rho {DEFAULT_CORRELATION:g}), {reps} repetitions each")
    print(f"   planned episodes per scenario for --mde {planned.mde:g} --power {planned.power:g}: "
          f"{planned.episodes} ({planned.assumption})")
    sized = plan_episodes(names, mde=0.2, power=0.8)
    print(f"   planned for --mde 0.2 --power 0.8: {sized.episodes} per scenario")
    designs = [(planned.episodes, "default (planned for --mde 0.3)"),
               (sized.episodes, "power-sized for --mde 0.2"), (20, "20 per scenario (the former default)")]
    for n, label in designs:
        print(f"  {n} episodes per scenario, {label}:")
        cases = [
            ("identical policies: FAIL", {}, None),
            ("one scenario 0 % -> 30 %: FAIL and named", {0: (0.0, 0.3)}, 0),
            ("one scenario 0 % -> 30 %, another fixed 30 % -> 0 %: FAIL and named",
             {0: (0.0, 0.3), 1: (0.3, 0.0)}, 0),
            ("one scenario 5 % -> 25 % (+20 pp): FAIL and named", {2: (0.05, 0.25)}, 2),
            ("every scenario +3 pp: FAIL", {i: (p, p + 0.03) for i, p in enumerate(rates)}, None),
            ("identical policies: PASS", {}, "pass"),
            ("one scenario 5 % -> 15 % (+10 pp): PASS (should be rare)", {2: (0.05, 0.15)}, "pass"),
            ("one scenario 5 % -> 15 % (+10 pp): FAIL", {2: (0.05, 0.15)}, None),
        ]
        for text, changes, named in cases:
            overall, scenario_fail, passed = gate_outcomes(simulate_run(n, rates, reps, rng, changes))
            if named == "pass":
                print(f"    {text:<72} {MonteCarloRate(int(passed.sum()), reps)}")
            elif named is None:
                print(f"    {text:<72} {MonteCarloRate(int(overall.sum()), reps)}")
            else:
                hit = overall & scenario_fail[:, named]
                wrong = (scenario_fail.sum(axis=1) - scenario_fail[:, named]) > 0
                print(f"    {text:<72} {MonteCarloRate(int(hit.sum()), reps)}; another scenario named: "
                      f"{MonteCarloRate(int(wrong.sum()), reps).rate:.4f}")
    print("  power the default run states (planning model; per scenario at the Bonferroni level, pooled at its share):")
    for n, _ in designs:
        power = run_power({name: n for name in names}, {}, margin=DEFAULT_MARGIN, alpha=DEFAULT_ALPHA)
        one, pooled = power.per_scenario[names[0]], power.pooled
        at20 = run_power({name: n for name in names}, {}, margin=DEFAULT_MARGIN, alpha=DEFAULT_ALPHA, mde=0.2)
        print(f"    {n} per scenario: one scenario at the margin {one.at_margin:.4f}, at +30 pp {one.at_mde:.3f}, "
              f"at +20 pp {at20.per_scenario[names[0]].at_mde:.3f}, "
              f"80 % at +{100 * one.detectable:.1f} pp; pooled ({pooled.n} pairs) at the margin "
              f"{pooled.at_margin:.3f}, 80 % at +{100 * pooled.detectable:.1f} pp")


def gate_sequential(reps: int, rng: np.random.Generator, looks: int = 5) -> None:
    """The gate as ``dv2s regress --sequential`` runs it: the pooled table looked at after every fifth of the
    seeds by ``SequentialTest`` (spending the pooled share, alpha/2; stopping only for FAIL), then the family
    at the stop with the pooled member decided by the sequential test."""
    names = [f"s{i}" for i in range(BANK_SCENARIOS)]
    n = plan_episodes(names).episodes
    rates = bank_rates()
    print(f"\n== the gate with --sequential: {BANK_SCENARIOS} scenarios x {n} seeds, {looks} looks, {reps} repetitions")
    for text, changes, named in (("identical policies: FAIL", {}, None),
                                 ("one scenario 0 % -> 30 %: FAIL and named", {0: (0.0, 0.3)}, 0),
                                 ("every scenario +3 pp: FAIL", {i: (p, p + 0.03) for i, p in enumerate(rates)}, None)):
        episodes = []  # per scenario: (reps, n, 4) one-hot cells per seed
        for i, p in enumerate(rates):
            base_rate, cand_rate = changes.get(i, (p, p))
            difficulty = rng.standard_normal((reps, n))
            threshold = lambda q: stats.norm.isf(q) if q > 0 else np.inf  # noqa: E731
            shared, own = np.sqrt(DEFAULT_CORRELATION), np.sqrt(1 - DEFAULT_CORRELATION)
            cand = shared * difficulty + own * rng.standard_normal((reps, n)) > threshold(cand_rate)
            base = shared * difficulty + own * rng.standard_normal((reps, n)) > threshold(base_rate)
            episodes.append(np.stack([cand & base, cand & ~base, ~cand & base, ~cand & ~base], axis=-1).cumsum(axis=1))
        cells = np.stack(episodes, axis=1)  # (reps, scenarios, n, 4) cumulative over seeds
        fails = hits = used = 0
        for r in range(reps):
            test = SequentialTest(DEFAULT_MARGIN, DEFAULT_ALPHA * DEFAULT_POOLED_WEIGHT, max_episodes=n * BANK_SCENARIOS,
                                  stop_for_pass=False)
            verdict, seeds = None, n
            for k in range(1, looks + 1):
                seeds = n * k // looks
                pooled = cells[r, :, seeds - 1].sum(axis=0)
                verdict = test.update(PairedTable(*map(int, pooled)))
                if verdict is not None:
                    break
            tables = {name: PairedTable(*map(int, cells[r, i, seeds - 1])) for i, name in enumerate(names)}
            per, whole = compare_scenarios(tables, DEFAULT_MARGIN, pooled_rejected=verdict is Verdict.FAIL)
            fails += whole.verdict is Verdict.FAIL
            hits += named is not None and per[names[named]].verdict is Verdict.FAIL and whole.verdict is Verdict.FAIL
            used += seeds
        rate = MonteCarloRate(hits if named is not None else fails, reps)
        print(f"    {text:<44} {rate}   mean seeds run {used / reps:.1f} of {n}")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--seed", type=int, default=20261123)
    parser.add_argument("--only", choices=["fixed", "sizes", "sequential", "gate", "gate-sequential"], default=None)
    args = parser.parse_args(argv)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    reps = 500 if args.quick else 4000
    search_reps = 500 if args.quick else 2000
    slow_reps = 300 if args.quick else 2000
    rng = np.random.default_rng(args.seed)
    start = time.perf_counter()
    print(f"alpha {DEFAULT_ALPHA:g} (FAIL one-sided; PASS at alpha/2), margin {DEFAULT_MARGIN:g}, "
          f"latent correlation rho {DEFAULT_CORRELATION:g} (phi {phi_of(P0, P1, DEFAULT_CORRELATION):.2f} at "
          f"{P0:.0%} vs {P1:.0%}), seed {args.seed}\n")
    sections = {"fixed": lambda: fixed_design(reps, rng), "sizes": lambda: sample_sizes(search_reps, args.seed),
                "sequential": lambda: sequential(slow_reps, rng), "gate": lambda: gate(slow_reps, rng),
                "gate-sequential": lambda: gate_sequential(slow_reps // 2, rng)}
    for name, section in sections.items():
        if args.only in (None, name):
            section()
    print(f"\nelapsed {time.perf_counter() - start:.0f} s; load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")


if __name__ == "__main__":
    main()
