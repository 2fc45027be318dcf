"""Failure mining: how many distinct failures each sampler finds, and how mining scales with workers.

    python -m bench.bench_mine                      # both parts, the settings recorded in bench/RESULTS.md
    python -m bench.bench_mine --quick              # a short run of both (budget 40, one seed)
    python -m bench.bench_mine --part samplers --policy dv2s-ppo --budget 200 --seeds 0 1
    python -m bench.bench_mine --part throughput --throughput-sampler cross-entropy
    python -m bench.bench_mine --part samplers --config 'b2:alpha=0.9,buckets=2' --config 'nov:feedback=novelty'
    python -m bench.bench_mine --part samplers --samplers random split --split-config 'ucb:chooser=ucb'
    python -m bench.bench_mine --part breadth --budget 100 --seeds 0 1 2   # breadth on three policies
    python -m bench.bench_mine --part saturation --budget 60 --saturation-budget 300 --seeds 50

**Samplers** (``--part samplers``): every sampler of :data:`dv2s_gym.mining.sampling.samplers.SAMPLERS`
mines the same policy on the same scenarios (the whole shipped bank by default) with the
same budget, once per run seed (``--seeds``; the seed fixes the sampler's draws and every
episode's env seed). Printed per sampler, pooled over the seeds: failed episodes per 100
episodes with the Wilson 95 % interval (``dv2s_gym.regress.stats.wilson_interval``), distinct
failure clusters per run (``dv2s_gym.mining.cluster``: scenario, failure class, cell of a
3-bins-per-parameter grid) and how many of them hold a failure the reference driver avoided,
and the ratio of each sampler's mean distinct clusters to random sampling's (target: the best
adaptive sampler >= 3x). Each adaptive sampler runs once per setting (``--config``; default:
VerifAI's defaults and the two settings of :data:`TUNED_CONFIGS`); the ``split`` sampler runs in its preset
(``dv2s mine --sampler split``) or in each ``--split-config``. With ``--reference none`` (the default when the policy under test is
the reference driver itself, ``rule``) avoidability is not checked.

**Breadth** (``--part breadth``): ``random``, ``cross-entropy`` (``dv2s mine``'s default) and ``split``, each as
``dv2s mine --sampler NAME`` runs it, on several policies the project did not train for it (``--policies``,
default :data:`BREADTH_POLICIES`) and seeds, at the same budget, measured on what none of them is fed:
behaviour clusters (``dv2s_gym.mining.cluster``), (scenario, failure type) pairs and scenarios with a failure;
printed with each sampler's ratio to random (target: the default adaptive sampler >= 2x random on behaviour
clusters and never below it on pairs).

**Saturation** (``--part saturation``): random sampling at ``--budget`` against ``--saturation-budget`` episodes
(one run per policy of ``--policies``, first seed): how much of what exists random already finds at the bench's
budget, which bounds the ratio any sampler can reach on that policy.

**Throughput** (``--part throughput``): the same mining run (same budget, seed, sampler -- default
``random`` -- and batch, 8 unless ``--batch``) with 1 worker and with 2, in alternating rounds so both see
the same load; episodes per minute end to end (scene space and worker pool start included) and the ratio
(target >= 1.8x). A non-adaptive sampler also runs with 2 workers one chunk at a time (what the miner did
before it sent whole chunks ahead, and still does for adaptive samplers): the cost of the idle worker at the
end of each chunk (an adaptive sampler streams on the sliding-window schedule, ``dv2s_gym/mining/sampling/window.py``). The
machine's parallel capacity (a busy loop in 2 processes against 1, from ``bench.bench_regress``)
is measured in the same rounds: other processes on a shared machine bound the ratio by it.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import tempfile
import time
from typing import Any, Dict, List, Optional, Sequence, Tuple

os.environ.setdefault("OMP_NUM_THREADS", "1")


def _load() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "n/a"


def mine_once(policy: str, sampler: str, seed: int, budget: int, workers: int, reference: Optional[str],
              scenarios: Optional[List[str]], batch: Optional[int], out: str,
              sampler_options: Optional[Dict[str, Any]] = None, feedback: Optional[str] = "robustness"
              ) -> Dict[str, Any]:
    """One mining run in a fresh folder; its counts and wall time."""
    from dv2s_gym.mining.miner import MineSettings, WorkerSettings, mine

    shutil.rmtree(out, ignore_errors=True)
    from dv2s_gym.mining.sampling.samplers import SAMPLER_OPTIONS

    takes = SAMPLER_OPTIONS.get(sampler, ())
    options = {k: v for k, v in (sampler_options or {}).items() if k in takes}  # random/halton take none
    extra: Dict[str, Any] = {"sampler_options": options} if options else {}
    if feedback is not None:  # None: the sampler's own default (mine's)
        extra["feedback"] = feedback
    start = time.perf_counter()
    settings = MineSettings(budget=budget, sampler=sampler, seed=seed, reference=reference, scenarios=scenarios,
                            batch=batch, **extra)
    run = mine(policy, settings, out=out, workers=WorkerSettings(workers=workers), progress=False, reports=False)
    seconds = time.perf_counter() - start
    failures = run.failures
    avoidable = [r for r in failures if r.avoidable is True]
    clusters = set(run.clusters.values())
    from dv2s_gym.mining.sampling.rate import failure_rate

    rate = failure_rate(run.records, scenarios=list(run.settings.scenarios or ()) or None,
                        sampler=run.settings.sampler)
    overall = rate.overall if rate.available else None
    avoidable_clusters = {run.clusters[int(r.index)] for r in avoidable}
    return {
        "sampler": sampler, "seed": seed, "episodes": len(run.records),
        "errors": sum(1 for r in run.records if r.error), "failures": len(failures),
        "avoidable": len(avoidable), "clusters": len(clusters), "avoidable_clusters": len(avoidable_clusters),
        "scenarios_failing": len({r.scenario for r in failures}),
        "kinds": len({(r.scenario, r.failure.kind) for r in failures}), "seconds": seconds,
        "rate": (overall.value, overall.low, overall.high, overall.ess) if overall else None,
        "collapsed": rate.collapsed,
    }


Config = Tuple[str, Dict[str, Any], Optional[str]]
"""A setting of the adaptive samplers: ``(label, sampler options, feedback)`` (feedback ``None``: the sampler's
default)."""

DEFAULT_CONFIG: Config = ("VerifAI defaults", {}, "robustness")
TUNED_CONFIGS: List[Config] = [
    ("alpha 0.9, 2 buckets", {"alpha": 0.9, "buckets": 2}, "robustness"),
    ("alpha 0.9, 1 bucket, thres 1", {"alpha": 0.9, "buckets": 1, "thres": 1.0}, "robustness"),
]
"""The settings chosen on a tuning seed (100) that is not one of the bench's seeds (see bench/RESULTS.md)."""

