"""``dv2s regress``: a candidate policy regression-tested against a baseline on paired episodes."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from dv2s_gym.cli.backend_options import worker_backend_option
from dv2s_gym.cli.inputs import env_config_option, output_folder, seed_value
from dv2s_gym.cli.interrupts import episodes_kept_note
from dv2s_gym.cli.output import json_text
from dv2s_gym.cli.parser import bank_option
from envs.errors import Interrupted

__all__ = ["add_parser", "run"]


def add_parser(subparsers) -> None:
    """Add ``regress`` to the ``dv2s`` subcommands."""
    p = subparsers.add_parser(
        "regress", help="regression-test a policy against a baseline on paired episodes (PASS/FAIL/INCONCLUSIVE/ERROR)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Run the candidate policy (and the baseline, on the same scenario x seed pairs: episode k "
        "uses seed S+k for both) over bank scenarios, in a local process pool or on Ray. Reports per scenario "
        "and overall collision, off-road and success rates (Wilson intervals), minimum TTC, mean speed and "
        "return (bootstrap intervals), and the paired difference in failure rate (Newcombe interval, exact "
        "McNemar test) with a non-inferiority verdict against --margin. Every scenario is a test in its own "
        "right, beside the pooled one, with the family-wise false-alarm rate at most --alpha. The episodes per "
        "scenario are planned from --mde and --power unless --episodes is given; the report states the power "
        "the run had. Writes "
        "report.json (schema dv2s-regress; its format in docs/regress.md), junit.xml, report.md, results.jsonl and traces/ of failed "
        "episodes to --out; rerunning with the same --out and settings resumes.",
        epilog="exit status: 0 PASS (or no baseline: measures only), 1 FAIL, 3 INCONCLUSIVE (too few episodes "
        "to tell), 4 ERROR (an episode ended in an error: never green), 2 bad input.\n"
        "examples:\n"
        "  dv2s regress --policy ppo:model.zip --baseline rule --scenarios tag:highway --episodes 50\n"
        "  dv2s regress --policy rule --out out/main          # measures only, keep report.json\n"
        "  dv2s regress --policy new.zip --baseline-report out/main/report.json\n"
        "  dv2s replay out/regress/report.json --episode highway_cut_in_from_left/3 --video ep.webm")
    p.add_argument("--policy", required=True, help="candidate policy spec: rule, idm, keep_lane, random, dv2s-ppo, "
                   "model.zip, ppo:PATH, module:attr, with ?key=value options (e.g. rule?action_noise=0.3)")
    group = p.add_mutually_exclusive_group()
    group.add_argument("--baseline", help="baseline policy spec, run on the same episodes")
    group.add_argument("--baseline-report", help="report.json of an earlier run: its episodes are the baseline "
                       "(refused if its schema version, bank scenarios or env config differ)")
    p.add_argument("--baseline-role", choices=["candidate", "baseline"], default="candidate",
                   help="with --baseline-report: which of its policies is the baseline (default: the one it tested)")
    p.add_argument("--accept-failed-baseline", action="store_true",
                   help="with --baseline-report: use a report whose verdict was FAIL or ERROR (refused otherwise)")
    bank_option(p)
    p.add_argument("--scenarios", nargs="+", help="bank names and/or tag:<tag> (default: the whole bank, or the "
                   "baseline report's scenarios)")
    p.add_argument("--episodes", type=int, default=None,
                   help="seeds per scenario (default: planned from --mde and --power, at most those of the "
                   "baseline report)")
    p.add_argument("--mde", type=float, default=None,
                   help="minimum detectable effect: the rise of one scenario's failure rate the run must FAIL "
                   "(default 0.30: 30 points); with --power it chooses --episodes")
    p.add_argument("--power", type=float, default=None,
                   help="probability of FAIL at --mde (default 0.8)")
    p.add_argument("--seed", type=seed_value, default=None,
                   help="seed of the first episode (default 0, or the baseline report's)")
    p.add_argument("--margin", type=float, default=None,
                   help="non-inferiority margin on the failure rate (default 0.02: 2 points)")
    p.add_argument("--alpha", type=float, default=None, help="level of the FAIL test (default 0.05)")
    p.add_argument("--failure", default=None,
                   help="what counts as a failure: a comma-separated list of collision, off_road, stall (default: "
                   "all three, or the --baseline-report's kinds; stall: the ego stands with a free road ahead); "
                   "each kind is also reported apart")
    p.add_argument("--stall-seconds", type=float, default=None,
                   help="seconds the ego must stand with a free road ahead for a stall (default 5)")
    worker_backend_option(p, help="local process pool or Ray")
    p.add_argument("--workers", type=int, default=None, help="worker processes (default: every core)")
    p.add_argument("--address", default=None, help="with --backend ray: the cluster address")
    p.add_argument("--timeout", type=float, default=None,
                   help="seconds one episode may take before its worker counts as hung (default 600)")
    p.add_argument("--sequential", action="store_true",
                   help="stop as soon as a group-sequential test settles PASS or FAIL")
    p.add_argument("--batch", type=int, default=None,
                   help="with --sequential: seeds per look (default: a fifth of --episodes)")
    p.add_argument("--config", help="DV2S-v0 config overrides as JSON (or a .json file), e.g. '{\"duration\": 10}' "
                   "(default: none, or the baseline report's)")
    p.add_argument("--out", default=None, type=output_folder, help="output folder (default out/regress)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true", help="print the report JSON instead of the table")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the regression test, print its summary (or the report JSON); the exit status is the verdict's."""
    from dv2s_gym.cli.name_checks import check_names

    check_names(policies=(args.policy, args.baseline), scenarios=args.scenarios, bank=args.bank)  # before imports
    from dv2s_gym.regress.report import baseline_defaults, exit_code, format_summary
    from dv2s_gym.regress.runner import DEFAULT_OUT, BaselineReport, WorkerSettings, run_regression, run_size

    env_config = env_config_option(args.config)
    out = args.out or DEFAULT_OUT
    episodes, seed = args.episodes, args.seed
    if args.baseline_report:
        seed, env_config, args.failure = baseline_defaults(args.baseline_report, seed, env_config, args.failure)
    try:
        baseline = args.baseline if not args.baseline_report else BaselineReport(
            args.baseline_report, role=args.baseline_role, accept_failed=args.accept_failed_baseline)
        settings = _settings(args, episodes, seed or 0, env_config)
        if baseline is None:
            _announce(args.policy, *run_size(settings), json=args.json)
        report = run_regression(
            args.policy, baseline, settings, out_dir=out,
            workers=WorkerSettings(backend=args.backend, workers=args.workers, address=args.address,
                                   timeout=args.timeout),
            progress=not args.no_progress and not args.json)
    except KeyboardInterrupt as stop:
        raise Interrupted(getattr(stop, "note", None) or episodes_kept_note(Path(out) / "results.jsonl")) from None
    if args.json:
        print(json_text(report.to_json(), indent=1))
    else:
        print(format_summary(report))
        names = ("report.json", "junit.xml", "report.md", "report.html")
        print(f"reports: {', '.join(str(Path(out) / f) for f in names if (Path(out) / f).is_file())}")
    return exit_code(report.verdict)


