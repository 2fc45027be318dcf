"""Closing the RL loop (``dv2s loop``): mine a policy's failures, grow the bank, fine-tune, measure.

One round, starting from policy ``P`` (an SB3 checkpoint spec, e.g. ``dv2s-ppo``):

a. **mine**: :func:`dv2s_gym.mining.miner.mine` runs ``P`` on sampled scenes of the starting
   bank's scenarios, clusters its failures, converts the representatives of at most
   ``max_conversions`` clusters (largest first; the rest are counted as not converted) through
   the D-V2S pipeline and adds the kept scenarios to the *working bank* (``out/bank``, a copy
   of the shipped bank, or the ``bank_dir`` given); every converted failure's scene is also kept
   exactly (its *exact replay* entry: the parent scenario narrowed around the failing parameters),
   and so is that of up to ``max_replays`` more clusters, largest first
   (:func:`dv2s_gym.mining.replays.replay_clusters`: no video, description or script, only the narrowed
   parent checked to replay the failing episode step for step): these are mined scenarios of the
   round too, so a round whose conversions are all rejected still has families to split;
b. **split**: the newly kept scenarios (converted scripts and exact replays) are split by *family* (their parent bank scenario,
   :func:`dv2s_gym.mining.split.split_by_family`) into a fine-tuning part and a held-out part,
   deterministically from the seed; a family held out once stays held out;
c. **before**: ``P`` runs on the held-out scenarios, ``k_eval`` evaluation seeds each
   (``EVAL_SEED_BASE + i``, never a training seed): failure rate (the miner's monitors) with
   a Wilson interval; fewer than ``min_heldout_episodes`` held-out episodes is said loudly and
   the round reports rates but no drop and no test;
d. **fine-tune**: :func:`policies.training.fine_tune` continues ``P`` on the working bank
   minus every held-out scenario and every held-out family's parent scenario (so the parent over
   its full range cannot leak the held-out failures), the mined fine-tuning scenarios drawn with ``mined_share``
   of the probability, the rest of the bank with the remainder (so it is not forgotten).
   The training reward is ``P``'s own with the terms of ``fine_tune_reward`` overridden
   (default ``{"standing": -0.3}``: standing still with a free path ahead, the miner's
   stall, is penalised like the monitors count it); only fine-tuning uses that env config:
   mining, the held-out evaluations and the regression test run ``P``'s own (a failure
   does not depend on the reward). That is ``fine_tune_method="ppo"``; with ``"dagger"``
   the policy instead imitates the reference driver (``rule``) on the states it visits
   itself in the same weighted scenario mix (:mod:`policies.imitation`; no reward; a killed
   DAgger run resumes from its last finished iteration, ``resumed`` in the step's record);
d'. **control**: the same fine-tuning (method, steps, seed, learning rate) on the same scenarios
   less every mined one, into ``round_<r>/control``: what the fine-tuning does without the mined
   scenarios, so a drop can be credited to them (``control=False`` leaves it out);
e. **after**: the fine-tuned policy and the control run on the same held-out episodes (paired):
   rates with Wilson intervals for start, control and fine-tuned, relative drop
   (scenario-bootstrap interval), exact two-sided McNemar p fine-tuned vs start and fine-tuned
   vs control;
e'. **untouched**: start, control and fine-tuned run on the scenario set the loop never mines or
   fine-tunes on (:data:`UNTOUCHED_BANK`: scripts written by others for Scenic's CARLA model),
   ``untouched_seeds`` seeds each, judged by :func:`dv2s_gym.regress.runner.run_regression`
   (failure rates, stalls apart, mean speed; fine-tuned vs start and control vs fine-tuned);
f. **regress**: :func:`dv2s_gym.regress.runner.run_regression` new against old on the starting
   bank's scenarios (PASS / FAIL / INCONCLUSIVE against ``margin``);
g. the next round starts from the new policy.

Everything lives under ``out``: ``loop.json`` (settings and every finished step, written
atomically after each), ``bank/``, ``round_<r>/{mine,heldout.jsonl,policy,control,untouched,regress}`` and the
report (``report.json``, ``report.md``, ``report.html``).
Restarted with the same ``out`` and settings, the loop skips finished steps and resumes the
unfinished one (the miner, the held-out store, training and the regression run are each
resumable); ``rounds`` may be raised to add rounds to a finished loop.
"""

from __future__ import annotations

import dataclasses
import json
import os
import sys
import time
from pathlib import Path
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence

from dv2s_gym.mining.jsonl import read_rows
from scenario_bank.run_identity import check_identity
from envs.errors import DV2SError

__all__ = ["LoopError", "LoopReport", "run_loop", "DEFAULT_OUT", "DEFAULTS", "mined_entries", "fine_tune_weights",
           "FINE_TUNE_METHODS"]

DEFAULT_OUT = "out/loop"
"""Where ``dv2s loop`` writes when ``--out`` is not given (rerunning resumes it)."""

DEFAULTS: Dict[str, Any] = {
    "rounds": 1,
    "budget": 80,
    "sampler": "novelty-bandit",
    "fine_tune_steps": 30_000,
    "fine_tune_lr": None,
    "holdout_fraction": 0.5,
    "k_eval": 10,
    "max_conversions": 4,
    "max_replays": 16,
    "min_heldout_episodes": 20,
    "min_heldout_families": 3,
    "control": True,
    "untouched_seeds": 2,
    "regress_episodes": 4,
    "mined_share": 0.5,
    "fine_tune_reward": {"standing": -0.3},
    "fine_tune_method": "dagger",
    "margin": 0.02,
    "seed": 0,
}
"""Embedded defaults: small, for one round in minutes on 2 cores (a small mining budget, at most 4
conversions, two short fine-tunes, a small evaluation; ``python -m bench.bench_loop`` times a round and
bench/RESULTS.md records it). The other measurements in bench/RESULTS.md use larger ones."""

IDENTITY = ("policy", "bank_dir", "budget", "sampler", "fine_tune_steps", "fine_tune_lr", "holdout_fraction", "k_eval",
            "regress_episodes", "mined_share", "fine_tune_reward", "margin", "seed", "scenarios", "fine_tune_method",
            "max_conversions", "control", "untouched_seeds", "min_heldout_episodes", "max_replays")
