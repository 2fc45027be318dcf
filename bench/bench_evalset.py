"""The offline backends' figures on the two whole evaluation sets, checked against targets and measured figures.

    python -m bench.bench_evalset                    # both sets, DRA and end to end
    python -m bench.bench_evalset --set external     # only bench/evalsets/highway_env
    python -m bench.bench_evalset --stage dra        # only the DRA figures

Sets: ``in-house`` is ``dv2s_gym/evalset`` (96 clips: 3 of each of the 32 bank scenarios in DV2S-v0), ``external``
is ``bench/evalsets/highway_env`` (66 clips rendered by stock highway-env). Backends: the bev DRA and the rules
SG. Checks (the in-house ones are targets: the paper's figures to beat; the external ones are floors at a
measured value less ``MARGIN``, ceilings at one plus it):

* in-house DRA: every clip described, SCS >= 0.90 and HR <= 0.10 overall;
* in-house end to end: every clip converted, E2E-SC >= 0.90 overall, >= 0.80 per use case except exactly the
  use cases in ``KNOWN_E2E_MISSES`` (each still >= 0.70), no generated script with a failure;
* external DRA and end to end: the overall and per-use-case figures of ``EXTERNAL_DRA_MEASURED`` /
  ``EXTERNAL_E2E_MEASURED`` (``bench/evalsets/highway_env/README.md`` states them).

Measured on 2026-11-27 (2 cores shared with other jobs, no GPU; in-house set 6 min 54 s wall): the in-house SCS
(0.860), its E2E-SC (0.879) and the >= 0.70 floor of three known misses (the two cyclist use cases, the car passing behind
the slow truck) fall short; every other check passes
(``docs/results.md``, ``bench/RESULTS.md``).

Prints each set's per-use-case table and one line per check; exits 1 when a check fails. The unit tests
(tests/test_evalset.py, tests/test_external_evalset.py) run the same pipeline on one clip per use case.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from typing import Any, Callable, Dict, List, Tuple

os.environ.setdefault("OMP_NUM_THREADS", "1")

MARGIN = 0.03

# the in-house use cases under 0.80, with E2E-SC measured on 2026-11-27 (3 clips each) and what loses it
KNOWN_E2E_MISSES = {
    # the clips show the two cars colliding as they merge (the script's own ego collides); the DRA describes the
    # collision and misses the lane changes (both in two clips, the ego's in the third), so the run lacks them
    "highway_simultaneous_merge_middle": 0.72,
    # the car overtakes the ego before it cuts in; the DRA reads the cut-in (and a brake), not the overtake
    "highway_cut_in_from_left": 0.78,
    "highway_cut_in_from_right": 0.78,
    # the DRA reads the car passing behind the slow truck as a cut-in that brakes, and not the truck at all
    "highway_fast_car_passes_behind_slow_truck": 0.54,
    # the ramp car's acceleration is read as a brake ("merges into the lane in front of it and suddenly brakes"),
    # so the generated run has no acceleration
    "insertion_highway": 0.78,
    # the DRA sees no cyclist ("no other road user comes near the ego car"): no bicycle, crossing or go-straight
    "urban_cyclist_crossing_paths": 0.50,
    "urban_left_turn_across_cyclist": 0.43,
    # the lead car is described as standing still ahead; its acceleration and its braking are not read
    "urban_lead_vehicle_accelerates_then_stops": 0.75,
}

# measured (bev DRA, rules SG) over the 66 clips (the 51 first ones and the 15 of stock classes, scales,
# roundabout and stock traffic): per use case (SCS, HR) on 2026-11-23, the same on 2026-11-27; E2E-SC on 2026-11-27
EXTERNAL_DRA_MEASURED = {
    "crossing_paths": (1.000, 0.000), "cut_in": (0.958, 0.000), "ego_lane_change": (1.000, 0.083),
    "ego_turn": (1.000, 0.000), "lead_vehicle_brakes": (1.000, 0.000), "lead_vehicle_stopped": (0.833, 0.000),
    "left_turn_oncoming": (1.000, 0.000), "obstacle_in_lane": (1.000, 0.048), "on_ramp_merge": (0.917, 0.000),
    "overtake": (0.500, 0.000), "roundabout": (0.944, 0.217), "turn_into_path": (1.000, 0.000),
}
EXTERNAL_DRA_OVERALL = (0.941, 0.039)
EXTERNAL_E2E_MEASURED = {
    "crossing_paths": 1.000, "cut_in": 0.958, "ego_lane_change": 1.000, "ego_turn": 1.000,
    "lead_vehicle_brakes": 1.000, "lead_vehicle_stopped": 0.944, "left_turn_oncoming": 1.000,
    "obstacle_in_lane": 1.000, "on_ramp_merge": 0.500, "overtake": 0.500, "roundabout": 0.738,
    "turn_into_path": 1.000,
}
EXTERNAL_E2E_OVERALL = 0.885

Check = Tuple[str, bool]


def in_house_dra_checks(report: Dict[str, Any]) -> List[Check]:
    overall = report["summary"]["overall"]
    return [("every clip described", overall["ok_rate"] == 1.0),
            (f"SCS {overall['SCS']['mean']:.3f} >= 0.90", overall["SCS"]["mean"] >= 0.90),
            (f"HR {overall['HR']['mean']:.3f} <= 0.10", overall["HR"]["mean"] <= 0.10)]


def in_house_e2e_checks(report: Dict[str, Any]) -> List[Check]:
    summary = report["summary"]
    low = {name: block["E2E-SC"]["mean"] for name, block in summary["per_use_case"].items()
           if block["E2E-SC"]["mean"] < 0.80}
    failed = [item["stem"] for item in report["items"] if item["detail"].get("failures")]
    overall = summary["overall"]["E2E-SC"]["mean"]
    return [("every clip converted", summary["overall"]["ok_rate"] == 1.0),
            (f"E2E-SC {overall:.3f} >= 0.90", overall >= 0.90),
            (f"use cases under 0.80 {sorted(low)} are the known ones", set(low) == set(KNOWN_E2E_MISSES)),
            (f"the known ones still >= 0.70 (under: {sorted(name for name, value in low.items() if value < 0.70)})",
             all(value >= 0.70 for value in low.values())),
            (f"no generated script with a failure {failed}", not failed)]


def external_dra_checks(report: Dict[str, Any]) -> List[Check]:
    summary = report["summary"]
    overall = summary["overall"]
    checks = [("every clip described", overall["ok_rate"] == 1.0),
              (f"SCS {overall['SCS']['mean']:.3f} >= {EXTERNAL_DRA_OVERALL[0] - MARGIN:.3f}",
               overall["SCS"]["mean"] >= EXTERNAL_DRA_OVERALL[0] - MARGIN),
              (f"HR {overall['HR']['mean']:.3f} <= {EXTERNAL_DRA_OVERALL[1] + MARGIN:.3f}",
               overall["HR"]["mean"] <= EXTERNAL_DRA_OVERALL[1] + MARGIN),
              ("the use cases measured", set(summary["per_use_case"]) == set(EXTERNAL_DRA_MEASURED))]
    for name, (scs, hr) in EXTERNAL_DRA_MEASURED.items():
        block = summary["per_use_case"].get(name, {"SCS": {"mean": 0.0}, "HR": {"mean": 1.0}})
        checks.append((f"{name}: SCS {block['SCS']['mean']:.3f} >= {scs - MARGIN:.3f}, "
                       f"HR {block['HR']['mean']:.3f} <= {hr + MARGIN:.3f}",
                       block["SCS"]["mean"] >= scs - MARGIN and block["HR"]["mean"] <= hr + MARGIN))
    return checks


def external_e2e_checks(report: Dict[str, Any]) -> List[Check]:
    summary = report["summary"]
    overall = summary["overall"]["E2E-SC"]["mean"]
    checks = [(f"E2E-SC {overall:.3f} >= {EXTERNAL_E2E_OVERALL - MARGIN:.3f}", overall >= EXTERNAL_E2E_OVERALL - MARGIN),
              ("the use cases measured", set(summary["per_use_case"]) == set(EXTERNAL_E2E_MEASURED))]
    for name, value in EXTERNAL_E2E_MEASURED.items():
        got = summary["per_use_case"].get(name, {"E2E-SC": {"mean": 0.0}})["E2E-SC"]["mean"]
        checks.append((f"{name}: E2E-SC {got:.3f} >= {value - MARGIN:.3f}", got >= value - MARGIN))
    return checks


def _runs() -> Dict[Tuple[str, str], Tuple[Any, Callable[[Dict[str, Any]], List[Check]]]]:
    from dv2s_gym.pipeline.evaluate import EVALSET_DIR
    from bench.evalsets.make_external_evalset import EXTERNAL_EVALSET_DIR

    return {("in-house", "dra"): (EVALSET_DIR, in_house_dra_checks),
            ("in-house", "e2e"): (EVALSET_DIR, in_house_e2e_checks),
            ("external", "dra"): (EXTERNAL_EVALSET_DIR, external_dra_checks),
            ("external", "e2e"): (EXTERNAL_EVALSET_DIR, external_e2e_checks)}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--set", choices=("in-house", "external", "both"), default="both")
    parser.add_argument("--stage", choices=("dra", "e2e", "both"), default="both")
    parser.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    args = parser.parse_args(argv)

    from dv2s_gym.pipeline.evaluate import evaluate, format_results

    failed = 0
    for (name, stage), (folder, checks) in _runs().items():
        if args.set not in ("both", name) or args.stage not in ("both", stage):
            continue
        start = time.perf_counter()
        report = evaluate(stage, folder, jobs=args.jobs, progress=True)
        print(f"\n== {name} set, {stage} ({len(report['items'])} clips, {time.perf_counter() - start:.0f} s wall)")
        print(format_results(report))
        for text, ok in checks(report):
            print(f"{'ok  ' if ok else 'FAIL'} {text}")
            failed += not ok
    if failed:
        print(f"\n{failed} check(s) failed")
        sys.exit(1)


if __name__ == "__main__":
    main()
