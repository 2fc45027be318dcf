"""Time from a mined failure to a validated bank entry, offline backends, one core.

``python -m bench.bench_mine_convert [--budget 80] [--failures 12] [--k 10] [--json OUT]``

1. mines the ``keep_lane`` policy (it runs into what stands in its lane) with the random sampler
   over the whole shipped bank (:func:`dv2s_gym.mining.miner.mine`, no conversion);
2. takes the first failure of each scenario (up to ``--failures`` scenarios, in index order: no picking);
3. converts each one (:func:`dv2s_gym.mining.conversion.convert.convert_failure`: failure video, interaction,
   exact replay, ``bev`` DRA, ``rules`` SG, safety + sandbox, ``k`` reproduction episodes, avoidability, E2E-SC,
   the judge, the converted clip, bank add or merge) into a new bank, and prints the median seconds of every stage
   the conversions recorded (``timings``, read from the records, so a new stage is listed too), the wall time
   outside every stage, and the kept / merged / rejected counts with the stages that rejected;
4. baseline measured in the same run: the plain D-V2S conversion of the same failure videos
   (:func:`dv2s_gym.pipeline.convert.convert_video`: describe, generate, checks, preview), and the
   paper's 19.08 s per conversion. The baseline runs its own sandbox check (its cache is off for it).

The process is pinned to CPU 0 (``os.sched_setaffinity``) and uses a fresh cache directory, so every
new script pays its sandbox run (cached only when a later failure yields the same script).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

PAPER_SECONDS = 19.08
"""The paper's conversion time per video (D-V2S with GPT-4o)."""


def _summary(values):
    return {"median": statistics.median(values), "mean": statistics.fmean(values), "max": max(values),
            "min": min(values), "n": len(values)}


def stage_medians(rows):
    """Median seconds of every stage the conversions recorded (their ``timings``), in the order the conversion runs
    them, with how many conversions reached each stage; ``unrecorded`` is the wall time outside every stage."""
    order = []
    for row in rows:
        order.extend(s for s in row["timings"] if s not in order)
    stages = {s: {"median": statistics.median([row["timings"][s] for row in rows if s in row["timings"]]),
                  "n": sum(s in row["timings"] for row in rows)} for s in order}
    if rows:
        rest = [max(0.0, row["seconds"] - sum(row["timings"].values())) for row in rows]
        stages["unrecorded"] = {"median": statistics.median(rest), "n": len(rows)}
    return stages


