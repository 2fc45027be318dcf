"""The failing scene itself as a bank entry: its parent scenario, narrowed around the failure, and its seed.

A mined failure is kept exactly, whatever the D-V2S conversion makes of it: the **replay entry** is the
parent's Scenic script with every continuous mined parameter (``param x = Range(a, b)``) narrowed to
:data:`NARROW` of its width on either side of the failing value (:func:`narrowed_script`; integer and
choice parameters keep their values), and its provenance ``replay`` holds what pins the scene exactly:
``{"params", "seed", "trajectory_hash", "policy"}``. Running the entry with those parameters and that seed
(:func:`replay_failure`) is the failing episode, step for step: Scenic draws nothing for a fixed parameter,
so narrowing the ranges around the fixed values changes no other random draw of the scene. Run with other
seeds and no fixed parameters, the entry samples the neighbourhood of the failure.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any, Dict, Mapping, Optional, Tuple

__all__ = ["NARROW", "REPLAY_TAG", "narrowed_script", "replay_name", "run_replay", "replay_failure",
           "ReplayOutcome"]

NARROW = 0.02
"""Share of a continuous parameter's range kept on either side of the failing value."""
REPLAY_TAG = "replay"
"""Tag of replay entries (besides ``mined`` and the failure type)."""

_PARAM_LINE = re.compile(r"^(\s*param\s+)(\w+)(\s*=\s*)(.+?)(\s*(#.*)?)$")


def narrowed_script(script: str, params: Mapping[str, Any], narrow: float = NARROW) -> Tuple[str, Dict[str, list]]:
    """``script`` with each parameter of ``params`` that the script draws from a continuous ``Range(a, b)``
    of numbers rewritten to ``Range(lo, hi)``, ``narrow`` of the width on either side of its value; returns
    the script and the new intervals ``{name: [lo, hi]}``. Other parameters are left as they are. Raises
    ``ValueError`` for a value outside its range."""
    from scenario_bank.bank import param_ranges

    intervals: Dict[str, list] = {}
    lines = script.splitlines(keepends=True)
    for i, line in enumerate(lines):
        body = line.rstrip("\r\n")
        match = _PARAM_LINE.match(body)
        name = match.group(2) if match else None
        if name not in params or not re.match(r"Range\s*\(", match.group(4)):
            continue
        bounds = param_ranges(f"param {name} = {match.group(4)}\n").get(name)
        if bounds is None or isinstance(params[name], bool) or not isinstance(params[name], (int, float)):
            continue
        low, high = bounds
        value = float(params[name])
        if not low - 1e-9 <= value <= high + 1e-9:
            raise ValueError(f"parameter {name}={value} lies outside its range {low:g}..{high:g}")
        width = narrow * (high - low)
        lo, hi = max(low, value - width), min(high, value + width)
        intervals[name] = [lo, hi]
        lines[i] = f"{match.group(1)}{name}{match.group(3)}Range({lo!r}, {hi!r})" \
                   f"  # narrowed around the failing value {value!r}" + line[len(body):]
    return "".join(lines), intervals


def replay_name(parent: str, failure_type: str) -> str:
    """The base name of a replay entry (the bank adds ``_2``, ``_3``... when taken)."""
    base = re.sub(r"[^a-z0-9_\-]+", "_", f"replay_{parent}_{failure_type}".lower()).strip("_-")
    return base[:90] or "replay"


class ReplayOutcome(dict):
    """What :func:`replay_failure` saw: ``{"trajectory_hash", "matches", "failure", "steps"}`` plus the trace
    (attribute ``trace``, not serialised)."""

    trace: Any = None


def run_replay(scenario: Any, *, policy: Any, seed: int, params: Mapping[str, Any],
               env_config: Optional[Mapping[str, Any]] = None, bank_dir: Optional[str] = None,
               monitor: Optional[Mapping[str, Any]] = None) -> Tuple[Any, Any, Optional[Dict[str, Any]]]:
    """Run ``policy`` on ``scenario`` (a bank name or a ``.scenic`` path) with ``seed`` and ``params`` fixed;
    returns ``(EpisodeResult, EpisodeTrace, failure dict or None)`` (the miner's monitors)."""
    from envs.dv2s_env import DV2SEnv
    from dv2s_gym.mining.monitors import detect_failure
    from policies.evaluation import run_episode
    from policies.registry import load_policy

    env = DV2SEnv(scenario=str(scenario), config=dict(env_config or {}), bank_dir=bank_dir)
    try:
        bound = load_policy(policy)
        bound.bind([env])
        path = Path(str(scenario))
        name = (path.parent.name if path.name == "scenario.scenic" else path.stem) if path.suffix == ".scenic" \
            else str(scenario)
        result, trace = run_episode(env, bound, name, int(seed), params=dict(params) or None)
    finally:
        env.close()
    found = detect_failure(result, trace, **dict(monitor or {}))
    return result, trace, None if found is None else found.to_json()


def replay_failure(bank: Any, name: str, *, policy: Optional[Any] = None,
                   env_config: Optional[Mapping[str, Any]] = None,
                   monitor: Optional[Mapping[str, Any]] = None) -> ReplayOutcome:
    """Run replay entry ``name`` of ``bank`` (a :class:`~scenario_bank.bank.Bank` or folder) with the seed and
    parameters of its provenance ``replay`` and the policy that failed (or ``policy``); ``matches`` says
    whether the episode is the recorded failing one (same trajectory hash)."""
    from scenario_bank.bank import Bank, BankError

    bank = bank if isinstance(bank, Bank) else Bank(bank)
    entry = bank.get(name)
    replay = entry.source.get("replay")
    if not isinstance(replay, Mapping) or replay.get("seed") is None:
        raise BankError(f"bank entry {name!r} is no replay of a mined failure (its provenance has no 'replay'); "
                        "replay entries are tagged 'replay'")
    if policy is None:
        from policies.registry import spec_from_file

        policy = spec_from_file(replay.get("policy"), f"the provenance of bank entry {name!r}", "policy=SPEC")
    result, trace, failure = run_replay(str(entry.script_path), policy=policy,
                                        seed=int(replay["seed"]), params=replay.get("params") or {},
                                        env_config=env_config, monitor=monitor)
    out = ReplayOutcome(trajectory_hash=result.trajectory_hash, matches=result.trajectory_hash == replay.get(
        "trajectory_hash"), failure=failure, steps=result.steps)
    out.trace = trace
    return out
