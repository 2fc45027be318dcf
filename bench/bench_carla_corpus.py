"""Side by side: the public CARLA-model Scenic corpus in DV2S-v0 and in Scenic's Newtonian simulator.

One command::

    python -m bench.bench_carla_corpus [--steps 100] [--seeds 0 1 2] [--workers 2] [--timeout 300]

For every script under ``tests/data/carla_corpus/`` (``scenic3/``: Scenic 3 scripts,
counted for the target; ``scenic2/``: Scenic 2 syntax, counted apart) it tries

* **DV2S-v0**: ``gym.make("dv2s_gym:DV2S-v0", scenario=PATH)`` (for ``scenic2/`` with the env's
  ``config={"upgrade_scenic2": True}``, the Scenic 2 -> 3 upgrade a user asks for), ``reset(seed=s)`` for each
  seed, then up to ``--steps`` steps of the idle action (``DiscreteMetaAction`` 1) or until
  the episode ends (a collision ends it and still counts as running);
* **Scenic 3.1.1 Newtonian**: ``scenic.scenarioFromFile(PATH, mode2D=True,
  model="scenic.simulators.newtonian.driving_model")`` (Scenic's ``--2d --model`` override of
  the script's ``model`` line), ``scenario.generate()`` seeded like the env, then
  ``scenario.getSimulator().simulate(scene, maxSteps=--steps)``.

A script *runs* in a simulator when it compiles, samples and steps for every seed without an
exception. Each attempt is a child process with a time limit (a timeout is a failure). A DV2S
failure is *clear* when it is a ``DV2SError`` that names its cause (see :func:`failure_construct`).
Prints the per-script table and both counts, writes ``bench/research/carla_corpus_results.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import tempfile
import sys
import time
import traceback
from collections import Counter
from pathlib import Path
from typing import Dict, List, Optional

ROOT = Path(__file__).resolve().parents[1]
CORPUS = ROOT / "tests" / "data" / "carla_corpus"
NEWTONIAN_MODEL = "scenic.simulators.newtonian.driving_model"
IDLE = 1
CONSTRUCT = re.compile(r"`([^`]+)`")


def corpus_scripts(root: Path = CORPUS) -> List[Path]:
    """Every corpus script, Scenic 3 ones first, sorted by name within each folder."""
    return sorted(root.glob("scenic3/*.scenic")) + sorted(root.glob("scenic2/*.scenic"))


def _first_line(text: str) -> str:
    text = text.strip().replace(str(CORPUS) + os.sep, "")
    return text.splitlines()[0][:300] if text else ""


def failure_construct(error: BaseException) -> Optional[str]:
    """What a DV2S failure names as its cause, or None when the message names nothing.

    * :class:`UnsafeScenarioError`: the construct of its first safety finding;
    * :class:`SceneSamplingError`: the requirement that rejects most (``requirement on line N``);
    * any other ``DV2SError``: the first name its message puts in backticks.
    Errors that are not ``DV2SError`` (bare Python or Scenic exceptions) name nothing.
    """
    from envs.errors import DV2SError, SceneSamplingError
    from scenario_bank.safety import UnsafeScenarioError

    message = str(error)
    if isinstance(error, UnsafeScenarioError):
        findings = getattr(error, "findings", None) or []
        return str(findings[0].construct) if findings else None
    if not isinstance(error, DV2SError):
        return None
    if isinstance(error, SceneSamplingError):
        found = re.search(r"requirement on line \d+", message)
        return found.group(0) if found else None
    names = CONSTRUCT.findall(message)
    return names[0] if names else None


def _failure(error: BaseException) -> Dict[str, object]:
    from envs.errors import DV2SError

    message = str(error).strip() or type(error).__name__
    return {
        "runs": False,
        "error": type(error).__name__,
        "dv2s_error": isinstance(error, DV2SError),
        "construct": failure_construct(error),
        "message": _first_line(message),
        "traceback_tail": "".join(traceback.format_exception(error)[-3:])[-1500:],
    }


def attempt_dv2s(path: str, seeds: List[int], steps: int) -> Dict[str, object]:
    """Run one script in DV2S-v0 for each seed; the outcome as a JSON-able dict."""
    import gymnasium as gym

    import dv2s_gym  # noqa: F401  (registers DV2S-v0)

    stepped = 0
    env = None
    try:
        # Scenic 2 scripts: the env upgrades them when asked to (config upgrade_scenic2), as a user would ask
        config = {"upgrade_scenic2": True} if Path(path).parent.name == "scenic2" else None
        env = gym.make("dv2s_gym:DV2S-v0", scenario=path, config=config)
        for seed in seeds:
            env.reset(seed=seed)
            for _ in range(steps):
                _, _, terminated, truncated, _ = env.step(IDLE)
                stepped += 1
                if terminated or truncated:
                    break
    except Exception as error:  # the bench records every failure, whatever its class
        out = _failure(error)
        out["steps"] = stepped
        return out
    finally:
        if env is not None:
            try:
                env.close()
            except Exception:
                pass
    return {"runs": True, "steps": stepped}


def attempt_newtonian(path: str, seeds: List[int], steps: int) -> Dict[str, object]:
    """Run one script in Scenic 3.1.1's Newtonian simulator (model overridden) for each seed."""
    import random

    import numpy as np
    import scenic

    stepped = 0
    rejected = 0
    try:
        scenario = scenic.scenarioFromFile(path, mode2D=True, model=NEWTONIAN_MODEL, params={"render": 0})
        for seed in seeds:
            random.seed(seed)
            np.random.seed(seed)
            scene, _ = scenario.generate(maxIterations=2000, verbosity=0)
            simulator = scenario.getSimulator()
            try:
                result = simulator.simulate(scene, maxSteps=steps, verbosity=0)
            finally:
                simulator.destroy()
            if result is None:
                rejected += 1
            else:
                stepped += len(result.trajectory) - 1
    except Exception as error:
        out = _failure(error)
        out["dv2s_error"] = False
        out["construct"] = None  # Scenic's own errors are not classified
        out["steps"] = stepped
        return out
    return {"runs": True, "steps": stepped, "rejected_simulations": rejected}


