"""The D-V2S pipeline's commands: ``dv2s describe`` (DRA), ``dv2s generate`` (SG) and ``dv2s convert`` (both,
video to validated scenario, optionally into the bank)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import TYPE_CHECKING

from dv2s_gym.cli.backend_options import sg_option
from dv2s_gym.cli.errors import UsageError
from dv2s_gym.cli.inputs import description_text, input_file, llm_config, output_folder, seed_value
from dv2s_gym.cli.output import emit, json_text
from dv2s_gym.cli.parser import bank_option, llm_options, video_options
from dv2s_gym.pipeline.stages import describe, Description

if TYPE_CHECKING:  # the pipeline is imported when a command runs
    from dv2s_gym.pipeline.convert import ConversionReport

__all__ = ["add_parser", "report_text", "run_convert", "run_describe", "run_generate"]


def add_parser(subparsers) -> None:
    """Add ``describe``, ``generate`` and ``convert`` to the ``dv2s`` subcommands."""
    p = subparsers.add_parser("describe", help="describe a driving video (DRA)",
                              description="Sample frames from a video and describe it in three sentences, with elements.")
    p.add_argument("video")
    video_options(p)
    p.add_argument("--fps", type=float, default=2.0, help="frames sampled per second (default 2)")
    p.add_argument("--max-frames", type=int, default=16, help="frame cap, spread over the whole video (default 16)")
    p.add_argument("--max-pixels", type=int, default=448 * 448, help="pixel budget per frame (default 448*448)")
    p.add_argument("--json", action="store_true")
    llm_options(p)
    p.set_defaults(func=run_describe)

    p = subparsers.add_parser("generate", help="turn a description into a validated Scenic scenario (SG)",
                              description="Generate a Scenic script from a description (in quotes or --from FILE), "
                              "check it (safety, compile, sample, run) and render a preview.")
    p.add_argument("description", nargs="?")
    p.add_argument("--from", dest="from_file", type=input_file, help="read the description from this file (e.g. an edited description.txt)")
    sg_option(p)
    p.add_argument("--out", default="out/generated", type=output_folder, help="output folder")
    p.add_argument("--seed", type=seed_value, default=0)
    p.add_argument("--seconds", type=float, default=10.0, help="simulated seconds of the check run")
    p.add_argument("--json", action="store_true")
    llm_options(p)
    p.set_defaults(func=run_generate)

    p = subparsers.add_parser("convert", help="video -> description -> Scenic scenario (D-V2S end to end)",
                              description="Convert a video (or every video of a folder, in parallel) into a described, "
                              "generated and validated Scenic scenario; optionally add it to the bank.")
    p.add_argument("video", help="a video file or a folder of videos")
    video_options(p)
    sg_option(p)
    p.add_argument("--out", default="out/convert", type=output_folder, help="output folder (one subfolder per video in batch mode)")
    p.add_argument("--add-to-bank", action="store_true", help="add validated scenarios to the bank with provenance "
                                                               "(--bank names it)")
    bank_option(p)
    p.add_argument("--jobs", type=int, default=1, help="parallel processes in batch mode")
    p.add_argument("--seed", type=seed_value, default=0)
    p.add_argument("--seconds", type=float, default=10.0)
    p.add_argument("--json", action="store_true")
    llm_options(p)
    p.set_defaults(func=run_convert)


def run_describe(args: argparse.Namespace) -> int:
    """``dv2s describe``: the video's description and its elements."""
    result = describe(args.video, backend=args.dra, camera=args.camera, question=args.question, fps=args.fps,
                      max_frames=args.max_frames, max_pixels=args.max_pixels, llm_config=llm_config(args))
    emit(args, result.as_dict(), f"{result.text}\n\nelements: {json.dumps(result.elements.to_dict())}")
    return 0


