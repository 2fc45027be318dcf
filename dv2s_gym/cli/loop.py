"""``dv2s loop``: closed-loop failure mining: mine, add to the bank, fine-tune, measure, round after round."""

from __future__ import annotations

import argparse
import json
from typing import Any, List, Mapping, Optional

from dv2s_gym.cli.errors import UsageError
from dv2s_gym.cli.parser import bank_option

__all__ = ["add_parser", "run"]


EPILOG = """\
exit status (the verdict on the last round's fine-tuned policy; the summary names the policy to use):
  0  ACCEPTED: its regression test on the rest of the bank PASSed and the control did not beat it
     on the held-out scenarios: use it
  1  REJECTED: it regressed on the rest of the bank, the control beat it, or over several rounds it
     regressed against the starting policy: keep the last accepted policy, else the starting one
  3  NOT ACCEPTED: the regression test was INCONCLUSIVE or in ERROR, or no round fine-tuned a policy
  2  bad input; 130 interrupted

examples:
  dv2s loop                                   # one round on dv2s-ppo, out/loop
  dv2s loop --budget 400 --fine-tune-steps 100000 --k-eval 10 --out out/loop-big
  dv2s loop --policy ppo:out/train/my_ppo/model.zip --rounds 3"""
"""The end of ``dv2s loop --help``: what the exit status says, and examples."""


