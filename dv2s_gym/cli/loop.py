"""``dv2s loop``: closed-loop failure mining: mine, add to the bank, fine-tune, measure, round after round."""

from __future__ import annotations

import argparse
import dataclasses
import json
from typing import TYPE_CHECKING, Any, List, Optional

from dv2s_gym.cli.errors import UsageError
from dv2s_gym.cli.inputs import json_value, output_folder, seed_value
from dv2s_gym.cli.parser import bank_option
from dv2s_gym.loop.settings import DEFAULT_PROFILE, DEFAULTS, EVIDENCE, FINE_TUNE_METHODS, PROFILES, LoopSettings
from dv2s_gym.loop.verdict import EVIDENCE_FLOOR as FLOOR, HELDOUT_ALPHA as ALPHA

if TYPE_CHECKING:  # the loop itself loads the simulator and torch: not at the command line's start-up
    from dv2s_gym.loop.run import LoopReport

__all__ = ["add_parser", "run", "loop_settings"]


EPILOG = """\
exit status (the verdict on the last round's fine-tuned policy; the summary names the policy to use):
  0  ACCEPTED: its regression test on the rest of the bank PASSed, on the held-out families it is
     significantly worse neither than the starting policy nor than the control, no held-out family is
     worse for it by more than the margin (per-family harm rule), and on the untouched scenario set it
     did not FAIL against the starting policy: use it
  1  REJECTED: it regressed on the rest of the bank, it is significantly worse than the starting policy or
     the control on the held-out families, or over several rounds it regressed against the starting
     policy: keep the last accepted policy, else the starting one
  3  NOT ACCEPTED: the regression test was INCONCLUSIVE or in ERROR, the held-out tests could not run (too
     few held-out episodes or families, against the start or the control), a held-out family is worse for
     it by more than the margin (per-family harm rule), it FAILed against the starting policy on the
     untouched scenario set, or no round fine-tuned a policy
  2  bad input; 130 interrupted

examples:
  dv2s loop                                   # one quick round on dv2s-ppo, out/loop
  dv2s loop --profile evidence --out out/loop-evidence   # a round large enough to judge
  dv2s loop --profile evidence --rounds 3 --budget 400 --out out/loop-big   # options override the profile
  dv2s loop --policy ppo:out/train/my_ppo/model.zip --rounds 3"""
"""The end of ``dv2s loop --help``: what the exit status says, and examples."""