SPLIT_PRESET: Config = ("preset", {}, None)
"""The split sampler as ``dv2s mine --sampler split`` runs it (its defaults, chosen on tuning seeds 7-14)."""

_TEXT_OPTIONS = ("chooser", "params")


def parse_config(text: str) -> Config:
    """``"label:alpha=0.9,buckets=2,thres=1,feedback=novelty"`` (every key optional; also ``chooser`` and
    ``params`` of the split sampler) as a :data:`Config`; no feedback: the sampler's default."""
    label, _, body = text.partition(":")
    options: Dict[str, Any] = {}
    feedback: Optional[str] = None  # the sampler's default (robustness, novelty for split)
    for item in filter(None, body.split(",")):
        key, _, value = item.partition("=")
        if key == "feedback":
            feedback = value
        elif key in _TEXT_OPTIONS:
            options[key] = value
        elif key in ("buckets", "warmup", "avoid"):
            options[key] = int(value)
        else:
            options[key] = float(value)
    return label or body, options, feedback


def bench_samplers(policy: str, samplers: Sequence[str], seeds: Sequence[int], budget: int, workers: int,
                   reference: Optional[str], scenarios: Optional[List[str]], batch: Optional[int],
                   configs: Sequence[Config], root: str,
                   split_configs: Sequence[Config] = (SPLIT_PRESET,)) -> Dict[str, Dict[str, Any]]:
    """Every sampler (each adaptive one in every config; ``split`` in each of ``split_configs``) on every
    seed; the summary by entry (printed)."""
    from dv2s_gym.mining.sampling.samplers import SPLIT, is_adaptive
    from dv2s_gym.regress.stats import wilson_interval

    entries: List[Tuple[str, str, Config]] = []
    for name in samplers:
        if name == SPLIT:
            entries += [(f"{name} [{config[0]}]", name, config) for config in split_configs]
            continue
        for config in (configs if is_adaptive(name) else [DEFAULT_CONFIG]):
            label = name if not is_adaptive(name) or len(configs) == 1 and config == DEFAULT_CONFIG \
                else f"{name} [{config[0]}]"
            entries.append((label, name, config))
    print(f"# samplers: policy {policy}, reference {reference or 'none'}, "
          f"scenarios {' '.join(scenarios) if scenarios else 'whole bank'}, budget {budget}, seeds {list(seeds)}, "
          f"{workers} workers, batch {batch or 'default'}; adaptive sampler settings: "
          + "; ".join(f"{label} = {options or 'VerifAI defaults'}, feedback {feedback or 'robustness'}"
                      for label, options, feedback in configs)
          + ("; split settings: " + "; ".join(f"{label} = {options or 'its defaults'}, feedback "
                                               f"{feedback or 'its default'}" for label, options, feedback in
                                               split_configs) if SPLIT in samplers else ""), flush=True)
    runs: Dict[str, List[Dict[str, Any]]] = {label: [] for label, _, _ in entries}
    for seed in seeds:  # seed-major, so an interrupted bench still compares the samplers on equal terms
        for label, name, (_, options, feedback) in entries:
            row = mine_once(policy, name, seed, budget, workers, reference, scenarios, batch,
                            os.path.join(root, f"{len(runs[label])}-{seed}-{name}"), options, feedback)
            runs[label].append(row)
            print(f"  {label:46s} seed {seed}: {row['failures']:4d} failures / {row['episodes']} episodes "
                  f"({row['errors']} errors), {row['clusters']:4d} distinct clusters, "
                  f"{row['avoidable_clusters']:4d} avoidable, {row['scenarios_failing']:2d} scenarios, "
                  f"{row['kinds']:2d} (scenario, class) pairs, "
                  f"{row['seconds']:.0f} s, load {_load()}", flush=True)
    summary: Dict[str, Dict[str, Any]] = {}
    for label, rows in runs.items():
        episodes = sum(r["episodes"] - r["errors"] for r in rows)
        failures = sum(r["failures"] for r in rows)
        low, high = wilson_interval(failures, episodes)
        summary[label] = {
            "per100": 100.0 * failures / max(episodes, 1), "interval": (100.0 * low, 100.0 * high),
            "clusters": statistics.mean(r["clusters"] for r in rows),
            "avoidable_clusters": statistics.mean(r["avoidable_clusters"] for r in rows),
            "kinds": statistics.mean(r["kinds"] for r in rows),
            "per_seed": [r["clusters"] for r in rows], "runs": rows,
        }
    base = summary.get("random")
    print("\n| sampler | failures / 100 episodes (95% CI) | distinct clusters per run (per seed) "
          "| avoidable clusters | (scenario, class) pairs | clusters vs random |")
    print("|---|---|---|---|---|---|")
    for label, s in summary.items():
        ratio = s["clusters"] / base["clusters"] if base and base["clusters"] else float("nan")
        s["ratio"] = ratio
        print(f"| {label} | {s['per100']:.1f} ({s['interval'][0]:.1f}-{s['interval'][1]:.1f}) "
              f"| {s['clusters']:.1f} ({', '.join(map(str, s['per_seed']))}) "
              f"| {s['avoidable_clusters']:.1f} | {s['kinds']:.1f} | {ratio:.2f}x |")
    adaptive = {label: summary[label] for label, name, _ in entries if is_adaptive(name)}
    if adaptive and base and base["clusters"]:
        best = max(adaptive, key=lambda k: adaptive[k]["ratio"])
        print(f"\nbest adaptive sampler: {best}, {adaptive[best]['ratio']:.2f}x the distinct failures of random "
              "(target >= 3x)", flush=True)
    return summary


