"""Monte Carlo calibration of the ``dv2s regress`` statistics (dv2s_gym/regress/stats.py).

    python -m bench.calibrate_regress            # full run (a few minutes on 2 cores)
    python -m bench.calibrate_regress --quick    # fewer repetitions

Synthetic paired outcomes from the shared-difficulty model (a per-episode latent difficulty
shared by both policies, latent correlation rho; see the module docstring), fed through the
actual decision rules. It prints:

* the false-alarm rate (FAIL with identical policies) of ``compare`` at the documented episode
  count, with its Wilson interval, and at a few other designs;
* P(PASS) when the true difference equals the non-inferiority margin;
* the power (FAIL rate) at +3 percentage points from a 5 % baseline at the documented count,
  and what the same count gives unpaired;
* the episodes needed for 80 % power, paired against unpaired, analytic and simulated, for a
  few correlations;
* the same checks for ``SequentialTest`` (5 looks) and for ``compare_scenarios`` with several
  scenarios (default rule and the one-family ``pooled_weight`` variant).
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

from dv2s_gym.regress.stats import (
    DEFAULT_ALPHA,
    DEFAULT_CORRELATION,
    DEFAULT_MARGIN,
    DOCUMENTED_BASELINE_RATE,
    DOCUMENTED_DELTA,
    DOCUMENTED_EPISODES,
    DOCUMENTED_POWER,
    MonteCarloRate,
    PairedTable,
    SequentialTest,
    Verdict,
    compare_scenarios,
    discordant_probability,
    paired_cell_probabilities,
    paired_sample_size,
    simulate_false_alarm,
    simulate_paired_outcomes,
    simulate_tables,
    simulate_unpaired_power,
    simulate_verdict_rates,
    simulated_sample_size,
    unpaired_sample_size,
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


def run_sequential(p_candidate: float, reps: int, rng: np.random.Generator, spending: str,
                   looks: int = 5) -> tuple[dict, float]:
    n_max = DOCUMENTED_EPISODES
    counts = {verdict: 0 for verdict in Verdict}
    used = 0
    for start in range(0, reps, 500):
        size = min(500, reps - start)
        cand, base = simulate_paired_outcomes(n_max, P0, p_candidate, DEFAULT_CORRELATION, size, rng)
        cells = np.stack([cand & base, cand & ~base, ~cand & base, ~cand & ~base], axis=-1).cumsum(axis=1)
        for r in range(size):
            test = SequentialTest(DEFAULT_MARGIN, max_episodes=n_max, spending=spending)
            for k in range(1, looks + 1):
                n = n_max * k // looks
                verdict = test.update(PairedTable(*map(int, cells[r, n - 1])))
                if verdict is not None:
                    break
            counts[verdict] += 1
            used += n
    return counts, used / reps


def sequential(reps: int, rng: np.random.Generator) -> None:
    print(f"\n== SequentialTest, 5 looks every {DOCUMENTED_EPISODES // 5} paired episodes up to "
          f"{DOCUMENTED_EPISODES}, {reps} repetitions each")
    for spending in ("obrien-fleming", "pocock"):
        for label, p_candidate, verdict in (("false alarm (FAIL), identical", P0, Verdict.FAIL),
                                            ("P(PASS) at the margin", P0 + DEFAULT_MARGIN, Verdict.PASS),
                                            (f"power (FAIL) at +{DOCUMENTED_DELTA * 100:.0f} pp", P1, Verdict.FAIL)):
            counts, mean_used = run_sequential(p_candidate, reps, rng, spending)
            print(f"    {spending:<14} {label:<32} {MonteCarloRate(counts[verdict], reps)}   "
                  f"mean episodes {mean_used:5.0f}   (PASS/FAIL/INCONCLUSIVE "
                  f"{counts[Verdict.PASS]}/{counts[Verdict.FAIL]}/{counts[Verdict.INCONCLUSIVE]})")


def scenarios(reps: int, rng: np.random.Generator) -> None:
    print(f"\n== compare_scenarios: overall verdict, {DOCUMENTED_EPISODES} paired episodes split over the scenarios, "
          f"{reps} repetitions each")
    designs = {
        "2 scenarios x 400, 5 %": [0.05] * 2,
        "4 scenarios x 200, 3/5/5/8 %": [0.03, 0.05, 0.05, 0.08],
        "8 scenarios x 100, 1-15 %": [0.01, 0.02, 0.03, 0.05, 0.05, 0.07, 0.1, 0.15],
    }
    for name, rates in designs.items():
        n_each = DOCUMENTED_EPISODES // len(rates)
        for label, delta in (("false alarm (FAIL), identical", 0.0), (f"power (FAIL) at +{DOCUMENTED_DELTA * 100:.0f} pp", DOCUMENTED_DELTA)):
            sims = [simulate_tables(n_each, p, p + delta, DEFAULT_CORRELATION, reps, rng) for p in rates]
            default = family = 0
            for r in range(reps):
                tables = {f"s{i}": PairedTable(*map(int, sims[i][r])) for i in range(len(rates))}
                default += compare_scenarios(tables, DEFAULT_MARGIN, pooled_weight=None)[1].verdict is Verdict.FAIL
                family += compare_scenarios(tables, DEFAULT_MARGIN, pooled_weight=0.8)[1].verdict is Verdict.FAIL
            print(f"    {name:<30} {label:<30} default: {MonteCarloRate(default, reps)}")
            print(f"    {'':<30} {'':<30} pooled_weight=0.8: {MonteCarloRate(family, reps)}")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--seed", type=int, default=20261123)
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
    fixed_design(reps, rng)
    sample_sizes(search_reps, args.seed)
    sequential(slow_reps, rng)
    scenarios(slow_reps, rng)
    print(f"\nelapsed {time.perf_counter() - start:.0f} s; load average {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")


if __name__ == "__main__":
    main()
