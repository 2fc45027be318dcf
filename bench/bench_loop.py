"""How long one round of ``dv2s loop`` on its embedded defaults takes, as a whole process.

    python -m bench.bench_loop                    # one default round into a fresh temporary folder
    python -m bench.bench_loop --keep out/bench_loop -- --seed 1   # keep the folder; extra `dv2s loop` options

Runs ``python -m dv2s_gym.cli loop --out <fresh folder> --no-progress [extra options]`` as a child process (the
same process a user starts with ``dv2s loop``: interpreter start, imports, the working bank's copy, every step,
the reports) and prints its wall time, the machine's load average before, during (sampled every 10 s) and after,
the core count, the CPU time of the process tree (every descendant's user and system time read from ``/proc``
every 2 s, so a process living less than that may be missed: a lower bound; on idle cores the wall time is at
least that CPU time spread over every core), and the loop's own per-step timings and headline figures from
``loop.json``. Each run starts from an empty folder: a
resumed loop would skip finished steps. The round's log goes to ``<folder>/bench_loop.log``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Dict, List, Optional


def _rate(r: Optional[Dict[str, Any]]) -> str:
    if not r or r.get("rate") is None:
        return "-"
    return f"{r['k']}/{r['n']} = {r['rate']:.2f} [{r['low']:.2f}, {r['high']:.2f}]"


def _tree_cpu(root: int, seen: Dict[int, float]) -> None:
    """Record in ``seen`` (pid -> CPU seconds) the user + system time of ``root`` and its descendants now."""
    parents: Dict[int, int] = {}
    times: Dict[int, float] = {}
    tick = os.sysconf("SC_CLK_TCK")
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat", encoding="utf-8") as handle:
                fields = handle.read().rsplit(")", 1)[1].split()
        except OSError:
            continue
        parents[int(entry)] = int(fields[1])
        times[int(entry)] = (int(fields[11]) + int(fields[12])) / tick
    for pid, seconds in times.items():
        ancestor, hops = pid, 0
        while ancestor not in (root, 0, 1) and hops < 50:
            ancestor, hops = parents.get(ancestor, 0), hops + 1
        if ancestor == root:
            seen[pid] = max(seen.get(pid, 0.0), seconds)


def summarize(out: Path) -> List[str]:
    """Per-step timings and the headline figures of the round in ``out/loop.json``."""
    state = json.loads((out / "loop.json").read_text(encoding="utf-8"))
    lines = []
    for record in state.get("rounds", []):
        steps = record.get("steps") or {}
        timings = record.get("timings") or {}
        lines.append("round {}: {}".format(record.get("round"), ", ".join(
            f"{step} {seconds:.0f} s" for step, seconds in timings.items())))
        mine = steps.get("mine") or {}
        split = steps.get("split") or {}
        lines.append(f"  mined {mine.get('failures')} failures / {mine.get('episodes')} episodes, "
                     f"{mine.get('clusters')} clusters, {mine.get('clusters_not_converted')} not converted, "
                     f"conversions {mine.get('conversions')}; kept {len({e['scenario'] for e in mine.get('kept', [])})}"
                     f"; held out {len(split.get('held_out', []))} scenarios of families "
                     f"{split.get('held_out_families')}")
        after = steps.get("after") or {}
        if after:
            lines.append(f"  held-out: start {_rate(after.get('before'))}, control {_rate(after.get('control'))}, "
                         f"fine-tuned {_rate(after.get('after'))}; McNemar p vs start {after.get('mcnemar_p')}, "
                         f"vs control {(after.get('vs_control') or {}).get('mcnemar_p')}"
                         + (f"; UNDERPOWERED: {after['underpowered']}" if after.get("underpowered") else ""))
        untouched = steps.get("untouched") or {}
        for role, row in (untouched.get("policies") or {}).items():
            rate = (row.get("failure_rate") or {}).get("value")
            stall = (row.get("stall_rate") or {}).get("value")
            speed = (row.get("mean_speed") or {}).get("value")
            lines.append(f"  untouched {role}: failure {rate}, stall {stall}, mean speed {speed}")
        if untouched:
            lines.append(f"  untouched fine-tuned vs start: {(untouched.get('fine_tuned_vs_start') or {}).get('verdict')}")
        regress = steps.get("regress") or {}
        if regress:
            lines.append(f"  rest of the bank: {regress.get('verdict')} ({regress.get('reason')})")
    return lines


def main(argv: Optional[List[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--keep", default=None, help="write the loop here (must not exist) and keep it")
    parser.add_argument("extra", nargs="*", help="extra `dv2s loop` options, after `--`")
    args = parser.parse_args(argv)
    if args.keep is not None and Path(args.keep).exists():
        parser.error(f"--keep {args.keep} exists; a timed round must start from an empty folder")
    out = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="bench_loop_")) / "loop"
    out.parent.mkdir(parents=True, exist_ok=True)
    command = [sys.executable, "-m", "dv2s_gym.cli", "loop", "--out", str(out), "--no-progress", *args.extra]
    load_before = os.getloadavg()
    started = time.time()
    log_path = out.parent / f"{out.name}.bench_loop.log"
    loads: List[float] = []
    cpu_seen: Dict[int, float] = {}
    with open(log_path, "w", encoding="utf-8") as log:
        child = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT)
        ticks = 0
        while True:
            _tree_cpu(child.pid, cpu_seen)
            try:
                code = child.wait(timeout=2)
                break
            except subprocess.TimeoutExpired:
                ticks += 1
                if ticks % 5 == 0:
                    loads.append(os.getloadavg()[0])
    wall = time.time() - started
    load_after = os.getloadavg()
    cpu = sum(cpu_seen.values())
    print(f"command: {' '.join(command)}")
    print(f"machine: {platform.platform()}, {os.cpu_count()} cores, Python {platform.python_version()}")
    print(f"date: {time.strftime('%Y-%m-%d %H:%M', time.gmtime(started))} UTC; load average before "
          f"{load_before[0]:.1f}, during {min(loads, default=load_before[0]):.1f}-{max(loads, default=load_before[0]):.1f} "
          f"(mean {sum(loads) / len(loads) if loads else load_before[0]:.1f}), after {load_after[0]:.1f} (1 min)")
    print(f"exit status {code}; wall time {wall:.0f} s ({wall / 60:.1f} min); CPU time of the process tree at "
          f"least {cpu:.0f} s ({len(cpu_seen)} processes; over {os.cpu_count()} cores "
          f"{cpu / (os.cpu_count() or 1):.0f} s); log {log_path}")
    if (out / "loop.json").is_file():
        for line in summarize(out):
            print(line)
    if args.keep is None:
        shutil.rmtree(out.parent, ignore_errors=True)
    return code


if __name__ == "__main__":
    sys.exit(main())
