"""Closing the RL loop (``dv2s loop``): mine a policy's failures, grow the bank, fine-tune, measure.

One round, starting from policy ``P`` (an SB3 checkpoint spec, e.g. ``dv2s-ppo``):

a. **mine**: :func:`dv2s_gym.mining.miner.mine` runs ``P`` on sampled scenes of the starting
   bank's scenarios, clusters its failures, converts each cluster's representative through
   the D-V2S pipeline and adds the kept scenarios to the *working bank* (``out/bank``, a copy
   of the shipped bank, or the ``bank_dir`` given);
b. **split**: the newly kept scenarios are split by cluster (:mod:`dv2s_gym.mining.split`)
   into a fine-tuning part and a held-out part, deterministically from the seed;
c. **before**: ``P`` runs on the held-out scenarios, ``k_eval`` evaluation seeds each
   (``EVAL_SEED_BASE + i``, never a training seed): failure rate (the miner's monitors) with
   a Wilson interval;
d. **fine-tune**: :func:`policies.training.fine_tune` continues ``P`` on the working bank
   minus every held-out scenario, the mined fine-tuning scenarios drawn with ``mined_share``
   of the probability, the rest of the bank with the remainder (so it is not forgotten).
   The training reward is ``P``'s own with the terms of ``fine_tune_reward`` overridden
   (default ``{"standing": -0.3}``: standing still with a free path ahead, the miner's
   stall, is penalised like the monitors count it); only fine-tuning uses that env config:
   mining, the held-out evaluations and the regression test run ``P``'s own (a failure
   does not depend on the reward). That is ``fine_tune_method="ppo"``; with ``"dagger"``
   the policy instead imitates the reference driver (``rule``) on the states it visits
   itself in the same weighted scenario mix (:mod:`policies.imitation`; no reward; a killed
   DAgger run resumes from its last finished iteration, ``resumed`` in the step's record);
e. **after**: the new policy runs on the same held-out episodes (paired): rate, interval,
   relative drop (scenario-bootstrap interval), exact two-sided McNemar p;
f. **regress**: :func:`dv2s_gym.regress.runner.run_regression` new against old on the starting
   bank's scenarios (PASS / FAIL / INCONCLUSIVE against ``margin``);
g. the next round starts from the new policy.

Everything lives under ``out``: ``loop.json`` (settings and every finished step, written
atomically after each), ``bank/``, ``round_<r>/{mine,heldout.jsonl,policy,regress}`` and the
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

from envs.errors import DV2SError

__all__ = ["LoopError", "LoopReport", "run_loop", "DEFAULT_OUT", "DEFAULTS", "mined_entries", "fine_tune_weights",
           "FINE_TUNE_METHODS"]

DEFAULT_OUT = "out/loop"
"""Where ``dv2s loop`` writes when ``--out`` is not given (rerunning resumes it)."""

DEFAULTS: Dict[str, Any] = {
    "rounds": 1,
    "budget": 80,
    "sampler": "cross-entropy",
    "fine_tune_steps": 30_000,
    "fine_tune_lr": None,
    "holdout_fraction": 0.5,
    "k_eval": 6,
    "regress_episodes": 4,
    "mined_share": 0.5,
    "fine_tune_reward": {"standing": -0.3},
    "fine_tune_method": "dagger",
    "margin": 0.02,
    "seed": 0,
}
"""Embedded defaults: one round finishes in a few minutes on 2 cores (a small mining budget,
a short fine-tune, a small evaluation). The measurement in bench/RESULTS.md uses larger ones."""

IDENTITY = ("policy", "bank_dir", "budget", "sampler", "fine_tune_steps", "fine_tune_lr", "holdout_fraction", "k_eval",
            "regress_episodes", "mined_share", "fine_tune_reward", "margin", "seed", "scenarios", "fine_tune_method")

FINE_TUNE_METHODS = ("ppo", "dagger")
"""How the loop fine-tunes: ``ppo`` continues PPO on the fine-tuning reward
(:func:`policies.training.fine_tune`); ``dagger`` imitates the reference driver on the
policy's own states (:func:`policies.imitation.dagger_fine_tune`)."""

METHOD_LEARNING_RATES = {"ppo": 1e-4, "dagger": 1e-3}
"""The fine-tuning learning rate when none is given: PPO's constant rate (its own 5e-4 made the
bank worse, bench/RESULTS.md) and DAgger's Adam rate."""