def add_parser(subparsers) -> None:
    """Add ``loop`` to the ``dv2s`` subcommands."""
    p = subparsers.add_parser("loop", help="mine a policy's failures, add them to the bank, fine-tune, measure (one round "
                              "on the embedded defaults, sized for about 5 minutes on 2 idle cores; --profile evidence for "
                              "a round large enough to judge)",
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
    p.add_argument("--profile", choices=list(PROFILES), default=DEFAULT_PROFILE,
                   help="the settings every option below defaults to: quick (the embedded defaults: a round sized for "
                   "about 5 minutes on 2 idle cores, too small to judge the fine-tuned policy) or evidence (a round large "
                   "enough to judge, about 25 minutes on 2 cores: " + ", ".join(f"--{k.replace('_', '-')} {v}"
                                                                    for k, v in EVIDENCE.items())
                   + "); options given explicitly override the profile's values")
    p.add_argument("--rounds", type=int, default=None, help=_default("rounds", "rounds"))
    bank_option(p)
    p.add_argument("--scenarios", nargs="+", help="scenarios mined and regression-tested (default: the whole bank)")
    p.add_argument("--budget", type=int, default=None, help=_default("budget", "mining episodes per round"))
    p.add_argument("--sampler", default=None, help=_default("sampler", "the miner's sampler: random, halton, "
                   "cross-entropy, bandit, split or novelty-bandit (see dv2s mine --help)"))
    p.add_argument("--fine-tune-steps", type=int, default=None,
                   help=_default("fine_tune_steps", "env steps of fine-tuning per round, each arm"))
    p.add_argument("--fine-tune-lr", type=float, default=None,
                   help="learning rate of the fine-tuning (default: the method's, ppo 1e-4, dagger 1e-3)")
    p.add_argument("--holdout-fraction", type=float, default=None,
                   help=_default("holdout_fraction", "share of the mined families (parent scenarios) held out"))
    p.add_argument("--max-conversions", default=None,
                   help=_default("max_conversions", "failure clusters converted into bank scenarios per round, "
                                 "largest first; 0 for none, 'all' for every cluster; the clusters not converted are "
                                 "counted in the log and the reports"))
    p.add_argument("--max-replays", default=None,
                   help=_default("max_replays", "failure clusters beyond the converted ones whose failing scene is "
                                 "kept as an exact replay entry (the parent scenario narrowed around the failure, "
                                 "checked to replay it step for step) per round, the scenario families taking turns, "
                                 "each its largest cluster first; 0 for none, 'all' "
                                 "for every cluster"))

    p.add_argument("--min-heldout-episodes", type=int, default=None,
                   help=_default("min_heldout_episodes", "below this many held-out episodes a round reports rates "
                                 f"only, no drop and no test; never fewer than {FLOOR} tested pairs, whatever this "
                                 f"says: below {FLOOR} discordant pairs the exact McNemar test cannot reach "
                                 f"p < {ALPHA:g}, so a smaller minimum is flagged as one that can never give "
                                 "evidence"))
    p.add_argument("--min-heldout-families", type=int, default=None,
                   help=_default("min_heldout_families", "below this many held-out scenario families a round "
                                 "reports rates only, no drop and no test (a family counts only with a tested pair; "
                                 "never fewer than 1)"))
    _add_arms_and_run_arguments(p)
    p.set_defaults(func=run)


def _add_arms_and_run_arguments(p: argparse.ArgumentParser) -> None:
    """``dv2s loop``'s options from ``--no-control`` on (the arms, the evaluation, the fine-tuning, the run)."""
    p.add_argument("--no-control", action="store_true",
                   help="skip the control arm (the same fine-tuning without the mined scenarios)")
    p.add_argument("--untouched-seeds", type=int, default=None,
                   help=_default("untouched_seeds", "seeds per scenario of the untouched set the loop never mines "
                                 "or fine-tunes on; 0 skips it"))
    p.add_argument("--k-eval", type=int, default=None,
                   help=_default("k_eval", "evaluation seeds per held-out scenario"))
    p.add_argument("--regress-episodes", type=int, default=None,
                   help=_default("regress_episodes", "seeds per scenario of the regression test"))
    p.add_argument("--mined-share", type=float, default=None,
                   help=_default("mined_share", "probability of a mined scenario in fine-tuning"))
    p.add_argument("--fine-tune-reward", default=None, metavar="JSON",
                   help="reward-term weights overriding the policy's own during fine-tuning only, e.g. "
                   f"'{{\"standing\": -1.0, \"low_ttc\": -0.4}}' (default {json.dumps(DEFAULTS['fine_tune_reward'])}; "
                   "'{}' keeps the policy's reward; evaluation always uses the policy's own env config)")
    p.add_argument("--fine-tune-method", choices=FINE_TUNE_METHODS, default=None,
                   help=_default("fine_tune_method", "ppo: continue PPO on the fine-tuning reward; dagger: imitate "
                                 "the rule-based reference driver on the policy's own states (DAgger; "
                                 "--fine-tune-reward unused)"))
    p.add_argument("--dagger-beta-decay", type=float, default=None,
                   help=_default("dagger_beta_decay", "DAgger's beta decay in both arms, in [0, 1]: the reference "
                                 "driver drives the first DAgger iteration alone and each later iteration i with "
                                 "probability decay**i, the policy being fine-tuned the rest; 0: the policy drives "
                                 "every later iteration (--fine-tune-method dagger only)"))
    p.add_argument("--margin", type=float, default=None,
                   help=_default("margin", "the regression test's non-inferiority margin"))
    p.add_argument("--seed", type=seed_value, default=None, help=_default("seed", "seed"))
    p.add_argument("--workers", type=int, default=None, help="processes for mining and evaluation (default: every core)")
    p.add_argument("--envs", type=int, default=LoopSettings.n_envs,
                   help=f"training environments (default {LoopSettings.n_envs})")
    p.add_argument("--out", default=None, type=output_folder, help="loop folder (default out/loop; rerunning resumes it)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")


def run(args: argparse.Namespace) -> int:
    """Run (or resume) the loop in ``--out``; print a summary, the verdict and the report paths. The exit status
    is the verdict's (:data:`EPILOG`)."""
    from dv2s_gym.loop.run import DEFAULT_OUT, run_loop

    out = args.out or DEFAULT_OUT
    report = run_loop(args.policy, loop_settings(args), out=out, progress=not args.no_progress)
    print("\n".join(summary_lines(report)))
    return int(report.recommendation.exit_code)


_PARSED_HERE = ("bank_dir", "n_envs", "control", "fine_tune_reward", "max_conversions", "max_replays")
"""The settings whose option has another name or is read by :func:`loop_settings` itself."""

_VALUED = tuple(field.name for field in dataclasses.fields(LoopSettings) if field.name not in _PARSED_HERE)
"""The settings whose option has their name and whose value, when given, overrides the profile's (an option not
given is ``None``)."""


def loop_settings(args: argparse.Namespace):
    """The :class:`~dv2s_gym.loop.settings.LoopSettings` of ``dv2s loop``'s arguments: ``--profile``'s
    values with every option given explicitly on top."""
    options = {key: getattr(args, key) for key in _VALUED if getattr(args, key) is not None}
    for flag in ("max_conversions", "max_replays"):
        if getattr(args, flag) is not None:
            options[flag] = _count_or_all(getattr(args, flag), "--" + flag.replace("_", "-"))
    if args.no_control:
        options["control"] = False
    if args.fine_tune_reward is not None:
        options["fine_tune_reward"] = json_value(args.fine_tune_reward, "--fine-tune-reward",
                                                 "a JSON object of reward-term weights ('{}' keeps the policy's own "
                                                 "reward)", "'{\"standing\": -1.0}'", mapping=True)
    return LoopSettings.from_profile(getattr(args, "profile", None) or "quick", bank_dir=getattr(args, "bank", None),
                                     n_envs=args.envs, **options)


def _default(key: str, text: str) -> str:
    """``text`` with the option's default and, where it differs, the evidence profile's value."""
    def shown(value: Any) -> str:
        return "all" if value is None and key in ("max_conversions", "max_replays") else str(value)

    evidence = f"; --profile evidence: {shown(EVIDENCE[key])}" if key in EVIDENCE else ""
    return f"{text} (default {shown(DEFAULTS[key])}{evidence})"


def summary_lines(report: "LoopReport") -> List[str]:
    """The terminal's summary of a finished loop: one line per round, the verdict, where the reports are."""
    from dv2s_gym.loop.report_text import round_summary

    lines = [round_summary(record) for record in report.rounds]
    verdict = report.recommendation
    lines += ["", f"verdict: {verdict.sentence}", f"policy to use: {verdict.policy}"]
    lines += [f"report ({kind}): {report.paths[kind]}" for kind in ("html", "md", "json") if kind in report.paths]
    return lines


def _count_or_all(value: str, flag: str) -> Optional[int]:
    """A ``--max-...`` value: a whole number of clusters, or ``None`` for ``all``."""
    if value == "all":
        return None
    try:
        count = int(value)
    except ValueError:
        count = -1
    if count < 0:  # said here: the settings' own message speaks of leaving the value out, which means the default
        raise UsageError(f"{flag} must be a whole number of clusters (0 or more) or 'all', not {value!r}")
    return count
