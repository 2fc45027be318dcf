"""Re-run only the fine-tuning half of a finished ``dv2s loop`` round with other fine-tuning settings.

    python -m bench.research.loop_finetune_sweep --loop out/loop-seed0 --name s03_100k --steps 100000 \\
        --reward '{"standing": -0.3}' --regress
    python -m bench.research.loop_finetune_sweep --loop out/loop-seed0 --name dagger_40k --method dagger --steps 40000 \
        --lr 3e-4 --regress
    python -m bench.research.loop_finetune_sweep --loop out/loop-seed0 --name dagger_w3 --method dagger --steps 40000 \
        --lr 1e-3 --epochs 8 --slower-weight 3 --regress

Reuses the round-1 mining run, working bank and split of ``--loop`` (so settings are
compared on the same held-out episodes; a by-family split also keeps every member of a held-out family, its
parent scenario included, out of the fine-tuning, as the loop does: the scenario draw is the loop's own
:func:`dv2s_gym.loop.arms.arm_weights`), evaluates the starting policy on the held-out scenarios
once (cached in ``OUT/before.jsonl``), fine-tunes exactly as the loop does
(``--method ppo``: :func:`policies.training.fine_tune`; ``--method dagger``:
:func:`policies.imitation.dagger_fine_tune`; the loop's weights from
:func:`dv2s_gym.loop.arms.fine_tune_weights`, seed ``loop seed * 1000 + 1``, 2 subprocess envs),
evaluates the fine-tuned policy on the same episodes (paired, the policy's own env config) and,
with ``--regress``, regression-tests it against the starting policy on the starting bank
(``--regress-episodes`` seeds per scenario from 10000). Prints one JSON line and appends it to
``OUT/results.jsonl``. This is how the loop's fine-tuning settings were chosen on seed 0
(bench/RESULTS.md); a choice is confirmed only by a fresh ``dv2s loop`` on another seed. When the loop's
round ran a control arm, the result also pairs the new fine-tune with the control's held-out episodes
(``vs_control``: the table and exact McNemar p), the loop's own fine-tuned arm beside it.

``--control`` fine-tunes the CONTROL arm with the given settings instead: the same fine-tuning without the mined
scenarios, exactly as the loop's control arm is drawn (``arm_weights(..., with_mined=False)``). Two finished
sweep arms are paired on the held-out episodes by ``python -m bench.research.loop_sweep_pair``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--loop", required=True, help="a dv2s loop folder whose round 1 finished its split")
    parser.add_argument("--out", default="out/loop-sweep", help="where the sweep's runs go")
    parser.add_argument("--name", required=True, help="this setting's folder under --out")
    parser.add_argument("--steps", type=int, default=40_000)
    parser.add_argument("--lr", type=float, default=1e-4)
    parser.add_argument("--share", type=float, default=0.5, help="mined share")
    parser.add_argument("--reward", default="{}", help="fine-tuning reward-term overrides (JSON)")
    parser.add_argument("--method", choices=["ppo", "dagger"], default="ppo", help="the loop's --fine-tune-method")
    parser.add_argument("--iterations", type=int, default=None, help="DAgger iterations (default: its own)")
    parser.add_argument("--epochs", type=int, default=None, help="DAgger epochs per iteration (default: its own)")
    parser.add_argument("--beta-decay", type=float, default=None, help="DAgger mixture decay (default: its own)")
    parser.add_argument("--slower-weight", type=float, default=None,
                        help="DAgger: weight of the reference's SLOWER labels in the cross-entropy (default: its own, 3; "
                             "1 is unweighted)")
    parser.add_argument("--disagreement-weight", type=float, default=None,
                        help="DAgger: weight of the states where the collecting student's greedy action was not the "
                             "reference's label (default: its own, 1: unweighted)")
    parser.add_argument("--control", action="store_true",
                        help="fine-tune the loop's CONTROL arm instead: the same fine-tuning without the mined "
                             "scenarios, built as the loop builds its control (--share then has no effect)")
    parser.add_argument("--regress", action="store_true")
    parser.add_argument("--regress-episodes", type=int, default=4)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--train-seed", type=int, default=None,
                        help="the fine-tuning's seed (default: the loop's own, loop seed * 1000 + 1): another value "
                        "trains the same arm again, to see how far two runs of one recipe differ")
    args = parser.parse_args()

    from dv2s_gym.loop.heldout import HeldOutStore, evaluate_heldout, failure_types, paired_summary
    from dv2s_gym.workers.settings import WorkerSettings
    from dv2s_gym.loop.arms import arm_weights
    from dv2s_gym.loop.state import IN_FOLDER
    from policies.training import EVAL_SEED_BASE, TrainConfig, fine_tune

    loop = Path(args.loop)
    state = json.loads((loop / "loop.json").read_text(encoding="utf-8"))
    settings, steps = state["settings"], state["rounds"][0]["steps"]
    held = steps["split"]["held_out"]
    # loop.json writes paths inside the loop folder relative to it (a moved loop folder resumes)
    inside = lambda value: value.replace(f"{IN_FOLDER}/", f"{loop.resolve()}/")  # noqa: E731
    bank = inside(state["start"]["bank"])
    policy, env_config = inside(settings["policy"]), dict(settings["env_config"])
    episodes = [(name, EVAL_SEED_BASE + i) for name in held for i in range(settings["k_eval"])]
    base = Path(args.out)
    began = time.perf_counter()
    loop_store = loop / "round_1" / "heldout.jsonl"
    cached = HeldOutStore(loop_store) if loop_store.is_file() else None
    if cached is not None and all(cached.get("before", name, seed) for name, seed in episodes):
        before_store = cached  # the loop's own episodes of the starting policy: nothing runs again
    else:
        before_store = HeldOutStore(base / "before.jsonl")
    before = evaluate_heldout("before", policy, episodes, store=before_store, bank_dir=bank,
                              env_config=env_config,
                             workers=WorkerSettings(workers=args.workers), progress=False)
    t_before = time.perf_counter() - began
    excluded = set(held) | set(steps["split"].get("held_out_families") or [])
    out = base / args.name
    began = time.perf_counter()
    # the loop's own scenario draw for its fine-tuned arm, or with --control for its control arm (the mined
    # scenarios left out, every other scenario drawn uniformly)
    weights, _ = arm_weights(bank, excluded, args.share, with_mined=not args.control)
    def fine_tune_log(line: str) -> None:
        print(line, file=sys.stderr, flush=True)
    config = TrainConfig.fine_tuning(out / "policy", steps=args.steps, weights=weights, bank_dir=bank,
                                     seed=settings["seed"] * 1000 + 1 if args.train_seed is None else args.train_seed, n_envs=2, env_config=env_config,
                                     progress_bar=False)
    if args.method == "dagger":
        from policies.imitation import DaggerConfig, dagger_fine_tune

        extra = {key: getattr(args, key) for key in ("iterations", "epochs", "beta_decay", "slower_weight",
                                                             "disagreement_weight")
                 if getattr(args, key) is not None}
        if args.lr is not None:
            extra["learning_rate"] = args.lr
        path = dagger_fine_tune(policy, config, DaggerConfig(**extra), log=fine_tune_log)
    else:
        config = dataclasses.replace(config, reward_weights=json.loads(args.reward) or None, learning_rate=args.lr)
        path = fine_tune(policy, config, log=lambda _: None)
    t_fine_tune = time.perf_counter() - began
    spec = f"ppo:{path.resolve()}"
    began = time.perf_counter()
    after = evaluate_heldout("after", spec, episodes, store=HeldOutStore(out / "heldout.jsonl"), bank_dir=bank,
                             env_config=env_config,
                             workers=WorkerSettings(workers=args.workers), progress=False)
    t_after = time.perf_counter() - began
    summary = paired_summary(before, after, seed=settings["seed"]).to_dict()
    result = {"name": args.name, "args": vars(args), "before": summary["before"], "after": summary["after"],
              "drop": summary["relative_drop"], "drop_interval": summary["relative_drop_interval"],
              "mcnemar_p": summary["mcnemar_p"], "table": summary["table"], "types_before": failure_types(before),
              "types_after": failure_types(after), "seconds": {"before": round(t_before, 1),
                                                              "fine_tune": round(t_fine_tune, 1),
                                                              "after": round(t_after, 1)}}
    if loop_store.is_file():  # the loop's own control arm (and fine-tuned arm) on the same episodes
        store = HeldOutStore(loop_store)
        for role in ("control", "after"):
            records = [store.get(role, name, seed) for name, seed in episodes]
            if all(r is not None for r in records):
                versus = paired_summary(records, after, seed=settings["seed"], bootstrap=0).to_dict()
                result[f"vs_loop_{role}"] = {"loop_rate": versus["before"], "table": versus["table"],
                                             "mcnemar_p": versus["mcnemar_p"]}
    if args.method == "dagger":
        from policies.registry import read_model_card

        tuned = read_model_card(path).fine_tune
        section = tuned.to_dict() if tuned is not None else {}
        result["dagger"] = {key: value for key, value in section.items()
                            if key in ("agreement", "history", "iterations", "epochs", "beta_decay", "learning_rate")}
    if args.regress:
        from dv2s_gym.regress.runner import RegressSettings, WorkerSettings, run_regression

        began = time.perf_counter()
        regress = RegressSettings(bank_dir=bank, scenarios=state["start"]["scenarios"], episodes=args.regress_episodes,
                                  seed=EVAL_SEED_BASE, margin=settings["margin"], env_config=env_config)
        report = run_regression(spec, policy, regress, workers=WorkerSettings(workers=args.workers),
                                out_dir=out / "regress", progress=False).to_dict()
        overall = report["overall"]
        result["regress"] = {"verdict": report["verdict"], "new": overall["candidate"]["failure_rate"],
                             "old": overall["baseline"]["failure_rate"],
                             "difference": overall["comparison"].get("difference"),
                             "reason": overall["comparison"].get("reason")}
        result["seconds"]["regress"] = round(time.perf_counter() - began, 1)
    line = json.dumps(result, default=str)
    print(line)
    base.mkdir(parents=True, exist_ok=True)
    with open(base / "results.jsonl", "a", encoding="utf-8") as handle:
        handle.write(line + "\n")


if __name__ == "__main__":
    main()
