"""Cost of starting a jailed worker: forked by the zygote against a bubblewrap of its own, in one run.

    python bench/bench_jail_start.py              # 3 rounds
    python bench/bench_jail_start.py --rounds 5

Two measurements, each taken with the zygote (``scenario_bank/jail/zygote.py``)
and with a bubblewrap per worker (``DV2S_JAIL_ZYGOTE=0``), alternating round by
round so both share the machine's load:

* worker start: ``JailedProcess("envs.jail_worker")`` until its hello (wall
  time), and the CPU time the worker process spent by then (from ``/proc``; for
  bubblewrap's, its Python process, not bubblewrap);
* a jailed env: ``DV2SEnv(scenario=text)`` on a shipped scenario's text with a
  comment appended (so it is untrusted and runs in the jail), ``reset`` and 10
  steps, then ``close``.

The zygote's own start (once per process: it imports the simulator) is timed
apart, before the rounds. Spare workers are off (``DV2S_JAIL_SPARE=0``): a spare
hides the bubblewrap start only when the user's process is idle long enough, and
costs the same CPU. Prints medians, the ratios and the load average.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path
from typing import Callable, Dict, List, Sequence

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))  # run as a script: this checkout's packages, not an installed copy

from envs.dv2s_env import DV2SEnv  # noqa: E402
from scenario_bank.jail import JailedProcess, zygote  # noqa: E402

SCENARIO = "highway_cut_in_from_left"
STEPS = 10
IDLE = 1
MODES = ("zygote", "bubblewrap")


def _process_cpu(pid: int) -> float:
    """CPU seconds of process ``pid`` so far (utime + stime from ``/proc``)."""
    with open(f"/proc/{pid}/stat", encoding="ascii") as handle:
        fields = handle.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _python_under(pid: int) -> int:
    """The Python process bubblewrap ``pid`` runs (its deepest descendant)."""
    children: Dict[int, List[int]] = {}
    for entry in os.listdir("/proc"):
        try:
            with open(f"/proc/{entry}/stat", encoding="ascii") as handle:
                children.setdefault(int(handle.read().rsplit(")", 1)[1].split()[1]), []).append(int(entry))
        except (OSError, ValueError, IndexError):
            pass
    while children.get(pid):
        pid = children[pid][0]
    return pid


def start_worker(mode: str) -> Dict[str, float]:
    """Wall seconds of starting one env worker until its hello, and the CPU seconds the worker spent."""
    start = time.perf_counter()
    worker = JailedProcess("envs.jail_worker", name="bench")
    wall = time.perf_counter() - start
    assert worker.forked == (mode == "zygote"), f"asked for {mode}, got forked={worker.forked}"
    cpu = _process_cpu(worker.pid if worker.forked else _python_under(worker.pid))
    worker.close()
    return {"wall": wall, "cpu": cpu}


def run_env(text: str) -> Dict[str, float]:
    """Seconds to build a jailed env on ``text`` (start and compile), reset it and run ``STEPS`` steps."""
    start = time.perf_counter()
    env = DV2SEnv(scenario=text)
    made = time.perf_counter()
    assert env.runs_in_jail
    env.reset(seed=0)
    reset = time.perf_counter()
    for _ in range(STEPS):
        env.step(IDLE)
    stepped = time.perf_counter()
    env.close()
    return {"make": made - start, "reset": reset - made, "steps": stepped - reset, "total": stepped - start}


def in_mode(mode: str, measure: Callable[[], Dict[str, float]]) -> Dict[str, float]:
    os.environ["DV2S_JAIL_ZYGOTE"] = "1" if mode == "zygote" else "0"
    try:
        return measure()
    finally:
        os.environ.pop("DV2S_JAIL_ZYGOTE", None)


def median(rows: List[Dict[str, float]], key: str) -> float:
    return statistics.median(row[key] for row in rows)


def main(argv: Sequence[str] | None = None) -> Dict[str, float]:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    args = parser.parse_args(argv)
    os.environ["DV2S_JAIL_SPARE"] = "0"
    text = (ROOT / "scenario_bank" / "scenarios" / SCENARIO / "scenario.scenic").read_text(encoding="utf-8")
    text += "\n# edited: not the shipped text, so it runs in the jail\n"
    load_before = os.getloadavg()

    first = in_mode("zygote", lambda: start_worker("zygote"))  # starts the zygote
    print(f"zygote start (imports the simulator, once per process) and first worker: {first['wall']:.2f} s")
    if zygote.zygote_status() != (True, ""):
        raise SystemExit(f"no zygote here: {zygote.zygote_status()[1]}")

    starts: Dict[str, List[Dict[str, float]]] = {mode: [] for mode in MODES}
    envs: Dict[str, List[Dict[str, float]]] = {mode: [] for mode in MODES}
    for round_ in range(args.rounds):
        for mode in (MODES if round_ % 2 == 0 else MODES[::-1]):
            starts[mode].append(in_mode(mode, lambda: start_worker(mode)))
            envs[mode].append(in_mode(mode, lambda: run_env(text)))
        print(f"round {round_ + 1}: start " + ", ".join(f"{m} {starts[m][-1]['wall']:.3f} s" for m in MODES)
              + "; env " + ", ".join(f"{m} {envs[m][-1]['total']:.2f} s" for m in MODES), flush=True)
    load_after = os.getloadavg()

    result: Dict[str, float] = {}
    print(f"\nload average {load_before[0]:.2f} before, {load_after[0]:.2f} after ({os.cpu_count()} cores); "
          f"median of {args.rounds} rounds")
    print(f"{'':34}{'zygote':>12}{'bubblewrap':>12}{'ratio':>9}")
    for label, rows, key in (("worker start, wall (s)", starts, "wall"), ("worker start, CPU (s)", starts, "cpu"),
                             ("env: make (start + compile) (s)", envs, "make"), ("env: reset (s)", envs, "reset"),
                             (f"env: {STEPS} steps (s)", envs, "steps"),
                             (f"env: make + reset + {STEPS} steps (s)", envs, "total")):
        fast, slow = median(rows["zygote"], key), median(rows["bubblewrap"], key)
        ratio = slow / fast if fast > 0 else float("inf")
        result[f"{key}/{'start' if rows is starts else 'env'}"] = ratio
        print(f"{label:34}{fast:12.3f}{slow:12.3f}{ratio:8.1f}x" if fast > 0 else f"{label:34}{fast:12.3f}{slow:12.3f}")
    return result


if __name__ == "__main__":
    main()