def rejection_stages(rows):
    """Rejected conversions counted by the stage that rejected them (the record's ``stage``), most first."""
    counts = {}
    for row in rows:
        if row["status"] == "rejected":
            counts[row["stage"]] = counts.get(row["stage"], 0) + 1
    return dict(sorted(counts.items(), key=lambda item: -item[1]))


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--budget", type=int, default=80, help="mining episodes (default 80)")
    parser.add_argument("--failures", type=int, default=12, help="failures to convert, one per scenario")
    parser.add_argument("--k", type=int, default=10, help="reproduction episodes (default 10)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--policy", default="keep_lane")
    parser.add_argument("--no-baseline", action="store_true", help="skip the convert_video baseline")
    parser.add_argument("--json", help="write the measurements here")
    args = parser.parse_args(argv)

    work = Path(tempfile.mkdtemp(prefix="bench-mine-convert-"))
    os.environ["DV2S_CACHE_DIR"] = str(work / "cache")  # before dv2s-gym reads it: nothing cached
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})

    t0 = time.perf_counter()
    from dv2s_gym.mining.conversion.settings import ConversionSettings
    from dv2s_gym.mining.conversion.convert import convert_failure
    from dv2s_gym.mining.miner import MineSettings, WorkerSettings, mine
    from dv2s_gym.pipeline.convert import convert_video
    imports = time.perf_counter() - t0

    t0 = time.perf_counter()
    run = mine(args.policy, MineSettings(budget=args.budget, sampler="random", seed=args.seed, reference=None),
               out=work / "run", workers=WorkerSettings(workers=1), progress=False, reports=False)
    mining = time.perf_counter() - t0
    failed = [r for r in sorted(run.records, key=lambda r: r.index) if r.failed]
    chosen, seen = [], set()
    for record in failed:
        if record.scenario not in seen:
            seen.add(record.scenario)
            chosen.append(record)
    chosen = chosen[:args.failures]
    print(f"mined {len(run.records)} episodes in {mining:.1f} s: {len(failed)} failures in {len(seen)} scenarios; "
          f"converting {len(chosen)} (imports {imports:.2f} s)")

    rows = []
    for record in chosen:
        start = time.perf_counter()
        out = convert_failure(record, work / "run", ConversionSettings(policy=args.policy, k=args.k), bank=work / "bank",
                              cluster=f"{record.scenario}/{record.failure.type}/bench")
        wall = time.perf_counter() - start
        baseline = None
        if not args.no_baseline and out.video:
            os.environ["DV2S_SANDBOX_CACHE"] = "0"  # the baseline's own sandbox run, not the conversion's cached pass
            try:
                start = time.perf_counter()
                convert_video(work / "run" / out.video, work / "baseline" / record.scenario)
                baseline = time.perf_counter() - start
            finally:
                del os.environ["DV2S_SANDBOX_CACHE"]
        rate = (out.reproduction or {}).get("rate")
        rows.append({"scenario": record.scenario, "failure": record.failure.kind, "status": str(out.status),
                     "stage": out.stage, "reason": out.reason, "rejections": list(out.rejections or ()), "rate": rate, "e2e_sc": out.e2e_sc,
                     "seconds": wall, "timings": dict(out.timings or {}), "baseline_seconds": baseline})
        print(f"  {record.scenario:<38} {str(out.status):<8} {wall:6.2f} s  rate {rate if rate is None else f'{rate:.1f}'}"
              f"  e2e {out.e2e_sc if out.e2e_sc is None else round(out.e2e_sc, 2)}"
              f"  baseline {baseline if baseline is None else round(baseline, 2)} s"
              + (f"  ({out.reason})" if out.rejected else ""))

    seconds = [row["seconds"] for row in rows]
    valid = [row["seconds"] for row in rows if row["status"] in ("kept", "merged")]
    summary = {"all": _summary(seconds)}
    if valid:
        summary["to_bank_entry"] = _summary(valid)
    stages = stage_medians(rows)
    rejected_by = rejection_stages(rows)
    baselines = [row["baseline_seconds"] for row in rows if row["baseline_seconds"] is not None]
    print(f"\n{len(rows)} failures: kept {sum(r['status'] == 'kept' for r in rows)}, merged "
          f"{sum(r['status'] == 'merged' for r in rows)}, rejected {sum(r['status'] == 'rejected' for r in rows)}"
          + (f" (by stage: {', '.join(f'{stage} {n}' for stage, n in rejected_by.items())})" if rejected_by else ""))
    for label, stats in summary.items():
        print(f"seconds per failure ({label}, n={stats['n']}): median {stats['median']:.2f}, mean {stats['mean']:.2f}, "
              f"max {stats['max']:.2f}; median vs the paper's {PAPER_SECONDS} s: {stats['median'] / PAPER_SECONDS:.2f}x "
              f"({PAPER_SECONDS / stats['median']:.1f}x faster)")
    if baselines:
        base = statistics.median(baselines)
        print(f"baseline convert_video (same videos, this run): median {base:.2f} s; mined conversion / baseline: "
              f"{summary['all']['median'] / base:.2f}x")
    print("median seconds per stage (every stage the conversions recorded; n = conversions that reached it): "
          + ", ".join(f"{s} {v['median']:.2f}" + (f" (n={v['n']})" if v["n"] != len(rows) else "")
                      for s, v in stages.items()))
    print(f"target: median <= 5 s -> {'met' if summary['all']['median'] <= 5 else 'MISSED'}"
          f" (load average at the end: {', '.join(f'{x:.2f}' for x in os.getloadavg())} on {os.cpu_count()} CPUs)")
    if args.json:
        Path(args.json).write_text(json.dumps({"rows": rows, "summary": summary, "stages": stages,
                                               "rejected_by_stage": rejected_by,
                                               "baseline_median": statistics.median(baselines) if baselines else None,
                                               "mining_seconds": mining, "imports_seconds": imports,
                                               "episodes": len(run.records), "failures": len(failed)}, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
