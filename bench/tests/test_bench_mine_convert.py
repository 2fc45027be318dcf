"""The conversion bench's summary: every stage the conversions recorded is listed, in the conversion's order, and the
rejections are counted by the stage that rejected them."""

from __future__ import annotations

import pytest

from bench.bench_mine_convert import rejection_stages, stage_medians


def _row(timings, seconds, status="kept", stage=None):
    return {"timings": timings, "seconds": seconds, "status": status, "stage": stage}


def test_every_recorded_stage_is_listed_in_the_conversion_order():
    rows = [_row({"video": 1.0, "replay": 4.0, "describe": 0.5, "avoidability": 3.0, "bank": 0.1}, 9.0),
            _row({"video": 2.0, "replay": 6.0, "a_stage_added_later": 1.0}, 9.5, "rejected", "a_stage_added_later"),
            _row({"video": 3.0, "replay": 5.0, "describe": 0.7, "avoidability": 1.0, "bank": 0.3}, 10.0)]
    stages = stage_medians(rows)
    assert list(stages) == ["video", "replay", "describe", "avoidability", "bank", "a_stage_added_later",
                            "unrecorded"]
    assert stages["video"] == {"median": 2.0, "n": 3}
    assert stages["replay"] == {"median": 5.0, "n": 3}
    assert stages["describe"] == {"median": pytest.approx(0.6), "n": 2}  # only the conversions that reached it
    assert stages["a_stage_added_later"] == {"median": 1.0, "n": 1}
    # the wall time outside every stage: 0.4, 0.5 and 0.0 s
    assert stages["unrecorded"]["median"] == pytest.approx(0.4)


def test_no_rows_no_stages():
    assert stage_medians([]) == {}


def test_rejections_are_counted_by_their_stage_most_first():
    rows = [_row({}, 1.0, "rejected", "reproduction"), _row({}, 1.0, "kept"), _row({}, 1.0, "rejected", "check"),
            _row({}, 1.0, "rejected", "reproduction"), _row({}, 1.0, "merged")]
    assert rejection_stages(rows) == {"reproduction": 2, "check": 1}
    assert rejection_stages([_row({}, 1.0, "kept")]) == {}
