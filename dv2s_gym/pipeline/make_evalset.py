"""Build the labeled evaluation set: bird's-eye clips of bank scenarios with ground-truth labels.

For every chosen bank scenario and seed, one ``DV2S-v0`` episode is rendered
(:func:`dv2s_gym.pipeline.make_bev_clips.render_clip`), the ego driven by the
script's own ego behaviour when it has one (the scenario as written, ego actions
included) and otherwise, or when that episode does not play the story, by the
rule-based driver; and labeled with the
scenario's semantic elements from its bank sidecar. A clip is kept only when its
episode shows what the label says: the elements read off the episode's trace
(:func:`dv2s_gym.pipeline.trace_semantics.elements_from_trace`) must hold every
labeled element, and the episode must have no collision the label does not name.
A seed whose episode does not play its story (the cut-in came after the clip
ended, say) is skipped and the next seed is tried, as a person labeling clips
would drop a clip that does not show the event.

Command line::

    python -m dv2s_gym.pipeline.make_evalset OUT_DIR [--scenario NAME ...] [--per-scenario 3]
        [--seconds 10] [--size 480] [--max-seed 40]

writes ``OUT_DIR/<scenario>_seed<seed>.webm`` and ``<scenario>_seed<seed>.label.json``
(``{"use_case", "scenario", "seed", "description", "elements"}``, the format
``dv2s eval`` reads) and ``OUT_DIR/README.md`` listing what was kept and skipped.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence

__all__ = ["CLIP_SECONDS", "build_evalset", "story_problem", "main"]

CLIP_SECONDS: Dict[str, float] = {
    # The on-ramp car reaches the end of its acceleration lane 10-14 s in.
    "highway_onramp_insertion": 16.0,
}
"""Clip lengths that differ from the default (the scripted event happens later)."""


def story_problem(label: Dict[str, Any], shown: Dict[str, Any]) -> Optional[str]:
    """Why a clip whose trace shows ``shown`` does not illustrate ``label``; None if it does."""
    from scenario_bank.elements import element_set

    missing = element_set(label) - element_set(shown)
    if missing:
        return "the episode does not show " + ", ".join(" ".join(map(str, e)) for e in sorted(missing, key=str))
    labeled = {tuple(a) for a in label.get("actions", [])}
    unlabeled = sorted({tuple(a) for a in shown.get("actions", []) if a[1] == "collide"} - labeled)
    if unlabeled:
        return f"the episode has an unlabeled collision ({unlabeled})"
    return None


def build_evalset(out: str | os.PathLike, scenarios: Optional[Sequence[str]] = None, *,
                  per_scenario: int = 3, seconds: float = 10.0, size: int = 480, max_seed: int = 40,
                  progress: bool = True) -> Dict[str, Any]:
    """Render and label ``per_scenario`` clips of each scenario into ``out``; returns what was kept/skipped."""
    from tqdm import tqdm

    from dv2s_gym.pipeline.make_bev_clips import render_clip
    from dv2s_gym.pipeline.trace_semantics import elements_from_trace
    from scenario_bank.bank import Bank
    from scenario_bank.elements import normalize_elements

    bank = Bank()
    names = list(scenarios) if scenarios else [e.name for e in bank.list()]
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    kept: Dict[str, List[int]] = {}
    skipped: Dict[str, List[str]] = {}
    bar = tqdm(total=len(names) * per_scenario, desc="evalset", unit="clip", disable=not progress)
    for name in names:
        entry = bank.get(name)
        label = normalize_elements(entry.elements)
        kept[name], skipped[name] = [], []
        length = CLIP_SECONDS.get(name, seconds)
        policies = ("scenic", "agent") if _ego_has_behavior(entry) else ("agent",)
        for seed in range(max_seed):
            if len(kept[name]) == per_scenario:
                break
            stem = f"{name}_seed{seed}"
            video = out / f"{stem}.webm"
            problems = []
            for policy in policies:
                summary = render_clip(name, seed, video, seconds=length, size=size, ego_policy=policy)
                problem = story_problem(label, elements_from_trace(summary["trace"]))
                if problem is None:
                    break
                problems.append(f"{policy} ego: {problem}")
            if problem:
                video.unlink()
                skipped[name].append(f"seed {seed}: " + "; ".join(problems))
                continue
            record = {"use_case": entry.meta.get("use_case") or name, "scenario": name, "seed": seed,
                      "seconds": length, "ego_policy": policy, "description": entry.description,
                      "elements": label}
            (out / f"{stem}.label.json").write_text(json.dumps(record, indent=1, sort_keys=True) + "\n",
                                                    encoding="utf-8")
            kept[name].append(seed)
            bar.update()
    bar.close()
    _write_readme(out, kept, skipped, size)
    return {"kept": kept, "skipped": skipped}


def _ego_has_behavior(entry) -> bool:
    from envs.scenarios import compile_scenario

    return compile_scenario(entry.script, name=entry.name).scenario.egoObject.behavior is not None


def _write_readme(out: Path, kept: Dict[str, List[int]], skipped: Dict[str, List[str]], size: int) -> None:
    lines = [
        "# dv2s-gym evaluation set",
        "",
        "Bird's-eye clips (VP8 `.webm`, 5 fps, {0}x{0} px) of bank scenarios, each one `DV2S-v0` episode (the ego"
        .format(size),
        "driven by the script's ego behaviour, or by the rule-based driver: `ego_policy` in the label), and",
        "`<clip>.label.json` holding the ground-truth semantic elements (the scenario's sidecar elements) and",
        "reference description. A seed was kept only when the elements read off its",
        "episode trace contain every labeled element and no unlabeled collision; skipped seeds are listed.",
        "Rebuild with `python -m dv2s_gym.pipeline.make_evalset dv2s_gym/evalset` (deterministic).",
        "",
        "| scenario | kept seeds | skipped |",
        "|---|---|---|",
    ]
    for name in kept:
        lines.append(f"| {name} | {', '.join(map(str, kept[name]))} | {len(skipped[name])} |")
    lines += ["", "## Skipped seeds", ""]
    for name, reasons in skipped.items():
        lines += [f"- {name}: {reason}" for reason in reasons]
    (out / "README.md").write_text("\n".join(lines) + "\n", encoding="utf-8")


def main(argv: Optional[Sequence[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("out", help="output folder")
    parser.add_argument("--scenario", action="append", help="bank scenario (repeatable; default: the whole bank)")
    parser.add_argument("--per-scenario", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--size", type=int, default=480)
    parser.add_argument("--max-seed", type=int, default=40)
    args = parser.parse_args(argv)
    result = build_evalset(args.out, args.scenario, per_scenario=args.per_scenario, seconds=args.seconds,
                           size=args.size, max_seed=args.max_seed)
    short = [n for n, seeds in result["kept"].items() if len(seeds) < args.per_scenario]
    for name in short:
        print(f"{name}: only {len(result['kept'][name])} clips play the story", file=sys.stderr)
    return 1 if short else 0


if __name__ == "__main__":
    sys.exit(main())