_RECORDED = ("holdout_by",)
"""Settings a loop keeps as first recorded (not chosen by the user, so never a reason to refuse a resume)."""

HOLDOUT_BY = "family"
"""How new loops split their mined scenarios (loops recorded before hold out by ``cluster``)."""

UNTOUCHED_BANK = Path(__file__).resolve().parent / "untouched"
"""The scenario set no loop mines or fine-tunes on: a bank folder of scripts written by others for Scenic's
CARLA model (its ``SOURCES.md`` names them and their licence)."""

FINE_TUNE_METHODS = ("ppo", "dagger")
"""How the loop fine-tunes: ``ppo`` continues PPO on the fine-tuning reward
(:func:`policies.training.fine_tune`); ``dagger`` imitates the reference driver on the
policy's own states (:func:`policies.imitation.dagger_fine_tune`)."""

METHOD_LEARNING_RATES = {"ppo": 1e-4, "dagger": 1e-3}
"""The fine-tuning learning rate when none is given: PPO's constant rate (its own 5e-4 made the
bank worse, bench/RESULTS.md) and DAgger's Adam rate."""

_LEGACY = {"fine_tune_method": "ppo", "max_conversions": None, "holdout_by": "cluster", "control": False,
           "untouched_seeds": 0, "min_heldout_episodes": 0, "max_replays": 0}
"""Identity settings added later, with the value a ``loop.json`` written before them meant."""


class LoopError(DV2SError, ValueError):
    """Bad loop input, or an ``out`` folder holding a loop with other settings."""


@dataclasses.dataclass
class LoopReport:
    """What :func:`run_loop` returns: the rounds' records and where the reports are."""

    out: Path
    rounds: List[Dict[str, Any]]
    policy: str
    """The spec of the last round's fine-tuned policy (the starting policy if no round fine-tuned)."""
    paths: Dict[str, Path]
    settings: Dict[str, Any]

    def to_json(self) -> Dict[str, Any]:
        """A JSON-safe dict (the body of ``report.json``)."""
        return {"schema": "dv2s-loop", "schema_version": 1, "out": str(self.out), "settings": self.settings,
                "policy": self.policy, "rounds": self.rounds}


# --------------------------------------------------------------------------- state
class _State:
    """``loop.json``: settings, the starting bank's scenarios and every finished step (atomic writes)."""

    def __init__(self, path: Path, settings: Dict[str, Any]) -> None:
        self.path = path
        if path.is_file():
            try:
                data = json.loads(path.read_text(encoding="utf-8"))
            except ValueError as error:
                raise LoopError(f"{path} is not readable JSON ({error}); choose another --out") from error
            _check_structure(data, path)
            recorded = data.get("settings", {})
            check_identity(recorded, settings, IDENTITY, legacy=_LEGACY, run=f"{path.parent} holds a loop",
                           fix="rerun with its settings to resume it, or choose another --out")
            data["settings"].update({k: settings[k] for k in settings if k not in IDENTITY and k not in _RECORDED})
            for key in _RECORDED:
                data["settings"].setdefault(key, _LEGACY[key])
            self.data = data
        else:
            self.data = {"settings": settings, "start": None, "rounds": []}

    def save(self) -> None:
        from scenario_bank.atomic import atomic_write_json

        self.path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_json(self.path, self.data, indent=1)

    def round(self, number: int) -> Dict[str, Any]:
        while len(self.data["rounds"]) < number:
            self.data["rounds"].append({"round": len(self.data["rounds"]) + 1, "steps": {}, "timings": {}})
        return self.data["rounds"][number - 1]


def _check_structure(data: Any, path: Path) -> None:
    """Refuse a ``loop.json`` that is JSON but not a loop's record, in one line naming the file and the fix."""
    problem = None
    if not isinstance(data, dict):
        problem = f"holds a {type(data).__name__}, not an object"
    elif not isinstance(data.get("settings"), dict):
        problem = "has no \"settings\" object"
    elif not isinstance(data.get("rounds"), list) or not all(
            isinstance(r, dict) and isinstance(r.get("steps", {}), dict) and isinstance(r.get("timings", {}), dict)
            for r in data["rounds"]):
        problem = "has no list of round objects under \"rounds\""
    elif data.get("start") is not None and not (isinstance(data["start"], dict)
                                                and isinstance(data["start"].get("scenarios"), list)):
        problem = "has a \"start\" that is not an object with a list of scenarios"
    if problem:
        raise LoopError(f"{path} is not a dv2s loop record ({problem}); choose another --out, or delete the file "
                        "to start the loop over")


# --------------------------------------------------------------------------- helpers
def _round_spec(spec: Any, folder: Path, out: Path) -> str:
    """A round's policy spec read back from ``loop.json``: an SB3 checkpoint inside that round's own
    ``folder``, as the loop writes it. A spec naming anything else (code, a checkpoint elsewhere) is refused:
    ``loop.json`` is a file, not the user's command line."""
    from policies.registry import SB3_ALGORITHMS

    text = spec if isinstance(spec, str) else repr(spec)
    algorithm, sep, path = text.partition(":")
    inside = False
    if sep and algorithm in SB3_ALGORITHMS and "?" not in path:
        try:
            inside = Path(path).resolve().is_relative_to(folder.resolve())
        except (OSError, ValueError):
            inside = False
    if not inside:
        raise LoopError(f"{out / 'loop.json'} names the round policy {text[:200]!r}, not a checkpoint in {folder}: "
                        "this loop folder was not written by this loop as it stands; choose another --out")
    return text


def _working_bank(out: Path, bank_dir: Optional[str]) -> str:
    """The bank the loop adds to: ``bank_dir`` itself, or a copy of the shipped bank in ``out/bank``."""
    if bank_dir is not None:
        return str(Path(bank_dir).resolve())
    from scenario_bank.bank import Bank

    target = out / "bank"
    if not target.is_dir() or not any(target.iterdir()):
        Bank().copy_to(target)  # atomic: a killed copy leaves no half bank behind
    return str(target.resolve())