BREADTH = ("clusters", "kinds", "scenarios_failing")
"""The breadth measures of ``--part breadth``: behaviour clusters, (scenario, failure type) pairs, scenarios with a
failure (keys of :func:`mine_once`'s row)."""
BREADTH_NAMES = {"clusters": "behaviour clusters", "kinds": "(scenario, failure type) pairs",
                 "scenarios_failing": "scenarios with a failure"}
BREADTH_POLICIES = ("idm", "keep_lane", "rule?action_noise=0.2")
"""Policies the project did not train for the comparison (``policies/registry.py``)."""


def _rate_text(row: Dict[str, Any]) -> str:
    """The run's importance-weighted failure-rate estimate under the scenarios' own distributions
    (``dv2s_gym.mining.sampling.rate``), with its 95 % interval and effective sample size."""
    if row.get("rate") is None:
        return "n/a (no proposal densities)"
    value, low, high, ess = row["rate"]
    return f"{value:.3f} [{low:.3f}, {high:.3f}] (ess {ess:.0f}{', collapsed' if row.get('collapsed') else ''})"


def bench_breadth(policies: Sequence[str], samplers: Sequence[str], seeds: Sequence[int], budget: int, workers: int,
                  scenarios: Optional[List[str]], batch: Optional[int], root: str) -> Dict[str, Any]:
    """Every sampler, in the setting ``dv2s mine --sampler NAME`` runs it (its default options and feedback; a name
    ``NAME+FEEDBACK`` runs it with that feedback, e.g. ``cross-entropy+novelty``), on
    every policy and seed, at the same budget; the breadth of the failures found, none of which any sampler is fed:
    behaviour clusters, (scenario, failure type) pairs and scenarios with a failure. Printed per run, then the
    mean per policy and each sampler's ratio to random's mean (per policy and over all runs)."""
    print(f"# breadth: policies {list(policies)}, samplers {list(samplers)}, budget {budget}, seeds {list(seeds)}, "
          f"{workers} workers, batch {batch or 'default'}, no reference driver, scenarios "
          f"{' '.join(scenarios) if scenarios else 'whole bank'}", flush=True)
    rows: Dict[Tuple[str, str], List[Dict[str, Any]]] = {}
    for policy in policies:
        for seed in seeds:  # seed-major within a policy: an interrupted bench still compares on equal terms
            for sampler in samplers:
                name, _, feedback = sampler.partition("+")  # "cross-entropy+novelty": another feedback
                row = mine_once(policy, name, seed, budget, workers, None, scenarios, batch,
                                os.path.join(root, f"breadth-{len(rows)}-{seed}-{name}"), None, feedback or None)
                rows.setdefault((policy, sampler), []).append(row)
                print(f"  {policy:24s} {sampler:14s} seed {seed}: {row['failures']:4d} failures / {row['episodes']} "
                      f"episodes ({row['errors']} errors), {row['clusters']:3d} behaviour clusters, "
                      f"{row['kinds']:3d} (scenario, type) pairs, {row['scenarios_failing']:2d} scenarios, "
                      f"failure rate {_rate_text(row)}, {row['seconds']:.0f} s, load {_load()}", flush=True)
    summary: Dict[str, Any] = {"per_policy": {}, "overall": {}}
    print("\n| policy | sampler | failures | " + " | ".join(BREADTH_NAMES[m] for m in BREADTH)
          + " | " + " | ".join(f"{BREADTH_NAMES[m]} vs random" for m in BREADTH) + " |")
    print("|---|---|---:|" + "---:|" * (2 * len(BREADTH)))
    for policy in policies:
        base = {m: statistics.mean(r[m] for r in rows[(policy, "random")]) for m in BREADTH} \
            if (policy, "random") in rows else None
        for sampler in samplers:
            got = rows[(policy, sampler)]
            means = {m: statistics.mean(r[m] for r in got) for m in BREADTH}
            ratios = {m: (means[m] / base[m] if base and base[m] else None) for m in BREADTH}
            summary["per_policy"][(policy, sampler)] = {"means": means, "ratios": ratios,
                                                        "failures": statistics.mean(r["failures"] for r in got)}
            print(f"| {policy} | {sampler} | {statistics.mean(r['failures'] for r in got):.1f} | "
                  + " | ".join(f"{means[m]:.1f} ({', '.join(str(r[m]) for r in got)})" for m in BREADTH) + " | "
                  + " | ".join("-" if ratios[m] is None else f"{ratios[m]:.2f}x" for m in BREADTH) + " |")
    if "random" not in samplers:
        print("\nno ratios to random: add random to --samplers for them", flush=True)
    if "random" in samplers:
        print("\nover all policies and seeds (sum over runs, ratio to random at the same budget):")
        totals = {s: {m: sum(r[m] for p in policies for r in rows[(p, s)]) for m in BREADTH} for s in samplers}
        for sampler in samplers:
            ratios = {m: totals[sampler][m] / totals["random"][m] if totals["random"][m] else float("nan")
                      for m in BREADTH}
            summary["overall"][sampler] = ratios
            print(f"  {sampler:14s} " + ", ".join(f"{BREADTH_NAMES[m]} {totals[sampler][m]} ({ratios[m]:.2f}x)"
                                                  for m in BREADTH), flush=True)
    return summary


