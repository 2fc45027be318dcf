"""The ``dv2s`` command: one CLI for the whole product."""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import threading
from dataclasses import asdict
from typing import List, Optional

from envs.errors import Interrupted
from scenario_bank.errors import DV2SError

__all__ = ["main", "build_parser"]


def _cmd_demo(args: argparse.Namespace) -> int:
    from dv2s_gym.demo import format_table, run_demo

    rows = run_demo(args.out, scenarios=args.scenario or None, episodes=args.episodes, seed=args.seed,
                    duration=args.duration)
    if args.json:
        print(json.dumps([asdict(r) for r in rows], indent=2, default=str))
    else:
        print(format_table(rows))
    return 0


def _cmd_run(args: argparse.Namespace) -> int:
    import gymnasium as gym

    import dv2s_gym  # noqa: F401
    from envs.recording import record_episode
    from policies import CautiousDriver

    config = {"ego_policy": args.ego_policy}
    if args.duration:
        config["duration"] = args.duration
    if args.map:
        config["map"] = args.map
    env = gym.make("dv2s_gym:DV2S-v0", scenario=args.scenario, config=config, render_mode="rgb_array",
                   trusted=args.trusted, bank_dir=args.bank)
    policy = None if args.ego_policy == "scenic" or args.random else CautiousDriver(env)
    result = record_episode(env, args.video, policy, seed=args.seed)
    if args.trace:
        env.unwrapped.save_trace(args.trace)
    info = result.pop("info")
    result.update({k: info[k] for k in ("scenario", "scene_seed", "collisions", "lane_changes", "min_ttc", "off_road")})
    result["params"] = info["params"]
    print(json.dumps(result, indent=2, default=str))
    env.close()
    return 0


def _cmd_replay(args: argparse.Namespace) -> int:
    from pathlib import Path

    from dv2s_gym.mining.report import SCHEMA as MINE_SCHEMA
    from dv2s_gym.regress.report import SCHEMA

    if _json_schema(args.trace) == SCHEMA:
        return _cmd_replay_report(args)
    if Path(args.trace).is_dir() or _json_schema(args.trace) == MINE_SCHEMA:
        folder = Path(args.trace) if Path(args.trace).is_dir() else Path(args.trace).parent
        return _cmd_replay_mined(args, folder)
    if args.episode:
        raise ValueError(f"--episode picks an episode of a regression report; {args.trace} is an episode trace "
                         "(replay it without --episode)")
    from envs.replay import replay_trace
    from envs.trace import EpisodeTrace

    trace = EpisodeTrace.load(args.trace)
    frames = [] if args.video else None
    env, replayed = replay_trace(trace, render_mode="rgb_array" if args.video else None, frames=frames)
    fps = env.unwrapped.config["policy_frequency"]
    env.close()
    if args.video:
        from envs.recording import VideoWriter

        with VideoWriter(args.video, fps=fps) as video:
            for frame in frames:
                video.write(frame)
    print(f"replayed {len(replayed.actions)} steps of {trace.scenario!r}: every actor state matches the trace"
          + (f"; video {args.video}" if args.video else ""))
    return 0


def _cmd_replay_mined(args: argparse.Namespace, folder) -> int:
    from pathlib import Path

    from dv2s_gym.mining.failure_video import rerun_failure, write_failure_video
    from dv2s_gym.mining.miner import read_records

    settings_file = folder / "settings.json"
    if not settings_file.is_file():
        raise ValueError(f"{folder} is not a `dv2s mine` run folder (no settings.json); pass a trace file, a "
                         "regress report.json or a mining run folder")
    if args.episode is None or not str(args.episode).isdigit():
        raise ValueError(f"{folder} is a mining run: name the episode with --episode INDEX (report.md lists the "
                         "failures and their indices)")
    settings = json.loads(settings_file.read_text(encoding="utf-8"))
    records = {int(r["index"]): r for r in read_records(folder / "episodes.jsonl")}
    record = records.get(int(args.episode))
    if record is None or record.get("error") or not record.get("result"):
        raise ValueError(f"episode {args.episode} of {folder} did not finish (not in episodes.jsonl, or an error); "
                         f"it has episodes 0..{max(records) if records else -1}")
    if args.policy_spec:
        policy = args.policy_spec
    else:
        from policies.registry import spec_from_file

        policy = spec_from_file(settings.get("policy"), str(settings_file), "--policy-spec SPEC")
    from envs.trace_bounds import check_file_config

    options = {"policy": policy, "bank_dir": settings.get("bank_dir"),
               "env_config": check_file_config(settings.get("env_config"), str(settings_file))}
    if args.video and record.get("failure"):
        write_failure_video(record, args.video, trace_path=Path(args.video).with_suffix(".json.gz"), **options)
    else:
        _, _, frames = rerun_failure(record, render=bool(args.video), **options)
        if args.video:
            from envs.recording import VideoWriter

            fps = (settings.get("env_config") or {}).get("policy_frequency", 5)
            with VideoWriter(args.video, fps=fps) as video:
                for frame in frames:
                    video.write(frame)
    failure = record.get("failure") or {}
    print(f"episode {record['index']} ({record['scenario']}, seed {record['seed']}): {policy} re-run "
          f"with the recorded parameters; trajectory hash {record['result']['trajectory_hash'][:16]} matches the record"
          + (f"; failure {failure.get('kind')} at {failure.get('time')} s" if failure else "")
          + (f"; video {args.video}" if args.video else ""))
    return 0


def _json_schema(path: str):
    """The ``schema`` of a JSON file (None for anything else: a gzip trace, not JSON, no schema)."""
    from pathlib import Path

    try:
        with open(path, "rb") as handle:
            if handle.read(2) == b"\x1f\x8b":
                return None
        data = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return None
    return data.get("schema") if isinstance(data, dict) else None


def _cmd_replay_report(args: argparse.Namespace) -> int:
    from dv2s_gym.regress.replay import replay_episode

    if not args.episode:
        raise ValueError(f"{args.trace} is a regression report: name the episode with --episode SCENARIO/SEED "
                         "(its newly_failing list and report.md show the failed ones)")
    result = replay_episode(args.trace, args.episode, role=args.policy, video=args.video,
                            from_policy=args.from_policy, spec=args.policy_spec)
    how = "trace replayed, every actor state matches" if result["source"] == "trace" else "policy re-run"
    verdict = "matches the report" if result["matches"] else (
        f"DIFFERS from the report ({result['expected_hash']})")
    print(f"{result['id']} ({result['role']}): {how}; {result['steps']} steps; trajectory hash "
          f"{result['trajectory_hash'][:16]} {verdict}" + (f"; video {result['video']}" if result["video"] else ""))
    return 0 if result["matches"] else 1