def mined_entries(mine_out: os.PathLike | str, replays: bool = True) -> List[Dict[str, Any]]:
    """The kept scenarios of a mining run: ``[{"cluster", "scenario", "reproduction"}]`` from
    its ``conversions.jsonl`` (status ``kept`` with a bank entry), then (``replays``) the exact replays of its
    failing scenes (:func:`dv2s_gym.mining.replays.replay_entries`: ``"replay": True`` and ``"parent"``, from
    the conversions' ``replay_entry`` and from ``replays.jsonl``)."""
    records = read_rows(Path(mine_out) / "conversions.jsonl")  # none when no cluster was converted
    entries: Dict[str, Dict[str, Any]] = {}
    for record in records:
        if record.get("status") == "kept" and record.get("bank_entry"):
            entries[str(record["cluster"])] = {"cluster": str(record["cluster"]), "scenario": record["bank_entry"],
                                               "reproduction": (record.get("reproduction") or {}).get("rate")}
    kept = {entry["scenario"] for entry in entries.values()}
    for record in records:  # a cluster merged into a scenario kept in this run is tied to it
        if record.get("status") == "merged" and record.get("merged_into") in kept:
            entries.setdefault(str(record["cluster"]), {"cluster": str(record["cluster"]),
                                                        "scenario": record["merged_into"],
                                                        "reproduction": (record.get("reproduction") or {}).get("rate")})
    converted = [entries[key] for key in sorted(entries)]
    if not replays:
        return converted
    from dv2s_gym.mining.replays import replay_entries

    return converted + replay_entries(mine_out)


def _mining_summary(mine_out: Path) -> Dict[str, Any]:
    """Counts read from a mining run folder (episodes, failures, avoidable ones, clusters, conversions)."""
    episodes, failures, counted, errors = 0, 0, 0, 0
    records = read_rows(mine_out / "episodes.jsonl")
    for record in records:
        episodes += 1
        errors += bool(record.get("error"))
        if record.get("failure"):
            failures += 1
            counted += record.get("avoidable") is not False  # as MineRun.avoidable
    clusters = None
    try:
        from dv2s_gym.mining.cluster import cluster_failures

        clusters = len(set(cluster_failures(records).values()))
    except Exception:  # the count is informative; the loop goes on without it
        pass
    statuses: Dict[str, int] = {}
    reasons: List[str] = []
    for record in read_rows(mine_out / "conversions.jsonl"):
        statuses[record.get("status", "?")] = statuses.get(record.get("status", "?"), 0) + 1
        if record.get("status") == "rejected" and record.get("reason"):
            reasons.append(str(record["reason"]))
    converted = sum(statuses.values())
    from dv2s_gym.mining.replays import REPLAYS_FILE

    replayed: Dict[str, int] = {}
    for row in read_rows(mine_out / REPLAYS_FILE):
        replayed[row.get("status", "?")] = replayed.get(row.get("status", "?"), 0) + 1
    return {"replays": replayed, "episodes": episodes, "errors": errors, "failures": failures, "failures_against_policy": counted,
            "clusters": clusters, "conversions": statuses, "rejected_reasons": reasons[:20],
            "clusters_not_converted": None if clusters is None else max(0, clusters - converted),
            "clusters_not_kept": None if clusters is None else max(0, clusters - converted
                                                                   - sum(replayed.values()))}


def fine_tune_weights(names: Sequence[str], mined: Sequence[str], mined_share: float) -> Dict[str, float]:
    """Scenario -> sampling weight: the ``mined`` scenarios share ``mined_share`` of the probability
    equally, the other ``names`` share the rest (everything else in ``names`` stays in the mix)."""
    mined = sorted(set(mined) & set(names))
    rest = sorted(set(names) - set(mined))
    if not mined:
        return {name: 1.0 for name in rest}
    if not rest:
        return {name: 1.0 for name in mined}
    share = min(max(float(mined_share), 0.0), 1.0)
    weights = {name: (1.0 - share) / len(rest) for name in rest}
    weights.update({name: share / len(mined) for name in mined})
    return weights


def _policy_env_config(spec: str) -> Dict[str, Any]:
    from policies.training import TrainingError, resolve_checkpoint

    try:
        _, _, card = resolve_checkpoint(spec)
    except TrainingError as error:
        raise LoopError(f"dv2s loop fine-tunes the policy, so it needs a stable-baselines3 checkpoint "
                        f"(dv2s-ppo, ppo:PATH or a `dv2s train` folder): {error}") from None
    return dict(card.get("env_config") or {})


def _regress_summary(report: Mapping[str, Any], path: Path, parents: Sequence[str] = ()) -> Dict[str, Any]:
    """The regression step's record; ``parents``: scenarios whose own results are kept apart (the held-out
    families' parents, never fine-tuned on: the regression test's view beyond the fine-tuning mix)."""
    overall = report.get("overall") or {}
    per_scenario = report.get("scenarios") or {}
    comparison = overall.get("comparison") or {}

    def rate(role: str) -> Optional[Dict[str, Any]]:
        summary = overall.get(role) or {}
        return summary.get("failure_rate")

    return {"verdict": report.get("verdict"), "reason": comparison.get("reason"),
            "episodes": comparison.get("n"), "new_failure_rate": rate("candidate"), "old_failure_rate": rate("baseline"),
            "difference": comparison.get("difference"), "p_value": comparison.get("p_value"),
            "regressed": report.get("regressed") or [], "report": str(path),
            "held_out_parents": {name: {role: {key: ((per_scenario[name].get(side) or {}).get(key))
                                               for key in ("failure_rate", "stall_rate", "mean_speed")}
                                        for role, side in (("new", "candidate"), ("old", "baseline"))}
                                 for name in parents if name in per_scenario}}


def _log_default(line: str) -> None:
    print(line, file=sys.stderr)