ATTEMPTS = {"dv2s": attempt_dv2s, "newtonian": attempt_newtonian}


def _child(kind: str, path: str, seeds: List[int], steps: int) -> None:
    """Entry point of one child process: print the outcome as the last stdout line."""
    import warnings

    warnings.simplefilter("ignore")
    outcome = ATTEMPTS[kind](path, seeds, steps)
    sys.stdout.write("\n@@RESULT@@" + json.dumps(outcome) + "\n")
    sys.stdout.flush()


def _launch(kind: str, path: Path, seeds: List[int], steps: int) -> subprocess.Popen:
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    cmd = [sys.executable, "-m", "bench.bench_carla_corpus", "--child", kind, str(path),
           "--steps", str(steps), "--seeds", *map(str, seeds)]
    # files, not pipes: a child that prints more than a pipe holds would block until the timeout
    out, err = tempfile.TemporaryFile("w+"), tempfile.TemporaryFile("w+")
    proc = subprocess.Popen(cmd, cwd=ROOT, env=env, stdout=out, stderr=err, text=True)
    proc.outputs = (out, err)  # type: ignore[attr-defined]
    return proc


def _outputs(proc: subprocess.Popen) -> tuple:
    texts = []
    for handle in proc.outputs:  # type: ignore[attr-defined]
        handle.seek(0)
        texts.append(handle.read())
        handle.close()
    return tuple(texts)


def _collect(proc: subprocess.Popen, out: str, err: str) -> Dict[str, object]:
    for line in reversed(out.splitlines()):
        if line.startswith("@@RESULT@@"):
            return json.loads(line[len("@@RESULT@@"):])
    return {"runs": False, "error": f"child exited {proc.returncode}", "dv2s_error": False,
            "construct": None, "message": _first_line(err.strip().splitlines()[-1] if err.strip() else "")}