def _cmd_regress(args: argparse.Namespace) -> int:
    from pathlib import Path

    from dv2s_gym.regress.report import exit_code, format_summary
    from dv2s_gym.regress.runner import DEFAULT_OUT, run_regression

    env_config = None
    if args.config:
        text = Path(args.config).read_text(encoding="utf-8") if args.config.endswith(".json") else args.config
        try:
            env_config = json.loads(text)
        except ValueError as error:
            raise ValueError(f"--config must be a JSON object of DV2S-v0 config overrides (or a .json file), e.g. "
                             f"'{{\"duration\": 10}}'; {error}") from None
        if not isinstance(env_config, dict):
            raise ValueError("--config must be a JSON object of DV2S-v0 config overrides, e.g. '{\"duration\": 10}'")
    out = args.out or DEFAULT_OUT
    episodes, seed = args.episodes, args.seed
    if args.baseline_report and (seed is None or env_config is None):
        from dv2s_gym.regress.report import load_report

        old = load_report(args.baseline_report).get("settings") or {}  # by default: the seeds it ran
        seed = old.get("seed") if seed is None else seed
        env_config = old.get("env_config") if env_config is None else env_config
    try:
        report = run_regression(
            args.policy, args.baseline, baseline_report=args.baseline_report, bank_dir=args.bank,
            scenarios=args.scenarios, episodes=episodes, seed=seed or 0,
            margin=args.margin, alpha=args.alpha, mde=args.mde, power=args.power,
            backend=args.backend, workers=args.workers, address=args.address, out_dir=out,
            sequential=args.sequential, env_config=env_config, progress=not args.no_progress and not args.json,
            timeout=args.timeout, batch=args.batch, baseline_role=args.baseline_role, failure=args.failure,
            stall_seconds=args.stall_seconds, accept_failed_baseline=args.accept_failed_baseline)
    except KeyboardInterrupt as stop:
        raise Interrupted(getattr(stop, "note", None) or f"finished episodes are kept in "
                          f"{Path(out) / 'results.jsonl'}; rerun the same command to resume") from None
    if args.json:
        print(json.dumps(report, indent=1))
    else:
        print(format_summary(report))
        names = ("report.json", "junit.xml", "report.md", "report.html")
        print(f"reports: {', '.join(str(Path(out) / f) for f in names if (Path(out) / f).is_file())}")
    return exit_code(report["verdict"])


def _cmd_mine(args: argparse.Namespace) -> int:
    from pathlib import Path

    from dv2s_gym.mining.miner import mine

    env_config = _json_option(args.config, "--config")
    if env_config is not None and not isinstance(env_config, dict):
        raise ValueError("--config must be a JSON object of DV2S-v0 config overrides, e.g. '{\"duration\": 10}'")
    out = Path(args.out or "out/mine")
    convert_options = {"dra": args.dra, "sg": args.sg, "k": args.k, "threshold": args.threshold,
                       "llm_config": _llm_config(args)}
    try:
        run = mine(args.policy, out=out, budget=args.budget, sampler=args.sampler, scenarios=args.scenarios,
                   bank_dir=args.bank, backend=args.backend, workers=args.workers, address=args.address,
                   seed=args.seed, reference=None if args.reference == "none" else args.reference,
                   batch=args.batch, timeout=args.timeout, progress=not args.no_progress, env_config=env_config,
                   ttc_threshold=args.ttc_threshold, stall_seconds=args.stall_seconds,
                   convert=not args.no_convert, convert_options=convert_options,
                   max_conversions=args.max_conversions, feedback=args.feedback,
                   sampler_options=_json_option(args.sampler_options, "--sampler-options"))
    except KeyboardInterrupt as stop:
        raise Interrupted(getattr(stop, "note", None) or f"finished episodes are kept in "
                          f"{out / 'episodes.jsonl'}; rerun the same command to resume") from None
    print(run.summary())
    if run.reports:
        print(f"reports: {', '.join(str(p) for p in run.reports.values())}")
    return 0


def _cmd_maps(args: argparse.Namespace) -> int:
    from scenario_bank.maps import MAPS_DIR, list_maps

    if args.build:
        from scenario_bank.maps import build_maps

        build_maps.main(["--out", str(MAPS_DIR)])
    for name in list_maps():
        print(f"{name}\t{MAPS_DIR / (name + '.xodr')}")
    return 0


def _bank(args: argparse.Namespace):
    from pathlib import Path

    from scenario_bank.bank import Bank, BankError

    writes = getattr(args, "bank_command", None) in ("add", "import") or getattr(args, "add_to_bank", False)
    if args.bank is not None and not writes and not Path(args.bank).exists():
        raise BankError(f"there is no bank at {args.bank} (the folder does not exist); check the path, or create "
                        "a bank there with `dv2s bank add` or `dv2s bank import`")
    return Bank(args.bank)


def _read_input_file(path: str, what: str, max_bytes: int) -> bytes:
    """A file named on the command line: a regular file (a FIFO or device is refused, never waited on) of at
    most ``max_bytes``."""
    from scenario_bank.bank import UnsafeBankInputError
    from scenario_bank.safe_files import UnsafeInputError, read_regular_file

    try:
        return read_regular_file(path, max_bytes, follow_symlinks=True)
    except UnsafeInputError as error:
        raise UnsafeBankInputError(f"the {what} {error}") from None


def _json_argument(text: str, what: str):
    """A JSON value given on the command line (or in a file), size and nesting capped."""
    from scenario_bank.bank import MAX_JSON_DEPTH, MAX_SIDECAR_BYTES, UnsafeBankInputError
    from scenario_bank.safe_files import UnsafeInputError, load_json_bounded

    data = text.encode("utf-8", "surrogateescape") if isinstance(text, str) else text
    if len(data) > MAX_SIDECAR_BYTES:
        raise UnsafeBankInputError(f"{what} is larger than {MAX_SIDECAR_BYTES} bytes; shorten it")
    try:
        return load_json_bounded(data, MAX_JSON_DEPTH, what)
    except UnsafeInputError as error:
        raise UnsafeBankInputError(str(error)) from None


def _print(args: argparse.Namespace, data, human: str) -> None:
    from scenario_bank.jail.output import printable

    # bank text comes from folders and archives of others: no escape sequence reaches the terminal
    print(json.dumps(data, indent=2, default=str) if args.json else printable(human))


def _cmd_bank_list(args: argparse.Namespace) -> int:
    bank = _bank(args)
    entries = bank.list(tag=args.tag, text=args.text, element=args.element, map=args.map, source=args.source)
    lines = [f"{e.name:<40} {e.map or '':<18} {e.source.get('kind', ''):<13} {', '.join(e.tags)}" for e in entries]
    lines += [f"! {name}: {message}" for name, message in sorted(bank.problems.items())]
    _print(args, {"scenarios": [e.summary() for e in entries], "problems": bank.problems},
           "\n".join(lines) + f"\n{len(entries)} scenario(s)")
    return 0


def _cmd_bank_show(args: argparse.Namespace) -> int:
    entry = _bank(args).get(args.name)
    missing = set(entry.missing_files())
    files = [str(f) + (" (missing)" if str(f.relative_to(entry.folder)) in missing else "") for f in entry.files]
    data = {**entry.meta, "path": str(entry.script_path), "script": entry.script, "files": files}
    human = (f"{entry.name}  ({entry.map}, {entry.source.get('kind')})\n{entry.description}\n"
             f"tags: {', '.join(entry.tags)}\nelements: {json.dumps(entry.elements)}\n"
             f"source: {json.dumps(entry.source)}\npath: {entry.script_path}\n"
             + "".join(f"file: {f}\n" for f in files) + f"\n{entry.script}")
    _print(args, data, human)
    return 0