def bench_saturation(policies: Sequence[str], seed: int, budget: int, large: int, workers: int,
                     scenarios: Optional[List[str]], batch: Optional[int], root: str) -> Dict[str, Any]:
    """How close random sampling at ``budget`` episodes already is to everything it finds at ``large``: one random
    run of ``large`` episodes per policy (its first ``budget`` episodes are exactly a random run of ``budget`` with
    the same seed: random draws do not depend on outcomes or on the budget); the breadth counts after ``budget``
    and after ``large``. ``found / found_large`` above 1/2 means no sampler can find 2x random's at ``budget`` on
    that policy, unless it finds what ``large`` random episodes do not."""
    from dv2s_gym.mining.cluster import cluster_id, pair_of
    from dv2s_gym.mining.miner import MineSettings, WorkerSettings, mine

    print(f"# saturation: random sampling, policies {list(policies)}, seed {seed}, {budget} against {large} episodes, "
          f"{workers} workers", flush=True)
    result: Dict[str, Any] = {}
    for index, policy in enumerate(policies):
        out = os.path.join(root, f"saturation-{index}")
        shutil.rmtree(out, ignore_errors=True)
        settings = MineSettings(budget=large, sampler="random", seed=seed, reference=None, scenarios=scenarios,
                                batch=batch)
        run = mine(policy, settings, out=out, workers=WorkerSettings(workers=workers), progress=False, reports=False)
        counts = {}
        for n in (budget, large):
            failed = [r for r in run.records[:n] if r.failure and not r.error]
            counts[n] = {"failures": len(failed), "clusters": len({cluster_id(r) for r in failed}),
                         "kinds": len({pair_of(r) for r in failed}),
                         "scenarios_failing": len({r.scenario for r in failed})}
        result[policy] = counts
        print(f"  {policy:24s} " + "; ".join(
            f"{BREADTH_NAMES[m]} {counts[budget][m]} at {budget} of {counts[large][m]} at {large} "
            f"({counts[budget][m] / counts[large][m]:.0%}; at most {counts[large][m] / max(counts[budget][m], 1):.2f}x)"
            if counts[large][m] else f"{BREADTH_NAMES[m]} 0" for m in BREADTH) + f", load {_load()}", flush=True)
    return result


