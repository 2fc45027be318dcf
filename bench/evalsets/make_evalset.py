"""Build the labeled evaluation set: bird's-eye clips of bank scenarios with ground-truth labels.

For every chosen bank scenario, seeds ``0 .. per_scenario - 1`` are rendered, one
``DV2S-v0`` episode each (:func:`bench.evalsets.make_bev_clips.render_clip`),
the ego driven by the rule-based driver, or by the script's own ego behaviour where
the label asks the ego for a manoeuvre (a turn, a lane change), chosen per scenario; and labeled
with the scenario's semantic elements from its bank sidecar. Every seed drawn is
kept: no seed is skipped for not playing its story (the bank's scenarios play
their story in at least 90% of seeds whatever the ego does, checked by
``dv2s bank validate --story``). Where the elements read off an episode's trace
(:func:`dv2s_gym.pipeline.semantics.trace.elements_from_trace`) miss a labeled
element or show a collision the label does not name, the clip is still kept and
the README lists the difference.

Command line::

    python -m bench.evalsets.make_evalset OUT_DIR [--scenario NAME ...] [--per-scenario 3]
        [--seconds 10] [--size 480]

writes ``OUT_DIR/<scenario>_seed<seed>.webm`` and ``<scenario>_seed<seed>.label.json``
(``{"use_case", "scenario", "seed", "description", "elements"}``, the format
``dv2s eval`` reads) and ``OUT_DIR/README.md`` listing the clips and where an episode differs from its label.
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
    # A careful ego waits behind the standing car, which drives off only when the ego comes near and
    # stops again 10-12 s in.
    "urban_lead_vehicle_accelerates_then_stops": 16.0,
    # A careful ego follows the turning car 60-80 m to the junction, slowing behind it.
    "urban_lead_vehicle_turns": 16.0,
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
                  per_scenario: int = 3, seconds: float = 10.0, size: int = 480,
                  progress: bool = True) -> Dict[str, Any]:
    """Render and label seeds ``0 .. per_scenario - 1`` of each scenario into ``out``.

    Returns ``{"kept": {scenario: [seeds]}, "differs": {scenario: ["seed N: what differs"]}}``.
    """
    from tqdm import tqdm

    from bench.evalsets.make_bev_clips import render_clip
    from dv2s_gym.pipeline.semantics.trace import elements_from_trace
    from scenario_bank.bank import Bank

    bank = Bank()
    names = list(scenarios) if scenarios else [e.name for e in bank.list()]
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    kept: Dict[str, List[int]] = {}
    differs: Dict[str, List[str]] = {}
    bar = tqdm(total=len(names) * per_scenario, desc="evalset", unit="clip", disable=not progress)
    for name in names:
        entry = bank.get(name)
        label = entry.elements.to_dict()
        kept[name], differs[name] = [], []
        length = CLIP_SECONDS.get(name, seconds)
        policy = _ego_driver(entry, label)
        for seed in range(per_scenario):
            stem = f"{name}_seed{seed}"
            summary = render_clip(name, seed, out / f"{stem}.webm", seconds=length, size=size, ego_policy=policy)
            problem = story_problem(label, elements_from_trace(summary["trace"]).to_dict())
            if problem:
                differs[name].append(f"seed {seed} ({policy} ego): {problem}")
            record = {"use_case": entry.sidecar.use_case or name, "scenario": name, "seed": seed,
                      "seconds": length, "ego_policy": policy, "description": entry.description,
                      "elements": label}
            (out / f"{stem}.label.json").write_text(json.dumps(record, indent=1, sort_keys=True) + "\n",
                                                    encoding="utf-8")
            kept[name].append(seed)
            bar.update()
    bar.close()
    _write_readme(out, kept, differs, size)
    return {"kept": kept, "differs": differs}


EGO_MANEUVERS = frozenset({"turn_left", "turn_right", "lane_change_left", "lane_change_right", "u_turn",
                           "overtake", "merge", "cut_in"})
"""Labeled ego actions the rule-based driver does not perform (it keeps its lane and follows its route)."""


def _ego_driver(entry, label: Dict[str, Any]) -> str:
    """Who drives the ego in a scenario's clips, decided per scenario (never per seed).

    The script's own ego behaviour (``"scenic"``) when the label asks the ego for a manoeuvre
    the rule-based driver does not make and the script has an ego behaviour; otherwise the
    rule-based driver (``"agent"``), which drives like a careful human and does not run into
    the scene's adversary the way a script's lane-following ego at constant speed does.
    """
    from envs.scenarios import compile_scenario

    wants_maneuver = any(actor == "ego" and action in EGO_MANEUVERS for actor, action in label.get("actions", []))
    has_behavior = compile_scenario(entry.script, name=entry.name).scenario.egoObject.behavior is not None
    return "scenic" if wants_maneuver and has_behavior else "agent"


def _write_readme(out: Path, kept: Dict[str, List[int]], differs: Dict[str, List[str]], size: int) -> None:
    lines = [
        "# dv2s-gym evaluation set",
        "",
        "Bird's-eye clips (VP8 `.webm`, 5 fps, {0}x{0} px) of bank scenarios, each one `DV2S-v0` episode (the ego"
        .format(size),
        "driven by the rule-based driver, or by the script's ego behaviour where the label asks the ego for a",
        "manoeuvre such as a turn or a lane change: `ego_policy` in the label; chosen per scenario, never per seed), and",
        "`<clip>.label.json` holding the ground-truth semantic elements (the scenario's sidecar elements) and",
        "reference description. Seeds 0 .. N-1 of every scenario (N clips each), none skipped; episodes whose trace",
        "misses a labeled element or shows an unlabeled collision are listed below.",
        "Rebuild with `python -m bench.evalsets.make_evalset dv2s_gym/evalset` (deterministic).",
        "",
        "| scenario | seeds | differ from label |",
        "|---|---|---|",
    ]
    for name in kept:
        lines.append(f"| {name} | {', '.join(map(str, kept[name]))} | {len(differs[name])} |")
    lines += ["", "## Episodes that differ from their label", ""]
    for name, reasons in differs.items():
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
    args = parser.parse_args(argv)
    result = build_evalset(args.out, args.scenario, per_scenario=args.per_scenario, seconds=args.seconds,
                           size=args.size)
    for name, reasons in result["differs"].items():
        for reason in reasons:
            print(f"{name}: {reason}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