def _cmd_bank_add(args: argparse.Namespace) -> int:
    from scenario_bank.bank import MAX_SCRIPT_BYTES, MAX_SIDECAR_BYTES
    from scenario_bank.scenic2 import upgrade_scenic2

    try:
        script = _read_input_file(args.script, "script", MAX_SCRIPT_BYTES).decode("utf-8")
    except UnicodeDecodeError as error:
        raise ValueError(f"the script {args.script} is not UTF-8 text ({error.reason}); save it as UTF-8") from None
    upgrade = upgrade_scenic2(script)  # Scenic 2 syntax -> Scenic 3; Scenic 3 scripts come back unchanged
    for line in upgrade.report() if upgrade.changed else []:
        print(line, file=sys.stderr)
    elements = (_json_argument(_read_input_file(args.elements, "elements file", MAX_SIDECAR_BYTES),
                               f"the elements file {args.elements}") if args.elements else None)
    provenance = {"kind": args.kind, "video": args.video, "parent": args.parent}
    # Bank.add upgrades the same way (recording the rewrites in provenance), then its allowlist + sandbox checks
    entry = _bank(args).add(script, args.description, name=args.name, elements=elements, tags=args.tag or [],
                            map=args.map, provenance=provenance, upgrade_scenic2=True)
    summary = dict(entry.summary(), scenic2_rewrites=[str(r) for r in upgrade.rewrites])
    _print(args, summary, f"added {entry.name} ({entry.script_path})")
    return 0


def _cmd_bank_rm(args: argparse.Namespace) -> int:
    bank = _bank(args)
    for name in args.name:
        bank.remove(name)
    _print(args, {"removed": args.name}, f"removed {', '.join(args.name)}")
    return 0


def _cmd_bank_validate(args: argparse.Namespace) -> int:
    if args.story:
        return _cmd_bank_story(args)
    from dv2s_gym.bank_validate import validate_bank
    from scenario_bank.bank import UnsafeBankInputError
    from scenario_bank.safe_files import UnsafeInputError, validate_entry_name

    bank = _bank(args)  # a --bank that does not exist is an error, not "0/0 scenarios valid"
    for name in args.name or []:
        if name not in bank.problems:
            try:
                validate_entry_name(name, "scenario name")
            except UnsafeInputError as error:
                raise UnsafeBankInputError(str(error)) from None
    reports = validate_bank(args.bank, args.name or None, samples=args.samples, seconds=args.seconds,
                            jobs=args.jobs, progress=not args.json)
    lines = []
    for r in reports:
        rate = f"{r.acceptance_rate:.2f}" if r.acceptance_rate is not None else "-"
        compile_s = f"{r.compile_seconds:.2f}s" if r.compile_seconds is not None else "-"
        outcomes = ",".join(e["outcome"] for e in r.episodes) or "-"
        lines.append(f"{'ok  ' if r.ok else 'FAIL'} {r.name:<40} compile {compile_s:>7}  accept {rate:>5}  "
                     f"runs {outcomes}" + (f"\n     {r.error}" if r.error else ""))
    broken = [r.name for r in reports if not r.ok]
    lines.append(f"{len(reports) - len(broken)}/{len(reports)} scenarios valid" +
                 (f"; broken: {', '.join(broken)}" if broken else ""))
    _print(args, [r.as_dict() for r in reports], "\n".join(lines))
    return 1 if broken else 0


def _cmd_bank_story(args: argparse.Namespace) -> int:
    from dv2s_gym.story import EGOS, story_table

    known = _bank(args).names()
    unknown = [n for n in args.name if n not in known]
    if unknown:
        print(f"dv2s: unknown scenario {unknown[0]!r} in the bank; `dv2s bank list` shows its scenarios",
              file=sys.stderr)
        return 2
    names = args.name or known
    egos = args.egos or list(EGOS)
    table = story_table(names, egos, range(args.seeds), bank_root=args.bank, jobs=args.jobs,
                        progress=not args.json)
    under = sorted(n for n, row in table.items() if any(cell["rate"] < args.threshold for cell in row.values()))
    width = max(len(n) for n in names)
    lines = [f"story rate over {args.seeds} seeds (threshold {args.threshold:.2f})",
             f"{'scenario':<{width}}  " + "  ".join(f"{e:>9}" for e in egos)]
    for name, row in table.items():
        cells = [f"{row[e]['rate']:>8.2f}" + ("*" if row[e]["rate"] < args.threshold else " ") for e in egos]
        lines.append(f"{name:<{width}}  " + "  ".join(cells))
    crashes = sum(cell["by_collision"] for row in table.values() for cell in row.values())
    lines.append(f"({crashes} of {len(names) * len(egos) * args.seeds} episodes count because the ego hit an "
                 "actor of the story before the trace showed all of it)")
    for name in under:
        for ego in egos:
            cell = table[name][ego]
            if cell["rate"] >= args.threshold:
                continue
            lines.append(f"  {name} / {ego}: rate {cell['rate']:.2f}")
            for step, miss in cell.get("missed", {}).items():
                lines.append(f"    missed {step!s} in {miss['count']}/{args.seeds} seeds, e.g. seed {miss['seed']}"
                             + (f": {miss['why']}" if miss["why"] else ""))
    lines.append(f"{len(names) - len(under)}/{len(names)} scenarios play their story in at least "
                 f"{args.threshold:.0%} of seeds with every ego" + (f"; under: {', '.join(under)}" if under else ""))
    _print(args, {"seeds": args.seeds, "threshold": args.threshold, "egos": egos, "table": table,
                  "under_threshold": under}, "\n".join(lines))
    return 1 if under else 0


def _cmd_bank_sample(args: argparse.Namespace) -> int:
    bank = _bank(args)
    candidates = [e.name for e in bank.list(tag=args.tag)] if args.tag else None
    weights = _json_argument(args.weights, "--weights") if args.weights else None
    if weights is not None and not (isinstance(weights, dict) and all(isinstance(v, (int, float)) for v in weights.values())):
        raise ValueError('--weights must be a JSON object of scenario name -> number, e.g. \'{"a": 2, "b": 1}\'')
    picks = [bank.sample(args.seed + k, weights=weights, candidates=candidates).name for k in range(args.count)]
    _print(args, picks, "\n".join(picks))
    return 0


def _cmd_bank_export(args: argparse.Namespace) -> int:
    path = _bank(args).export(args.archive, names=args.name or None)
    _print(args, {"archive": str(path)}, f"wrote {path}")
    return 0


def _cmd_bank_import(args: argparse.Namespace) -> int:
    result = _bank(args).import_archive(args.archive, on_duplicate=args.on_duplicate)
    _print(args, result, f"added {len(result['added'])}: {', '.join(result['added']) or '-'}; "
           f"skipped {len(result['skipped'])} duplicate(s): {', '.join(result['skipped']) or '-'}")
    return 0


def _cmd_bank_stats(args: argparse.Namespace) -> int:
    stats = _bank(args).stats()
    human = "\n".join(f"{k}: {v}" for k, v in stats.items())
    _print(args, stats, human)
    return 0


def _llm_config(args: argparse.Namespace):
    config = {k: getattr(args, k, None) for k in ("base_url", "model", "api_key")}
    return {k: v for k, v in config.items() if v} or None


def _cmd_describe(args: argparse.Namespace) -> int:
    from dv2s_gym.pipeline.stages import describe

    result = describe(args.video, backend=args.dra, camera=args.camera, question=args.question, fps=args.fps,
                      max_frames=args.max_frames, max_pixels=args.max_pixels, llm_config=_llm_config(args))
    _print(args, result.as_dict(), f"{result.text}\n\nelements: {json.dumps(result.elements)}")
    return 0