# --------------------------------------------------------------------------- the loop
def run_loop(policy: str = "dv2s-ppo", *, rounds: int = DEFAULTS["rounds"], out: os.PathLike | str = DEFAULT_OUT,
             bank_dir: Optional[os.PathLike | str] = None, budget: int = DEFAULTS["budget"],
             sampler: str = DEFAULTS["sampler"], fine_tune_steps: int = DEFAULTS["fine_tune_steps"],
             holdout_fraction: float = DEFAULTS["holdout_fraction"], k_eval: int = DEFAULTS["k_eval"],
             regress_episodes: int = DEFAULTS["regress_episodes"], mined_share: float = DEFAULTS["mined_share"],
             fine_tune_reward: Optional[Mapping[str, float]] = None,
             fine_tune_method: str = DEFAULTS["fine_tune_method"],
             margin: float = DEFAULTS["margin"], seed: int = DEFAULTS["seed"], workers: Optional[int] = None,
             fine_tune_lr: Optional[float] = DEFAULTS["fine_tune_lr"],
             max_conversions: Optional[int] = DEFAULTS["max_conversions"],
             max_replays: Optional[int] = DEFAULTS["max_replays"],
             min_heldout_episodes: int = DEFAULTS["min_heldout_episodes"],
             min_heldout_families: int = DEFAULTS["min_heldout_families"], control: bool = DEFAULTS["control"],
             untouched_seeds: int = DEFAULTS["untouched_seeds"],
             scenarios: Optional[Sequence[str]] = None, n_envs: int = 2, progress: bool = True,
             mine_options: Optional[Mapping[str, Any]] = None, miner: Optional[Callable[..., Any]] = None,
             log: Callable[[str], None] = _log_default) -> LoopReport:
    """Run ``rounds`` rounds of mine -> split -> evaluate -> fine-tune (+ control) -> evaluate -> regress
    (module docstring).

    Args:
        policy: the starting policy, an SB3 checkpoint spec (``dv2s-ppo``, ``ppo:PATH``, a run folder).
        rounds: rounds to have finished when it returns (a resumed loop runs only the missing ones).
        out: the loop folder (resumable).
        bank_dir: a writable bank to grow (default: a copy of the shipped bank in ``out/bank``).
        budget / sampler: the miner's episodes per round and its sampler.
        fine_tune_steps: env steps of fine-tuning per round.
        fine_tune_lr: the fine-tuning's (constant) learning rate (``None``: the method's,
            :data:`METHOD_LEARNING_RATES`).
        holdout_fraction: share of the round's mined families held out from fine-tuning.
        k_eval: evaluation seeds per held-out scenario.
        regress_episodes: seeds per starting-bank scenario in the regression test.
        mined_share: probability of drawing a mined fine-tuning scenario during fine-tuning.
        fine_tune_reward: reward-term weights overriding the policy's own in the fine-tuning env
            only (``None``: ``DEFAULTS["fine_tune_reward"]``; ``{}``: the policy's reward unchanged);
            used by the ``ppo`` method only (imitation has no reward).
        fine_tune_method: ``ppo`` or ``dagger`` (:data:`FINE_TUNE_METHODS`).
        margin: the regression test's non-inferiority margin.
        seed: seeds the miner, the split and the fine-tuning (each round derives its own).
        max_conversions: clusters converted into bank scenarios per round, largest first (``None``: all).
        max_replays: clusters beyond the converted ones whose failing scene is kept as an exact replay entry
            per round, largest first (:func:`dv2s_gym.mining.replays.replay_clusters`; ``None``: all, 0: none).
        min_heldout_episodes: below this many held-out episodes a round reports rates only, no drop and no
            test, and says so in the log and the reports.
        min_heldout_families: likewise below this many held-out families (parent scenarios): the episodes of
            one family are near-identical scenes, so the paired test needs several families, not only episodes.
        control: also fine-tune without the mined scenarios (the control arm) and compare on held-out.
        untouched_seeds: seeds per scenario of the untouched set (:data:`UNTOUCHED_BANK`); 0 skips it.
        workers: processes for mining and evaluation (default: every core).
        scenarios: the scenarios mined and regression-tested (default: the starting bank's).
        n_envs: training environments (subprocesses).
        mine_options: extra keyword arguments for :func:`~dv2s_gym.mining.miner.mine`.
        miner: the mining function (default :func:`dv2s_gym.mining.miner.mine`; tests pass a stand-in).

    Returns:
        A :class:`LoopReport`; the reports are written to ``out`` after every round.
    """
    for name, value, low in (("rounds", rounds, 1), ("budget", budget, 1), ("fine-tune-steps", fine_tune_steps, 1),
                             ("k-eval", k_eval, 1), ("regress-episodes", regress_episodes, 1),
                             ("min-heldout-episodes", min_heldout_episodes, 0),
                             ("min-heldout-families", min_heldout_families, 0),
                             ("untouched-seeds", untouched_seeds, 0)):
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise LoopError(f"--{name} must be an integer >= {low}, not {value!r}")
    if max_conversions is not None and (isinstance(max_conversions, bool) or not isinstance(max_conversions, int)
                                        or max_conversions < 0):
        raise LoopError(f"--max-conversions must be an integer >= 0 (0: no conversions, only exact replays; "
                        f"'all' on the command line: every cluster), not {max_conversions!r}")
    if max_replays is not None and (isinstance(max_replays, bool) or not isinstance(max_replays, int)
                                    or max_replays < 0):
        raise LoopError(f"--max-replays must be an integer >= 0 (0: no replays beyond the converted clusters; "
                        f"'all' on the command line: every cluster), not {max_replays!r}")
    if not 0.0 <= float(holdout_fraction) <= 1.0:
        raise LoopError(f"--holdout-fraction must be in [0, 1], not {holdout_fraction}")
    if not 0.0 < float(mined_share) < 1.0:
        raise LoopError(f"--mined-share must be strictly between 0 and 1, not {mined_share}")
    from dv2s_gym.mining.samplers import SAMPLERS

    if sampler not in SAMPLERS:  # else round 1 starts (the working bank copied) before the miner refuses it
        raise LoopError(f"--sampler must be one of {', '.join(SAMPLERS)}, not {sampler!r}")
    if fine_tune_method not in FINE_TUNE_METHODS:
        raise LoopError(f"--fine-tune-method must be one of {', '.join(FINE_TUNE_METHODS)}, not {fine_tune_method!r}")
    if fine_tune_lr is None:
        fine_tune_lr = METHOD_LEARNING_RATES[fine_tune_method]
    if not float(fine_tune_lr) > 0:
        raise LoopError(f"--fine-tune-lr must be a positive number, not {fine_tune_lr}")
    from dv2s_gym.workers.pool import default_workers

    workers = int(workers or default_workers())
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise LoopError(f"--out {out} is a file; choose a folder for the loop")
    env_config = _policy_env_config(policy)
    if fine_tune_reward is None:
        fine_tune_reward = DEFAULTS["fine_tune_reward"]
    from policies.training import TrainingError, with_reward_weights

    try:
        fine_tune_config = with_reward_weights(env_config, fine_tune_reward)
    except TrainingError as error:
        raise LoopError(f"--fine-tune-reward: {error}") from None
    settings = {"policy": policy, "bank_dir": None if bank_dir is None else str(Path(bank_dir).resolve()),
                "budget": budget, "sampler": sampler, "fine_tune_steps": fine_tune_steps, "fine_tune_lr": fine_tune_lr,
                "holdout_fraction": float(holdout_fraction), "k_eval": k_eval, "regress_episodes": regress_episodes,
                "mined_share": float(mined_share), "fine_tune_reward": dict(fine_tune_reward),
                "fine_tune_method": fine_tune_method,
                "margin": float(margin), "seed": seed,
                "scenarios": list(scenarios) if scenarios is not None else None, "rounds": rounds,
                "max_conversions": max_conversions, "max_replays": max_replays, "holdout_by": HOLDOUT_BY, "control": bool(control),
                "untouched_seeds": untouched_seeds, "min_heldout_episodes": min_heldout_episodes,
                "min_heldout_families": min_heldout_families, "workers": workers, "n_envs": n_envs, "env_config": env_config,
                "fine_tune_env_config": fine_tune_config}
    state = _State(out / "loop.json", settings)
    settings = state.data["settings"]
    holdout_by = settings.get("holdout_by", _LEGACY["holdout_by"])
    bank = _working_bank(out, settings["bank_dir"])
    if state.data.get("start") is None:
        from scenario_bank import select_scenarios

        names = sorted(select_scenarios(list(scenarios) if scenarios is not None else None, bank))
        if not names:
            raise LoopError("the scenario selection is empty; name bank scenarios or tag:<tag>")
        state.data["start"] = {"bank": bank, "scenarios": names}
        state.save()
    start_names: List[str] = state.data["start"]["scenarios"]
    if miner is None:
        from dv2s_gym.mining.miner import mine as miner

    current = policy
    for number in range(1, rounds + 1):
        record = state.round(number)
        steps, timings = record["steps"], record["timings"]
        record.setdefault("policy", current)
        round_dir = out / f"round_{number}"
        if "regress" in steps or steps.get("skipped"):
            if record.get("new_policy"):
                current = _round_spec(record["new_policy"], round_dir / "policy", out)
            continue
        log(f"round {number}: policy {current}")
        stages = ["mine", "split", "before", "fine_tune"] + (["control"] if control else []) + ["after"] + (
            ["untouched"] if untouched_seeds else []) + ["regress"]

        def timed(step: str, function: Callable[[], Any]) -> Any:
            log(f"round {number} [{stages.index(step) + 1}/{len(stages)}] {_STAGE_NAMES[step]} ...")
            began = time.perf_counter()
            value = function()
            timings[step] = round(time.perf_counter() - began, 1)  # of the run that finished the step
            steps[step] = value
            state.save()
            log(f"round {number} [{stages.index(step) + 1}/{len(stages)}] {_STAGE_NAMES[step]}: done in "
                f"{timings[step]:.0f} s")
            return value

        if "mine" not in steps:
            def do_mine() -> Dict[str, Any]:
                options = {"sampler": sampler, "scenarios": start_names, "bank_dir": bank, "workers": workers,
                           "seed": seed * 1000 + number, "progress": progress, "env_config": env_config,
                           "convert": True, "max_conversions": max_conversions,
                           "origin": {"command": "dv2s loop", "seed": seed, "round": number},
                           **dict(mine_options or {})}
                miner(current, out=str(round_dir / "mine"), budget=budget, **options)
                if max_replays != 0 and (round_dir / "mine" / "settings.json").is_file():  # a miner's run folder
                    from dv2s_gym.mining.replays import replay_clusters

                    replay_clusters(round_dir / "mine", bank_dir=bank, max_replays=max_replays, progress=progress)
                return {**_mining_summary(round_dir / "mine"), "kept": mined_entries(round_dir / "mine"),
                        "folder": str(round_dir / "mine")}

            timed("mine", do_mine)
            mined = steps["mine"]
            log(f"round {number}: mined {mined['failures']} failures in {mined['episodes']} episodes, "
                f"{mined.get('clusters')} clusters, "
                f"{len({e['scenario'] for e in mined['kept'] if not e.get('replay')})} converted scenarios and "
                f"{len({e['scenario'] for e in mined['kept'] if e.get('replay')})} exact replays kept"
                + (f"; {mined['clusters_not_converted']} clusters not converted (--max-conversions "
                   f"{'all' if max_conversions is None else max_conversions})" if mined.get("clusters_not_converted") else "")
                + (f", {mined['clusters_not_kept']} neither converted nor replayed (--max-replays "
                   f"{'all' if max_replays is None else max_replays})" if mined.get("clusters_not_kept") else ""))
        if "split" not in steps:
            held_families, tuned_families = _earlier_sides(state.data["rounds"][:number - 1])
            timed("split", lambda: _split(steps["mine"]["kept"], holdout_fraction, seed * 1000 + number, holdout_by,
                                          bank, held_families, tuned_families))
            if steps["split"].get("moved_to_fine_tune"):
                log(f"round {number}: WARNING: earlier held-out famil(ies) "
                    f"{', '.join(steps['split']['moved_to_fine_tune'])} now share a mined scenario with a family "
                    "fine-tuned on earlier, so they are fine-tuned on from this round")
        split = steps["split"]
        held_out, tuned = split["held_out"], split["fine_tune"]
        if not tuned and not held_out:
            mined = steps["mine"]
            tried = sum((mined.get("conversions") or {}).values())
            replayed = sum((mined.get("replays") or {}).values())
            steps["skipped"] = (f"no mined scenario was kept this round ({tried} conversion(s) tried"
                                + (f", {replayed} exact replay(s) tried" if replayed else "")
                                + (f", {mined['clusters_not_converted']} cluster(s) not converted: raise "
                                   "--max-conversions, --max-replays or --budget"
                                   if mined.get("clusters_not_converted") else "")
                                + "): nothing to fine-tune on or to measure")
            state.save()
            log(f"round {number}: {steps['skipped']}")
            _write(out, state, current)
            continue

        from dv2s_gym.mining.heldout import HeldOutStore, evaluate_heldout
        from policies.training import EVAL_SEED_BASE

        episodes = [(name, EVAL_SEED_BASE + i) for name in held_out for i in range(k_eval)]
        families = _families_of(steps["mine"]["kept"], held_out, bank)
        shortfall = underpowered(len(episodes), min_heldout_episodes, len(set(families.values())),
                                 min_heldout_families)
        if shortfall:
            log(f"round {number}: WARNING: {shortfall}")
        store_path = round_dir / "heldout.jsonl"
        if "before" not in steps:
            timed("before", lambda: {"episodes": len(episodes), "done": bool(evaluate_heldout(
                "before", current, episodes, store=HeldOutStore(store_path), bank_dir=bank, env_config=env_config,
                workers=workers, progress=progress))})
        excluded = set(held_out) | set(split.get("held_out_families", []))
        for earlier in state.data["rounds"][:number - 1]:
            earlier_split = earlier.get("steps", {}).get("split") or {}
            excluded.update(earlier_split.get("held_out", []))
            excluded.update(earlier_split.get("held_out_families", []))
        arm = dict(bank=bank, method=fine_tune_method, steps=fine_tune_steps, seed=seed * 1000 + number,
                   n_envs=n_envs, env_config=env_config, fine_tune_config=fine_tune_config,
                   reward=fine_tune_reward, learning_rate=fine_tune_lr, progress=progress, log=log)
        if "fine_tune" not in steps:
            timed("fine_tune", lambda: _fine_tune_arm(current, round_dir / "policy", excluded, mined_share,
                                                      with_mined=True, label=f"round {number}", **arm))
        from policies.training import resolve_checkpoint

        def spec_of(model: str, folder: Path) -> str:
            _round_spec(f"ppo:{model}", folder, out)  # loop.json is a file: only this round's own checkpoint
            return f"{resolve_checkpoint(model)[0]}:{model}"

        new_policy = spec_of(steps["fine_tune"]["model"], round_dir / "policy")
        record["new_policy"] = new_policy
        control_policy = None
        if control:
            if "control" not in steps:
                timed("control", lambda: _fine_tune_arm(current, round_dir / "control", excluded, mined_share,
                                                        with_mined=False, label=f"round {number} control", **arm))
            control_policy = spec_of(steps["control"]["model"], round_dir / "control")
            record["control_policy"] = control_policy
        if "after" not in steps:
            def do_after() -> Dict[str, Any]:
                store = HeldOutStore(store_path)
                before = evaluate_heldout("before", current, episodes, store=store, bank_dir=bank,
                                          env_config=env_config, workers=workers, progress=False)
                after = evaluate_heldout("after", new_policy, episodes, store=store, bank_dir=bank,
                                         env_config=env_config, workers=workers, progress=progress)
                control_records = None
                if control_policy is not None:
                    control_records = evaluate_heldout("control", control_policy, episodes, store=store,
                                                       bank_dir=bank, env_config=env_config, workers=workers,
                                                       progress=progress)
                return heldout_comparison(before, after, control_records, min_episodes=min_heldout_episodes,
                                          seed=seed, families=families, min_families=min_heldout_families)

            timed("after", do_after)
        if untouched_seeds and "untouched" not in steps:
            timed("untouched", lambda: evaluate_untouched(
                current, new_policy, control_policy, seeds=untouched_seeds, out=round_dir / "untouched",
                env_config=env_config, margin=margin, workers=workers, progress=progress))
        if "regress" not in steps:
            def do_regress() -> Dict[str, Any]:
                from dv2s_gym.regress.runner import run_regression

                report = run_regression(new_policy, current, bank_dir=bank, scenarios=start_names,
                                        episodes=regress_episodes, seed=EVAL_SEED_BASE, margin=margin,
                                        workers=workers, out_dir=round_dir / "regress", env_config=env_config,
                                        progress=progress)
                return _regress_summary(report, round_dir / "regress" / "report.json",
                                        split.get("held_out_families", []))

            timed("regress", do_regress)
        _log_round(log, number, steps)
        current = new_policy
        _write(out, state, current)
    return _write(out, state, current)


