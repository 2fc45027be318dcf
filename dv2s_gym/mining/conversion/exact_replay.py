"""The failing scene itself as a bank entry: its parent scenario, narrowed around the failure, and its seed.

A mined failure is kept exactly, whatever the D-V2S conversion makes of it: the **replay entry** is the
parent's Scenic script with every continuous mined parameter (``param x = Range(a, b)``, also offset or scaled by
numbers) narrowed to :data:`NARROW` of its width on either side of the failing value and every discrete one
(``Uniform(0.3, 1.0)``, ``DiscreteRange(1, 3)``) fixed at it (:func:`narrowed_script`; any other distribution
keeps the parent's, and the provenance's ``not_narrowed`` lists it with why, as it lists every value the script
draws outside its params: :mod:`dv2s_gym.mining.conversion.scene_draws`), and its provenance ``replay`` holds
what pins the scene exactly: ``{"params", "seed", "trajectory_hash", "policy", "intervals", "not_narrowed"}`` and
what the episode depends on beyond the scene
(:func:`replay_versions`): the policy checkpoint's SHA-256 (``policy_sha256``, ``None`` when the policy is
no checkpoint), the dv2s-gym version, one SHA-256 of its simulator and policy sources (an edited install
keeps its version) and the trace format's version. Running the entry with those parameters and that seed
(:func:`replay_failure`) is the failing episode, step for step: Scenic draws nothing for a fixed parameter,
so narrowing the ranges around the fixed values changes no other random draw of the scene. Run with other
seeds, the entry samples the neighbourhood of the failure: its params near the failing values, its other draws
(``not_narrowed``) as the parent makes them. A replay that no longer
matches says why it may not (:func:`mismatch_reason`): another checkpoint, another dv2s-gym, or, with
everything the same, a real divergence.
"""

from __future__ import annotations

import os
import re
from dv2s_gym.mining.errors import MiningError
from dv2s_gym.mining.monitors import Failure, MonitorSettings, detect_failure
from dv2s_gym.mining.conversion.scenic_values import read_support, support_contains, support_text
from dv2s_gym.mining.conversion.scene_draws import inline_draws
from policies.run_identity import checkpoint_path, dv2s_sources_sha256, installed_version
from envs.trace import TRACE_VERSION
from pathlib import Path
from scenario_bank.atomic import file_sha256
from scenario_bank.bank import Bank, BankError, param_ranges
from typing import Any, Dict, Mapping, Optional, Tuple, Union
from policies.registry import parse_spec, load_policy, spec_from_file
from policies.evaluation import run_episode

__all__ = ["NARROW", "REPLAY_TAG", "narrowed_script", "conditioned_params", "replay_name", "run_replay", "replay_failure",
           "ReplayOutcome", "replay_versions", "mismatch_reason"]

NARROW = 0.02
"""Share of a continuous parameter's range kept on either side of the failing value."""
REPLAY_TAG = "replay"
"""Tag of replay entries (besides ``mined`` and the failure type)."""

_PARAM_LINE = re.compile(r"^(\s*param\s+)(\w+)(\s*=\s*)(.+?)(\s*(#.*)?)$")


