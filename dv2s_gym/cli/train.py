"""``dv2s train``: a stable-baselines3 policy trained on the bank (checkpoints, TensorBoard, model card)."""

from __future__ import annotations

import argparse

from dv2s_gym.cli.errors import UsageError
from dv2s_gym.cli.inputs import (WEIGHTS, WEIGHTS_EXAMPLE, env_config_option, json_option, json_value, output_folder,
                                  seed_value)
from dv2s_gym.cli.parser import bank_option
from dv2s_gym.progress_lines import log_line

__all__ = ["add_parser", "run"]


def add_parser(subparsers) -> None:
    """Add ``train`` to the ``dv2s`` subcommands."""
    p = subparsers.add_parser("train", help="train a PPO/DQN/SAC policy on the bank (checkpoints, TensorBoard, model card)",
                              description="Train a stable-baselines3 policy on DV2S-v0 over bank scenarios, in parallel "
                              "subprocess envs. Writes checkpoints/, tb/ (TensorBoard), evaluations.jsonl, model.zip and "
                              "model_card.json (+ README.md) in --out; --resume continues the newest checkpoint there. "
                              "Held-out evaluation uses seeds 10000+ per scenario; training never does.")
    p.add_argument("--algo", choices=["ppo", "dqn", "sac"], help="algorithm (default ppo; SAC trains with ContinuousAction)")
    bank_option(p)
    p.add_argument("--scenarios", nargs="*", metavar="NAME", help="bank names or tag:<tag> (default: the whole bank)")
    p.add_argument("--steps", type=int, help="total env steps to train to, across resumes (default 100000)")
    p.add_argument("--envs", type=int, help="environments in parallel subprocesses (default 2)")
    p.add_argument("--seed", type=seed_value, help="seed of the model and the training episodes (default 0)")
    p.add_argument("--out", required=True, type=output_folder, help="run folder")
    p.add_argument("--sampler", choices=["uniform", "weighted", "curriculum"],
                   help="scenario of each episode: uniform (default), weighted (--weights) or curriculum "
                   "(upweights the scenarios the policy fails)")
    p.add_argument("--weights", help='JSON object scenario -> weight for --sampler weighted, or a .json file')
    p.add_argument("--curriculum-floor", type=float, help="curriculum: share spread uniformly (default 0.25)")
    p.add_argument("--curriculum-window", type=int, help="curriculum: episodes remembered per scenario (default 20)")
    p.add_argument("--curriculum-update", type=int, help="curriculum: env steps between updates (default 1000)")
    p.add_argument("--config", help="JSON object of DV2S-v0 config overrides (e.g. reward_weights), or a .json file")
    p.add_argument("--hp", action="append", metavar="KEY=VALUE",
                   help="algorithm hyperparameter (repeatable; JSON values), e.g. --hp learning_rate=3e-4 --hp 'net_arch=[64,64]'")
    p.add_argument("--eval-freq", type=int, help="held-out evaluation every N env steps, 0 = off (default 10000)")
    p.add_argument("--eval-seeds", type=int, help="seeds per scenario of the periodic evaluation (default 2)")
    p.add_argument("--card-seeds", type=int, help="seeds per scenario of the model card's evaluation, 0 = none "
                   "(default 20, or 3 for runs under 100000 steps)")
    p.add_argument("--baselines", nargs="*", metavar="POLICY",
                   help="policies evaluated on the card's episodes for paired comparisons (default: keep_lane rule)")
    p.add_argument("--eval-jobs", type=int, help="processes for the card's evaluation (default 2)")
    p.add_argument("--checkpoint-freq", type=int, help="checkpoint every N env steps, 0 = only at the end (default 10000)")
    p.add_argument("--resume", action="store_true", help="continue the run in --out from its newest checkpoint")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--vec-env", choices=["subproc", "dummy"], default="subproc",
                   help="subproc: envs in worker processes (default); dummy: in this process")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Train (or resume) the run in ``--out``; progress lines go to stderr."""
    from policies.training import TrainingError, run_settings, train

    given = {
        "algo": args.algo, "scenarios": args.scenarios, "bank_dir": getattr(args, "bank", None), "seed": args.seed,
        "sampler": args.sampler, "weights": json_option(args.weights, "--weights", WEIGHTS, WEIGHTS_EXAMPLE),
        "env_config": env_config_option(args.config), "steps": args.steps, "n_envs": args.envs,
        "eval_freq": args.eval_freq, "eval_seeds": args.eval_seeds, "card_seeds": args.card_seeds,
        "baselines": args.baselines, "eval_jobs": args.eval_jobs, "checkpoint_freq": args.checkpoint_freq,
        "curriculum_floor": args.curriculum_floor, "curriculum_window": args.curriculum_window,
        "curriculum_update": args.curriculum_update, "progress_bar": not args.no_progress, "vec_env": args.vec_env,
    }
    if args.hp:
        hyperparameters = {}
        for pair in args.hp:
            key, sep, value = pair.partition("=")
            if not sep or not key:
                raise TrainingError(f"--hp {pair!r} is not KEY=VALUE (e.g. --hp learning_rate=3e-4)")
            try:
                hyperparameters[key] = json_value(value, f"--hp {key}", "a JSON value or a word")
            except UsageError:
                hyperparameters[key] = value  # a word (e.g. --hp activation=tanh)
        given["hyperparameters"] = hyperparameters
    train(run_settings(args.out, given, resume=args.resume), resume=args.resume, log=log_line)
    return 0
