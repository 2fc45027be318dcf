"""D-V2S pipeline speed: seconds of ``convert`` per 10-second video, offline backends, one core.

    python -m bench.bench_convert [--per-scenario 1]

Each video of the shipped evaluation set (one per scenario by default) goes
through :func:`dv2s_gym.pipeline.convert.convert_video` with ``--dra bev --sg
rules`` in this process (one core: OpenCV threads pinned to 1): read and sample the
video, describe it, generate the Scenic script, check it (safety, compile, sample,
a 10 s DV2S-v0 run), render the preview video and write the output folder.
Baseline: the paper's 19.08 s per video with GPT-4o; target: at most
2 s per 10 s of video. Prints the time per video, mean/median/max per 10 s of video and
the ratio to the paper.

It also times what a user waits for: ``python -m dv2s_gym.cli convert <clip>`` of
one clip as a whole new process (interpreter start, imports, first map load and
compile included), first with an empty parse cache (a first run after install) and
then with it filled (every later run), median of ``--cold-runs`` each.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
if os.environ.get("SDL_VIDEODRIVER", "dummy") == "dummy":
    os.environ["SDL_VIDEODRIVER"] = "offscreen"

PAPER_SECONDS_PER_VIDEO = 19.08
TARGET_PER_10S = 2.0
ROOT = Path(__file__).resolve().parents[1]


def cold_convert_seconds(video: Path, runs: int) -> dict:
    """Wall time of ``dv2s convert <video>`` in a new process: empty parse cache, then filled."""
    times = {"empty cache": [], "filled cache": []}
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))}
    with tempfile.TemporaryDirectory() as tmp:
        command = [sys.executable, "-m", "dv2s_gym.cli", "convert", str(video), "--out", str(Path(tmp) / "out")]
        for k in range(runs):
            for label in times:
                # one new cache folder per round: its first run fills it, the second reads it
                env["DV2S_CACHE_DIR"] = str(Path(tmp) / f"cache-{k}")
                start = time.perf_counter()
                done = subprocess.run(command, env=env, cwd=tmp, capture_output=True, text=True)
                times[label].append(time.perf_counter() - start)
                if done.returncode != 0:
                    raise RuntimeError(f"{' '.join(command)} failed:\n{done.stderr[-2000:]}")
    return {label: statistics.median(values) for label, values in times.items()}


def main(argv=None) -> int:
    import cv2

    from dv2s_gym.pipeline.convert import checks_passed, convert_video
    from dv2s_gym.pipeline.evaluate import EVALSET_DIR, collect_items

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--per-scenario", type=int, default=1)
    parser.add_argument("--cold-runs", type=int, default=3, help="whole-process conversions of one clip per cache state")
    args = parser.parse_args(argv)
    cv2.setNumThreads(1)
    chosen = defaultdict(list)
    for item in collect_items(EVALSET_DIR):
        scenario = item.stem.rsplit("_seed", 1)[0]
        if len(chosen[scenario]) < args.per_scenario:
            chosen[scenario].append(item)
    items = [i for group in chosen.values() for i in group]

    # Warm-up: imports and the first map load are paid once per process, not per video.
    with tempfile.TemporaryDirectory() as tmp:
        convert_video(items[0].video, Path(tmp) / "warm")

    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for k, item in enumerate(items):
            label = json.loads(Path(item.video).with_name(item.stem + ".label.json").read_text())
            video_seconds = float(label.get("seconds", 10.0))
            start = time.perf_counter()
            report = convert_video(item.video, Path(tmp) / f"{k:03d}")
            wall = time.perf_counter() - start
            rows.append({"stem": item.stem, "video_s": video_seconds, "wall": wall,
                         "per_10s": wall * 10.0 / video_seconds, "ok": checks_passed(report),
                         "e2e_sc": report.e2e_sc})
            print(f"{item.stem:45s} {wall:6.2f} s for {video_seconds:4.1f} s of video "
                  f"({rows[-1]['per_10s']:.2f} s per 10 s)  ok={rows[-1]['ok']}", flush=True)
    per10 = [r["per_10s"] for r in rows]
    mean = statistics.mean(per10)
    print()
    print(f"videos: {len(rows)}, all ran: {all(r['ok'] for r in rows)}")
    print(f"seconds per 10-second video: mean {mean:.2f}, median {statistics.median(per10):.2f}, "
          f"max {max(per10):.2f} (target <= {TARGET_PER_10S})")
    print(f"paper (GPT-4o): {PAPER_SECONDS_PER_VIDEO} s per video -> speed-up x{PAPER_SECONDS_PER_VIDEO / mean:.1f}")
    if args.cold_runs > 0:
        cold = cold_convert_seconds(Path(items[0].video), args.cold_runs)
        print(f"cold `python -m dv2s_gym.cli convert {Path(items[0].video).name}` (new process, wall, median of "
              f"{args.cold_runs}): " + ", ".join(f"{label} {seconds:.2f} s" for label, seconds in cold.items()))
    return 0 if mean <= TARGET_PER_10S else 1


if __name__ == "__main__":
    sys.exit(main())