def narrowed_script(script: str, params: Mapping[str, Any], narrow: float = NARROW
                    ) -> Tuple[str, Dict[str, list], Dict[str, str]]:
    """``script`` with each parameter of ``params`` narrowed around its failing value; returns the script, the new
    intervals ``{name: [lo, hi]}`` and the parameters left as the parent draws them, with why (``{name: reason}``).

    The parameter's distribution is read by :func:`dv2s_gym.mining.conversion.scenic_values.read_support`: one interval of
    numbers (``Range(a, b)``, or one offset or scaled by numbers, ``Range(0, 10) + 12``) becomes ``Range(lo, hi)``,
    ``narrow`` of its width on either side of the value; a discrete one (``Uniform(0.3, 1.0)``,
    ``DiscreteRange(1, 3)``, numbers offset or scaled) is fixed at the failing value. Any other (a ``Normal``, an
    interval mixed with points, text values, another parameter) is left as it is and listed, and so is a parameter
    the script draws that ``params`` does not hold (its failing value is unknown), and every value the script draws
    outside its params (:func:`~dv2s_gym.mining.conversion.scene_draws.inline_draws`: no run records those). Raises
    ``ValueError`` for a value the distribution cannot take."""
    intervals: Dict[str, list] = {}
    skipped: Dict[str, str] = {}
    lines = script.splitlines(keepends=True)
    for i, line in enumerate(lines):
        body = line.rstrip("\r\n")
        match = _PARAM_LINE.match(body)
        name = match.group(2) if match else None
        if name is None:
            continue
        if name not in params:
            if _random(match.group(4)):
                skipped[name] = ("not among the failure's recorded parameters (the mining run did not sample it: "
                                 "the scene drew it from the seed), so its failing value is unknown and it keeps "
                                 f"the parent's {match.group(4).strip()}")
            continue
        expression, value = match.group(4), params[name]
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            skipped[name] = f"its failing value {value!r} is not a number"
            continue
        parts = read_support(expression)
        if parts is None:
            skipped[name] = (f"its distribution {expression.strip()} is not read as an interval or a set of numbers, "
                             "so it keeps the parent's")
            continue
        value = float(value)
        kinds = {part[0] for part in parts}
        if kinds == {"interval"} and len(parts) == 1:
            low, high = parts[0][1], parts[0][2]
            if not low - 1e-9 <= value <= high + 1e-9:
                raise MiningError(f"parameter {name}={value} lies outside its range {low:g}..{high:g}")
            if high == low:
                continue  # a constant: nothing to narrow
            width = narrow * (high - low)
            lo, hi = max(low, value - width), min(high, value + width)
            intervals[name] = [lo, hi]
            lines[i] = f"{match.group(1)}{name}{match.group(3)}Range({lo!r}, {hi!r})" \
                       f"  # narrowed around the failing value {value!r}" + line[len(body):]
        elif "interval" not in kinds:
            if not support_contains(parts, value):
                raise MiningError(f"parameter {name}={value} lies outside its range {support_text(parts)}")
            if len(support_values(parts)) == 1:
                continue  # a constant: nothing to fix
            written = int(value) if float(value).is_integer() and _integers(parts) else value
            intervals[name] = [value, value]
            lines[i] = f"{match.group(1)}{name}{match.group(3)}{written!r}" \
                       f"  # fixed at the failing value (the parent draws {expression.strip()})" + line[len(body):]
        else:
            skipped[name] = (f"its distribution {expression.strip()} mixes intervals and separate values "
                             f"({support_text(parts)}), so it keeps the parent's")
    skipped.update(inline_draws(script, taken=skipped))
    return "".join(lines), intervals, skipped


def conditioned_params(params: Mapping[str, Any], intervals: Optional[Mapping[str, Any]]) -> Dict[str, Any]:
    """The failing ``params`` a run of the narrowed script conditions on: all but those :func:`narrowed_script` fixed
    in the script (``intervals[name]`` one value), which the script no longer draws and Scenic cannot condition."""
    fixed = {name for name, span in (intervals or {}).items()
             if isinstance(span, (list, tuple)) and len(span) == 2 and span[0] == span[1]}
    return {name: value for name, value in params.items() if name not in fixed}


_RANDOM = re.compile(r"\b(Range|Uniform|Normal|TruncatedNormal|Options|Discrete|DiscreteRange|VerifaiRange|"
                     r"VerifaiOptions|VerifaiParameter|resample)\s*\(")


def _random(expression: str) -> bool:
    """Whether a ``param`` line's expression draws a value (a distribution that is not a single value)."""
    parts = read_support(expression)
    if parts is not None:
        return any(part[0] == "interval" and part[1] != part[2] for part in parts) or \
            len(support_values(parts)) > 1
    return bool(_RANDOM.search(expression.split("#", 1)[0]))


def support_values(parts) -> list:
    """The separate values of a discrete :func:`~dv2s_gym.mining.conversion.scenic_values.read_support` (no interval)."""
    values = set()
    for part in parts:
        if part[0] == "points":
            values.update(part[1])
        elif part[3] <= 2:
            values.update(part[1] + k * part[2] for k in range(part[3]))
        else:
            return [None, None]  # many
    return sorted(values)


def _integers(parts) -> bool:
    """Whether every value of the discrete ``parts`` is an integer (a ``DiscreteRange``)."""
    return all(part[0] == "grid" and float(part[1]).is_integer() and float(part[2]).is_integer() for part in parts)


def replay_name(parent: str, failure_type: str) -> str:
    """The base name of a replay entry (the bank adds ``_2``, ``_3``... when taken)."""
    base = re.sub(r"[^a-z0-9_\-]+", "_", f"replay_{parent}_{failure_type}".lower()).strip("_-")
    return base[:90] or "replay"


def replay_versions(policy: Any) -> Dict[str, Any]:
    """What a replay depends on beyond its scene, as a replay entry records it: ``{"policy_sha256",
    "dv2s_gym_version", "dv2s_sources_sha256", "trace_version"}``; ``policy_sha256`` is the SHA-256 of the
    checkpoint a policy spec names (``dv2s-ppo``, ``model.zip``, ``ppo:PATH``, a folder), ``None`` for a
    driver, a ``module:attribute`` or a policy object."""
    return {"policy_sha256": _checkpoint_sha256(policy), "dv2s_gym_version": installed_version(),
            "dv2s_sources_sha256": dv2s_sources_sha256(), "trace_version": TRACE_VERSION}