_LEGACY = {"fine_tune_method": "ppo"}
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
            recorded = data.get("settings", {})
            for key in IDENTITY:
                value = recorded.get(key, _LEGACY.get(key))
                if json.dumps(value, sort_keys=True) != json.dumps(settings.get(key), sort_keys=True):
                    raise LoopError(f"{path.parent} holds a loop with {key}={value!r}, not "
                                    f"{settings.get(key)!r}; rerun with its settings to resume it, or choose "
                                    "another --out")
            data["settings"].update({k: settings[k] for k in settings if k not in IDENTITY})
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


# --------------------------------------------------------------------------- helpers
def _working_bank(out: Path, bank_dir: Optional[str]) -> str:
    """The bank the loop adds to: ``bank_dir`` itself, or a copy of the shipped bank in ``out/bank``."""
    if bank_dir is not None:
        return str(Path(bank_dir).resolve())
    from scenario_bank.bank import Bank

    target = out / "bank"
    if not target.is_dir() or not any(target.iterdir()):
        Bank().copy_to(target)  # atomic: a killed copy leaves no half bank behind
    return str(target.resolve())


def mined_entries(mine_out: os.PathLike | str) -> List[Dict[str, Any]]:
    """The kept scenarios of a mining run: ``[{"cluster", "scenario", "reproduction"}]`` from
    its ``conversions.jsonl`` (status ``kept`` with a bank entry)."""
    path = Path(mine_out) / "conversions.jsonl"
    if not path.is_file():
        return []
    records = []
    for line in path.read_text(encoding="utf-8").splitlines():
        try:
            records.append(json.loads(line))
        except ValueError:
            continue
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
    return [entries[key] for key in sorted(entries)]


def _mining_summary(mine_out: Path) -> Dict[str, Any]:
    """Counts read from a mining run folder (episodes, failures, avoidable ones, clusters, conversions)."""
    episodes, failures, counted, errors = 0, 0, 0, 0
    records = []
    path = mine_out / "episodes.jsonl"
    if path.is_file():
        for line in path.read_text(encoding="utf-8").splitlines():
            try:
                record = json.loads(line)
            except ValueError:
                continue
            records.append(record)
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
    conversions = mine_out / "conversions.jsonl"
    if conversions.is_file():
        for line in conversions.read_text(encoding="utf-8").splitlines():
            try:
                record = json.loads(line)
            except ValueError:
                continue
            statuses[record.get("status", "?")] = statuses.get(record.get("status", "?"), 0) + 1
            if record.get("status") == "rejected" and record.get("reason"):
                reasons.append(str(record["reason"]))
    return {"episodes": episodes, "errors": errors, "failures": failures, "failures_against_policy": counted,
            "clusters": clusters, "conversions": statuses, "rejected_reasons": reasons[:20]}


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


