"""Per-test CPU time, for choosing the tests marked ``slow`` from measurements rather than guesses.

Set ``DV2S_TEST_CPU_LOG=path`` and every test appends one JSON line to ``path``: its node id and, for
setup, call and teardown together, the wall time and the CPU time (user + system) of the test process
and of its descendants: the children it waited for and, read from ``/proc``, those still running (the
jail's zygote and its workers live across tests, so waiting for them is not when their time is counted). Wall time on a shared machine says more about the other
load than about the test; CPU time does not, except that a test which only waits (a timeout, a
sleep) shows little CPU and a long wall time, so both are kept. Under ``-n 2`` each xdist worker
appends its own lines (one ``write`` per line, so lines from two workers do not interleave).

    DV2S_TEST_CPU_LOG=/tmp/cpu.jsonl python -m pytest -q -n 2 -m "not slow"
    python tests/cpu_time_report.py /tmp/cpu.jsonl
"""

from __future__ import annotations

import json
import os
import resource
import time

import pytest

LOG_VARIABLE = "DV2S_TEST_CPU_LOG"


_TICK = os.sysconf("SC_CLK_TCK") if hasattr(os, "sysconf") else 100


def _live_descendants_cpu() -> float:
    """CPU seconds of the running descendants of this process and of the children they waited for."""
    parents, times = {}, {}
    try:
        entries = os.listdir("/proc")
    except OSError:
        return 0.0
    for entry in entries:
        if not entry.isdigit():
            continue
        try:
            with open(f"/proc/{entry}/stat", "rb") as f:
                stat = f.read().decode(errors="replace")
        except OSError:
            continue  # exited meanwhile
        fields = stat[stat.rindex(")") + 2:].split()
        # after the command: state ppid ... utime(12) stime(13) cutime(14) cstime(15), 0-based from state
        parents[int(entry)] = int(fields[1])
        times[int(entry)] = sum(int(v) for v in fields[11:15]) / _TICK
    children = {}
    for pid, parent in parents.items():
        children.setdefault(parent, []).append(pid)
    total, todo = 0.0, list(children.get(os.getpid(), []))
    while todo:
        pid = todo.pop()
        total += times[pid]
        todo.extend(children.get(pid, []))
    return total


def _clock() -> tuple[float, float, float]:
    own = resource.getrusage(resource.RUSAGE_SELF)
    waited = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (time.perf_counter(), own.ru_utime + own.ru_stime,
            waited.ru_utime + waited.ru_stime + _live_descendants_cpu())


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    path = os.environ.get(LOG_VARIABLE)
    if not path:
        yield
        return
    start = _clock()
    yield
    end = _clock()
    line = json.dumps({
        "test": item.nodeid,
        "wall": round(end[0] - start[0], 3),
        "cpu": round(end[1] - start[1], 3),
        "children_cpu": round(end[2] - start[2], 3),
        "slow": item.get_closest_marker("slow") is not None,
        "worker": os.environ.get("PYTEST_XDIST_WORKER", "main"),
        "end": round(time.time(), 3),
    })
    fd = os.open(path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    try:
        os.write(fd, (line + "\n").encode())
    finally:
        os.close(fd)
