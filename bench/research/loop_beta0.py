"""Does the closed loop's fine-tuned arm beat its control on held-out families with DAgger ``beta_decay`` 0?
A pre-declared measurement; the design below was committed before any run.

    python -m bench.research.loop_beta0 run [--out /work/exp/beta0loop]
    python -m bench.research.loop_beta0 analyse [--out /work/exp/beta0loop] [--markdown]

Design (fixed before running; see bench/RESULTS.md, "DAgger beta_decay 0 in the loop's two arms"):

* Loops, in this order (a stop leaves whole loops): ``/work/exp/loop_ev2``, ``/work/exp/loop_intent``,
  ``/work/exp/loop_ev1`` (the three finished ``dv2s loop --profile evidence`` rounds of bench/RESULTS.md; 100, 70
  and 100 held-out episodes).  Each loop's own round 1: its starting policy, working bank, by-family split and
  held-out episodes (every held-out scenario, seeds ``EVAL_SEED_BASE + 0 .. 9``), unchanged.
* Two new arms per loop, each by :mod:`bench.research.loop_finetune_sweep` (the loop's own scenario draw,
  :func:`dv2s_gym.loop.arms.arm_weights`): **B0-FT** (``--name ft_beta0``: the mined scenarios drawn with
  probability 0.5, as the loop's fine-tuned arm) and **B0-CTL** (``--name ctl_beta0 --control``: the mined
  scenarios left out, as the loop's control arm).  Both: ``--method dagger --lr 1e-3 --steps 40000
  --beta-decay 0``, every other DAgger setting its default (4 iterations, 8 epochs, SLOWER weight 3), the loop's
  seed (0 for all three: fine-tuning seed ``0 * 1000 + 1``), 2 subprocess envs, 2 evaluation workers: the
  loop's defaults except beta_decay.  The two arms of one loop run at the same time (two processes; the result
  does not depend on it), then the next loop.  40,000 steps: the loops' own; decided before any run (the
  machine's load was about 1 when this was written, two 40k DAgger runs in parallel are estimated at 10-15
  minutes per loop).
* Failure: the loop's held-out judgement (``detect_failure``: collision, off road, low TTC, stall), from the
  held-out records.
* **Primary**: B0-FT against B0-CTL on the held-out episodes, paired by (scenario, seed).  Per loop: the table and
  the exact two-sided McNemar p.  Pooled over the finished loops: the stratified exact test of the discordant pairs
  (under no difference every discordant pair of every loop is B0-FT-only or B0-CTL-only with probability 1/2,
  independently, so the pooled B0-FT-only count is Binomial(all discordant pairs, 1/2); exact two-sided binomial
  p, i.e. McNemar on the summed table).  Per-loop claims Holm-adjusted over the THREE planned loops (a loop not
  finished counts p = 1).
* **Meets the target** (the loop's: the fine-tuned arm beats the control on held-out families, paired exact
  McNemar, significant): pooled p < 0.05 with fewer B0-FT failures than B0-CTL failures, and no loop where
  B0-FT fails significantly more than B0-CTL (Holm-adjusted p < 0.05).  A loop "meets the target on its own"
  when its Holm-adjusted p < 0.05 with fewer B0-FT failures.  Anything else: target not met.  Caveat stated with
  the result: pairs of one family are not independent, so the per-pair p is optimistic.
* **Secondary** (descriptive, unadjusted): B0-FT against the loop's own fine-tuned arm (beta_decay 0.5) and
  B0-CTL against the loop's own control, paired, per loop and pooled the same way; the loop's own fine-tuned vs
  control beside the primary; per-family tables of the primary; failure kinds (stall / collision / other) per
  arm; DAgger agreement with the rule driver per arm.
* Nothing is rerun or dropped after seeing results; a run killed by the machine resumes its own checkpoint
  (``run`` skips finished arms).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any, Dict, List, Optional

os.environ.setdefault("OMP_NUM_THREADS", "1")

LOOPS = ["/work/exp/loop_ev2", "/work/exp/loop_intent", "/work/exp/loop_ev1"]
COMMON = ["--method", "dagger", "--lr", "1e-3", "--steps", "40000", "--beta-decay", "0", "--share", "0.5",
          "--workers", "2"]
ARMS = {"ft_beta0": [], "ctl_beta0": ["--control"]}
ALPHA = 0.05


def _finished(folder: Path, name: str) -> bool:
    results = folder / "results.jsonl"
    if not results.is_file():
        return False
    return any(json.loads(line).get("name") == name for line in results.read_text().splitlines() if line.strip())


def run(out: Path) -> None:
    """Both arms of every loop in the declared order, the two arms of one loop in parallel."""
    for loop in LOOPS:
        folder = out / Path(loop).name
        folder.mkdir(parents=True, exist_ok=True)
        procs = []
        for name, extra in ARMS.items():
            if _finished(folder, name):
                continue
            command = [sys.executable, "-m", "bench.research.loop_finetune_sweep", "--loop", loop,
                       "--out", str(folder), "--name", name, *COMMON, *extra]
            log = open(folder / f"{name}.log", "a", encoding="utf-8")
            print(" ".join(command), flush=True)
            procs.append((name, subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT)))
        for name, proc in procs:
            if proc.wait() != 0:
                raise SystemExit(f"{loop} {name} failed: see {folder / (name + '.log')}")
        print(f"{loop}: both arms finished", flush=True)


def holm(pvalues: List[float]) -> List[float]:
    """Holm-adjusted p values (same order)."""
    order = sorted(range(len(pvalues)), key=lambda i: pvalues[i])
    adjusted, running = [0.0] * len(pvalues), 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (len(pvalues) - rank) * pvalues[i]))
        adjusted[i] = running
    return adjusted


def pooled(rows: List[Dict[str, Any]]) -> Dict[str, Any]:
    """The stratified exact test: McNemar on the summed table of the loops' pairs."""
    from dv2s_gym.regress.stats import PairedTable, mcnemar_exact

    keys = ("pairs", "a_failed", "b_failed", "both_fail", "a_only", "b_only", "neither")
    total = {key: sum(r[key] for r in rows) for key in keys}
    table = PairedTable(both_fail=total["both_fail"], candidate_only=total["a_only"],
                        baseline_only=total["b_only"], neither=total["neither"])
    total["mcnemar_p"] = mcnemar_exact(table) if total["pairs"] else None
    return total