def run_generate(args: argparse.Namespace) -> int:
    """``dv2s generate``: a checked scenario from a description; exit 1 if its checks fail or nothing of the
    description could be placed."""
    from dv2s_gym.pipeline.convert import generate_to_folder, generated, placed_nothing
    from dv2s_gym.pipeline.semantics.text import elements_from_text

    if args.from_file:
        text = Path(args.from_file).read_text(encoding="utf-8")
    elif args.description:
        text = description_text(args.description)
    else:
        raise UsageError("give a description in quotes or --from FILE")
    description = Description(text.strip(), elements_from_text(text), backend="user")
    report = generate_to_folder(description, Path(args.out), sg=args.sg, seed=args.seed,
                                llm_config=llm_config(args), seconds=args.seconds)
    emit(args, report.to_json(), report_text(report, args.out, nothing_placed=placed_nothing(report)))
    return 0 if generated(report) else 1


NOTHING_PLACED = ("nothing of the description could be placed, so the script only has the ego driving: name the "
                  "road and its road users (car, truck, pedestrian, cyclist, obstacle) and what they do, e.g. "
                  "'on a highway, a car ahead of the ego brakes suddenly'")


def report_text(report: "ConversionReport", out, nothing_placed: bool = False) -> str:
    """A conversion's report as text: the description, what failed, the checks, the scores and the files;
    with ``nothing_placed``, the line saying so and how to fix it in place of the warnings and the SP."""
    check = report.check
    lines = [f"description: {report.description.text}"]
    if not nothing_placed:
        lines.extend(f"warning: {warning}" for warning in report.warnings)
    if report.generation_error is not None:
        lines.append(f"generation failed: {report.generation_error}")
    if check is not None:
        stages = " ".join(f"{k}={'ok' if getattr(check, k) else 'FAIL'}"
                          for k in ("safe", "compiled", "sampled", "ran"))
        lines.append(f"checks: {stages}" + (f" ({check.error})" if check.error else ""))
    for name, score, partial in (("SP", report.sp, report.partial_sp), ("E2E-SC", report.e2e_sc, False)):
        if score is not None and not nothing_placed:
            lines.append(f"{name}: {score:.2f}"
                         + (" (of the parts of the description that were placed)" if partial else ""))
    files = report.files
    lines.append(f"written to {out}/ ({', '.join(files)})" if files else f"nothing written to {out}/")
    if nothing_placed:
        lines.append(NOTHING_PLACED)
    return "\n".join(lines)


def run_convert(args: argparse.Namespace) -> int:
    """``dv2s convert``: each video to a checked scenario (added to the bank with ``--add-to-bank``); exit 1 if
    any conversion's checks fail."""
    from dv2s_gym.pipeline.batch_convert import convert_videos, videos_to_convert
    from dv2s_gym.pipeline.convert import ConvertSettings, add_converted, checks_passed

    if args.bank is not None and not args.add_to_bank:
        raise UsageError(f"--bank {args.bank} names the bank converted scenarios are added to, and nothing is "
                         "added without --add-to-bank, so it would be ignored: add --add-to-bank, or drop --bank")
    pairs = videos_to_convert(args.video, args.out)
    settings = ConvertSettings(dra=args.dra, sg=args.sg, camera=args.camera, question=args.question, seed=args.seed,
                               llm_config=llm_config(args), seconds=args.seconds)
    reports = convert_videos(pairs, settings, jobs=args.jobs, progress=not args.json)
    added = []
    if args.add_to_bank:
        added = [add_converted(args.bank, v, o, r, seed=args.seed, dra=args.dra, sg=args.sg)
                 for (v, o), r in zip(pairs, reports)]
    if args.json:
        print(json_text({"reports": [report.to_json() for report in reports], "added": added}))
    else:
        for (v, o), r in zip(pairs, reports):
            print(f"== {v}\n{report_text(r, o)}")
        for name in added:
            print(f"added to bank: {name}")
    return 0 if all(checks_passed(r) for r in reports) else 1