def _cmd_generate(args: argparse.Namespace) -> int:
    from pathlib import Path

    from dv2s_gym.pipeline.convert import generate_to_folder
    from dv2s_gym.pipeline.semantics.text import elements_from_text
    from dv2s_gym.pipeline.stages import Description

    if args.from_file:
        text = Path(args.from_file).read_text(encoding="utf-8")
    elif args.description:
        text = args.description
    else:
        raise ValueError("give a description in quotes or --from FILE")
    description = Description(text.strip(), elements_from_text(text), backend="user")
    report = generate_to_folder(description, Path(args.out), sg=args.sg, seed=args.seed,
                                llm_config=_llm_config(args), seconds=args.seconds)
    _print(args, report, _report_text(report, args.out))
    return 0 if report.get("check", {}).get("ok") else 1


def _report_text(report, out) -> str:
    generation = report.get("generation", {})
    check = report.get("check", {})
    lines = [f"description: {report['description']['text']}"]
    if generation.get("warnings"):
        lines.append("could not place: " + "; ".join(generation["warnings"]))
    if "error" in generation:
        lines.append(f"generation failed: {generation['error']}")
    if check:
        stages = " ".join(f"{k}={'ok' if check.get(k) else 'FAIL'}" for k in ("safe", "compiled", "sampled", "ran"))
        lines.append(f"checks: {stages}" + (f" ({check['error']})" if check.get("error") else ""))
    for key in ("sp", "e2e_sc"):
        if key in report:
            lines.append(f"{key.upper().replace('_', '-')}: {report[key]:.2f}")
    files = report.get("files") or []
    lines.append(f"written to {out}/ ({', '.join(files)})" if files else f"nothing written to {out}/")
    return "\n".join(lines)


def _convert_one(video: str, out: str, args_dict: dict) -> dict:
    from dv2s_gym.pipeline.convert import convert_video

    return convert_video(video, out, dra=args_dict["dra"], sg=args_dict["sg"], camera=args_dict["camera"],
                         question=args_dict["question"], seed=args_dict["seed"], llm_config=args_dict["llm"],
                         seconds=args_dict["seconds"])


def _cmd_convert(args: argparse.Namespace) -> int:
    from concurrent.futures import ProcessPoolExecutor
    from pathlib import Path

    from tqdm import tqdm

    from dv2s_gym.pipeline.evaluate import VIDEO_SUFFIXES

    source = Path(args.video)
    if source.is_dir():
        videos = sorted(p for p in source.iterdir() if p.suffix.lower() in VIDEO_SUFFIXES)
        if not videos:
            raise FileNotFoundError(f"no videos ({', '.join(VIDEO_SUFFIXES)}) in {source}")
        outs = [Path(args.out) / v.stem for v in videos]
    else:
        videos, outs = [source], [Path(args.out)]
    options = {"dra": args.dra, "sg": args.sg, "camera": args.camera, "question": args.question,
               "seed": args.seed, "llm": _llm_config(args), "seconds": args.seconds}
    reports = []
    with tqdm(total=len(videos), desc="converting", unit="video", disable=args.json or len(videos) == 1) as bar:
        if args.jobs > 1 and len(videos) > 1:
            with ProcessPoolExecutor(max_workers=args.jobs) as pool:
                futures = [pool.submit(_convert_one, str(v), str(o), options) for v, o in zip(videos, outs)]
                for future in futures:
                    reports.append(future.result())
                    bar.update()
        else:
            for v, o in zip(videos, outs):
                reports.append(_convert_one(str(v), str(o), options))
                bar.update()
    added = []
    if args.add_to_bank:
        added = [_add_converted(v, o, r, args) for v, o, r in zip(videos, outs, reports)]
    if args.json:
        print(json.dumps({"reports": reports, "added": added}, indent=2, default=str))
    else:
        for v, o, r in zip(videos, outs, reports):
            print(f"== {v}\n{_report_text(r, o)}")
        for name in added:
            print(f"added to bank: {name}")
    return 0 if all(r.get("check", {}).get("ok") for r in reports) else 1


def _add_converted(video, out, report, args) -> str:
    import datetime

    if not report.get("check", {}).get("ok"):
        return f"(not added: {video} failed validation)"
    generation = report["generation"]
    description = report["description"]
    provenance = {"kind": "generated", "video": str(video), "seed": args.seed,
                  "generator": f"dra={args.dra},sg={args.sg}",
                  "model": generation.get("model") or description.get("model"),
                  "context_hash": generation.get("context_hash") or description.get("prompt_hash"),
                  "date": datetime.date.today().isoformat()}
    script = (out / "scenario.scenic").read_text(encoding="utf-8")
    entry = _bank(args).add(script, description["text"], elements=description["elements"],
                                tags=["generated"], provenance=provenance, name=None)
    return entry.name


def _cmd_eval(args: argparse.Namespace) -> int:
    from dv2s_gym.pipeline.evaluate import evaluate, format_results

    from dv2s_gym.pipeline.evaluate import EVALSET_DIR

    report = evaluate(args.stage, args.folder or EVALSET_DIR, dra=args.dra, sg=args.sg, llm_config=_llm_config(args),
                      jobs=args.jobs, seconds=args.seconds, progress=not args.json)
    _print(args, report, format_results(report))
    return 0


def _json_option(text: Optional[str], what: str):
    """A JSON value given inline or as a path to a .json file."""
    from pathlib import Path

    if text is None:
        return None
    source = Path(text).read_text(encoding="utf-8") if text.endswith(".json") and Path(text).is_file() else text
    try:
        return json.loads(source)
    except ValueError as error:
        raise ValueError(f"{what} is not valid JSON ({error}); pass a JSON object or a path to a .json file") from None


def _cmd_train(args: argparse.Namespace) -> int:
    from policies.training import TrainConfig, TrainingError, load_run_config, train

    given = {
        "algo": args.algo, "scenarios": args.scenarios, "bank_dir": getattr(args, "bank", None), "seed": args.seed,
        "sampler": args.sampler, "weights": _json_option(args.weights, "--weights"),
        "env_config": _json_option(args.config, "--config"), "steps": args.steps, "n_envs": args.envs,
        "eval_freq": args.eval_freq, "eval_seeds": args.eval_seeds, "card_seeds": args.card_seeds,
        "baselines": args.baselines, "eval_jobs": args.eval_jobs, "checkpoint_freq": args.checkpoint_freq,
        "curriculum_floor": args.curriculum_floor, "curriculum_window": args.curriculum_window,
        "curriculum_update": args.curriculum_update,
    }
    if args.hp:
        hyperparameters = {}
        for pair in args.hp:
            key, sep, value = pair.partition("=")
            if not sep or not key:
                raise TrainingError(f"--hp {pair!r} is not KEY=VALUE (e.g. --hp learning_rate=3e-4)")
            try:
                hyperparameters[key] = json.loads(value)
            except ValueError:
                hyperparameters[key] = value
        given["hyperparameters"] = hyperparameters
    given = {key: value for key, value in given.items() if value is not None}
    if args.resume:
        recorded, _ = load_run_config(args.out)
        settings = {**recorded.to_json(), **given, "out": args.out}
    else:
        settings = {**given, "out": args.out}
    settings["progress_bar"] = not args.no_progress
    settings["vec_env"] = args.vec_env
    train(TrainConfig.from_json(settings), resume=args.resume, log=lambda line: print(line, file=sys.stderr))
    return 0