def bench_throughput(policy: str, sampler: str, seed: int, budget: int, repeats: int, reference: Optional[str],
                     scenarios: Optional[List[str]], batch: Optional[int], root: str) -> Dict[str, float]:
    """1 worker against 2 on the same run, alternating; medians of episodes/min and of the per-round ratios.

    A non-adaptive sampler is also run with 2 workers one chunk at a time (``LOOKAHEAD_CHUNKS = 1``): the
    difference is what the idle workers at the end of each chunk cost.
    """
    from bench.bench_regress import parallel_capacity
    from dv2s_gym.mining import miner
    from dv2s_gym.mining.sampling.samplers import is_adaptive

    shipped = miner.LOOKAHEAD_CHUNKS
    batch = batch or 8  # the same for 1 and 2 workers: both run the same episodes (the miner's default: 4 per worker)
    configs = [("1 worker", 1, shipped, batch), ("2 workers", 2, shipped, batch)]
    if not is_adaptive(sampler):  # an adaptive sampler streams on the window schedule: no chunks
        configs.append(("2 workers, chunk by chunk", 2, 1, batch))
    print(f"# throughput: policy {policy}, sampler {sampler}, seed {seed}, budget {budget}, reference "
          f"{reference or 'none'}, batch {batch}, {repeats} rounds", flush=True)
    rates: Dict[str, List[float]] = {label: [] for label, _, _, _ in configs}
    ratios: Dict[str, List[float]] = {label: [] for label, _, _, _ in configs[1:]}
    capacity: List[float] = []
    try:
        for round_ in range(repeats):
            capacity.append(parallel_capacity())
            load = _load()
            seconds = {}
            order = configs if round_ % 2 == 0 else configs[::-1]
            for label, workers, lookahead, size in order:
                miner.LOOKAHEAD_CHUNKS = lookahead
                row = mine_once(policy, sampler, seed, budget, workers, reference, scenarios, size,
                                os.path.join(root, f"throughput-{workers}-{lookahead}-{size}"))
                seconds[label] = row["seconds"]
                rates[label].append(60.0 * row["episodes"] / row["seconds"])
                if row["errors"]:
                    print(f"  ({label}: {row['errors']} of {row['episodes']} episodes are errors)", flush=True)
            for label in ratios:
                ratios[label].append(seconds["1 worker"] / seconds[label])
            print(f"  round {round_ + 1}: " + ", ".join(f"{label} {rates[label][-1]:.1f} ep/min" for label in rates)
                  + "; " + ", ".join(f"{label} / 1 worker {ratios[label][-1]:.2f}x" for label in ratios)
                  + f"; parallel capacity {capacity[-1]:.2f}x; load {load} -> {_load()}", flush=True)
    finally:
        miner.LOOKAHEAD_CHUNKS = shipped
    result = {"rates": {k: statistics.median(v) for k, v in rates.items()},
              "ratios": {k: statistics.median(v) for k, v in ratios.items()},
              "capacity": statistics.median(capacity)}
    print("\nmining throughput (medians): " + ", ".join(f"{k} {v:.1f} ep/min" for k, v in result["rates"].items()))
    for label, ratio in result["ratios"].items():
        print(f"{label} / 1 worker: {ratio:.2f}x" + (" (target >= 1.8x)" if label == "2 workers" else ""))
    print(f"machine's parallel capacity: {result['capacity']:.2f}x", flush=True)
    return result


