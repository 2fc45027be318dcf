"""SP of an SG on the labelled description set, and what it loses.

    python -m bench.bench_sg_descriptions [--jobs 2] [--sg rules] [--report REPORT.json] [--top 25]
                                          [--save SCORES.json] [--compare bench/research/sg_descriptions_baseline.json]

Runs ``dv2s eval sg dv2s_gym/evalset/descriptions`` (or reads a report written by
``dv2s eval sg ... --json`` with ``--report``) and prints SP mean ± sd per source group and overall,
the share of descriptions whose script compiles and runs, the labelled elements most often lost
(label elements absent from the simulated ones), the most common warnings, how many descriptions
lost elements without any warning (silent drops) and how many lost elements no warning names (their words,
e.g. ``action ego collide side``, appear in none of the description's warnings). ``--save`` writes the per-description scores
(stem -> use case, SP, runs); ``--compare`` prints SP before/after on the descriptions both score, and
which got worse (the shipped baseline, ``bench/research/sg_descriptions_baseline.json``, is today's rules SG).
"""

from __future__ import annotations

import argparse
import json
import statistics
from collections import Counter
from pathlib import Path
from typing import Any, Dict, List, Mapping

from dv2s_gym.pipeline.labels import read_label
from scenario_bank.elements import element_set, with_undirected

FOLDER = Path(__file__).resolve().parents[1] / "dv2s_gym" / "evalset" / "descriptions"


def _mean_sd(values: List[float]) -> str:
    if not values:
        return "-"
    sd = statistics.stdev(values) if len(values) > 1 else 0.0
    return f"{statistics.fmean(values):.3f} ± {sd:.3f}"


def _words(element) -> str:
    """An element as warnings name it: ``action ego collide side``."""
    return " ".join(str(x) for x in element if not isinstance(x, int)).replace("_", " ")


def analyse(report: Mapping[str, Any], folder: Path = FOLDER) -> Dict[str, Any]:
    """Per-group SP, run share, lost elements and warnings of an ``eval sg`` report on ``folder``."""
    groups: Dict[str, List[float]] = {}
    lost: Counter = Counter()
    lost_by_kind: Counter = Counter()
    total_by_kind: Counter = Counter()
    warnings: Counter = Counter()
    silent = 0
    unnamed = 0
    items = report["items"]
    for item in items:
        groups.setdefault(item["use_case"], []).append(item["metrics"]["SP"])
        label = element_set(read_label(folder / f"{item['stem']}.label.json").elements)
        detail = item.get("detail") or {}
        simulated = with_undirected(element_set(detail.get("simulated") or {}))
        missing = [e for e in label if e not in simulated]
        for element in label:
            total_by_kind[element[0]] += 1
        for element in missing:
            lost[" ".join(str(x) for x in element)] += 1
            lost_by_kind[element[0]] += 1
        item_warnings = detail.get("warnings") or []
        warnings.update(w.split(":")[0][:90] for w in item_warnings)
        silent += bool(missing) and not item_warnings
        said = " ".join(w.lower().replace("_", " ") for w in item_warnings)
        unnamed += sum(_words(e) not in said for e in missing)
    every = [sp for values in groups.values() for sp in values]
    return {
        "groups": {g: {"n": len(v), "SP": _mean_sd(v)} for g, v in sorted(groups.items())},
        "overall": {"n": len(every), "SP": _mean_sd(every)},
        "runs": sum(bool(i["ok"]) for i in items), "items": len(items),
        "lost_by_kind": {k: f"{lost_by_kind[k]}/{total_by_kind[k]}" for k in sorted(total_by_kind)},
        "lost": lost.most_common(), "warnings": warnings.most_common(),
        "with_warnings": sum(bool((i.get("detail") or {}).get("warnings")) for i in items),
        "silent_drops": silent, "lost_unnamed": unnamed,
    }


def scores(report: Mapping[str, Any]) -> Dict[str, Dict[str, Any]]:
    """Per-description scores of a report: stem -> {use_case, SP, ok}."""
    return {i["stem"]: {"use_case": i["use_case"], "SP": round(i["metrics"]["SP"], 4), "ok": bool(i["ok"])}
            for i in report["items"]}


def compare(before: Mapping[str, Mapping[str, Any]], after: Mapping[str, Mapping[str, Any]]) -> Dict[str, Any]:
    """SP before/after on the stems both score; the stems that got worse / better."""
    common = sorted(set(before) & set(after))
    worse = [(s, before[s]["SP"], after[s]["SP"]) for s in common if after[s]["SP"] < before[s]["SP"] - 1e-9]
    better = [s for s in common if after[s]["SP"] > before[s]["SP"] + 1e-9]
    mean = (lambda table: statistics.fmean(table[s]["SP"] for s in common) if common else 0.0)
    return {"n": len(common), "before": mean(before), "after": mean(after), "worse": worse, "better": better,
            "runs_before": sum(before[s]["ok"] for s in common), "runs_after": sum(after[s]["ok"] for s in common)}


def main(argv: List[str] | None = None) -> None:
    """Run (or read) the evaluation and print the analysis."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--sg", default="rules")
    parser.add_argument("--report", help="a JSON report of `dv2s eval sg ... --json` to analyse instead of running")
    parser.add_argument("--top", type=int, default=25)
    parser.add_argument("--save", help="write the per-description scores (JSON) here")
    parser.add_argument("--compare", help="per-description scores (JSON, from --save) to compare against")
    args = parser.parse_args(argv)
    if args.report:
        report = json.loads(Path(args.report).read_text(encoding="utf-8"))
    else:
        from dv2s_gym.pipeline.evaluate import evaluate

        report = evaluate("sg", FOLDER, sg=args.sg, jobs=args.jobs, progress=False)
    result = analyse(report)
    print("| group | n | SP mean ± sd |\n|---|---|---|")
    for group, row in result["groups"].items():
        print(f"| {group} | {row['n']} | {row['SP']} |")
    print(f"| **all** | {result['overall']['n']} | **{result['overall']['SP']}** |")
    print(f"\nscript compiles and runs: {result['runs']}/{result['items']} "
          f"({100 * result['runs'] / max(result['items'], 1):.1f}%)")
    print(f"descriptions with warnings: {result['with_warnings']}; lost elements without any warning: "
          f"{result['silent_drops']}; lost elements that no warning names: {result['lost_unnamed']}")
    print("lost / labelled, by kind: " + ", ".join(f"{k} {v}" for k, v in result["lost_by_kind"].items()))
    print("\nmost often lost:")
    for element, count in result["lost"][: args.top]:
        print(f"  {count:3d}  {element}")
    print("\nmost common warnings:")
    for warning, count in result["warnings"][: args.top]:
        print(f"  {count:3d}  {warning}")
    table = scores(report)
    if args.save:
        from scenario_bank.atomic import atomic_write_text

        atomic_write_text(Path(args.save), json.dumps(table, indent=0, sort_keys=True) + "\n")
    if args.compare:
        delta = compare(json.loads(Path(args.compare).read_text(encoding="utf-8")), table)
        print(f"\nagainst {args.compare} on {delta['n']} descriptions: SP {delta['before']:.3f} -> {delta['after']:.3f}"
              f", runs {delta['runs_before']} -> {delta['runs_after']}, better {len(delta['better'])}, "
              f"worse {len(delta['worse'])}")
        for stem, old, new in delta["worse"]:
            print(f"  worse: {stem} {old:.2f} -> {new:.2f}")


if __name__ == "__main__":
    main()
