"""``dv2s replay``: a saved episode trace, an episode of a regress report or one of a mining run, re-run and checked."""

from __future__ import annotations

import argparse
from pathlib import Path

from dv2s_gym.cli.errors import UsageError
from dv2s_gym.cli.inputs import output_file

__all__ = ["add_parser", "run"]


def add_parser(subparsers) -> None:
    """Add ``replay`` to the ``dv2s`` subcommands."""
    replay = subparsers.add_parser("replay", help="replay a saved episode trace (or an episode of a regress report or a "
                                   "mining run)",
                                   description="Re-run a saved trace with its seeds and actions; fails if any actor "
                                   "state differs. Given a `dv2s regress` report.json and --episode SCENARIO/SEED, "
                                   "re-runs that episode (from its stored trace when it failed, else by re-running the "
                                   "policy), checks its trajectory hash (exit 1 if it differs) and can write its video. "
                                   "Given a `dv2s mine` run folder and --episode INDEX, re-runs the policy on that "
                                   "episode's scene (scenario, parameters, seed), checks the hash and can write the "
                                   "failure's video.")
    replay.add_argument("trace", help="trace file written by `dv2s run --trace` or env.save_trace(), a "
                        "report.json written by `dv2s regress`, or a `dv2s mine` run folder")
    replay.add_argument("--episode", help="with a regress report: the episode id, SCENARIO/SEED; with a mining "
                        "run: the episode index")
    replay.add_argument("--policy", choices=["candidate", "baseline"], default="candidate",
                        help="with a report: whose episode (default: candidate)")
    replay.add_argument("--policy-spec", metavar="SPEC",
                        help="the policy to re-run (with a mining run, or a report episode re-run from its policy) "
                        "instead of the one the file names; needed for any policy that is not built in "
                        "(module:attribute, a checkpoint): a file's policy spec is loaded only if it is built in")
    replay.add_argument("--video", type=output_file, help="also write the replayed episode as a video (.webm)")
    replay.add_argument("--from-policy", action="store_true",
                        help="with a report: re-run the policy even when a trace is stored")
    replay.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Replay what ``trace`` names (a trace file, a regress report.json or a mining run folder) and say so."""
    from dv2s_gym.mining.report import SCHEMA as MINE_SCHEMA
    from dv2s_gym.regress.report import SCHEMA
    from envs.trace import saved_file_schema

    schema = None if Path(args.trace).is_dir() else saved_file_schema(args.trace)
    if schema == SCHEMA:
        return _replay_report(args)
    if Path(args.trace).is_dir() or schema == MINE_SCHEMA:
        folder = Path(args.trace) if Path(args.trace).is_dir() else Path(args.trace).parent
        return _replay_mined(args, folder)
    if args.episode:
        raise UsageError(f"--episode picks an episode of a regression report, and {args.trace} is not one (a "
                         "report.json written by `dv2s regress`); pass that report, or replay an episode trace "
                         "without --episode")
    from envs.replay import replay_trace_file

    trace, replayed = replay_trace_file(args.trace, video=args.video)
    print(f"replayed {len(replayed.actions)} steps of {trace.scenario!r}: every actor state matches the trace"
          + (f"; video {args.video}" if args.video else ""))
    return 0


def _replay_mined(args: argparse.Namespace, folder) -> int:
    from dv2s_gym.mining.episode_replay import replay_mined_episode

    record, policy = replay_mined_episode(folder, args.episode, policy=args.policy_spec, video=args.video)
    failure = record.failure
    print(f"episode {record.index} ({record.scenario}, seed {record.seed}): {policy} re-run "
          f"with the recorded parameters; trajectory hash {record.result.trajectory_hash[:16]} matches the record"
          + (f"; failure {failure.kind} at {failure.time} s" if failure is not None else "")
          + (f"; video {args.video}" if args.video else ""))
    return 0


def _replay_report(args: argparse.Namespace) -> int:
    from dv2s_gym.regress.replay import replay_episode

    if not args.episode:
        raise UsageError(f"{args.trace} is a regression report: name the episode with --episode SCENARIO/SEED "
                         "(its newly_failing list and report.md show the failed ones)")
    result = replay_episode(args.trace, args.episode, role=args.policy, video=args.video,
                            from_policy=args.from_policy, spec=args.policy_spec)
    how = "trace replayed, every actor state matches" if result.source == "trace" else "policy re-run"
    verdict = "matches the report" if result.matches else f"DIFFERS from the report ({result.expected_hash})"
    print(f"{result.id} ({result.role}): {how}; {result.steps} steps; trajectory hash "
          f"{result.trajectory_hash[:16]} {verdict}" + (f"; video {result.video}" if result.video else ""))
    return 0 if result.matches else 1