_STAGE_NAMES = {"mine": "mining failures", "split": "splitting by family", "before": "held-out: starting policy",
                "fine_tune": "fine-tuning with the mined scenarios", "control": "control: fine-tuning without them",
                "after": "held-out: fine-tuned and control", "untouched": "untouched scenario set",
                "regress": "regression test on the starting bank"}


def underpowered(episodes: int, minimum: int, families: Optional[int] = None,
                 min_families: int = 0) -> Optional[str]:
    """The warning for a round with fewer than ``minimum`` held-out episodes or fewer than ``min_families``
    held-out families (``families``, when known), or ``None``."""
    reasons = []
    if episodes < minimum:
        reasons.append(f"only {episodes} held-out episode(s), fewer than the {minimum} needed "
                       "(--min-heldout-episodes)")
    if families is not None and families < min_families:
        reasons.append(f"only {families} held-out famil{'y' if families == 1 else 'ies'} (parent scenarios), fewer "
                       f"than the {min_families} needed: episodes of one family are near-identical scenes, not "
                       "independent trials")
    if not reasons:
        return None
    return ("; ".join(reasons) + ": this round reports held-out rates but no drop and no test; raise --k-eval, "
            "--max-conversions, --max-replays or --budget for more held-out scenarios and families")


def _families_of(kept: Sequence[Mapping[str, Any]], held_out: Sequence[str], bank: Optional[str]) -> Dict[str, str]:
    """``{held-out scenario: its family}`` (:func:`dv2s_gym.mining.split.family_of`)."""
    from dv2s_gym.mining.split import family_of

    wanted = set(held_out)
    families = {str(e["scenario"]): family_of(e) for e in _with_parents(kept, bank) if e["scenario"] in wanted}
    return {name: families.get(name, name) for name in held_out}


