"""Summarise a ``DV2S_TEST_CPU_LOG`` file (see tests/cpu_time_plugin.py): the totals of the quick
(not slow) and slow tests and the quick tests over a threshold, most expensive first.

    python tests/cpu_time_report.py /tmp/cpu.jsonl [--over 1.5]
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("log")
    parser.add_argument("--over", type=float, default=1.5, help="list quick tests over this many CPU seconds")
    parser.add_argument("--by-module", action="store_true", help="totals per test module")
    parser.add_argument("--by-worker", action="store_true",
                        help="per xdist worker: tests, CPU and wall time, and when its last test ended")
    args = parser.parse_args()
    rows = {}
    with open(args.log) as f:
        for line in f:
            row = json.loads(line)
            rows[row["test"]] = row  # a later run of the same test replaces an earlier one
    totals = defaultdict(lambda: [0, 0.0, 0.0])
    for row in rows.values():
        kind = "slow" if row["slow"] else "quick"
        totals[kind][0] += 1
        totals[kind][1] += row["cpu"] + row["children_cpu"]
        totals[kind][2] += row["wall"]
    for kind, (count, cpu, wall) in sorted(totals.items()):
        print(f"{kind}: {count} tests, {cpu:.0f} s CPU, {wall:.0f} s wall")
    if args.by_module:
        modules = defaultdict(lambda: [0, 0.0])
        for row in rows.values():
            if not row["slow"]:
                module = row["test"].split("::")[0]
                modules[module][0] += 1
                modules[module][1] += row["cpu"] + row["children_cpu"]
        for module, (count, cpu) in sorted(modules.items(), key=lambda kv: -kv[1][1]):
            print(f"{cpu:8.1f} s {count:5d} {module}")
    if args.by_worker:
        workers = defaultdict(lambda: [0, 0.0, 0.0, 0.0])
        for row in rows.values():
            worker = workers[row.get("worker", "main")]
            worker[0] += 1
            worker[1] += row["cpu"] + row["children_cpu"]
            worker[2] += row["wall"]
            worker[3] = max(worker[3], row.get("end", 0.0))
        first_end = min(w[3] for w in workers.values())
        for name, (count, cpu, wall, end) in sorted(workers.items()):
            print(f"{name}: {count} tests, {cpu:.0f} s CPU, {wall:.0f} s wall, "
                  f"last test ended {end - first_end:.0f} s after the first worker's")
    heavy = sorted((r for r in rows.values() if not r["slow"] and r["cpu"] + r["children_cpu"] > args.over),
                   key=lambda r: -(r["cpu"] + r["children_cpu"]))
    for row in heavy:
        print(f"{row['cpu'] + row['children_cpu']:7.2f} s CPU {row['wall']:7.2f} s wall  {row['test']}")


if __name__ == "__main__":
    main()
