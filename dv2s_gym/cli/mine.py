"""``dv2s mine``: a policy's failures found by sampling scenes, clustered and turned into bank scenarios."""

from __future__ import annotations

import argparse
from pathlib import Path

from dv2s_gym.cli.backend_options import dra_option, sg_option, worker_backend_option
from dv2s_gym.cli.inputs import env_config_option, json_option, llm_config, output_folder, seed_value
from dv2s_gym.cli.interrupts import episodes_kept_note
from dv2s_gym.cli.parser import bank_option, llm_options
from dv2s_gym.mining.conversion.settings import ConversionSettings
from dv2s_gym.mining.sampling.samplers import SAMPLERS, registered_samplers
from dv2s_gym.mining.settings import FEEDBACKS, MineSettings
from dv2s_gym.registered_names import RegisteredNames
from dv2s_gym.workers.settings import WorkerSettings
from envs.errors import Interrupted

__all__ = ["add_parser", "run"]

MINE = MineSettings()
"""The defaults of every mining option."""


def add_parser(subparsers) -> None:
    """Add ``mine`` to the ``dv2s`` subcommands."""
    p = subparsers.add_parser(
        "mine", help="mine a policy's failures: sample scenes, cluster failures, turn them into bank scenarios",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Sample scenes (a bank scenario and values of its Scenic parameters, drawn by a sampler "
        "that learns from the outcomes: by default novelty-bandit, which favours scenarios and behaviours not yet "
        "seen; --sampler picks VerifAI's or uniform ones), run the policy on each in a local process pool or on Ray, and "
        "detect failures: collision (with whom, and how), off road, time-to-collision under a threshold, stall. "
        "Failures are clustered by scenario family (a mined or replay entry counts with the bank scenario it "
        "came from), failure class, the other actor's manoeuvre and the ego's; a failure counts "
        "against the policy only if the reference driver avoids it in the same scene. With a writable --bank, "
        "one failure per cluster is kept exactly (its parent scenario narrowed around the failing parameters, "
        "with its seed: a 'replay' entry), and is recorded as a bird's-eye video, turned into a Scenic scenario by "
        "the D-V2S pipeline, checked in the sandbox, kept if its runs show the failure's actor and manoeuvre, the "
        "policy fails on it the same way and the reference driver drives it without any collision, off-road "
        "or stall, and added to the bank with its "
        "provenance. Rerunning with the same --out resumes (a larger --budget continues the run).",
        epilog="examples:\n"
        "  dv2s mine --policy dv2s-ppo --budget 200 --bank my_bank --out out/mine\n"
        "  dv2s mine --policy rule --sampler halton --scenarios tag:highway --budget 500 --no-convert\n"
        "  dv2s mine --policy dv2s-ppo --backend ray --address HEAD:6379 --budget 5000 --bank /shared/bank")
    p.add_argument("--policy", required=True, help="policy spec: rule, idm, keep_lane, random, dv2s-ppo, model.zip, "
                   "ppo:PATH, module:attr, with ?key=value options")
    bank_option(p)
    p.add_argument("--scenarios", nargs="+", help="bank names and/or tag:<tag> (default: the whole bank)")
    p.add_argument("--budget", type=int, default=MINE.budget, help=f"episodes to run (default {MINE.budget})")
    p.add_argument("--sampler", default=MINE.sampler,
                   choices=RegisteredNames(registered_samplers, SAMPLERS),
                   help=f"scene sampler (default {MINE.sampler}); split: VerifAI's cross-entropy over which scenario "
                   "and a Halton sequence per scenario over its parameters; novelty-bandit: the scenarios that keep "
                   "giving failures unlike earlier ones, once every scenario had a scene, mixed with uniform, parameters "
                   "uniform (explore, prior_new, prior_old, cover)")
    p.add_argument("--sampler-options", default=None,
                   help="VerifAI settings of cross-entropy/bandit as JSON: alpha (default 0.9), buckets (5), thres (0); "
                   "split also takes chooser (cross-entropy|ucb|epsilon-greedy), params (halton|random|bandit|cross-entropy) "
                   "warmup (0) and avoid (81: redraws past parameter cells that already failed; 0: off); novelty-bandit "
                   "takes explore (0.2), prior_new (2), prior_old (1) and cover (1: scenes of every scenario before "
                   "the scores rank them) (see dv2s_gym/mining/sampling/samplers.py)")
    p.add_argument("--feedback", choices=list(FEEDBACKS), default=None,
                   help="what adaptive samplers learn from: robustness (every failure), novelty (a failure in a "
                   "parameter cell that already failed counts as an easy scene, to spread the search) or "
                   "scenario-novelty (only each scenario's first failure counts) or state-novelty (a failure whose "
                   "speeds and geometry at the failure are close to an earlier one's in the scenario counts as easy) or "
                   "cluster-novelty (a failure in a behaviour cluster already found counts as easy); "
                   "default novelty for split, state-novelty for novelty-bandit, robustness for the others")
    p.add_argument("--seed", type=seed_value, default=MINE.seed,
                   help=f"seed of the sampler and the episodes (default {MINE.seed})")
    p.add_argument("--reference", default=MINE.reference,
                   help=f"driver deciding avoidability (default {MINE.reference}; 'none' skips the check)")
    p.add_argument("--ttc-threshold", type=float, default=MINE.ttc_threshold,
                   help=f"low-TTC failure threshold [s] (default {MINE.ttc_threshold:g})")
    p.add_argument("--stall-seconds", type=float, default=MINE.stall_seconds,
                   help="seconds standing with nothing in the lane 40 m ahead that count as a stall "
                   f"(default {MINE.stall_seconds:g})")
    worker_backend_option(p, help="local process pool or Ray")
    p.add_argument("--workers", type=int, default=None, help="worker processes (default: every core)")
    p.add_argument("--address", default=None, help="with --backend ray: the cluster address")
    p.add_argument("--timeout", type=float, default=None,
                   help="seconds one episode may take before its worker counts as hung (default 600)")
    p.add_argument("--batch", type=int, default=None,
                   help="scenes drawn ahead of the outcomes fed back to the sampler: the sliding window of an "
                        "adaptive sampler, the chunk of random/halton; with the seed it decides the run, whatever "
                        "the workers (default 8: raise it to keep more than 8 workers busy)")
    p.add_argument("--config", help="DV2S-v0 config overrides as JSON (or a .json file)")
    p.add_argument("--no-convert", action="store_true", help="only find and cluster failures; add nothing to a bank")
    p.add_argument("--max-conversions", type=int, default=None,
                   help="convert at most this many clusters, those with most avoidable failures first (default: all)")
    dra_option(p, help="DRA backend for failure videos")
    sg_option(p, help="SG backend")
    llm_options(p)
    p.add_argument("-k", type=int, default=10, dest="k",
                   help="scenes the new scenario is run on to check it reproduces the failure (default 10)")
    p.add_argument("--threshold", type=float, default=0.3,
                   help="reproduction rate a new scenario needs to be kept (default 0.3)")
    p.add_argument("--out", default=None, type=output_folder, help="run folder (default out/mine)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Mine the policy's failures and print the run's summary and reports."""
    from dv2s_gym.cli.name_checks import check_names

    check_names(policies=(args.policy, args.reference if args.reference != "none" else None),
                scenarios=args.scenarios, bank=args.bank, bank_names_only="dv2s mine")  # a typo is reported before the slow imports
    from dv2s_gym.mining.miner import mine

    env_config = env_config_option(args.config)
    out = Path(args.out or "out/mine")
    try:
        run = mine(args.policy, _settings(args, env_config), out=out, progress=not args.no_progress,
                   workers=WorkerSettings(backend=args.backend, workers=args.workers, address=args.address,
                                          timeout=args.timeout))
    except KeyboardInterrupt as stop:
        raise Interrupted(getattr(stop, "note", None) or episodes_kept_note(Path(out) / "episodes.jsonl")) from None
    print(run.summary())
    if run.reports:
        print(f"reports: {', '.join(str(p) for p in run.reports.values())}")
    return 1 if run.all_errored else 0


def _settings(args: argparse.Namespace, env_config) -> MineSettings:
    """The run's :class:`MineSettings` from the command line."""
    return MineSettings(
        budget=args.budget, sampler=args.sampler, scenarios=args.scenarios, bank_dir=args.bank, seed=args.seed,
        reference=None if args.reference == "none" else args.reference, batch=args.batch,
        env_config=env_config or {}, ttc_threshold=args.ttc_threshold, stall_seconds=args.stall_seconds,
        convert=not args.no_convert, max_conversions=args.max_conversions, feedback=args.feedback,
        sampler_options=json_option(args.sampler_options, "--sampler-options",
                                    "VerifAI settings as a JSON object (or a .json file holding one)",
                                    "'{\"alpha\": 0.9}'"),
        conversion=ConversionSettings(dra=args.dra, sg=args.sg, k=args.k, threshold=args.threshold,
                                      llm_config=llm_config(args)))