def _fine_tune_arm(current: str, out: Path, excluded: set, mined_share: float, *, with_mined: bool, label: str,
                   bank: str, method: str, steps: int, seed: int, n_envs: int, env_config: Dict[str, Any],
                   fine_tune_config: Dict[str, Any], reward: Mapping[str, float], learning_rate: float,
                   progress: bool, log: Callable[[str], None]) -> Dict[str, Any]:
    """Fine-tune ``current`` into ``out`` on the working bank less ``excluded``: the mined scenarios upweighted
    (``with_mined``) or left out (the control arm); everything else identical between the two arms."""
    from scenario_bank.bank import Bank

    # a held-out family's every member stays out too: exact replays of its failures and entries of earlier rounds
    entries = [e for e in Bank(bank) if e.name not in excluded and e.source.get("parent") not in excluded]
    mined = sorted(e.name for e in entries if e.source.get("kind") == "mined")
    names = sorted(e.name for e in entries if with_mined or e.name not in mined)
    weights = fine_tune_weights(names, mined if with_mined else [], mined_share)
    common = {"scenarios": len(names), "mined_upweighted": len(mined) if with_mined else 0, "steps": steps,
              "mined_left_out": 0 if with_mined else len(mined),
              "families": sorted({str(e.source.get("parent") or e.name) for e in entries if e.name in names})}
    if method == "dagger":
        from policies.dagger_checkpoint import checkpoint_position, describe_position
        from policies.imitation import DAGGER_DEFAULTS, dagger_fine_tune
        from policies.registry import read_model_card

        position = checkpoint_position(out)
        if position is not None:
            log(f"{label}: fine-tune (dagger) resumed from "
                f"{describe_position(*position, DAGGER_DEFAULTS['iterations'])}")
        path = dagger_fine_tune(current, bank_dir=bank, out=out, steps=steps, weights=weights, seed=seed,
                                n_envs=n_envs, env_config=env_config, learning_rate=learning_rate,
                                progress_bar=progress, log=log)
        dagger = read_model_card(path).get("fine_tune") or {}
        return {"model": str(path.resolve()), "method": "dagger", **common, "reward_weights": None,
                "env_config": env_config, "reference": dagger.get("reference"), "agreement": dagger.get("agreement"),
                "resumed": dagger.get("resumed") or []}
    from policies.training import fine_tune

    path = fine_tune(current, bank_dir=bank, out=out, steps=steps, weights=weights, seed=seed, n_envs=n_envs,
                     env_config=env_config, reward_weights=reward, progress_bar=progress,
                     learning_rate=learning_rate, log=log)
    return {"model": str(path.resolve()), "method": "ppo", **common, "reward_weights": dict(reward),
            "env_config": fine_tune_config}