def _agreement(folder: Path) -> Optional[float]:
    from policies.registry import read_model_card

    model = folder / "policy" / "model.zip"
    if not model.is_file():
        return None
    tuned = read_model_card(model).fine_tune
    return ((tuned.agreement if tuned is not None else None) or {}).get("fine_tuned")


def analyse(out: Path) -> Dict[str, Any]:
    from bench.research.loop_sweep_pair import pair_arms

    comparisons = {"primary: B0-FT vs B0-CTL": ("ft_beta0", "ctl_beta0"),
                   "B0-FT vs loop FT (beta 0.5)": ("ft_beta0", "loop:after"),
                   "B0-CTL vs loop CTL (beta 0.5)": ("ctl_beta0", "loop:control"),
                   "loop FT vs loop CTL (beta 0.5)": ("loop:after", "loop:control")}
    result: Dict[str, Any] = {"loops": [], "comparisons": {}}
    finished = [loop for loop in LOOPS
                if all(_finished(out / Path(loop).name, name) for name in ARMS)]
    result["loops"] = finished
    for label, (a, b) in comparisons.items():
        rows = []
        for loop in finished:
            folder = out / Path(loop).name
            arm = lambda x: x if x.startswith("loop:") else str(folder / x)  # noqa: E731
            rows.append(pair_arms(Path(loop), arm(a), arm(b)))
        entry: Dict[str, Any] = {"per_loop": rows, "pooled": pooled(rows) if rows else None}
        if label.startswith("primary"):
            planned = {Path(r["loop"]).name: r["mcnemar_p"] for r in rows}
            ps = [planned.get(Path(loop).name, 1.0) for loop in LOOPS]
            entry["holm"] = dict(zip([Path(loop).name for loop in LOOPS], holm(ps)))
            harm = any(entry["holm"][Path(r["loop"]).name] < ALPHA and r["a_failed"] > r["b_failed"] for r in rows)
            p = entry["pooled"]
            met = bool(p and p["mcnemar_p"] is not None and p["mcnemar_p"] < ALPHA and p["a_failed"] < p["b_failed"]
                       and not harm)
            entry["meets_target"] = met
            entry["loops_meeting_target"] = [Path(r["loop"]).name for r in rows
                                             if entry["holm"][Path(r["loop"]).name] < ALPHA
                                             and r["a_failed"] < r["b_failed"]]
        result["comparisons"][label] = entry
    result["agreement"] = {Path(loop).name: {name: _agreement(out / Path(loop).name / name) for name in ARMS}
                           for loop in finished}
    return result