def add_parser(subparsers) -> None:
    """Add ``loop`` to the ``dv2s`` subcommands."""
    from dv2s_gym.mining.loop import DEFAULTS as LOOP
    from dv2s_gym.mining.loop_settings import LoopSettings

    p = subparsers.add_parser("loop", help="mine a policy's failures, add them to the bank, fine-tune, measure (a round "
                              "on embedded defaults that keeps scenarios took 45-55 minutes on 2 cores; --budget and "
                              "--max-replays shorten it)",
                              formatter_class=argparse.RawDescriptionHelpFormatter,
                              description="Closed-loop failure mining. Each round: mine the policy's failures (dv2s mine) "
                              "into new bank scenarios in a working bank (a copy of the shipped bank in the bank folder of --out, out/loop/bank by default; or --bank), "
                              "split them by family (parent bank scenario) into a fine-tuning and a held-out part, "
                              "evaluate the policy on the held-out scenarios (seeds 10000+), fine-tune it on the grown bank "
                              "minus the held-out scenarios and their parents (mined ones upweighted), fine-tune a control "
                              "the same way without any mined scenario, evaluate both on the same episodes (paired: "
                              "relative drop, exact McNemar against the start and against the control), run all three on "
                              "an untouched scenario set (Scenic's CARLA examples) and regression-test new against old on "
                              "the starting bank (dv2s regress statistics). Writes report.json, report.md, report.html to --out; rerunning with the same "
                              "--out and settings resumes (raise --rounds to add rounds).",
                              epilog=EPILOG)
    p.add_argument("--policy", default="dv2s-ppo", help="starting policy: an SB3 checkpoint spec (default dv2s-ppo)")
    p.add_argument("--rounds", type=int, default=LOOP["rounds"], help=f"rounds (default {LOOP['rounds']})")
    bank_option(p)
    p.add_argument("--scenarios", nargs="+", help="scenarios mined and regression-tested (default: the whole bank)")
    p.add_argument("--budget", type=int, default=LOOP["budget"],
                   help=f"mining episodes per round (default {LOOP['budget']})")
    p.add_argument("--sampler", default=LOOP["sampler"], help=f"the miner's sampler: random, halton, cross-entropy, "
                   f"bandit, split or novelty-bandit (default {LOOP['sampler']}; see dv2s mine --help)")
    p.add_argument("--fine-tune-steps", type=int, default=LOOP["fine_tune_steps"],
                   help=f"env steps of fine-tuning per round (default {LOOP['fine_tune_steps']})")
    p.add_argument("--fine-tune-lr", type=float, default=LOOP["fine_tune_lr"],
                   help="learning rate of the fine-tuning (default: the method's, ppo 1e-4, dagger 1e-3)")
    p.add_argument("--holdout-fraction", type=float, default=LOOP["holdout_fraction"],
                   help=f"share of the mined families (parent scenarios) held out (default {LOOP['holdout_fraction']})")
    p.add_argument("--max-conversions", default=str(LOOP["max_conversions"]),
                   help="failure clusters converted into bank scenarios per round, largest first; 0 for none, 'all' "
                   f"for every cluster (default {LOOP['max_conversions']})")
    p.add_argument("--max-replays", default=str(LOOP["max_replays"]),
                   help="failure clusters beyond the converted ones whose failing scene is kept as an exact replay "
                   "entry (the parent scenario narrowed around the failure, checked to replay it step for step) per "
                   f"round, largest first; 0 for none, 'all' for every cluster (default {LOOP['max_replays']})")
    p.add_argument("--min-heldout-episodes", type=int, default=LOOP["min_heldout_episodes"],
                   help="below this many held-out episodes a round reports rates only, no drop and no test "
                   f"(default {LOOP['min_heldout_episodes']})")
    p.add_argument("--min-heldout-families", type=int, default=LOOP["min_heldout_families"],
                   help="below this many held-out scenario families a round reports rates only, no drop and no "
                   f"test (default {LOOP['min_heldout_families']})")
    p.add_argument("--no-control", action="store_true",
                   help="skip the control arm (the same fine-tuning without the mined scenarios)")
    p.add_argument("--untouched-seeds", type=int, default=LOOP["untouched_seeds"],
                   help="seeds per scenario of the untouched set the loop never mines or fine-tunes on; 0 skips it "
                   f"(default {LOOP['untouched_seeds']})")
    p.add_argument("--k-eval", type=int, default=LOOP["k_eval"],
                   help=f"evaluation seeds per held-out scenario (default {LOOP['k_eval']})")
    p.add_argument("--regress-episodes", type=int, default=LOOP["regress_episodes"],
                   help=f"seeds per scenario of the regression test (default {LOOP['regress_episodes']})")
    p.add_argument("--mined-share", type=float, default=LOOP["mined_share"],
                   help=f"probability of a mined scenario in fine-tuning (default {LOOP['mined_share']})")
    p.add_argument("--fine-tune-reward", default=None, metavar="JSON",
                   help="reward-term weights overriding the policy's own during fine-tuning only, e.g. "
                   f"'{{\"standing\": -1.0, \"low_ttc\": -0.4}}' (default {json.dumps(LOOP['fine_tune_reward'])}; "
                   "'{}' keeps the policy's reward; evaluation always uses the policy's own env config)")
    p.add_argument("--fine-tune-method", choices=["ppo", "dagger"], default=LOOP["fine_tune_method"],
                   help="ppo: continue PPO on the fine-tuning reward; dagger: imitate the rule-based reference "
                   "driver on the policy's own states (DAgger; --fine-tune-reward unused) "
                   f"(default {LOOP['fine_tune_method']})")
    p.add_argument("--margin", type=float, default=LOOP["margin"],
                   help=f"the regression test's non-inferiority margin (default {LOOP['margin']})")
    p.add_argument("--seed", type=int, default=LOOP["seed"], help=f"seed (default {LOOP['seed']})")
    p.add_argument("--workers", type=int, default=None, help="processes for mining and evaluation (default: every core)")
    p.add_argument("--envs", type=int, default=LoopSettings.n_envs,
                   help=f"training environments (default {LoopSettings.n_envs})")
    p.add_argument("--out", default=None, help="loop folder (default out/loop; rerunning resumes it)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run (or resume) the loop in ``--out``; print a summary, the verdict and the report paths. The exit status
    is the verdict's (:data:`EPILOG`)."""
    from dv2s_gym.mining.loop import DEFAULT_OUT, LoopSettings, run_loop

    options = {key: getattr(args, key) for key in ("rounds", "budget", "sampler", "fine_tune_steps", "fine_tune_lr",
                                                    "holdout_fraction", "k_eval", "regress_episodes", "mined_share",
                                                    "margin", "seed", "workers", "scenarios",
                                                    "fine_tune_method", "max_conversions", "min_heldout_episodes", "min_heldout_families",
                                                    "untouched_seeds")}
    for flag in ("max_conversions", "max_replays"):
        options[flag] = _count_or_all(getattr(args, flag), "--" + flag.replace("_", "-"))
    options["control"] = not args.no_control
    if args.fine_tune_reward is not None:
        try:
            options["fine_tune_reward"] = json.loads(args.fine_tune_reward)
        except ValueError as error:
            raise UsageError(f"--fine-tune-reward must be a JSON object of reward-term weights, e.g. "
                             f"'{{\"standing\": -1.0}}'; {error}") from None
        if not isinstance(options["fine_tune_reward"], dict):
            raise UsageError("--fine-tune-reward must be a JSON object of reward-term weights, e.g. "
                             "'{\"standing\": -1.0}' ('{}' keeps the policy's own reward)")
    out = args.out or DEFAULT_OUT
    settings = LoopSettings(bank_dir=getattr(args, "bank", None), n_envs=args.envs, **options)
    report = run_loop(args.policy, settings, out=out, progress=not args.no_progress)
    print("\n".join(summary_lines({**report.to_json(), "recommendation": report.recommendation}, report.paths)))
    return int(report.recommendation["exit_code"])


def summary_lines(report: Mapping[str, Any], paths: Mapping[str, Any]) -> List[str]:
    """The terminal's summary of a finished loop: one line per round, the verdict, where the reports are."""
    from dv2s_gym.mining.loop_report import round_summary

    lines = [round_summary(record) for record in report.get("rounds") or []]
    verdict = report.get("recommendation") or {}
    lines += ["", f"verdict: {verdict.get('sentence')}", f"recommended policy: {verdict.get('policy')}"]
    lines += [f"report ({kind}): {paths[kind]}" for kind in ("html", "md", "json") if kind in paths]
    return lines


def _count_or_all(value: str, flag: str) -> Optional[int]:
    """A ``--max-...`` value: a whole number of clusters, or ``None`` for ``all``."""
    if value == "all":
        return None
    try:
        return int(value)
    except ValueError:
        raise UsageError(f"{flag} must be a whole number of clusters or 'all', not {value!r}") from None