def _cmd_loop(args: argparse.Namespace) -> int:
    from pathlib import Path

    from dv2s_gym.mining.loop import DEFAULT_OUT, run_loop

    options = {key: getattr(args, key) for key in ("rounds", "budget", "sampler", "fine_tune_steps", "fine_tune_lr",
                                                    "holdout_fraction", "k_eval", "regress_episodes", "mined_share",
                                                    "margin", "seed", "workers", "scenarios",
                                                    "fine_tune_method", "max_conversions", "min_heldout_episodes",
                                                    "untouched_seeds")}
    options["max_conversions"] = None if options["max_conversions"] == 0 else options["max_conversions"]
    if args.max_replays == "all":
        options["max_replays"] = None
    else:
        try:
            options["max_replays"] = int(args.max_replays)
        except ValueError:
            raise ValueError(f"--max-replays must be a whole number of clusters or 'all', not {args.max_replays!r}") \
                from None
    options["control"] = not args.no_control
    if args.fine_tune_reward is not None:
        try:
            options["fine_tune_reward"] = json.loads(args.fine_tune_reward)
        except ValueError as error:
            raise ValueError(f"--fine-tune-reward must be a JSON object of reward-term weights, e.g. "
                             f"'{{\"standing\": -1.0}}'; {error}") from None
        if not isinstance(options["fine_tune_reward"], dict):
            raise ValueError("--fine-tune-reward must be a JSON object of reward-term weights, e.g. "
                             "'{\"standing\": -1.0}' ('{}' keeps the policy's own reward)")
    out = args.out or DEFAULT_OUT
    report = run_loop(args.policy, out=out, bank_dir=getattr(args, "bank", None), n_envs=args.envs,
                      progress=not args.no_progress, **options)
    print((Path(out) / "report.md").read_text(encoding="utf-8") if (Path(out) / "report.md").is_file() else "")
    print(f"final policy: {report.policy}")
    for kind in ("json", "md", "html"):
        if kind in report.paths:
            print(f"report ({kind}): {report.paths[kind]}")
    return 0


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line in the words of the (sub)command the user typed.

    argparse prints the whole usage block before a usage error and reports an unknown option of a
    subcommand as the top-level command's; here the subcommand that received it names it, with the
    closest option it has and where its help is.
    """

    def error(self, message: str):  # argparse's hook; never returns
        self.exit(2, f"{self.prog}: error: {message} (see `{self.prog} --help`)\n")

    def parse_known_args(self, args=None, namespace=None):
        leaf = not any(isinstance(action, argparse._SubParsersAction) for action in self._actions)
        if leaf and args is not None:  # a mistyped option is named before "--policy is required" hides it
            unknown = [token for token in args if token.startswith("--") and token != "--"
                       and not any(flag.startswith(token.split("=", 1)[0]) for flag in self._option_string_actions)]
            if unknown:
                self.error(self._unrecognized(unknown))
        namespace, extras = super().parse_known_args(args, namespace)
        if extras and leaf:
            self.error(self._unrecognized(extras))
        return namespace, extras

    def _unrecognized(self, extras: List[str]) -> str:
        import difflib

        message = f"unrecognized arguments: {' '.join(extras)}"
        flags = [flag.split("=", 1)[0] for flag in extras if flag.startswith("-")]
        close = difflib.get_close_matches(flags[0], list(self._option_string_actions), n=1) if flags else []
        return message + (f"; did you mean {close[0]}?" if close else "")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``dv2s`` (every subcommand has ``--help``)."""
    parser = _Parser(prog="dv2s", description="dv2s-gym: turn driving videos into Scenic "
                                     "scenarios and run them as Gymnasium episodes in highway-env.")
    parser.add_argument("--debug", action="store_true", help="on an error, show the full traceback")
    parser.add_argument("--bank", default=None, help="bank folder (default: the bank shipped with dv2s-gym); "
                        "also accepted after `bank` and after its subcommand")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def bank_option(p):
        # SUPPRESS: given at several levels, the one the user wrote wins; not given, the top level's None stays
        p.add_argument("--bank", default=argparse.SUPPRESS, help="bank folder (default: the bank shipped with dv2s-gym)")

    demo = sub.add_parser("demo", help="run every bank scenario with a rule-based ego; one video each and a table",
                          description="Run DV2S-v0 episodes of every bank scenario with the rule-based "
                          "CautiousDriver, write one .webm per episode and print a summary table.")
    demo.add_argument("--out", default="out/demo", help="folder for the videos (default: out/demo)")
    demo.add_argument("--scenario", action="append", help="only this bank scenario (repeatable)")
    demo.add_argument("--episodes", type=int, default=1, help="episodes per scenario (default: 1)")
    demo.add_argument("--seed", type=int, default=0, help="seed of the first episode (default: 0)")
    demo.add_argument("--duration", type=float, default=None, help="episode length in seconds")
    demo.add_argument("--json", action="store_true", help="print JSON instead of a table")
    demo.set_defaults(func=_cmd_demo)

    run = sub.add_parser("run", help="run one episode of a scenario and record it",
                         description="Run one DV2S-v0 episode of a scenario (bank name, .scenic path or "
                         "tag:<tag>) and record it as a video; optionally save its trace.")
    run.add_argument("scenario", help="bank name, path to a .scenic file, or tag:<tag>")
    bank_option(run)
    run.add_argument("--video", default="out/episode.webm", help="video path (.webm VP8; .mp4/.avi also work)")
    run.add_argument("--trace", default=None, help="also save the episode trace here (.json or .json.gz)")
    run.add_argument("--seed", type=int, default=0)
    run.add_argument("--duration", type=float, default=None, help="episode length in seconds")
    run.add_argument("--map", default=None, help="override the script's map (name or .xodr path)")
    run.add_argument("--ego-policy", choices=["agent", "scenic"], default="agent",
                     help="agent: rule-based driver; scenic: the script's ego behaviour")
    run.add_argument("--random", action="store_true", help="drive with random actions")
    run.add_argument("--trusted", action="store_true",
                     help="run the script in this process, without the jail: only for a script you wrote or "
                     "reviewed (scripts that ship with dv2s-gym always run in process)")
    run.set_defaults(func=_cmd_run)

    replay = sub.add_parser("replay", help="replay a saved episode trace (or an episode of a regress report or a "
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
    replay.add_argument("--video", help="also write the replayed episode as a video (.webm)")
    replay.add_argument("--from-policy", action="store_true",
                        help="with a report: re-run the policy even when a trace is stored")
    replay.set_defaults(func=_cmd_replay)

    maps = sub.add_parser("maps", help="list the shipped OpenDRIVE maps (or rebuild them)",
                          description="List the shipped maps; --build regenerates them deterministically.")
    maps.add_argument("--build", action="store_true", help="regenerate the .xodr files first")
    maps.set_defaults(func=_cmd_maps)

    bank = sub.add_parser("bank", help="list, add, validate, sample, export and import bank scenarios",
                          description="The scenario bank: versioned, validated, searchable Scenic scenarios.")
    bank_option(bank)
    bank_sub = bank.add_subparsers(dest="bank_command", required=True, metavar="BANK_COMMAND")

    def bank_cmd(name, help_text, func):
        p = bank_sub.add_parser(name, help=help_text, description=help_text)
        bank_option(p)
        p.add_argument("--json", action="store_true", help="print JSON instead of text")
        p.set_defaults(func=func)
        return p

    p = bank_cmd("list", "list scenarios, optionally filtered", _cmd_bank_list)
    p.add_argument("--tag", help="only scenarios with this tag")
    p.add_argument("--text", help="substring of the name or description")
    p.add_argument("--element", action="append", help="participant, action (car:cut_in), relation or road type")
    p.add_argument("--map", help="only scenarios on this map")
    p.add_argument("--source", choices=["hand-written", "generated", "mined"], help="only this source kind")
    p = bank_cmd("show", "show one scenario: metadata and script", _cmd_bank_show)
    p.add_argument("name")
    p = bank_cmd("add", "add a Scenic script with its description: safety-checked, then compiled, sampled and run once in the sandbox (atomic; duplicates and failures refused)", _cmd_bank_add)
    p.add_argument("script", help="path to the .scenic file")
    p.add_argument("--description", required=True, help="natural-language description")
    p.add_argument("--name", help="entry name (default: from the description)")
    p.add_argument("--elements", help="JSON file with the semantic elements")
    p.add_argument("--tag", action="append", help="tag (repeatable)")
    p.add_argument("--map", help="map name (default: read from `param map`)")
    p.add_argument("--kind", default="hand-written", choices=["hand-written", "generated", "mined"])
    p.add_argument("--video", help="source video (provenance)")
    p.add_argument("--parent", help="parent scenario (provenance)")
    p = bank_cmd("rm", "remove scenarios", _cmd_bank_rm)
    p.add_argument("name", nargs="+")
    p = bank_cmd("validate", "safety-check, compile, sample and run every scenario; exit 1 if any is broken",
                 _cmd_bank_validate)
    p.add_argument("name", nargs="*", help="only these scenarios")
    p.add_argument("--samples", type=int, default=3, help="scenes sampled and run per scenario (default 3)")
    p.add_argument("--seconds", type=float, default=3.0, help="simulated seconds per run (default 3)")
    p.add_argument("--jobs", type=int, default=1, help="parallel processes")
    p.add_argument("--story", action="store_true",
                   help="instead: measure how often each scenario plays its story (see dv2s_gym/story.py)")
    p.add_argument("--seeds", type=int, default=20, help="with --story: seeds per scenario and ego (default 20)")
    p.add_argument("--threshold", type=float, default=0.9,
                   help="with --story: lowest acceptable story rate (default 0.9); exit 1 below it")
    p.add_argument("--egos", nargs="+", choices=["scenic", "rule", "keep_lane", "idm"],
                   help="with --story: egos to drive (default: all four)")
    p = bank_cmd("sample", "draw scenarios by weight", _cmd_bank_sample)
    p.add_argument("--count", type=int, default=1)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--tag", help="draw among scenarios with this tag")
    p.add_argument("--weights", help='JSON object name -> weight, e.g. \'{"a": 2, "b": 1}\'')
    p = bank_cmd("export", "write scenarios to one .tar.gz archive", _cmd_bank_export)
    p.add_argument("archive")
    p.add_argument("--name", action="append", help="only this scenario (repeatable)")
    p = bank_cmd("import", "import an archive (all or nothing; every new script verified in the sandbox like add)", _cmd_bank_import)
    p.add_argument("archive")
    p.add_argument("--on-duplicate", choices=["skip", "error"], default="skip")
    bank_cmd("stats", "counts by map, source, road type, tag and participant", _cmd_bank_stats)
    def llm_options(p):
        p.add_argument("--base-url", help="OpenAI-compatible endpoint (default: $DV2S_LLM_BASE_URL)")
        p.add_argument("--model", help="model name (default: $DV2S_LLM_MODEL)")
        p.add_argument("--api-key", help="API key (default: $OPENAI_API_KEY)")

    def video_options(p):
        p.add_argument("--dra", choices=["bev", "openai"], default="bev",
                       help="Driving Record Analyzer: bev (offline, bird's-eye renders) or openai (any VLM endpoint)")
        p.add_argument("--camera", choices=["bev", "front", "rear", "chase"], default="bev", help="camera viewpoint")
        p.add_argument("--question", help='video-specific question, e.g. "Why did the ego vehicle brake?"')

    p = sub.add_parser("describe", help="describe a driving video (DRA)",
                       description="Sample frames from a video and describe it in three sentences, with elements.")
    p.add_argument("video")
    video_options(p)
    p.add_argument("--fps", type=float, default=2.0, help="frames sampled per second (default 2)")
    p.add_argument("--max-frames", type=int, default=16, help="frame cap, spread over the whole video (default 16)")
    p.add_argument("--max-pixels", type=int, default=448 * 448, help="pixel budget per frame (default 448*448)")
    p.add_argument("--json", action="store_true")
    llm_options(p)
    p.set_defaults(func=_cmd_describe)

    p = sub.add_parser("generate", help="turn a description into a validated Scenic scenario (SG)",
                       description="Generate a Scenic script from a description (in quotes or --from FILE), "
                       "check it (safety, compile, sample, run) and render a preview.")
    p.add_argument("description", nargs="?")
    p.add_argument("--from", dest="from_file", help="read the description from this file (e.g. an edited description.txt)")
    p.add_argument("--sg", choices=["rules", "openai"], default="rules")
    p.add_argument("--out", default="out/generated", help="output folder")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--seconds", type=float, default=10.0, help="simulated seconds of the check run")
    p.add_argument("--json", action="store_true")
    llm_options(p)
    p.set_defaults(func=_cmd_generate)

    p = sub.add_parser("convert", help="video -> description -> Scenic scenario (D-V2S end to end)",
                       description="Convert a video (or every video of a folder, in parallel) into a described, "
                       "generated and validated Scenic scenario; optionally add it to the bank.")
    p.add_argument("video", help="a video file or a folder of videos")
    video_options(p)
    p.add_argument("--sg", choices=["rules", "openai"], default="rules")
    p.add_argument("--out", default="out/convert", help="output folder (one subfolder per video in batch mode)")
    p.add_argument("--add-to-bank", action="store_true", help="add validated scenarios to the bank with provenance")
    bank_option(p)
    p.add_argument("--jobs", type=int, default=1, help="parallel processes in batch mode")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--json", action="store_true")
    llm_options(p)
    p.set_defaults(func=_cmd_convert)

    p = sub.add_parser(
        "regress", help="regression-test a policy against a baseline on paired episodes (PASS/FAIL/INCONCLUSIVE)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Run the candidate policy (and the baseline, on the same scenario x seed pairs: episode k "
        "uses seed S+k for both) over bank scenarios, in a local process pool or on Ray. Reports per scenario "
        "and overall collision, off-road and success rates (Wilson intervals), minimum TTC, mean speed and "
        "return (bootstrap intervals), and the paired difference in failure rate (Newcombe interval, exact "
        "McNemar test) with a non-inferiority verdict against --margin. Every scenario is a test in its own "
        "right, beside the pooled one, with the family-wise false-alarm rate at most --alpha. The episodes per "
        "scenario are planned from --mde and --power unless --episodes is given; the report states the power "
        "the run had. Writes "
        "report.json (schema dv2s-regress v1), junit.xml, report.md, results.jsonl and traces/ of failed "
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
    p.add_argument("--seed", type=int, default=None,
                   help="seed of the first episode (default 0, or the baseline report's)")
    p.add_argument("--margin", type=float, default=0.02,
                   help="non-inferiority margin on the failure rate (default 0.02: 2 points, as calibrated in bench/calibrate_regress.py)")
    p.add_argument("--alpha", type=float, default=0.05, help="level of the FAIL test (default 0.05)")
    p.add_argument("--failure", default=None,
                   help="what counts as a failure: a comma-separated list of collision, off_road, stall (default: "
                   "all three; stall: the ego stands with a free road ahead); each kind is also reported apart")
    p.add_argument("--stall-seconds", type=float, default=5.0,
                   help="seconds the ego must stand with a free road ahead for a stall (default 5)")
    p.add_argument("--backend", choices=["local", "ray"], default="local", help="local process pool or Ray")
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
    p.add_argument("--out", default=None, help="output folder (default out/regress)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true", help="print the report JSON instead of the table")
    p.set_defaults(func=_cmd_regress)

    p = sub.add_parser(
        "mine", help="mine a policy's failures: sample scenes, cluster failures, turn them into bank scenarios",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description="Sample scenes (a bank scenario and values of its Scenic parameters, drawn by a VerifAI "
        "sampler that learns from the outcomes), run the policy on each in a local process pool or on Ray, and "
        "detect failures: collision (with whom, and how), off road, time-to-collision under a threshold, stall. "
        "Failures are clustered by scenario, failure class and region of parameter space; a failure counts "
        "against the policy only if the reference driver avoids it in the same scene. With a writable --bank, "
        "one failure per cluster is kept exactly (its parent scenario narrowed around the failing parameters, "
        "with its seed: a 'replay' entry), and is recorded as a bird's-eye video, turned into a Scenic scenario by "
        "the D-V2S pipeline, checked in the sandbox, kept if its runs show the failure's actor and manoeuvre, the "
        "policy fails on it the same way and the reference driver avoids it, and added to the bank with its "
        "provenance. Rerunning with the same --out resumes (a larger --budget continues the run).",
        epilog="examples:\n"
        "  dv2s mine --policy dv2s-ppo --budget 200 --bank my_bank --out out/mine\n"
        "  dv2s mine --policy rule --sampler halton --scenarios tag:highway --budget 500 --no-convert\n"
        "  dv2s mine --policy dv2s-ppo --backend ray --address HEAD:6379 --budget 5000 --bank /shared/bank")
    p.add_argument("--policy", required=True, help="policy spec: rule, idm, keep_lane, random, dv2s-ppo, model.zip, "
                   "ppo:PATH, module:attr, with ?key=value options")
    bank_option(p)
    p.add_argument("--scenarios", nargs="+", help="bank names and/or tag:<tag> (default: the whole bank)")
    p.add_argument("--budget", type=int, default=200, help="episodes to run (default 200)")
    p.add_argument("--sampler", default="novelty-bandit",
                   choices=["random", "halton", "cross-entropy", "bandit", "split", "novelty-bandit"],
                   help="scene sampler (default novelty-bandit); split: VerifAI's cross-entropy over which scenario "
                   "and a Halton sequence per scenario over its parameters; novelty-bandit: the scenarios that keep "
                   "giving failures unlike earlier ones, mixed with uniform, parameters uniform (explore, prior_new, "
                   "prior_old)")
    p.add_argument("--sampler-options", default=None,
                   help="VerifAI settings of cross-entropy/bandit as JSON: alpha (default 0.9), buckets (5), thres (0); "
                   "split also takes chooser (cross-entropy|ucb|epsilon-greedy), params (halton|random|bandit|cross-entropy) "
                   "and warmup (0), and against scenarios that stop yielding: forget, patience, floor, capacity, avoid "
                   "(see dv2s_gym/mining/samplers.py)")
    p.add_argument("--feedback", choices=["robustness", "novelty", "scenario-novelty", "state-novelty"], default=None,
                   help="what adaptive samplers learn from: robustness (every failure), novelty (a failure in a "
                   "parameter cell that already failed counts as an easy scene, to spread the search) or "
                   "scenario-novelty (only each scenario's first failure counts) or state-novelty (a failure whose "
                   "speeds and geometry at the failure are close to an earlier one's in the scenario counts as easy); "
                   "default novelty for split, state-novelty for novelty-bandit, robustness for the others")
    p.add_argument("--seed", type=int, default=0, help="seed of the sampler and the episodes (default 0)")
    p.add_argument("--reference", default="rule",
                   help="driver deciding avoidability (default rule; 'none' skips the check)")
    p.add_argument("--ttc-threshold", type=float, default=1.0, help="low-TTC failure threshold [s] (default 1)")
    p.add_argument("--stall-seconds", type=float, default=5.0,
                   help="seconds standing with nothing in the lane 40 m ahead that count as a stall (default 5)")
    p.add_argument("--backend", choices=["local", "ray"], default="local", help="local process pool or Ray")
    p.add_argument("--workers", type=int, default=None, help="worker processes (default: every core)")
    p.add_argument("--address", default=None, help="with --backend ray: the cluster address")
    p.add_argument("--timeout", type=float, default=None,
                   help="seconds one episode may take before its worker counts as hung (default 600)")
    p.add_argument("--batch", type=int, default=None,
                   help="scenes drawn ahead of the outcomes fed back to the sampler: the sliding window of an "
                        "adaptive sampler, the chunk of random/halton (default 4 per worker)")
    p.add_argument("--config", help="DV2S-v0 config overrides as JSON (or a .json file)")
    p.add_argument("--no-convert", action="store_true", help="only find and cluster failures; add nothing to a bank")
    p.add_argument("--max-conversions", type=int, default=None,
                   help="convert at most this many clusters, those with most avoidable failures first (default: all)")
    p.add_argument("--dra", choices=["bev", "openai"], default="bev", help="DRA backend for failure videos")
    p.add_argument("--sg", choices=["rules", "openai"], default="rules", help="SG backend")
    llm_options(p)
    p.add_argument("-k", type=int, default=10, dest="k",
                   help="scenes the new scenario is run on to check it reproduces the failure (default 10)")
    p.add_argument("--threshold", type=float, default=0.3,
                   help="reproduction rate a new scenario needs to be kept (default 0.3)")
    p.add_argument("--out", default=None, help="run folder (default out/mine)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(func=_cmd_mine)

    p = sub.add_parser("eval", help="SCS/HR (dra), SP (sg) or E2E-SC (e2e) over a labeled folder",
                       description="Evaluate a stage over a folder of videos/descriptions with <name>.label.json "
                       "files; prints mean ± sd per use case and overall.")
    p.add_argument("stage", choices=["dra", "sg", "e2e"])
    p.add_argument("folder", nargs="?", default=None, help="labeled folder (default: the shipped evaluation set)")
    p.add_argument("--dra", choices=["bev", "openai"], default="bev")
    p.add_argument("--sg", choices=["rules", "openai"], default="rules")
    p.add_argument("--jobs", type=int, default=1)
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--json", action="store_true")
    llm_options(p)
    p.set_defaults(func=_cmd_eval)

    p = sub.add_parser("train", help="train a PPO/DQN/SAC policy on the bank (checkpoints, TensorBoard, model card)",
                       description="Train a stable-baselines3 policy on DV2S-v0 over bank scenarios, in parallel "
                       "subprocess envs. Writes checkpoints/, tb/ (TensorBoard), evaluations.jsonl, model.zip and "
                       "model_card.json (+ README.md) in --out; --resume continues the newest checkpoint there. "
                       "Held-out evaluation uses seeds 10000+ per scenario; training never does.")
    p.add_argument("--algo", choices=["ppo", "dqn", "sac"], help="algorithm (default ppo; SAC trains with ContinuousAction)")
    bank_option(p)
    p.add_argument("--scenarios", nargs="*", metavar="NAME", help="bank names or tag:<tag> (default: the whole bank)")
    p.add_argument("--steps", type=int, help="total env steps to train to, across resumes (default 100000)")
    p.add_argument("--envs", type=int, help="environments in parallel subprocesses (default 2)")
    p.add_argument("--seed", type=int, help="seed of the model and the training episodes (default 0)")
    p.add_argument("--out", required=True, help="run folder")
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
    p.add_argument("--card-seeds", type=int, help="seeds per scenario of the model card's evaluation, 0 = none (default 20)")
    p.add_argument("--baselines", nargs="*", metavar="POLICY",
                   help="policies evaluated on the card's episodes for paired comparisons (default: keep_lane rule)")
    p.add_argument("--eval-jobs", type=int, help="processes for the card's evaluation (default 2)")
    p.add_argument("--checkpoint-freq", type=int, help="checkpoint every N env steps, 0 = only at the end (default 10000)")
    p.add_argument("--resume", action="store_true", help="continue the run in --out from its newest checkpoint")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--vec-env", choices=["subproc", "dummy"], default="subproc",
                   help="subproc: envs in worker processes (default); dummy: in this process")
    p.set_defaults(func=_cmd_train)

    from dv2s_gym.mining.loop import DEFAULTS as LOOP

    p = sub.add_parser("loop", help="mine a policy's failures, add them to the bank, fine-tune, measure (a round "
                       "on embedded defaults that keeps scenarios took 45-55 minutes on 2 cores; --budget and "
                       "--max-replays shorten it)",
                       formatter_class=argparse.RawDescriptionHelpFormatter,
                       description="Closed-loop failure mining. Each round: mine the policy's failures (dv2s mine) "
                       "into new bank scenarios in a working bank (out/bank, a copy of the shipped bank, or --bank), "
                       "split them by family (parent bank scenario) into a fine-tuning and a held-out part, "
                       "evaluate the policy on the held-out scenarios (seeds 10000+), fine-tune it on the grown bank "
                       "minus the held-out scenarios and their parents (mined ones upweighted), fine-tune a control "
                       "the same way without any mined scenario, evaluate both on the same episodes (paired: "
                       "relative drop, exact McNemar against the start and against the control), run all three on "
                       "an untouched scenario set (Scenic's CARLA examples) and regression-test new against old on "
                       "the starting bank (dv2s regress statistics). Writes report.json, report.md, report.html to --out; rerunning with the same "
                       "--out and settings resumes (raise --rounds to add rounds).",
                       epilog="examples:\n"
                       "  dv2s loop                                   # one round on dv2s-ppo, out/loop\n"
                       "  dv2s loop --budget 400 --fine-tune-steps 100000 --k-eval 10 --out out/loop-big\n"
                       "  dv2s loop --policy ppo:out/train/my_ppo/model.zip --rounds 3")
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
    p.add_argument("--max-conversions", type=int, default=LOOP["max_conversions"],
                   help="failure clusters converted into bank scenarios per round, largest first; 0 converts every "
                   f"cluster (default {LOOP['max_conversions']})")
    p.add_argument("--max-replays", default=str(LOOP["max_replays"]),
                   help="failure clusters beyond the converted ones whose failing scene is kept as an exact replay "
                   "entry (the parent scenario narrowed around the failure, checked to replay it step for step) per "
                   f"round, largest first; 0 for none, 'all' for every cluster (default {LOOP['max_replays']})")
    p.add_argument("--min-heldout-episodes", type=int, default=LOOP["min_heldout_episodes"],
                   help="below this many held-out episodes a round reports rates only, no drop and no test "
                   f"(default {LOOP['min_heldout_episodes']})")
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
    p.add_argument("--envs", type=int, default=2, help="training environments (default 2)")
    p.add_argument("--out", default=None, help="loop folder (default out/loop; rerunning resumes it)")
    p.add_argument("--no-progress", action="store_true", help="no progress bars")
    p.set_defaults(func=_cmd_loop)
    return parser


def _error_line(error: BaseException) -> str:
    """One line for the user: the project's errors say what is wrong and the fix; others get their type."""
    message = " ".join(str(error).split())
    if message and (isinstance(error, DV2SError) and error.expected or isinstance(error, ValueError)):
        return message
    if isinstance(error, OSError) and error.strerror:
        where = f": {error.filename}" if error.filename and str(error.filename) not in message else ""
        return f"{message}{where}"
    if isinstance(error, FileNotFoundError) and message:
        return message   # raised with a sentence of its own ("scenario file ... does not exist")
    return f"{type(error).__name__}: {message}" if message else type(error).__name__


_RESUME_NOTES = {
    "loop": "finished steps are kept in {out} (loop.json); rerun the same command to resume",
    "train": "rerun the same command with --resume to continue from the last checkpoint",
}
"""What an interrupted command kept, for commands whose own code does not say it more precisely."""


def _resume_note(args) -> Optional[str]:
    note = _RESUME_NOTES.get(args.command)
    return note.format(out=getattr(args, "out", None) or "the output folder") if note else None


class _SigintFlag:
    """Notes whether Ctrl-C arrived while a command ran (the default handler still raises KeyboardInterrupt)."""

    def __init__(self) -> None:
        self.received = False
        self._previous = None

    def _handle(self, signum, frame) -> None:
        self.received = True
        signal.default_int_handler(signum, frame)

    def __enter__(self) -> "_SigintFlag":
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, self._handle)
        return self

    def __exit__(self, *exc) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)


