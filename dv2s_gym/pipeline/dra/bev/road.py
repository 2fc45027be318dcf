"""Road layout from the lane lines: lateral line offsets, lane indices, lane changes and the
road type (highway, two-way street, intersection, T-junction, merge, roundabout)."""

from __future__ import annotations

import math
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from dv2s_gym.pipeline.dra.bev.detection import _Frame

__all__ = ["LANE_WIDTH_M"]


LANE_WIDTH_M = 3.5          # lane width when no lines are seen


def _lines_lat(fr: _Frame, heading: float, scale: float, along_m: float = 0.0) -> np.ndarray:
    """Lateral offsets (m, left of the ego positive) of the lane lines parallel to the ego's heading,
    taken ``along_m`` metres ahead of the ego."""
    if fr.ego is None:
        return np.zeros(0)
    L = fr.lines
    c, s = math.cos(heading), math.sin(heading)
    if abs(c) >= 0.85:
        pos, ext, along = L.h_pos, L.h_ext, fr.ego.x + along_m * scale * c
        lat = -(pos - fr.ego.y) / scale * math.copysign(1.0, c)
    elif abs(s) >= 0.85:
        pos, ext, along = L.v_pos, L.v_ext, fr.ego.y - along_m * scale * s
        lat = -(pos - fr.ego.x) / scale * math.copysign(1.0, s)
    else:
        return np.zeros(0)
    if len(pos) == 0:
        return np.zeros(0)
    keep = (ext[:, 0] - 2.5 * scale <= along) & (along <= ext[:, 1] + 2.5 * scale)
    return np.sort(lat[keep])


def _lane_of(lines_lat: np.ndarray, lat: float, margin: float = 0.0) -> Optional[int]:
    """Lane index counted from the left (in the ego's driving direction) of a lateral offset;
    None off the lanes or within ``margin`` metres of a line (undecided while crossing it)."""
    if lines_lat.size < 2 or lat > lines_lat[-1] + 0.3 or lat < lines_lat[0] - 0.3:
        return None
    if margin > 0 and float(np.min(np.abs(lines_lat - lat))) < margin:
        return None
    return int(np.count_nonzero(lines_lat > lat)) - 1


def _road_type(frames: List[_Frame], scale: float, heading: np.ndarray, oncoming: bool,
               size: Tuple[int, int]) -> Tuple[Optional[str], Dict[str, Any]]:
    w, h = size
    ev: Dict[str, Any] = {}
    n_h = float(sum(f.lines.n_h for f in frames))
    n_v = float(sum(f.lines.n_v for f in frames))
    n_o = float(sum(f.lines.n_other for f in frames))
    total = n_h + n_v + n_o
    if total < 50:
        ev["reason"] = "no lane lines visible"
        return None, ev
    # arcs in many directions: a roundabout
    hist = np.zeros(12)
    for f in frames:
        for ang, length in f.lines.diag:
            hist[int(ang // 15) % 12] += length
    spread = int(np.count_nonzero(hist > 0.05 * hist.sum())) if hist.sum() > 0 else 0
    curved = n_o / total
    ev.update(curved_share=round(curved, 3), angle_bins=spread)
    if curved > 0.3 and spread >= 6:
        return "roundabout", ev
    # perpendicular roads in one frame: count the arms around the gap where lines stop
    arms_seen = arms_full = 0
    for f in frames:
        L = f.lines
        if len(L.h_pos) < 2 or len(L.v_pos) < 2 or min(L.n_h, L.n_v) < 0.12 * (L.n_h + L.n_v):
            continue
        vx0, vx1 = float(L.v_pos.min()), float(L.v_pos.max())
        hy0, hy1 = float(L.h_pos.min()), float(L.h_pos.max())
        if vx1 - vx0 < 1.5 * scale or hy1 - hy0 < 1.5 * scale:
            continue
        mgn = 1.0 * scale
        left = bool(np.any(L.h_ext[:, 0] < vx0 - mgn))
        right = bool(np.any(L.h_ext[:, 1] > vx1 + mgn))
        up = bool(np.any(L.v_ext[:, 0] < hy0 - mgn))
        down = bool(np.any(L.v_ext[:, 1] > hy1 + mgn))
        arms = int(left) + int(right) + int(up) + int(down)
        arms_seen = max(arms_seen, arms)
        room = 4.0 * scale
        if vx0 > room and vx1 < w - room and hy0 > room and hy1 < h - room:
            arms_full = max(arms_full, arms)
    ev.update(junction_arms=arms_seen, junction_arms_in_full_view=arms_full)
    if arms_seen >= 4:
        return "intersection", ev
    if arms_seen == 3:
        return "t_junction", ev
    main_h = n_h >= n_v
    ref = 0.0 if main_h else 90.0

    def off(a: float) -> float:
        return min(abs(a - ref), abs(a - ref - 180.0), abs(a - ref + 180.0))

    ramp_frames = sum(1 for f in frames if any(3.0 <= off(a) <= 40.0 and ln > 6 * scale for a, ln in f.lines.diag)
                      or any(3.0 <= off(a) <= 40.0 and ln > 12 * scale for a, ln in (f.lines.segments or [])))
    lanes, striped = [], []
    for i, f in enumerate(frames):
        lat = _lines_lat(f, heading[i], scale)
        if lat.size >= 2:
            lanes.append(lat.size - 1)
            L = f.lines
            st = L.h_striped if abs(math.cos(heading[i])) >= 0.85 else L.v_striped
            striped.append(bool(st.any()))
    n_lanes = int(np.median(lanes)) if lanes else 0
    stripes = bool(np.mean(striped) > 0.3) if striped else False
    ev.update(ramp_frames=ramp_frames, lanes=n_lanes, stripes=stripes, oncoming_traffic=oncoming)
    if ramp_frames >= 2 and n_lanes >= 2:
        return "merge", ev
    if n_lanes >= 3 and (stripes or not oncoming):
        return "highway", ev
    if n_lanes == 2 and stripes and not oncoming:
        return "highway", ev
    if n_lanes >= 1:
        return "straight_road", ev
    return None, ev


def _lane_changes(lanes: Sequence[Optional[int]], min_run: int = 2) -> List[Tuple[int, int, int]]:
    """(position, from lane, to lane) of each change between stable runs of a lane-index sequence."""
    runs: List[List[int]] = []
    for k, v in enumerate(lanes):
        if v is None:
            continue
        if runs and runs[-1][0] == v:
            runs[-1][2] = k
            runs[-1][3] += 1
        else:
            runs.append([v, k, k, 1])
    runs = [r for r in runs if r[3] >= min_run]
    merged: List[List[int]] = []
    for r in runs:
        if merged and merged[-1][0] == r[0]:
            merged[-1][2], merged[-1][3] = r[2], merged[-1][3] + r[3]
        else:
            merged.append(list(r))
    return [(b[1], a[0], b[0]) for a, b in zip(merged, merged[1:])]