def run_all(scripts: List[Path], seeds: List[int], steps: int, workers: int, timeout: float) -> List[Dict[str, object]]:
    """Every (script, simulator) attempt, ``workers`` child processes at a time."""
    jobs = [(kind, path) for path in scripts for kind in ATTEMPTS]
    results: Dict[tuple, Dict[str, object]] = {}
    running: List[tuple] = []
    while jobs or running:
        while jobs and len(running) < workers:
            kind, path = jobs.pop(0)
            running.append((kind, path, _launch(kind, path, seeds, steps), time.monotonic()))
        time.sleep(0.2)
        for item in list(running):
            kind, path, proc, started = item
            elapsed = time.monotonic() - started
            if proc.poll() is None and elapsed < timeout:
                continue
            if proc.poll() is None:
                proc.kill()
                proc.wait()
                _outputs(proc)
                outcome = {"runs": False, "error": "Timeout", "dv2s_error": False, "construct": None,
                           "message": f"no result within {timeout:.0f} s"}
            else:
                out, err = _outputs(proc)
                outcome = _collect(proc, out, err)
            outcome["seconds"] = round(elapsed, 1)
            results[(kind, path)] = outcome
            running.remove(item)
            print(f"  {kind:9s} {'runs' if outcome['runs'] else 'FAILS':5s} {elapsed:6.1f}s {path.parent.name}/{path.name}", flush=True)
    rows = []
    for path in scripts:
        rows.append({
            "script": str(path.relative_to(CORPUS)),
            "syntax": path.parent.name,
            "dv2s": results[("dv2s", path)],
            "newtonian": results[("newtonian", path)],
        })
    return rows


def _cell(outcome: Dict[str, object]) -> str:
    if outcome["runs"]:
        return "runs"
    return f"{outcome.get('error')}: {outcome.get('message', '')}"[:110]


def summarize(rows: List[Dict[str, object]]) -> Dict[str, object]:
    """Counts per syntax folder: scripts, runs in each simulator, clear DV2S failures; failures by construct."""
    summary: Dict[str, object] = {}
    for syntax in ("scenic3", "scenic2"):
        part = [r for r in rows if r["syntax"] == syntax]
        fails = [r["dv2s"] for r in part if not r["dv2s"]["runs"]]
        summary[syntax] = {
            "scripts": len(part),
            "dv2s_runs": sum(r["dv2s"]["runs"] for r in part),
            "newtonian_runs": sum(r["newtonian"]["runs"] for r in part),
            "dv2s_fail_clear": sum(bool(f.get("construct")) for f in fails),
            "dv2s_fail_unclear": sum(not f.get("construct") for f in fails),
            "dv2s_failures_by_construct": dict(Counter(f.get("construct") or f"<{f.get('error')}>" for f in fails).most_common()),
            "newtonian_failures_by_error": dict(Counter(
                f"{r['newtonian'].get('error')}: {r['newtonian'].get('message', '')[:80]}"
                for r in part if not r["newtonian"]["runs"]).most_common()),
        }
    return summary


def main(argv: Optional[List[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=100)
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--timeout", type=float, default=300.0)
    parser.add_argument("--only", default=None, help="regular expression on script names")
    parser.add_argument("--out", default=str(ROOT / "bench" / "research" / "carla_corpus_results.json"))
    parser.add_argument("--child", nargs=2, metavar=("KIND", "PATH"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.child:
        _child(args.child[0], args.child[1], args.seeds, args.steps)
        return 0
    scripts = corpus_scripts()
    if args.only:
        scripts = [p for p in scripts if re.search(args.only, str(p.relative_to(CORPUS)))]
    started = time.monotonic()
    print(f"{len(scripts)} scripts, seeds {args.seeds}, {args.steps} steps, {args.workers} workers")
    rows = run_all(scripts, args.seeds, args.steps, args.workers, args.timeout)
    print(f"\n{'script':52s} | {'DV2S-v0':50s} | Newtonian (Scenic 3.1.1)")
    for row in rows:
        print(f"{row['script'][:52]:52s} | {_cell(row['dv2s'])[:50]:50s} | {_cell(row['newtonian'])[:70]}")
    summary = summarize(rows)
    for syntax, s in summary.items():
        if s["scripts"]:
            print(f"\n{syntax}: {s['scripts']} scripts; runs in DV2S-v0: {s['dv2s_runs']}, in Newtonian: "
                  f"{s['newtonian_runs']}; DV2S failures naming the construct: {s['dv2s_fail_clear']}, "
                  f"unclear: {s['dv2s_fail_unclear']}")
            print("  DV2S failures by construct:", s["dv2s_failures_by_construct"])
    payload = {"date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()), "seeds": args.seeds,
               "steps": args.steps, "wall_seconds": round(time.monotonic() - started, 1),
               "summary": summary, "rows": rows}
    Path(args.out).write_text(json.dumps(payload, indent=1))
    print(f"\nwrote {args.out} ({payload['wall_seconds']} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