def heldout_comparison(before: Sequence[Mapping[str, Any]], after: Sequence[Mapping[str, Any]],
                       control: Optional[Sequence[Mapping[str, Any]]], *, min_episodes: int,
                       seed: int = 0, families: Optional[Mapping[str, str]] = None,
                       min_families: int = 0) -> Dict[str, Any]:
    """The ``after`` step: :func:`~dv2s_gym.mining.heldout.paired_summary` of fine-tuned against start, plus
    the control's rate and the paired fine-tuned-vs-control table and exact McNemar p (``vs_control``), and
    each policy's failures by type (``failure_types``: stalls apart from collisions and the rest).

    ``families`` maps each held-out scenario to its family (default: each scenario its own); ``heldout_families``
    and ``heldout_scenarios`` count those the episodes came from. Below ``min_episodes`` pairs or
    ``min_families`` families the drop, its interval and both p-values are ``None`` and ``underpowered``
    says why (the rates, with their wide intervals, stay)."""
    from dv2s_gym.mining.heldout import failure_types, paired_summary

    summary = paired_summary(before, after, seed=seed)
    summary["min_episodes"] = min_episodes
    scenarios = sorted({str(r["scenario"]) for r in before})
    summary["heldout_scenarios"] = len(scenarios)
    summary["heldout_families"] = len({(families or {}).get(name, name) for name in scenarios})
    summary["min_families"] = min_families
    summary["failure_types"] = {"start": failure_types(before), "fine_tuned": failure_types(after)}
    if control is not None:
        versus = paired_summary(control, after, seed=seed, bootstrap=0)
        table = versus["table"]
        summary["control"] = versus["before"]
        summary["failure_types"]["control"] = failure_types(control)
        summary["vs_control"] = {"pairs": versus["pairs"], "errors": versus["errors"],
                                 "relative_drop": versus["relative_drop"],
                                 "table": {"both_fail": table["both_fail"], "fine_tuned_only": table["after_only"],
                                           "control_only": table["before_only"], "neither": table["neither"]},
                                 "mcnemar_p": versus["mcnemar_p"],
                                 "per_scenario": {name: row["before"]
                                                  for name, row in versus["per_scenario"].items()}}
    shortfall = underpowered(summary["pairs"], min_episodes, summary["heldout_families"], min_families)
    if shortfall:
        summary["underpowered"] = shortfall
        summary.update(relative_drop=None, relative_drop_interval=[None, None], mcnemar_p=None)
        if "vs_control" in summary:
            summary["vs_control"].update(relative_drop=None, mcnemar_p=None)
    return summary


