"""A small evaluation folder for the tests: one clip of each use case of a shipped evaluation set.

The whole sets' figures are measured by ``python -m bench.bench_evalset``; the tests run the same pipeline
on this subset. The clip is the first of its use case by name, chosen without looking at any result.
"""

from __future__ import annotations

from pathlib import Path

from dv2s_gym.pipeline.evaluate import LABEL_SUFFIX, collect_items


def one_clip_per_use_case(folder: Path, into: Path) -> Path:
    """Link the first clip (by name) of every use case of ``folder``, with its label, into ``into``."""
    into.mkdir(parents=True, exist_ok=True)
    chosen = {}
    for item in collect_items(folder):  # sorted by name
        chosen.setdefault(item.use_case, item)
    for item in chosen.values():
        video = Path(item.video)
        (into / video.name).symlink_to(video)
        (into / f"{item.stem}{LABEL_SUFFIX}").symlink_to(folder / f"{item.stem}{LABEL_SUFFIX}")
    return into