def markdown(result: Dict[str, Any]) -> str:
    lines = []
    for label, entry in result["comparisons"].items():
        lines += [f"**{label}** (A = first, B = second)", "",
                  "| loop | pairs | A failed | B failed | A only | B only | both | neither | exact McNemar p |"
                  + (" Holm p |" if "holm" in entry else ""),
                  "|---|---|---|---|---|---|---|---|---|" + ("---|" if "holm" in entry else "")]
        for r in entry["per_loop"]:
            name = Path(r["loop"]).name
            lines.append(f"| {name} | {r['pairs']} | {r['a_failed']} | {r['b_failed']} | {r['a_only']} | "
                         f"{r['b_only']} | {r['both_fail']} | {r['neither']} | {r['mcnemar_p']:.3g} |"
                         + (f" {entry['holm'][name]:.3g} |" if "holm" in entry else ""))
        p = entry["pooled"]
        if p:
            lines.append(f"| pooled | {p['pairs']} | {p['a_failed']} | {p['b_failed']} | {p['a_only']} | "
                         f"{p['b_only']} | {p['both_fail']} | {p['neither']} | {p['mcnemar_p']:.3g} |"
                         + (" |" if "holm" in entry else ""))
        if "meets_target" in entry:
            lines.append("")
            lines.append(f"Meets the target: {entry['meets_target']}; loops meeting it on their own: "
                         f"{entry['loops_meeting_target'] or 'none'}")
        lines.append("")
    primary = result["comparisons"]["primary: B0-FT vs B0-CTL"]
    lines += ["Per family (primary, A = B0-FT, B = B0-CTL):", "",
              "| loop | family | pairs | B0-FT failed | B0-CTL failed | FT only | CTL only | p |",
              "|---|---|---|---|---|---|---|---|"]
    for r in primary["per_loop"]:
        for fam, row in r["per_family"].items():
            lines.append(f"| {Path(r['loop']).name} | {fam} | {row['pairs']} | {row['a_failed']} | {row['b_failed']} | "
                         f"{row['a_only']} | {row['b_only']} | {row['mcnemar_p']:.3g} |")
    lines += ["", "Failure kinds (stall / collision / other):", "", "| loop | arm | stall | collision | other |",
              "|---|---|---|---|---|"]
    seen = set()
    for entry_label, names in (("primary: B0-FT vs B0-CTL", ("B0-FT", "B0-CTL")),
                               ("loop FT vs loop CTL (beta 0.5)", ("loop FT (0.5)", "loop CTL (0.5)"))):
        for r in result["comparisons"][entry_label]["per_loop"]:
            for arm, kinds in zip(names, (r["kinds_a"], r["kinds_b"])):
                key = (Path(r["loop"]).name, arm)
                if key in seen:
                    continue
                seen.add(key)
                lines.append(f"| {key[0]} | {arm} | {kinds.get('stall', 0)} | {kinds.get('collision', 0)} | "
                             f"{kinds.get('other', 0)} |")
    lines += ["", "DAgger agreement with the rule driver (fine-tuned student, 40,000 labelled states): "
              + "; ".join(f"{loop}: " + ", ".join(f"{k} {v}" for k, v in arms.items())
                          for loop, arms in result["agreement"].items())]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("command", choices=["run", "analyse"])
    parser.add_argument("--out", default="/work/exp/beta0loop")
    parser.add_argument("--markdown", action="store_true")
    args = parser.parse_args()
    if args.command == "run":
        run(Path(args.out))
        return
    result = analyse(Path(args.out))
    print(markdown(result) if args.markdown else json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