def opening_line(policy: str, scenarios: int, seeds: int) -> str:
    """What a run without a baseline does, said before its episodes: it measures the policy alone and gives no
    verdict, how many episodes it runs, and how to compare instead."""
    return (f"measuring {policy} alone (no baseline: no verdict): {scenarios * seeds} episodes, "
            f"{scenarios} scenario{'s' if scenarios != 1 else ''} x {seeds} seed{'s' if seeds != 1 else ''}; "
            "to compare, add --baseline POLICY (e.g. --baseline rule) or --baseline-report REPORT.json")


def _announce(policy: str, scenarios: int, seeds: int, *, json: bool) -> None:
    # with --json, stdout is the report's alone
    print(opening_line(policy, scenarios, seeds), file=sys.stderr if json else sys.stdout, flush=True)


def _settings(args: argparse.Namespace, episodes, seed: int, env_config):
    """The run's :class:`~dv2s_gym.regress.settings.RegressSettings` from the command line (an option left out
    keeps the settings' default)."""
    from dv2s_gym.regress.settings import RegressSettings

    given = {key: getattr(args, key) for key in ("margin", "alpha", "stall_seconds") if getattr(args, key) is not None}
    return RegressSettings(bank_dir=args.bank, scenarios=args.scenarios, episodes=episodes, seed=seed, mde=args.mde,
                           power=args.power, sequential=args.sequential, env_config=env_config, batch=args.batch,
                           failure=args.failure, **given)