def main(argv: Optional[List[str]] = None) -> int:
    """Entry point of the ``dv2s`` console command.

    Exit status: 0 success, 1 a check failed (validation, generation; ``regress``: FAIL),
    2 an error (one line on stderr; ``--debug`` prints the traceback), 3 ``regress``
    INCONCLUSIVE, 4 ``regress`` ERROR (an episode ended in an error), 130 interrupted.
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    sigint = _SigintFlag()
    try:
        with sigint:
            return int(args.func(args) or 0)
    except KeyboardInterrupt as stop:
        note = getattr(stop, "note", None) or _resume_note(args)
        print("dv2s: interrupted" + (f"; {note}" if note else ""), file=sys.stderr)
        return 130
    except BrokenPipeError:
        # the reader of our output went away (`dv2s bank list | head`): stop quietly, as Unix tools do
        _silence_stdout()
        return 141
    except Exception as error:  # every error reaches the user as one line, never a raw traceback
        if sigint.received:  # e.g. a broken pipe to a worker that Ctrl-C stopped first
            note = _resume_note(args)
            print("dv2s: interrupted" + (f"; {note}" if note else ""), file=sys.stderr)
            return 130
        if args.debug:
            import traceback

            traceback.print_exc()
        known = _is_project_error(error)
        hint = "" if known or args.debug else " (an unexpected error: rerun with --debug for the traceback)"
        print(f"dv2s: error: {_error_line(error)}{hint}", file=sys.stderr)
        return 2


def _silence_stdout() -> None:
    """Point stdout at /dev/null so Python's flush at exit does not fail again on the closed pipe."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass


def _is_project_error(error: BaseException) -> bool:
    """An error whose message explains it: every expected :class:`DV2SError` (bad input, a script that hits a jail
    limit, a machine without the jail), and a bad value or a file problem from elsewhere."""
    if isinstance(error, DV2SError):
        return error.expected
    return isinstance(error, (ValueError, OSError))


if __name__ == "__main__":
    sys.exit(main())