def _checkpoint_sha256(policy: Any) -> Optional[str]:
    if not isinstance(policy, (str, os.PathLike)):
        return None
    try:
        path = checkpoint_path(parse_spec(os.fspath(policy))[0])
    except ValueError:
        return None
    return file_sha256(path.resolve()) if path is not None and path.resolve().is_file() else None


_VERSION_FACTS = (("policy_sha256", "the policy checkpoint differs from the one that failed (SHA-256 {now} now, "
                                    "{then} when recorded)"),
                  ("dv2s_gym_version", "dv2s-gym is version {now} now, {then} when recorded"),
                  ("dv2s_sources_sha256", "dv2s-gym's sources changed since it was recorded "
                                          "(an edited or updated install)"),
                  ("trace_version", "the trace format is version {now} now, {then} when recorded"))


def mismatch_reason(recorded: Mapping[str, Any], current: Mapping[str, Any]) -> str:
    """Why a replay whose trajectory differs from ``recorded`` (a replay entry's provenance ``replay``) may not
    match, given the ``current`` :func:`replay_versions`: what changed since, or, with everything the same, that
    the episode really diverged."""
    changed = []
    for key, text in _VERSION_FACTS:
        then, now = recorded.get(key), current.get(key)
        if then != now:
            short = (lambda v: str(v)[:12]) if key.endswith("sha256") else str
            changed.append(text.format(now=short(now), then=short(then)))
    if changed:
        return ("; ".join(changed) + ": replay with the checkpoint and dv2s-gym version the entry records to see "
                "the failing episode again, or mine the new policy anew")
    return ("the same policy checkpoint, dv2s-gym version and sources as when recorded: a real divergence (the "
            "episode is not deterministic, or the entry's script or parameters were edited)")


class ReplayOutcome(dict):
    """What :func:`replay_failure` saw: ``{"trajectory_hash", "matches", "failure", "steps", "reason"}`` plus
    the trace (attribute ``trace``, not serialised); ``reason`` is ``None`` for a match, else why the replay
    may not match (:func:`mismatch_reason`)."""

    trace: Any = None


def run_replay(scenario: Any, *, policy: Any, seed: int, params: Mapping[str, Any],
               env_config: Optional[Mapping[str, Any]] = None, bank_dir: Optional[str] = None,
               monitor: Union[MonitorSettings, Mapping[str, Any], None] = None) -> Tuple[Any, Any, Optional[Failure]]:
    """Run ``policy`` on ``scenario`` (a bank name or a ``.scenic`` path) with ``seed`` and ``params`` fixed;
    returns ``(EpisodeResult, EpisodeTrace, Failure or None)`` (the miner's monitors)."""
    from envs.dv2s_env import DV2SEnv

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
    return result, trace, detect_failure(result, trace, MonitorSettings.of(monitor))


def replay_failure(bank: Any, name: str, *, policy: Optional[Any] = None,
                   env_config: Optional[Mapping[str, Any]] = None,
                   monitor: Union[MonitorSettings, Mapping[str, Any], None] = None
                   ) -> ReplayOutcome:
    """Run replay entry ``name`` of ``bank`` (a :class:`~scenario_bank.bank.Bank` or folder) with the seed and
    parameters of its provenance ``replay`` and the policy that failed (or ``policy``); ``matches`` says
    whether the episode is the recorded failing one (same trajectory hash), and ``reason``, when it is not,
    why it may not be (:func:`mismatch_reason`: the checkpoint or dv2s-gym changed, or a real divergence)."""
    bank = bank if isinstance(bank, Bank) else Bank(bank)
    entry = bank.get(name)
    replay = entry.source.replay
    if not isinstance(replay, Mapping) or replay.get("seed") is None:
        raise BankError(f"bank entry {name!r} is no replay of a mined failure (its provenance has no 'replay'); "
                        "replay entries are tagged 'replay'")
    if policy is None:
        policy = spec_from_file(replay.get("policy"), f"the provenance of bank entry {name!r}", "policy=SPEC")
    result, trace, failure = run_replay(str(entry.script_path), policy=policy,
                                        seed=int(replay["seed"]),
                                        params=conditioned_params(replay.get("params") or {}, replay.get("intervals")),
                                        env_config=env_config, monitor=monitor)
    matches = result.trajectory_hash == replay.get("trajectory_hash")
    reason = None if matches else (f"replay entry {name!r} did not replay the recorded failing episode "
                                   f"(trajectory hash {result.trajectory_hash[:12]} != recorded "
                                   f"{str(replay.get('trajectory_hash'))[:12]}): "
                                   + mismatch_reason(replay, replay_versions(policy)))
    out = ReplayOutcome(trajectory_hash=result.trajectory_hash, matches=matches,
                        failure=failure.to_dict() if failure is not None else None,
                        steps=result.steps, reason=reason)
    out.trace = trace
    return out