def _regress_summary(report: Mapping[str, Any], path: Path) -> Dict[str, Any]:
    overall = report.get("overall") or {}
    comparison = overall.get("comparison") or {}

    def rate(role: str) -> Optional[Dict[str, Any]]:
        summary = overall.get(role) or {}
        return summary.get("failure_rate")

    return {"verdict": report.get("verdict"), "reason": comparison.get("reason"),
            "episodes": comparison.get("n"), "new_failure_rate": rate("candidate"), "old_failure_rate": rate("baseline"),
            "difference": comparison.get("difference"), "p_value": comparison.get("p_value"),
            "regressed": report.get("regressed") or [], "report": str(path)}


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
             scenarios: Optional[Sequence[str]] = None, n_envs: int = 2, progress: bool = True,
             mine_options: Optional[Mapping[str, Any]] = None, miner: Optional[Callable[..., Any]] = None,
             log: Callable[[str], None] = _log_default) -> LoopReport:
    """Run ``rounds`` rounds of mine -> split -> evaluate -> fine-tune -> evaluate -> regress (module docstring).

    Args:
        policy: the starting policy, an SB3 checkpoint spec (``dv2s-ppo``, ``ppo:PATH``, a run folder).
        rounds: rounds to have finished when it returns (a resumed loop runs only the missing ones).
        out: the loop folder (resumable).
        bank_dir: a writable bank to grow (default: a copy of the shipped bank in ``out/bank``).
        budget / sampler: the miner's episodes per round and its sampler.
        fine_tune_steps: env steps of fine-tuning per round.
        fine_tune_lr: the fine-tuning's (constant) learning rate (``None``: the method's,
            :data:`METHOD_LEARNING_RATES`).
        holdout_fraction: share of the round's mined clusters held out from fine-tuning.
        k_eval: evaluation seeds per held-out scenario.
        regress_episodes: seeds per starting-bank scenario in the regression test.
        mined_share: probability of drawing a mined fine-tuning scenario during fine-tuning.
        fine_tune_reward: reward-term weights overriding the policy's own in the fine-tuning env
            only (``None``: ``DEFAULTS["fine_tune_reward"]``; ``{}``: the policy's reward unchanged);
            used by the ``ppo`` method only (imitation has no reward).
        fine_tune_method: ``ppo`` or ``dagger`` (:data:`FINE_TUNE_METHODS`).
        margin: the regression test's non-inferiority margin.
        seed: seeds the miner, the split and the fine-tuning (each round derives its own).
        workers: processes for mining and evaluation (default: every core).
        scenarios: the scenarios mined and regression-tested (default: the starting bank's).
        n_envs: training environments (subprocesses).
        mine_options: extra keyword arguments for :func:`~dv2s_gym.mining.miner.mine`.
        miner: the mining function (default :func:`dv2s_gym.mining.miner.mine`; tests pass a stand-in).

    Returns:
        A :class:`LoopReport`; the reports are written to ``out`` after every round.
    """
    for name, value, low in (("rounds", rounds, 1), ("budget", budget, 1), ("fine-tune-steps", fine_tune_steps, 1),
                             ("k-eval", k_eval, 1), ("regress-episodes", regress_episodes, 1)):
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise LoopError(f"--{name} must be an integer >= {low}, not {value!r}")
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
                "workers": workers, "n_envs": n_envs, "env_config": env_config,
                "fine_tune_env_config": fine_tune_config}
    state = _State(out / "loop.json", settings)
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
            current = record.get("new_policy") or current
            continue
        log(f"round {number}: policy {current}")

        def timed(step: str, function: Callable[[], Any]) -> Any:
            began = time.perf_counter()
            value = function()
            timings[step] = round(time.perf_counter() - began, 1)  # of the run that finished the step
            steps[step] = value
            state.save()
            return value

        if "mine" not in steps:
            def do_mine() -> Dict[str, Any]:
                options = {"sampler": sampler, "scenarios": start_names, "bank_dir": bank, "workers": workers,
                           "seed": seed * 1000 + number, "progress": progress, "env_config": env_config,
                           "convert": True, **dict(mine_options or {})}
                miner(current, out=str(round_dir / "mine"), budget=budget, **options)
                return {**_mining_summary(round_dir / "mine"), "kept": mined_entries(round_dir / "mine"),
                        "folder": str(round_dir / "mine")}

            timed("mine", do_mine)
            log(f"round {number}: mined {steps['mine']['failures']} failures in {steps['mine']['episodes']} episodes, "
                f"{len({e['scenario'] for e in steps['mine']['kept']})} scenarios kept")
        if "split" not in steps:
            timed("split", lambda: _split(steps["mine"]["kept"], holdout_fraction, seed * 1000 + number))
        split = steps["split"]
        held_out, tuned = split["held_out"], split["fine_tune"]
        if not tuned and not held_out:
            steps["skipped"] = "no mined scenario was kept this round: nothing to fine-tune on or to measure"
            state.save()
            log(f"round {number}: {steps['skipped']}")
            _write(out, state, current)
            continue

        from dv2s_gym.mining.heldout import HeldOutStore, evaluate_heldout, paired_summary
        from policies.training import EVAL_SEED_BASE

        episodes = [(name, EVAL_SEED_BASE + i) for name in held_out for i in range(k_eval)]
        store_path = round_dir / "heldout.jsonl"
        if "before" not in steps:
            timed("before", lambda: {"episodes": len(episodes), "done": bool(evaluate_heldout(
                "before", current, episodes, store=HeldOutStore(store_path), bank_dir=bank, env_config=env_config,
                workers=workers, progress=progress))})
        if "fine_tune" not in steps:
            def do_fine_tune() -> Dict[str, Any]:
                from scenario_bank.bank import Bank

                excluded = set(held_out)
                for earlier in state.data["rounds"][:number - 1]:
                    excluded.update((earlier.get("steps", {}).get("split") or {}).get("held_out", []))
                entries = [e for e in Bank(bank) if e.name not in excluded]
                names = sorted(e.name for e in entries)
                mined = [e.name for e in entries if e.source.get("kind") == "mined"]
                weights = fine_tune_weights(names, mined, mined_share)
                if fine_tune_method == "dagger":
                    from policies.dagger_checkpoint import checkpoint_position, describe_position
                    from policies.imitation import DAGGER_DEFAULTS, dagger_fine_tune
                    from policies.registry import read_model_card

                    position = checkpoint_position(round_dir / "policy")
                    if position is not None:
                        log(f"round {number}: fine-tune (dagger) resumed from "
                            f"{describe_position(*position, DAGGER_DEFAULTS['iterations'])}")
                    path = dagger_fine_tune(current, bank_dir=bank, out=round_dir / "policy", steps=fine_tune_steps,
                                            weights=weights, seed=seed * 1000 + number, n_envs=n_envs,
                                            env_config=env_config, learning_rate=fine_tune_lr,
                                            progress_bar=progress, log=log)
                    dagger = read_model_card(path).get("fine_tune") or {}
                    return {"model": str(path.resolve()), "method": "dagger", "scenarios": len(names),
                            "mined_upweighted": len(mined), "steps": fine_tune_steps, "reward_weights": None,
                            "env_config": env_config, "reference": dagger.get("reference"),
                            "agreement": dagger.get("agreement"), "resumed": dagger.get("resumed") or []}
                from policies.training import fine_tune

                path = fine_tune(current, bank_dir=bank, out=round_dir / "policy", steps=fine_tune_steps,
                                 weights=weights, seed=seed * 1000 + number, n_envs=n_envs, env_config=env_config,
                                 reward_weights=fine_tune_reward, progress_bar=progress, learning_rate=fine_tune_lr,
                                 log=log)
                return {"model": str(path.resolve()), "method": "ppo", "scenarios": len(names),
                        "mined_upweighted": len(mined), "steps": fine_tune_steps,
                        "reward_weights": dict(fine_tune_reward), "env_config": fine_tune_config}

            timed("fine_tune", do_fine_tune)
        from policies.training import resolve_checkpoint

        new_policy = f"{resolve_checkpoint(steps['fine_tune']['model'])[0]}:{steps['fine_tune']['model']}"
        record["new_policy"] = new_policy
        if "after" not in steps:
            def do_after() -> Dict[str, Any]:
                store = HeldOutStore(store_path)
                before = evaluate_heldout("before", current, episodes, store=store, bank_dir=bank,
                                          env_config=env_config, workers=workers, progress=False)
                after = evaluate_heldout("after", new_policy, episodes, store=store, bank_dir=bank,
                                         env_config=env_config, workers=workers, progress=progress)
                return paired_summary(before, after, seed=seed)

            timed("after", do_after)
        if "regress" not in steps:
            def do_regress() -> Dict[str, Any]:
                from dv2s_gym.regress.runner import run_regression

                report = run_regression(new_policy, current, bank_dir=bank, scenarios=start_names,
                                        episodes=regress_episodes, seed=EVAL_SEED_BASE, margin=margin,
                                        workers=workers, out_dir=round_dir / "regress", env_config=env_config,
                                        progress=progress)
                return _regress_summary(report, round_dir / "regress" / "report.json")

            timed("regress", do_regress)
        _log_round(log, number, steps)
        current = new_policy
        _write(out, state, current)
    return _write(out, state, current)