def evaluate_untouched(start: str, fine_tuned: str, control: Optional[str], *, seeds: int, out: Path,
                       env_config: Mapping[str, Any], margin: float, workers: int, progress: bool,
                       bank_dir: Optional[os.PathLike | str] = None) -> Dict[str, Any]:
    """Start, fine-tuned and control on the untouched scenario set (``bank_dir``, default
    :data:`UNTOUCHED_BANK`), ``seeds`` seeds each from ``EVAL_SEED_BASE``, with ``dv2s regress``: fine-tuned
    against start (``out/vs_start``), then the control against the fine-tuned policy's episodes of that run
    (``out/vs_control``: only the control runs). Failure rates, stall rates and mean speeds per policy, and
    the two comparisons' verdicts, differences and p-values."""
    from dv2s_gym.regress.runner import run_regression
    from policies.training import EVAL_SEED_BASE

    bank_dir = str(Path(bank_dir or UNTOUCHED_BANK).resolve())
    first = run_regression(fine_tuned, start, bank_dir=bank_dir, episodes=seeds, seed=EVAL_SEED_BASE, margin=margin,
                           workers=workers, out_dir=out / "vs_start", env_config=dict(env_config), progress=progress)
    overall = first.get("overall") or {}
    result: Dict[str, Any] = {"scenarios": list((first.get("bank") or {}).get("scenarios") or []),
                              "seeds": seeds, "policies": {"start": _measures(overall.get("baseline")),
                                                           "fine_tuned": _measures(overall.get("candidate"))},
                              "fine_tuned_vs_start": _comparison(first, out / "vs_start" / "report.json")}
    if control is not None:
        # a measurement, not a gate: the fine-tuned policy is the reference whatever its own verdict was
        second = run_regression(control, baseline_report=out / "vs_start" / "report.json", baseline_role="candidate",
                                accept_failed_baseline=True,
                                bank_dir=bank_dir, episodes=seeds, seed=EVAL_SEED_BASE, margin=margin, workers=workers,
                                out_dir=out / "vs_control", env_config=dict(env_config), progress=progress)
        result["policies"]["control"] = _measures((second.get("overall") or {}).get("candidate"))
        result["control_vs_fine_tuned"] = _comparison(second, out / "vs_control" / "report.json")
    return result


def _measures(summary: Optional[Mapping[str, Any]]) -> Dict[str, Any]:
    summary = summary or {}
    return {"episodes": summary.get("episodes"), "errors": summary.get("errors"),
            "failure_rate": summary.get("failure_rate"), "stall_rate": summary.get("stall_rate"),
            "collision_rate": summary.get("collision_rate"), "mean_speed": summary.get("mean_speed")}


def _comparison(report: Mapping[str, Any], path: Path) -> Dict[str, Any]:
    comparison = (report.get("overall") or {}).get("comparison") or {}
    return {"verdict": report.get("verdict"), "reason": comparison.get("reason"), "episodes": comparison.get("n"),
            "difference": comparison.get("difference"), "p_value": comparison.get("p_value"), "report": str(path)}


def _split(kept: Sequence[Mapping[str, Any]], fraction: float, seed: int, by: str = HOLDOUT_BY,
           bank: Optional[str] = None, held_families: Sequence[str] = (),
           tuned_families: Sequence[str] = ()) -> Dict[str, Any]:
    from dv2s_gym.mining.split import split_by_cluster, split_by_family

    if by == "cluster":
        return split_by_cluster(kept, fraction, seed)
    return split_by_family(_with_parents(kept, bank), fraction, seed, held_families, tuned_families)


def _earlier_sides(rounds: Sequence[Mapping[str, Any]]) -> tuple:
    """``(held, tuned)``: the families earlier ``rounds`` held out, and those they fine-tuned on in any form
    (their split's fine-tuning families and every family in a fine-tuning arm's mix, parents included)."""
    held: set = set()
    tuned: set = set()
    for earlier in rounds:
        steps = earlier.get("steps") or {}
        split = steps.get("split") or {}
        held.update(split.get("held_out_families", []))
        tuned.update(split.get("fine_tune_families", []))
        for arm in ("fine_tune", "control"):
            tuned.update((steps.get(arm) or {}).get("families", []))
    return sorted(held), sorted(tuned)


def _with_parents(kept: Sequence[Mapping[str, Any]], bank: Optional[str]) -> List[Dict[str, Any]]:
    """The kept entries with ``parent``: the scenario family their bank provenance goes back to
    (:func:`dv2s_gym.mining.family.scenario_family`, the family their failures were clustered by)."""
    entries = [dict(e) for e in kept]
    if bank is None:
        return entries
    from dv2s_gym.mining.family import scenario_family

    for entry in entries:
        if not entry.get("parent"):
            family = scenario_family(str(entry["scenario"]), str(bank))
            if family != entry["scenario"]:
                entry["parent"] = family
    return entries


def _log_round(log: Callable[[str], None], number: int, steps: Mapping[str, Any]) -> None:
    after = steps.get("after") or {}

    def rate(r: Optional[Mapping[str, Any]]) -> str:
        if not r or r.get("rate") is None:
            return "-"
        return f"{r['k']}/{r['n']} = {r['rate']:.2f} [{r['low']:.2f}, {r['high']:.2f}]"

    if after:
        line = (f"round {number}: held-out failure rate start {rate(after.get('before'))}, "
                + (f"control {rate(after.get('control'))}, " if after.get("control") else "")
                + f"fine-tuned {rate(after.get('after'))}")
        if after.get("underpowered"):
            log(line + f"; NO DROP OR TEST REPORTED: {after['underpowered']}")
        else:
            drop = after.get("relative_drop")
            versus = after.get("vs_control") or {}
            log(line + (f", relative drop {drop:.0%}" if drop is not None else "")
                + (f", McNemar p vs start = {after['mcnemar_p']:.3g}" if after.get("mcnemar_p") is not None else "")
                + (f", vs control = {versus['mcnemar_p']:.3g}" if versus.get("mcnemar_p") is not None else ""))
    untouched = steps.get("untouched") or {}
    if untouched:
        policies = untouched.get("policies") or {}

        def share(role: str) -> str:
            value = ((policies.get(role) or {}).get("failure_rate") or {}).get("value")
            return "-" if value is None else f"{value:.2f}"

        log(f"round {number}: untouched set failure rate start {share('start')}, control {share('control')}, "
            f"fine-tuned {share('fine_tuned')}; fine-tuned vs start "
            f"{(untouched.get('fine_tuned_vs_start') or {}).get('verdict')}")
    regress = steps.get("regress") or {}
    log(f"round {number}: rest of the bank: {regress.get('verdict')} ({regress.get('reason')})")


def _write(out: Path, state: _State, current: str) -> LoopReport:
    from dv2s_gym.mining.loop_report import write_loop_reports

    report = LoopReport(out=out, rounds=state.data["rounds"], policy=current, paths={}, settings=state.data["settings"])
    report.paths = write_loop_reports(report.to_json(), out)
    return report
