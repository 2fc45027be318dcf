"""The bird's-eye Driving Record Analyzer's behaviour, recorded: what it says of every shipped evaluation clip.

For the seed-0 clip of every in-house evaluation use case (``dv2s_gym/evalset``) and every clip of the stock
highway-env set (``bench/evalsets/highway_env``, the data its benchmark reads; read here, not imported), ``tests/data/behaviour/dra.json`` holds the SHA-256 digests of
the ``bev`` backend's description and of its semantic elements. Only what the analyzer hands on is recorded (its
tracks' floating-point measurements are not: they are intermediate, and their last bits may differ between CPUs).
A refactor must leave them as they are; a change meant to be one is recorded by writing them again:

    .venv/bin/python tests/test_behaviour_dra.py --write
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Dict

import pytest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from behaviour_digest import differences, digest, write_record  # noqa: E402
from dv2s_gym.pipeline.dra.bev.analyze import analyze_bev_file  # noqa: E402

RECORD = ROOT / "tests" / "data" / "behaviour" / "dra.json"


def _clips():
    return sorted((ROOT / "dv2s_gym").glob("evalset/*_seed0.webm")) + \
        sorted((ROOT / "bench" / "evalsets").glob("highway_env/*.webm"))


def behaviour() -> Dict[str, Dict[str, str]]:
    """``{folder/clip: {description, elements}}`` for every recorded clip."""
    record = {}
    for clip in _clips():
        analysis = analyze_bev_file(clip)
        record[f"{clip.parent.name}/{clip.name}"] = {"description": digest(analysis.description),
                                                     "elements": digest(analysis.elements.to_dict())}
    return record


@pytest.mark.slow
def test_the_bev_analyzer_says_what_it_said_of_every_shipped_clip():
    recorded = json.loads(RECORD.read_text(encoding="utf-8"))
    now = behaviour()
    assert len(now) >= 90 and set(now) == set(recorded), "clips added or gone: write the record again"
    changed = differences(recorded, now)
    assert not changed, (f"the bev analyzer now says something else of {len(changed)} clip field(s): {changed[:10]}; "
                         "if the change is meant, record it: python tests/test_behaviour_dra.py --write")


if __name__ == "__main__" and sys.argv[1:] == ["--write"]:
    write_record(RECORD, behaviour)