def _split(kept: Sequence[Mapping[str, Any]], fraction: float, seed: int) -> Dict[str, Any]:
    from dv2s_gym.mining.split import split_by_cluster

    return split_by_cluster(kept, fraction, seed)


def _log_round(log: Callable[[str], None], number: int, steps: Mapping[str, Any]) -> None:
    after = steps.get("after") or {}
    if after.get("pairs"):
        b, a = after["before"], after["after"]
        drop = after.get("relative_drop")
        log(f"round {number}: held-out failure rate {b['rate']:.2f} [{b['low']:.2f}, {b['high']:.2f}] -> "
            f"{a['rate']:.2f} [{a['low']:.2f}, {a['high']:.2f}]"
            + (f", relative drop {drop:.0%}" if drop is not None else "")
            + f", McNemar p = {after['mcnemar_p']:.3g}")
    regress = steps.get("regress") or {}
    log(f"round {number}: rest of the bank: {regress.get('verdict')} ({regress.get('reason')})")


def _write(out: Path, state: _State, current: str) -> LoopReport:
    from dv2s_gym.mining.loop_report import write_loop_reports

    report = LoopReport(out=out, rounds=state.data["rounds"], policy=current, paths={}, settings=state.data["settings"])
    report.paths = write_loop_reports(report.to_json(), out)
    return report