def main(argv: Sequence[str] | None = None) -> Dict[str, Any]:
    from dv2s_gym.mining.sampling.samplers import SAMPLERS

    parser = argparse.ArgumentParser(prog="python -m bench.bench_mine", description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="budget 40, one seed, one throughput round")
    parser.add_argument("--part", choices=("all", "samplers", "throughput", "breadth", "saturation"), default="all",
                        help="all: samplers and throughput; breadth: the samplers' breadth on several policies; "
                             "saturation: random at --budget against --saturation-budget episodes on those policies")
    parser.add_argument("--saturation-budget", type=int, default=300,
                        help="the large random budget of --part saturation (default 300)")
    parser.add_argument("--policies", nargs="*", default=list(BREADTH_POLICIES),
                        help="policies of --part breadth (default: idm keep_lane rule?action_noise=0.2)")
    parser.add_argument("--policy", default="rule", help="policy under test (default: rule)")
    parser.add_argument("--reference", default=None,
                        help="reference driver for avoidability ('none' to skip; default: rule, or none when the "
                             "policy is rule)")
    parser.add_argument("--scenarios", nargs="*", default=None, help="bank names or tag:<tag> (default: whole bank)")
    parser.add_argument("--samplers", nargs="*", default=list(SAMPLERS))
    parser.add_argument("--budget", type=int, default=None, help="episodes per run (default 300; --quick 40)")
    parser.add_argument("--seeds", type=int, nargs="*", default=None, help="run seeds (default 0 1 2; --quick 0)")
    parser.add_argument("--workers", type=int, default=2, help="workers of the sampler runs")
    parser.add_argument("--batch", type=int, default=None, help="scenes per chunk (default: the miner's)")
    parser.add_argument("--config", action="append", default=None, metavar="LABEL:KEY=VALUE,...",
                        help="a setting of the adaptive samplers (repeatable): alpha, buckets, thres (VerifAI's "
                             "parameters) and feedback (robustness|novelty), e.g. 'b2:alpha=0.9,buckets=2'; "
                             "default: VerifAI's defaults and the two tuned settings of TUNED_CONFIGS")
    parser.add_argument("--split-config", action="append", default=None, metavar="LABEL:KEY=VALUE,...",
                        help="a setting of the split sampler (repeatable): alpha, buckets, thres, chooser "
                             "(cross-entropy|ucb|epsilon-greedy), params (halton|random|bandit|cross-entropy), "
                             "warmup, avoid, feedback; default: its preset "
                             "(dv2s mine --sampler split)")
    parser.add_argument("--throughput-sampler", default="random")
    parser.add_argument("--throughput-budget", type=int, default=None, help="default 600; --quick 40")
    parser.add_argument("--repeats", type=int, default=None, help="throughput rounds (default 3; --quick 1)")
    args = parser.parse_args(argv)

    reference = args.reference if args.reference is not None else (None if args.policy == "rule" else "rule")
    reference = None if reference in ("none", "") else reference
    budget = args.budget or (40 if args.quick else 300)
    seeds = args.seeds if args.seeds else ([0] if args.quick else [0, 1, 2])
    repeats = args.repeats or (1 if args.quick else 3)
    throughput_budget = args.throughput_budget or (40 if args.quick else 600)
    configs = [parse_config(text) for text in args.config] if args.config else [DEFAULT_CONFIG, *TUNED_CONFIGS]
    split_configs = [parse_config(text) for text in args.split_config] if args.split_config else [SPLIT_PRESET]
    print(f"machine: {os.cpu_count()} cores; {time.strftime('%Y-%m-%d %H:%M')}; load {_load()}", flush=True)
    root = tempfile.mkdtemp(prefix="dv2s-bench-mine-")
    results: Dict[str, Any] = {}
    try:
        if args.part in ("all", "samplers"):
            results["samplers"] = bench_samplers(args.policy, args.samplers, seeds, budget, args.workers, reference,
                                                 args.scenarios, args.batch, configs, root, split_configs)
        if args.part == "breadth":
            samplers = args.samplers if args.samplers != list(SAMPLERS) else ["random", "cross-entropy", "split",
                                                                                "novelty-bandit"]
            results["breadth"] = bench_breadth(args.policies, samplers, seeds, budget, args.workers, args.scenarios,
                                               args.batch, root)
        if args.part == "saturation":
            results["saturation"] = bench_saturation(args.policies, seeds[0], budget, args.saturation_budget,
                                                     args.workers, args.scenarios, args.batch, root)
        if args.part in ("all", "throughput"):
            results["throughput"] = bench_throughput(args.policy, args.throughput_sampler, seeds[0],
                                                     throughput_budget, repeats, reference, args.scenarios,
                                                     args.batch, root)
    finally:
        shutil.rmtree(root, ignore_errors=True)
    return results


if __name__ == "__main__":
    main()
