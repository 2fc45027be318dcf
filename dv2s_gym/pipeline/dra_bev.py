"""``bev``: the embedded, offline Driving Record Analyzer for bird's-eye renders.

It reads a video rendered in highway-env's style (flat grey canvas, white lane
lines, the green ego at a fixed spot of the view, light-blue cars, purple
trucks, orange pedestrian discs, grey props with black outlines, crashed
vehicles in red; the camera follows the ego, north up) and returns what the
Driving Record Analyzer returns: a three-sentence description and the semantic
elements of :mod:`scenario_bank.elements`. It works from the pixels alone: no
trace, sidecar or metadata is read.

How, per clip:

1. *Check* that the frames look like such a render, else :class:`NotBirdsEyeError`.
2. *Detect*, per frame: coloured blobs by hue (ego, cars, trucks, pedestrians,
   crashed vehicles), props by their black outline, white lane-line pixels
   split into horizontal, vertical and other (ramps, arcs) lines.
3. *Calibrate* the scale (px/m) from the ego rectangle; the ego's heading is its
   long axis, pointed by its lighter front end (headlights) or by the world's motion.
4. *Track* the blobs in the ego-centred view (nearest neighbour, constant relative velocity).
5. *World motion*: the static layer (lane lines, props, waiting pedestrians)
   moves opposite to the ego. Its shift between frames comes from correlating
   the line masks; the ambiguity of periodic stripes is resolved by a Viterbi
   pass favouring a smooth ego speed, agreement with static anchors and
   vehicles that do not drive backwards. Ego velocity plus relative motion gives
   every actor's absolute velocity.
6. *Road*: lane-line orientation, count and pattern: parallel one-way lanes
   (highway), 1+1 lanes (straight road), a + or a T of perpendicular roads,
   a ramp joining (merge), arcs (roundabout).
7. *Events* in the ego's driving frame: brake, stop, accelerate, lane changes,
   cut-in, merge, overtake, turns, crossing, collisions, drift; relations where
   each actor starts. Actors that interact with the ego are described in full;
   the other vehicles in view are only counted.

The description is written so that :func:`dv2s_gym.pipeline.semantics.elements_from_text`
reads the same elements back from it.

Use :func:`analyze_bev_file` on a path or :func:`analyze_bev` on a
:class:`~dv2s_gym.pipeline.video.VideoClip`. World motion is measured between
consecutive frames, so the analyzer wants 5 frames/s or more; a sparser clip
that names a readable file is re-read at :data:`BEV_READ_OPTIONS` (same pixels,
denser in time).
"""

from __future__ import annotations

import math
import os
import re
import time
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

from scenario_bank.elements import normalize_elements

__all__ = ["BevAnalysis", "NotBirdsEyeError", "analyze_bev", "analyze_bev_file", "BEV_READ_OPTIONS"]

BEV_READ_OPTIONS = {"fps": 5.0, "max_frames": 100, "max_pixels": 448 * 448}
""":func:`~dv2s_gym.pipeline.video.read_video` arguments that suit this backend."""

# ----------------------------------------------------------------------------- constants
EGO_LENGTH_M = 4.5          # size of the ego rectangle, calibrates px/m
EGO_WIDTH_M = 2.0
LANE_WIDTH_M = 3.5          # lane width when no lines are seen
MAX_SPEED = 42.0            # m/s, fastest plausible world motion
BRAKE_DROP = 3.5            # m/s lost ...
BRAKE_RATE = 1.8            # ... at this many m/s^2 or more
ACCEL_RISE = 5.0            # m/s gained, at BRAKE_RATE or more
STOP_SPEED = 1.0            # m/s
TURN_ANGLE = math.radians(50)
PARTIAL_TURN = math.radians(8)
NEAR = 45.0                 # m: actors never closer than this are left out
TRAFFIC_NEAR = 25.0         # m: vehicles this close for a while are counted as traffic around the ego
MIN_RESAMPLE_FPS = 4.0

_KINDS = ("none", "red", "ped", "yellow", "ego", "car", "truck")
_HUE_RANGES = [("red", 0, 7), ("ped", 9, 23), ("yellow", 24, 36), ("ego", 37, 78), ("car", 80, 118),
               ("truck", 119, 162), ("red", 163, 179)]
_HUE_LUT = np.zeros(256, dtype=np.uint8)
for _name, _lo, _hi in _HUE_RANGES:
    _HUE_LUT[_lo:_hi + 1] = _KINDS.index(_name)

ROAD_PHRASES = {
    "highway": "a straight multi-lane highway",
    "straight_road": "a two-way urban street",
    "intersection": "a four-way urban intersection",
    "t_junction": "an urban T-junction",
    "three_way": "a three-way junction",
    "roundabout": "a roundabout",
    "merge": "a highway with an on-ramp",
}
ROAD_SCENES = {
    "highway": "on a highway",
    "straight_road": "on a two-way urban street",
    "intersection": "at a four-way urban intersection",
    "t_junction": "at an urban T-junction",
    "three_way": "at a three-way junction",
    "roundabout": "at a roundabout",
    "merge": "on a highway where an on-ramp joins",
}


class NotBirdsEyeError(ValueError):
    """The video is not a bird's-eye render in highway-env's style."""


# ----------------------------------------------------------------------------- data
@dataclass
class Blob:
    """One object detected in one frame (pixels of the analysed frames, y down)."""

    kind: str                  # ego, car, truck, ped, red, yellow, prop
    x: float
    y: float
    area: float
    length: float = 0.0        # px along the long axis
    width: float = 0.0
    axis: float = 0.0          # map angle (y up) of the long axis, modulo pi
    front: int = 0             # +1: lighter end (front) along `axis`, -1: opposite, 0: unknown
    border: bool = False       # touches the image border (partly out of view)
    placed: bool = False       # a border vehicle whose centre was put back from its visible end


@dataclass
class Lines:
    """Lane lines of one frame: position across their family, extent along it, striped or not."""

    h_pos: np.ndarray
    h_ext: np.ndarray
    h_striped: np.ndarray
    v_pos: np.ndarray
    v_ext: np.ndarray
    v_striped: np.ndarray
    n_h: int
    n_v: int
    n_other: int
    diag: List[Tuple[float, float]] = field(default_factory=list)  # (angle deg modulo 180, length px)
    segments: Optional[List[Tuple[float, float]]] = None           # long straight segments (some frames)


@dataclass
class _Frame:
    t: float
    ego: Optional[Blob]
    blobs: List[Blob]
    lines: Lines
    soft: np.ndarray           # half-resolution, blurred line mask (float32)


@dataclass
class Track:
    """One actor followed across frames."""

    id: int
    kinds: List[str] = field(default_factory=list)
    idx: List[int] = field(default_factory=list)
    rel: List[Tuple[float, float]] = field(default_factory=list)  # map-frame offset from the ego [m]
    blobs: List[Blob] = field(default_factory=list)
    kind: str = "car"
    crashed: bool = False
    info: Dict[str, Any] = field(default_factory=dict)


@dataclass
class BevAnalysis:
    """What the ``bev`` backend read from a video.

    Attributes:
        description: three sentences (and an answer sentence when a question was asked).
        elements: semantic elements, canonical form of :func:`scenario_bank.elements.normalize_elements`.
        answer: the answer to the question, when one was asked and could be answered.
        tracks: actors followed across frames (ego-centred, metres), with speeds and what they did.
        debug: intermediate measurements (scale, road evidence, ego speed, timings...).
    """

    description: str
    elements: Dict[str, Any]
    answer: Optional[str] = None
    tracks: List[Dict[str, Any]] = field(default_factory=list)
    debug: Dict[str, Any] = field(default_factory=dict)


# ----------------------------------------------------------------------------- detection
def _hsv(frame: np.ndarray) -> np.ndarray:
    import cv2

    return cv2.cvtColor(frame, cv2.COLOR_RGB2HSV)


def _mask(hsv: np.ndarray, lo: Tuple[int, int, int], hi: Tuple[int, int, int]) -> np.ndarray:
    import cv2

    return cv2.inRange(hsv, lo, hi)


def _components(mask: np.ndarray) -> List[Tuple[np.ndarray, np.ndarray]]:
    """Pixel coordinates (ys, xs) of each 8-connected component of a 0/1 mask."""
    import cv2

    n, labels = cv2.connectedComponents(mask, connectivity=8)
    if n <= 1:
        return []
    flat = labels.ravel()
    idx = np.flatnonzero(flat)
    lab = flat[idx]
    order = np.argsort(lab, kind="stable")
    idx, lab = idx[order], lab[order]
    ys, xs = np.divmod(idx, labels.shape[1])
    cuts = np.searchsorted(lab, np.arange(2, n))
    return list(zip(np.split(ys, cuts), np.split(xs, cuts)))


def _shape(ys: np.ndarray, xs: np.ndarray, frame: np.ndarray, lights: bool = True):
    """(cx, cy, length, width, map axis angle, front sign) of a pixel set."""
    cx, cy = float(xs.mean()), float(ys.mean())
    dx, dy = xs - cx, ys - cy
    mu20, mu02, mu11 = float((dx * dx).mean()), float((dy * dy).mean()), float((dx * dy).mean())
    common = math.sqrt(max(0.0, ((mu20 - mu02) / 2) ** 2 + mu11 ** 2))
    l1, l2 = (mu20 + mu02) / 2 + common, max(0.0, (mu20 + mu02) / 2 - common)
    a = 0.5 * math.atan2(2 * mu11, mu20 - mu02)
    length, width = math.sqrt(12 * l1 + 1), math.sqrt(12 * l2 + 1)
    front = 0
    if lights and length > 1.4 * width and len(xs) >= 12:
        # headlights: the lighter end (compare the brightest pixels of both ends)
        bright = frame[ys, xs].astype(np.int16).sum(axis=1)
        proj = dx * math.cos(a) + dy * math.sin(a)
        ends = 0.3 * length
        pos, neg = bright[proj > ends], bright[proj < -ends]
        if pos.size >= 3 and neg.size >= 3:
            diff = float(np.sort(pos)[-3:].mean() - np.sort(neg)[-3:].mean())
            if abs(diff) >= 25:
                front = 1 if diff > 0 else -1
    # screen angle a (y down) is the map angle -a; folding it into [0, pi) turns it round when -a < 0
    if -a < 0:
        front = -front
    return cx, cy, length, width, (-a) % math.pi, front


def _detect_blobs(frame: np.ndarray, hsv: np.ndarray) -> List[Blob]:
    h, w = hsv.shape[:2]
    colored = _mask(hsv, (0, 70, 90), (179, 255, 255))
    blobs: List[Blob] = []
    flat = np.flatnonzero(colored)
    if flat.size:
        ys, xs = np.divmod(flat, w)
        cls = _HUE_LUT[hsv[..., 0].ravel()[flat]]
        for k in np.unique(cls):
            if k == 0:
                continue
            kind = _KINDS[int(k)]
            sel = cls == k
            ky, kx = ys[sel], xs[sel]
            y0, x0 = int(ky.min()), int(kx.min())
            mask = np.zeros((int(ky.max()) - y0 + 1, int(kx.max()) - x0 + 1), np.uint8)
            mask[ky - y0, kx - x0] = 1
            floor = 3 if kind in ("ped", "red") else 6
            for cy_, cx_ in _components(mask):
                if cy_.size < floor:
                    continue
                cy_ = cy_ + y0
                cx_ = cx_ + x0
                cx, cy, length, width, axis, front = _shape(cy_, cx_, frame)
                border = bool(cx_.min() <= 0 or cy_.min() <= 0 or cx_.max() >= w - 1 or cy_.max() >= h - 1)
                blobs.append(Blob(kind, cx, cy, float(cy_.size), length, width, axis, front, border))
    # props: a black outline around a grey inside, with no colour near it
    dark = _mask(hsv, (0, 0, 0), (179, 255, 39))
    flat = np.flatnonzero(dark)
    if flat.size >= 8:
        ys, xs = np.divmod(flat, w)
        y0, x0 = int(ys.min()), int(xs.min())
        mask = np.zeros((int(ys.max()) - y0 + 1, int(xs.max()) - x0 + 1), np.uint8)
        mask[ys - y0, xs - x0] = 1
        val = hsv[..., 2]
        for cy_, cx_ in _components(mask):
            if cy_.size < 8:
                continue
            bx0, bx1, by0, by1 = int(cx_.min()) + x0, int(cx_.max()) + x0, int(cy_.min()) + y0, int(cy_.max()) + y0
            if bx1 - bx0 < 2 or by1 - by0 < 2:
                continue
            if colored[max(0, by0 - 1):by1 + 2, max(0, bx0 - 1):bx1 + 2].any():
                continue  # a pedestrian's outline, or next to a vehicle
            inside = val[by0 + 1:by1, bx0 + 1:bx1]
            if inside.size == 0 or float(np.median(inside)) < 90:
                continue
            gy, gx = np.mgrid[by0:by1 + 1, bx0:bx1 + 1]
            cx, cy, length, width, axis, _ = _shape(gy.ravel(), gx.ravel(), frame, lights=False)
            border = bool(bx0 <= 0 or by0 <= 0 or bx1 >= w - 1 or by1 >= h - 1)
            blobs.append(Blob("prop", cx, cy, float((bx1 - bx0 + 1) * (by1 - by0 + 1)), length, width, axis, 0,
                              border))
    return blobs


def _line_groups(mask: np.ndarray, axis: int, min_count: int):
    """Lines of one family (axis=1: horizontal lines): positions, extents, striped flags."""
    counts = np.count_nonzero(mask, axis=axis)
    rows = np.nonzero(counts >= min_count)[0]
    pos, ext, striped = [], [], []
    if rows.size:
        for g in np.split(rows, np.nonzero(np.diff(rows) > 2)[0] + 1):
            band = mask[g[0]:g[-1] + 1, :] if axis == 1 else mask[:, g[0]:g[-1] + 1]
            along = np.nonzero(band.any(axis=0 if axis == 1 else 1))[0]
            if along.size < min_count:
                continue
            weights = counts[g].astype(float)
            pos.append(float((g * weights).sum() / weights.sum()))
            lo, hi = int(along[0]), int(along[-1])
            ext.append((lo, hi))
            gaps = int(np.count_nonzero(np.diff(along) > 1))
            striped.append(bool(gaps >= 2 and along.size / float(hi - lo + 1) < 0.9))
    return np.array(pos, float), np.array(ext, float).reshape(-1, 2), np.array(striped, bool)


def _straight_segments(white: np.ndarray, scale: float) -> List[Tuple[float, float]]:
    """(angle deg modulo 180, length px) of the long straight line segments of a line mask."""
    import cv2

    segs = cv2.HoughLinesP(white, 1, np.pi / 360, threshold=max(20, int(4 * scale)),
                           minLineLength=max(20, int(7 * scale)), maxLineGap=max(2, int(0.6 * scale)))
    out: List[Tuple[float, float]] = []
    if segs is not None:
        for x1, y1, x2, y2 in segs[:, 0, :]:
            out.append((math.degrees(math.atan2(-(float(y2) - y1), float(x2) - x1)) % 180.0,
                        float(math.hypot(float(x2) - x1, float(y2) - y1))))
    return out


def _detect_lines(white: np.ndarray, scale: float) -> Lines:
    import cv2

    k = max(5, int(round(2.3 * scale)))
    horiz = cv2.morphologyEx(white, cv2.MORPH_OPEN, np.ones((1, k), np.uint8))
    vert = cv2.morphologyEx(white, cv2.MORPH_OPEN, np.ones((k, 1), np.uint8))
    min_count = max(6, 2 * k)
    h_pos, h_ext, h_str = _line_groups(horiz, 1, min_count)
    v_pos, v_ext, v_str = _line_groups(vert, 0, min_count)
    n_h, n_v = int(np.count_nonzero(horiz)), int(np.count_nonzero(vert))
    other = white & (1 - cv2.dilate(horiz | vert, np.ones((3, 3), np.uint8)))
    n_other = int(np.count_nonzero(other))
    diag: List[Tuple[float, float]] = []
    if n_other >= 4 * k:
        segs = cv2.HoughLinesP(other, 1, np.pi / 180, threshold=max(8, k), minLineLength=int(1.5 * k),
                               maxLineGap=max(2, k // 2))
        if segs is not None:
            for x1, y1, x2, y2 in segs[:, 0, :]:
                ang = math.degrees(math.atan2(-(float(y2) - y1), float(x2) - x1)) % 180.0
                diag.append((ang, float(math.hypot(float(x2) - x1, float(y2) - y1))))
    return Lines(h_pos, h_ext, h_str, v_pos, v_ext, v_str, n_h, n_v, n_other, diag)


def _check_birds_eye(frames: Sequence[np.ndarray], path: str) -> Dict[str, float]:
    """Background statistics of a few frames; NotBirdsEyeError when they are not a BEV render."""
    picks = [frames[i] for i in sorted(set(np.linspace(0, len(frames) - 1, min(6, len(frames))).astype(int)))]
    shares, spreads, ego_frames = [], [], 0
    for f in picks:
        hsv = _hsv(f)
        grey = _mask(hsv, (0, 0, 71), (179, 29, 134)) > 0
        share = float(grey.mean())
        shares.append(share)
        spreads.append(float(hsv[..., 2][grey].std()) if share > 0 else 99.0)
        if int(np.count_nonzero(_mask(hsv, (37, 70, 90), (78, 255, 255)))) >= 12:
            ego_frames += 1
    stats = {"grey_share": round(float(np.median(shares)), 3), "grey_spread": round(float(np.median(spreads)), 2),
             "ego_frames": round(ego_frames / len(picks), 2)}
    reasons = []
    if stats["grey_share"] < 0.45:
        reasons.append(f"only {stats['grey_share']:.0%} of the pixels are the flat grey canvas (expected most)")
    elif stats["grey_spread"] > 6.0:
        reasons.append(f"its grey areas are textured (brightness spread {stats['grey_spread']:.1f}), as in a photo")
    if stats["ego_frames"] < 0.5:
        reasons.append("no green ego vehicle is visible in most frames")
    if reasons:
        raise NotBirdsEyeError(
            f"{path or 'the video'} does not look like a bird's-eye render in highway-env's style "
            f"({'; '.join(reasons)}). The 'bev' analyzer only reads such renders (grey canvas, white lane "
            "lines, green ego vehicle at a fixed spot); describe dashcam or other real driving videos with the "
            "VLM backend instead (--dra openai)."
        )
    return stats


# ----------------------------------------------------------------------------- helpers
def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def _unwrap_axis(axes: Sequence[float]) -> np.ndarray:
    """Unwrap angles known modulo pi into a continuous sequence."""
    out = np.array(axes, dtype=float)
    for i in range(1, len(out)):
        out[i] = out[i - 1] + (out[i] - out[i - 1] + math.pi / 2) % math.pi - math.pi / 2
    return out


def _facing_votes(axes_raw: Sequence[float], fronts: Sequence[int], unwrapped: np.ndarray) -> List[int]:
    """Headlight votes re-expressed against the unwrapped axis (+1: along it, -1: against it)."""
    votes = []
    for raw, f, u in zip(axes_raw, fronts, unwrapped):
        if not f:
            votes.append(0)
            continue
        direction = raw if f > 0 else raw + math.pi
        votes.append(1 if math.cos(direction - u) > 0 else -1)
    return votes


def _local_slope(t: np.ndarray, y: np.ndarray, half: float = 0.5) -> np.ndarray:
    """Derivative of y(t) by local linear fits over +-half seconds (NaN-aware; y may be 2-D)."""
    y = np.asarray(y, float)
    out = np.full(y.shape, np.nan)
    for i in range(len(t)):
        sel = (np.abs(t - t[i]) <= half + 1e-6)
        if y.ndim == 1:
            ok = sel & np.isfinite(y)
        else:
            ok = sel & np.isfinite(y).all(axis=1)
        if ok.sum() < 2:
            continue
        tt = t[ok] - t[ok].mean()
        den = float((tt * tt).sum())
        if den <= 1e-9:
            continue
        out[i] = (tt[:, None] * (y[ok] - y[ok].mean(axis=0))).sum(axis=0) / den if y.ndim > 1 else \
            float((tt * (y[ok] - y[ok].mean())).sum() / den)
    return out


def _smooth(t: np.ndarray, y: np.ndarray, half: float = 0.4) -> np.ndarray:
    y = np.asarray(y, float)
    out = np.full(y.shape, np.nan)
    for i in range(len(t)):
        sel = np.abs(t - t[i]) <= half + 1e-6
        vals = y[sel]
        vals = vals[np.isfinite(vals).all(axis=-1)] if y.ndim > 1 else vals[np.isfinite(vals)]
        if len(vals):
            out[i] = vals.mean(axis=0)
    return out


def _fft():
    try:
        import scipy.fft as sfft

        return sfft.rfft2, sfft.irfft2, sfft.next_fast_len
    except Exception:  # pragma: no cover - numpy fallback
        def next_len(n, real=True):
            return int(2 ** math.ceil(math.log2(max(2, n))))
        return np.fft.rfft2, np.fft.irfft2, next_len


# ----------------------------------------------------------------------------- tracking
def _vehicle_kind(kind: str) -> bool:
    return kind in ("car", "truck", "red", "yellow")


def _compatible(a: str, b: str) -> bool:
    return a == b or (_vehicle_kind(a) and _vehicle_kind(b)) or {a, b} <= {"ped", "red"}


def _track(frames: List[_Frame], scale: float, heading: Optional[np.ndarray] = None) -> List[Track]:
    tracks: List[Track] = []
    active: List[List[Any]] = []   # [track, pos, vel, time]
    next_id = 1
    for fi, fr in enumerate(frames):
        if fr.ego is None:
            continue
        obs = [(b, np.array([(b.x - fr.ego.x) / scale, -(b.y - fr.ego.y) / scale])) for b in fr.blobs]
        pairs = []
        for ti, (trk, pos, vel, t_last) in enumerate(active):
            dt = fr.t - t_last
            pred = pos + vel * dt
            for oi, (b, p) in enumerate(obs):
                if not _compatible(trk.kinds[-1], b.kind):
                    continue
                res = p - pred
                d = float(np.hypot(*res))
                gate = (1.0 if trk.kinds[-1] == "ped" else 2.2) + 3.0 * dt + 0.1 * float(np.hypot(*vel)) * dt
                if len(trk.idx) == 1:
                    gate += (6.0 if trk.kinds[-1] == "ped" else 30.0) * dt
                if d > gate:
                    continue
                if heading is not None and trk.kinds[-1] != "ped":
                    # sideways (across the ego's lanes) a vehicle moves little: do not jump to the next lane
                    hd = float(heading[fi])
                    side = abs(-res[0] * math.sin(hd) + res[1] * math.cos(hd))
                    if side > 1.3 + (6.0 if len(trk.idx) == 1 else 2.0) * min(dt, 1.0):
                        continue
                pairs.append((d, ti, oi))
        pairs.sort()
        used_t, used_o = set(), set()
        new_active = []
        for d, ti, oi in pairs:
            if ti in used_t or oi in used_o:
                continue
            used_t.add(ti)
            used_o.add(oi)
            trk, pos, vel, t_last = active[ti]
            b, p = obs[oi]
            meas = (p - pos) / max(1e-3, fr.t - t_last)
            vel = meas if len(trk.idx) == 1 else 0.6 * vel + 0.4 * meas
            trk.idx.append(fi)
            trk.rel.append((float(p[0]), float(p[1])))
            trk.kinds.append(b.kind)
            trk.blobs.append(b)
            new_active.append([trk, p, vel, fr.t])
        for ti, entry in enumerate(active):
            if ti not in used_t and fr.t - entry[3] < 1.0:
                new_active.append(entry)
        for oi, (b, p) in enumerate(obs):
            if oi in used_o:
                continue
            trk = Track(next_id, [b.kind], [fi], [(float(p[0]), float(p[1]))], [b])
            next_id += 1
            tracks.append(trk)
            new_active.append([trk, p, np.zeros(2), fr.t])
        active = new_active
    return tracks


def _stitch(tracks: List[Track], frames: List[_Frame], scale: float, heading: np.ndarray,
            size: Tuple[int, int]) -> List[Track]:
    """Join a track that left the view with one that comes back at the same edge in the same lane."""
    w, h = size
    margin = 4.0 * scale

    def at_edge(b: Blob) -> bool:
        return b.border or min(b.x, b.y, w - 1 - b.x, h - 1 - b.y) < margin

    def ego_frame(trk: Track, k: int) -> Tuple[float, float]:
        hd = heading[trk.idx[k]]
        x, y = trk.rel[k]
        return x * math.cos(hd) + y * math.sin(hd), -x * math.sin(hd) + y * math.cos(hd)

    tracks = sorted(tracks, key=lambda t: t.idx[0])
    merged = True
    while merged:
        merged = False
        best = None
        for a in tracks:
            if not at_edge(a.blobs[-1]):
                continue
            lon_a, lat_a = ego_frame(a, len(a.idx) - 1)
            for b in tracks:
                if b is a or b.idx[0] <= a.idx[-1] or not _compatible(a.kinds[-1], b.kinds[0]):
                    continue
                if not at_edge(b.blobs[0]) or frames[b.idx[0]].t - frames[a.idx[-1]].t > 8.0:
                    continue
                lon_b, lat_b = ego_frame(b, 0)
                if lon_a * lon_b <= 0 or abs(lat_a - lat_b) > 1.5 or abs(lon_a - lon_b) > 12.0:
                    continue
                gap = b.idx[0] - a.idx[-1]
                if best is None or gap < best[0]:
                    best = (gap, a, b)
        if best is not None:
            _, a, b = best
            a.idx += b.idx
            a.rel += b.rel
            a.kinds += b.kinds
            a.blobs += b.blobs
            tracks.remove(b)
            merged = True
    return tracks


def _fix_border_position(b: Blob, ref_len: float, w: int, h: int) -> None:
    """Move the centre of a vehicle cut by the image border to where its full rectangle would put it."""
    if not b.border or b.kind in ("ped", "prop"):
        return
    half = max(ref_len, b.length) / 2.0
    if b.length < 0.3 * ref_len or b.width > 1.6 * max(b.length, 1.0):
        return
    # pixel extent of the visible part along the image axes
    c, s = abs(math.cos(b.axis)), abs(math.sin(b.axis))
    if c > 0.9:
        x0, x1 = b.x - b.length / 2, b.x + b.length / 2
        if x0 <= 1.5:
            b.x, b.placed = x1 - half, True
        elif x1 >= w - 2.5:
            b.x, b.placed = x0 + half, True
    elif s > 0.9:
        y0, y1 = b.y - b.length / 2, b.y + b.length / 2
        if y0 <= 1.5:
            b.y, b.placed = y1 - half, True
        elif y1 >= h - 2.5:
            b.y, b.placed = y0 + half, True


# ----------------------------------------------------------------------------- world motion
def _shift_candidates(fa, fb, na: float, nb: float, shape, fft_shape, radius: int, axis_vec, irfft2):
    """Screen shifts (dx, dy) of the half-resolution line layer between two frames, with scores."""
    import cv2

    if na < 4.0 or nb < 4.0:
        return [], 0.0, True   # too few line pixels to tell a shift
    h, w = shape
    H, W = fft_shape
    # fa: the first frame's lines away from the borders (so nothing enters or leaves the view within the
    # search radius); fb: the whole next frame. Score 1: all of the first frame's lines found again.
    corr = irfft2(fb * np.conj(fa), s=(H, W))
    ys = np.r_[H - radius:H, 0:radius + 1]
    xs = np.r_[W - radius:W, 0:radius + 1]
    win = corr[np.ix_(ys, xs)].astype(np.float32) / na
    best = float(win.max())
    if best < 0.25:
        return [], best, True
    by, bx = np.unravel_index(int(win.argmax()), win.shape)
    # a ridge through the best shift, roughly along the ego's axis (continuous or slanted lines only):
    # the shift along the ego's heading is then not observable
    ks = np.arange(-radius, radius + 1)
    base = math.atan2(axis_vec[1], axis_vec[0])
    for tilt in (0.0, -0.26, 0.26, -0.52, 0.52):
        ux, uy = math.cos(base + tilt), math.sin(base + tilt)
        px = np.clip(np.round(bx + ks * ux).astype(int), 0, 2 * radius)
        py = np.clip(np.round(by + ks * uy).astype(int), 0, 2 * radius)
        if float(np.percentile(win[py, px], 10)) >= 0.9 * best:
            return [], best, True
    peaks = (win == cv2.dilate(win, np.ones((5, 5), np.uint8))) & (win >= 0.7 * best)
    cands = []
    for yy, xx in zip(*np.nonzero(peaks)):
        sx, sy = float(xx), float(yy)
        if 0 < xx < 2 * radius:
            l, c, r = win[yy, xx - 1], win[yy, xx], win[yy, xx + 1]
            den = l - 2 * c + r
            if den < 0:
                sx += float(np.clip(0.5 * (l - r) / den, -0.5, 0.5))
        if 0 < yy < 2 * radius:
            u, c, dn = win[yy - 1, xx], win[yy, xx], win[yy + 1, xx]
            den = u - 2 * c + dn
            if den < 0:
                sy += float(np.clip(0.5 * (u - dn) / den, -0.5, 0.5))
        cands.append((sx - radius, sy - radius, float(win[yy, xx])))
    cands.sort(key=lambda c: -c[2])
    return cands[:8], best, False


def _world_motion(frames: List[_Frame], tracks: List[Track], scale: float, heading: np.ndarray,
                  speed_prior: float) -> Tuple[np.ndarray, np.ndarray, Dict[str, Any]]:
    """Ego velocity (map frame, m/s) over each frame interval, and which intervals are measured."""
    n = len(frames)
    m = max(0, n - 1)
    vel = np.full((m, 2), np.nan)
    known = np.zeros(m, bool)
    if m == 0:
        return vel, known, {}
    rfft2, irfft2, next_len = _fft()
    half_scale = scale / 2.0
    dts = np.array([max(1e-3, frames[i + 1].t - frames[i].t) for i in range(m)])
    h, w = frames[0].soft.shape
    radius = int(min(MAX_SPEED * float(dts.max()) * half_scale + 3, min(h, w) // 3))
    fft_shape = (next_len(h + radius + 1, real=True), next_len(w + radius + 1, real=True))
    spectra, inner_spectra, energies, inner_energies = [], [], [], []
    for fr in frames:
        inner = np.zeros_like(fr.soft)
        inner[radius:h - radius, radius:w - radius] = fr.soft[radius:h - radius, radius:w - radius]
        spectra.append(rfft2(fr.soft, s=fft_shape))
        inner_spectra.append(rfft2(inner, s=fft_shape))
        energies.append(float((fr.soft * fr.soft).sum()))
        inner_energies.append(float((inner * inner).sum()))
    # static anchors: props and (slow) pedestrians move by the ego's displacement, reversed
    anchor: List[List[Tuple[np.ndarray, float]]] = [[] for _ in range(m)]
    for trk in tracks:
        if trk.kind not in ("obstacle", "pedestrian"):
            continue
        walk = 0.0 if trk.kind == "obstacle" else 2.2   # m/s a pedestrian may add
        for k in range(1, len(trk.idx)):
            i0, i1 = trk.idx[k - 1], trk.idx[k]
            if i1 == i0 + 1 and not trk.blobs[k].border and not trk.blobs[k - 1].border:
                v = -np.subtract(trk.rel[k], trk.rel[k - 1]) / dts[i0]
                if walk:
                    # a pedestrian crosses: only its motion along the ego's heading tells the ego's speed
                    hv = np.array([math.cos(heading[i0]), math.sin(heading[i0])])
                    v = float(v @ hv) * hv
                anchor[i0].append((v, walk + 0.35 / dts[i0]))
    states: List[List[Tuple[np.ndarray, float]]] = []
    line_intervals = 0
    for i in range(m):
        hv = (math.cos(heading[i]), -math.sin(heading[i]))  # the ego axis on screen (y down)
        cands, best, flat = _shift_candidates(inner_spectra[i], spectra[i + 1], inner_energies[i], energies[i + 1],
                                              (h, w), fft_shape, radius, hv, irfft2)
        opts: List[Tuple[np.ndarray, float]] = []
        for dx, dy, score in cands:
            # the lines' screen shift is minus the ego's displacement (y flipped to the map frame)
            v = -np.array([dx / half_scale, -dy / half_scale]) / dts[i]
            opts.append((v, 5.0 * (best - score) / max(best, 1e-6)))
        if opts:
            line_intervals += 1
        for v, tol in anchor[i]:
            if all(float(np.hypot(*(o[0] - v))) > tol for o in opts):
                opts.append((v, 0.5 if opts else 0.0))
        states.append(opts)
    # vehicles with a reliable facing must not drive backwards
    veh: List[List[Tuple[np.ndarray, np.ndarray]]] = [[] for _ in range(m)]
    for trk in tracks:
        hd = trk.info.get("headings")
        if trk.kind not in ("car", "truck") or hd is None or not trk.info.get("facing_sure"):
            continue
        for k in range(1, len(trk.idx)):
            i0, i1 = trk.idx[k - 1], trk.idx[k]
            if i1 == i0 + 1 and not trk.blobs[k].border and not trk.blobs[k - 1].border:
                d = np.subtract(trk.rel[k], trk.rel[k - 1]) / dts[i0]
                veh[i0].append((d, np.array([math.cos(hd[k]), math.sin(hd[k])])))
    costs: List[np.ndarray] = []
    for i, opts in enumerate(states):
        c = np.zeros(len(opts))
        hvec = np.array([math.cos(heading[i]), math.sin(heading[i])])
        for j, (v, e) in enumerate(opts):
            cost = e
            cost += 0.8 * max(0.0, -float(v @ hvec) - 0.7)            # the ego drives forwards
            speed = float(np.hypot(*v))
            cost += 0.02 * abs(speed - speed_prior)                     # tie-breaker only
            cost += 1.0 * max(0.0, speed - 36.0)                       # faster than any traffic here
            for d, hv in veh[i]:
                cost += min(2.0, 0.3 * max(0.0, -float((d + v) @ hv) - 1.5))
            for va, tol in anchor[i]:
                cost += min(3.0, max(0.0, float(np.hypot(*(v - va))) - tol) / max(tol, 0.5))
            c[j] = cost
        costs.append(c)
    # Viterbi over the measured intervals (gaps bridged: a longer gap allows a larger change of speed)
    total_cost = 0.0
    order = [k for k in range(m) if states[k]]
    if order:
        acc = costs[order[0]].copy()
        back = []
        for a, b in zip(order, order[1:]):
            prev_v = np.array([o[0] for o in states[a]])
            cur_v = np.array([o[0] for o in states[b]])
            dv = np.linalg.norm(cur_v[:, None, :] - prev_v[None, :, :], axis=2)
            elapsed = float(frames[b].t - frames[a].t)
            trans = (dv / (9.0 * elapsed + 0.8)) ** 2
            total = acc[None, :] + trans
            arg = total.argmin(axis=1)
            back.append(arg)
            acc = total[np.arange(len(cur_v)), arg] + costs[b]
        seq = [int(acc.argmin())]
        total_cost = float(acc.min())
        for arg in reversed(back):
            seq.append(int(arg[seq[-1]]))
        seq.reverse()
        for k, sidx in zip(order, seq):
            vel[k] = states[k][sidx][0]
            known[k] = True
    # isolated jumps (a wrong alias or a confusing frame pair): replace by the local median
    if known.sum() >= 5:
        idx = np.nonzero(known)[0]
        fixed = vel.copy()
        for pos, k in enumerate(idx):
            nb = idx[max(0, pos - 3):pos + 4]
            med = np.median(vel[nb], axis=0)
            if float(np.hypot(*(vel[k] - med))) > 3.0:
                fixed[k] = med
        vel = fixed
    # a car moves along its heading: limit the sideways part (pedestrian anchors walk across the road)
    for k in np.nonzero(known)[0]:
        c, s_ = math.cos(heading[k]), math.sin(heading[k])
        lon_v = vel[k, 0] * c + vel[k, 1] * s_
        lat_v = -vel[k, 0] * s_ + vel[k, 1] * c
        cap = 0.1 * abs(lon_v) + 0.3
        lat_v = max(-cap, min(cap, lat_v))
        vel[k] = (lon_v * c - lat_v * s_, lon_v * s_ + lat_v * c)
    measured = known.copy()
    # short gaps: interpolate
    if known.any() and not known.all():
        idx = np.nonzero(known)[0]
        for k in np.nonzero(~known)[0]:
            before, after = idx[idx < k], idx[idx > k]
            if len(before) and len(after) and (after[0] - before[-1] <= 6 or (
                    after[0] - before[-1] <= 30 and float(np.hypot(*(vel[after[0]] - vel[before[-1]]))) < 3.0)):
                a, b = before[-1], after[0]
                u = (k - a) / float(b - a)
                vel[k] = (1 - u) * vel[a] + u * vel[b]
                known[k] = True
    return vel, known, {"line_intervals": line_intervals, "anchor_intervals": int(sum(1 for a in anchor if a)),
                        "measured_intervals": int(measured.sum()), "interpolated_intervals":
                        int(known.sum() - measured.sum()), "intervals": m, "cost": round(total_cost, 3),
                        "measured": measured}


# ----------------------------------------------------------------------------- road
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


# ----------------------------------------------------------------------------- events
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


def _speed_events(t: np.ndarray, sp: np.ndarray) -> Tuple[bool, bool, float]:
    """(braked, accelerated, share of measured time below STOP_SPEED)."""
    ok = np.isfinite(sp)
    brake = accel = False
    idx = np.nonzero(ok)[0]
    for ai, a in enumerate(idx):
        for b in idx[ai + 1:]:
            span = t[b] - t[a]
            if span > 5.0:
                break
            drop = sp[a] - sp[b]
            rate = drop / max(span, 0.4)
            if drop >= BRAKE_DROP and rate >= BRAKE_RATE:
                brake = True
            if -drop >= ACCEL_RISE and -rate >= BRAKE_RATE:
                accel = True
    slow = float(np.mean(sp[ok] < STOP_SPEED)) if ok.any() else 0.0
    return brake, accel, slow


@dataclass
class _Ctx:
    frames: List[_Frame]
    times: np.ndarray
    scale: float
    heading: np.ndarray
    ego_v: np.ndarray          # per frame, map m/s (NaN unknown)
    road: Optional[str]
    lane_w: float
    ego_lanes: List[Optional[int]]
    junction: bool
    ego_pos: Optional[np.ndarray] = None   # per frame, integrated ego position (map m)
    ego_seg: Optional[np.ndarray] = None   # per frame, id of the stretch of measured ego motion (-1: none)
    ego_sure: Optional[np.ndarray] = None  # per frame, ego motion measured (not interpolated) around it


def _kinematics(ctx: _Ctx, trk: Track) -> None:
    idx = np.array(trk.idx)
    t = ctx.times[idx]
    rel = np.array(trk.rel, float)
    hd = ctx.heading[idx]
    lon = rel[:, 0] * np.cos(hd) + rel[:, 1] * np.sin(hd)
    lat = -rel[:, 0] * np.sin(hd) + rel[:, 1] * np.cos(hd)
    valid = np.array([not b.border or b.placed for b in trk.blobs])
    pos = rel.copy()
    if valid.sum() >= 3:
        pos[~valid] = np.nan
    # absolute velocity: slope of (ego position + relative position) within one stretch of measured ego
    # motion, so that the ego's and the actor's motion are smoothed alike
    vabs = np.full(rel.shape, np.nan)
    if ctx.ego_pos is not None:
        seg = ctx.ego_seg[idx]
        world = pos + ctx.ego_pos[idx]
        for sid in set(seg.tolist()) - {-1}:
            sel = seg == sid
            if sel.sum() >= 2:
                vabs[sel] = _local_slope(t[sel], world[sel], 0.5)
    speed = np.hypot(vabs[:, 0], vabs[:, 1])
    if ctx.ego_sure is not None:
        speed = np.where(ctx.ego_sure[idx], speed, np.nan)   # no speeds from a guessed ego motion
    trk.info.update(t=t, lon=lon, lat=lat, valid=valid, vabs=vabs, speed=speed)
    lanes, ego_lanes = [], []
    for k, fi in enumerate(idx):
        fr = ctx.frames[fi]
        lanes.append(_lane_of(_lines_lat(fr, ctx.heading[fi], ctx.scale, float(lon[k])), float(lat[k]),
                              0.2 * ctx.lane_w))
        ego_lanes.append(ctx.ego_lanes[fi])
    trk.info.update(lanes=lanes, ego_lanes=ego_lanes)


def _facing(trk: Track, ctx: _Ctx) -> None:
    """Headings of a vehicle track: long axis pointed by its headlights, else by its motion."""
    good = [k for k, b in enumerate(trk.blobs) if not b.border and b.length > 1.3 * b.width]
    if not good:
        trk.info.update(axis=np.array([b.axis for b in trk.blobs]), facing_votes=(0, 0), headings=None,
                        facing_sure=False)
        return
    raw = [trk.blobs[k].axis for k in good]
    axes = _unwrap_axis(raw)
    full = np.interp(np.arange(len(trk.blobs)), good, axes) if len(good) > 1 else np.full(len(trk.blobs), axes[0])
    votes = [v for v in _facing_votes(raw, [trk.blobs[k].front for k in good], axes) if v]
    score = float(np.sum(votes))
    sure = len(votes) >= 3 and abs(score) >= 0.6 * len(votes)
    trk.info["axis"] = full
    trk.info["facing_votes"] = (int(sum(1 for v in votes if v > 0)), int(sum(1 for v in votes if v < 0)))
    if votes and abs(score) >= 1:
        trk.info["headings"] = full + (0.0 if score > 0 else math.pi)
        trk.info["facing_sure"] = sure
    else:
        trk.info["headings"] = None
        trk.info["facing_sure"] = False


def _orient_by_motion(trk: Track, ctx: _Ctx) -> None:
    if trk.info.get("headings") is not None and trk.info.get("facing_sure"):
        return
    vabs = trk.info.get("vabs")
    if vabs is None:
        return
    ok = np.isfinite(vabs).all(axis=1)
    if ok.sum() < 3:
        return
    mean = vabs[ok].mean(axis=0)
    if float(np.hypot(*mean)) < 2.0:
        return
    ax = trk.info["axis"]
    axv = np.array([math.cos(ax[0]), math.sin(ax[0])])
    sign = 1.0 if float(mean @ axv) >= 0 else -1.0
    trk.info["headings"] = ax + (0.0 if sign > 0 else math.pi)
    trk.info["facing_sure"] = True
    trk.info["facing_from"] = "motion"


def _actor(ctx: _Ctx, trk: Track, ego_turn: Optional[str]) -> Optional[Dict[str, Any]]:
    """What one tracked actor does, relative to the ego; None when it is too far to matter."""
    t, lon, lat, speed = trk.info["t"], trk.info["lon"], trk.info["lat"], trk.info["speed"]
    valid = trk.info["valid"]
    lanes, ego_lanes = trk.info["lanes"], trk.info["ego_lanes"]
    n = len(t)
    dist = np.hypot(lon, lat)
    if n < 3 or dist.min() > NEAR:
        return None
    kind = trk.kind
    lane_w = ctx.lane_w
    vehicle = kind in ("car", "truck")
    acts: set = set()
    rels: set = set()
    notes: Dict[str, Any] = {"frames": n, "min_dist": round(float(dist.min()), 1)}
    # facing against the ego: oncoming
    oncoming = False
    hd = trk.info.get("headings")
    if vehicle and hd is not None:
        # compare with the ego's heading before it turns (an oncoming car stays oncoming while the ego turns)
        ego_start = float(ctx.heading[0])
        early = [k for k, i in enumerate(trk.idx) if abs(float(ctx.heading[i]) - ego_start) < math.radians(30)]
        own = [k for k in range(n) if not trk.blobs[k].border] or list(range(n))
        sel = [k for k in early if k in own] or own
        ref = [float(ctx.heading[trk.idx[k]]) if early else ego_start for k in sel]
        diffs = np.array([abs(_wrap(float(hd[k]) - r)) for k, r in zip(sel, ref)])
        first = diffs[: max(3, len(diffs) // 3)]
        oncoming = bool(np.median(diffs) > math.radians(135))
        crossing = not oncoming and bool(np.median(first) > math.radians(50))
        if oncoming and np.isfinite(speed).sum() >= 3 and float(np.nanmedian(speed)) < 1.5:
            oncoming = False   # parked facing the ego: not coming towards it
        notes["facing_diff_deg"] = round(math.degrees(float(np.median(diffs))), 1)
    else:
        crossing = False
    notes.update(oncoming=oncoming, crossing=crossing)
    in_lane = np.array([(lanes[k] is not None and ego_lanes[k] is not None and lanes[k] == ego_lanes[k]) or
                        ((lanes[k] is None or ego_lanes[k] is None) and abs(lat[k]) < 0.5 * lane_w)
                        for k in range(n)])
    # first frame fully in view: the set-up
    k0 = next((k for k in range(n) if valid[k]), 0)
    # ---- speed events
    moving = bool(np.nanmax(speed) > 2.0) if np.isfinite(speed).any() else True
    if vehicle:
        sp = np.where(valid, speed, np.nan) if valid.sum() >= 4 else speed
        brake, accel, slow = _speed_events(t, sp)
        fin = np.isfinite(sp)
        notes.update(speed_start=round(float(np.nanmedian(sp[fin][:3])), 1) if fin.any() else None,
                     speed_end=round(float(np.nanmedian(sp[fin][-3:])), 1) if fin.any() else None,
                     slow_share=round(slow, 2))
        stopped_from_start = fin.sum() >= 3 and bool(np.all(sp[fin][:3] < STOP_SPEED + 0.5))
        still_at_end = fin.sum() >= 3 and bool(np.all(sp[fin][-3:] < STOP_SPEED + 0.5))
        in_lane_ahead = bool(np.any(in_lane & (lon > 0)))
        if brake:
            acts.add("brake")   # braking hard, possibly to a standstill
        elif slow >= 0.6 or (stopped_from_start and slow >= 0.4):
            # waiting at a junction and driving off is not a stop; a car parked off the ego's lane is just parked
            if (not ctx.junction or still_at_end) and in_lane_ahead:
                acts.add("stop")
        elif not fin.any() and in_lane_ahead and not oncoming and not crossing:
            # no world reference to measure speeds: the ego closing in fast and then waiting behind it
            vr = _local_slope(t, lon, 0.5)
            ok = np.isfinite(vr)
            if ok.sum() >= 6:
                closing = -float(np.median(vr[ok][:3]))
                settle = abs(float(np.median(vr[ok][-3:])))
                notes["closing_speed"] = round(closing, 1)
                if closing >= 5.0 and settle < 0.8 and float(lon[-1]) < 15.0:
                    acts.add("stop")
        if accel and not brake and "stop" not in acts and not ctx.junction and not stopped_from_start:
            acts.add("accelerate")
    # ---- turns
    if vehicle and hd is not None:
        good = [k for k in range(n) if not trk.blobs[k].border and trk.blobs[k].length > 1.3 * trk.blobs[k].width]
        if len(good) >= 4:
            un = np.array(hd)[good]
            turn = float(np.median(un[-2:]) - np.median(un[:2]))
            notes["turn_deg"] = round(math.degrees(turn), 1)
            if abs(turn) >= TURN_ANGLE and moving:
                acts.add("turn_left" if turn > 0 else "turn_right")
    # ---- lane changes, cut-in, merge, overtake
    cut_in = False
    start_lane = lanes[k0]
    start_in_lane = bool(in_lane[k0])
    if vehicle and not oncoming and not ctx.junction and not crossing:
        changes = _lane_changes(lanes)
        for k, a, b in changes:
            acts.add("lane_change_right" if b > a else "lane_change_left")
            later = range(k, min(n, k + 8))
            if ego_lanes[k] is not None and b == ego_lanes[k] and any(-2.0 < lon[m] < 40.0 for m in later):
                cut_in = True
                notes["cut_in_t"] = round(float(t[k]), 2)
            if ctx.road == "merge" and b < a and (start_lane is None or a == max(l for l in lanes if l is not None)):
                acts.add("merge")
        near_lanes = bool(np.all(np.abs(lat[valid]) < 1.6 * lane_w)) if valid.any() else False
        if not changes and near_lanes:
            ok = np.isfinite(lat) & valid
            if ok.sum() >= 6:
                lat_s = _smooth(t[ok], lat[ok], 0.5)
                shift = float(lat_s[-1] - lat_s[0])
                if abs(shift) >= 0.75 * lane_w:
                    acts.add("lane_change_left" if shift > 0 else "lane_change_right")
                    if abs(lat_s[-1]) < 0.5 * lane_w and lon[ok][-1] > -2.0:
                        cut_in = True
        if ctx.road == "merge" and "merge" not in acts and start_lane is None and any(
                l is not None for l in lanes[k0 + 2:]) and lat[k0] < -1.0 * lane_w:
            acts.add("merge")
            if any(in_lane[k] and lon[k] > -2 for k in range(k0, n)):
                cut_in = True
        if cut_in:
            acts.add("cut_in")
        # overtaking: from behind to ahead, pulling out of a lane and back into it
        passed = lon[k0] < -2.0 and lon[-1] > 3.0
        out_and_back = any(changes[i][1] == changes[j][2] for i in range(len(changes))
                           for j in range(i + 1, len(changes)))
        beside = [k for k in range(n) if abs(lon[k]) < 3.0]
        if passed and out_and_back and beside and not all(in_lane[k] for k in beside):
            acts.add("overtake")
        notes["lane_changes"] = [(round(float(t[k]), 1), a, b) for k, a, b in changes]
        if changes:
            start_lane = changes[0][1]
            start_in_lane = ego_lanes[changes[0][0]] is not None and start_lane == ego_lanes[changes[0][0]]
            k_side = max(0, changes[0][0] - 1)
            if not start_in_lane:
                la_side = float(lat[k_side])
                side_hint = "left_of" if la_side > 0 else "right_of"
                notes["side_before_change"] = side_hint
    # ---- oncoming drift
    if vehicle and oncoming and not ctx.junction:
        # an oncoming car inside the ego's lane ahead has drifted over the centre line
        inside = (np.abs(lat) < 0.5 * lane_w) & (lon > 0) & (lon < 40) & valid
        if int(inside.sum()) >= 2:
            acts.add("drift")
    # ---- pedestrians crossing
    if kind == "pedestrian":
        ok = np.isfinite(lat)
        lat_s = _smooth(t[ok], lat[ok], 0.5) if ok.sum() else lat
        travel = float(np.nanmax(lat_s) - np.nanmin(lat_s)) if len(lat_s) else 0.0
        lane_seq = [l for l in lanes if l is not None]
        crossed = len(set(lane_seq)) >= 2 or (lanes[0] is None and lane_seq)
        if travel >= 2.0 and (crossed or travel >= 3.0):
            acts.add("cross")
        notes["lateral_travel"] = round(travel, 2)
    # ---- collisions
    if trk.crashed:
        acts.add("collide")   # crashed vehicles turn red
    # ---- through the junction
    if ctx.junction and vehicle and moving and not ({"turn_left", "turn_right"} & acts):
        acts.add("go_straight")
    if ctx.junction and (crossing or oncoming or int(np.sum(in_lane & (lon > 0))) < 4):
        acts.discard("brake")   # yielding and slowing for turns are part of crossing a junction
    # ---- relations (where it starts, and where a cut-in ends)
    lo0, la0 = float(lon[k0]), float(lat[k0])
    side = ("left_of" if la0 > 0 else "right_of") if abs(la0) > 0.5 * lane_w else None
    if notes.get("side_before_change"):
        side = notes["side_before_change"]
    if kind == "pedestrian":
        if "cross" in acts:
            rels.update({"ahead_of", "crossing_path"})
        else:
            rels.add("ahead_of" if lo0 > 0 else "behind")
            if side:
                rels.add(side)
    elif vehicle and oncoming:
        rels.add("oncoming")
        if ego_turn == "turn_left":
            rels.add("crossing_path")
    elif "cut_in" in acts or "merge" in acts:
        rels.add("ahead_of")
        if start_in_lane and not ("merge" in acts):
            rels.add("same_lane")
        elif "merge" in acts:
            rels.add("right_of" if la0 <= 0 else "left_of")
        elif side:
            rels.add(side)
    elif ctx.junction and vehicle:
        turned_in = bool(({"turn_left", "turn_right"} & acts) and in_lane[-1] and lon[-1] > 0)
        if turned_in:
            rels.add("ahead_of")
            if side:
                rels.add(side)
        elif crossing:
            # across the ego's course: it passes from one side of the ego's heading line to the other, ahead
            ahead = lon > -2.0
            if ahead.any() and (np.nanmax(lat[ahead]) > 0.5 * lane_w and np.nanmin(lat[ahead]) < -0.5 * lane_w
                                or "go_straight" in acts):
                rels.add("crossing_path")
            elif side:
                rels.add(side)
        elif start_in_lane:
            rels.update({"ahead_of" if lo0 > 0 else "behind", "same_lane"})
        else:
            if side:
                rels.add(side)
            rels.add("ahead_of" if lo0 > 0 else "behind")
    elif start_in_lane:
        rels.add("same_lane")
        rels.add("ahead_of" if lo0 > 0 else "behind")
    else:
        if side:
            rels.add(side)
        if abs(lo0) > 10.0 and not ("overtake" in acts):
            rels.add("ahead_of" if lo0 > 0 else "behind")
    # ---- does it interact with the ego?
    lead = int(np.sum(in_lane & (lon > 0) & (lon < 40.0) & valid)) >= 4 and not oncoming
    notable = bool(acts & {"brake", "stop", "cut_in", "merge", "lane_change_left", "lane_change_right",
                           "turn_left", "turn_right", "cross", "collide", "drift", "overtake"})
    if not (acts - {"accelerate"}):
        acts.discard("accelerate")  # speeding up alone is not part of the scene's story
    close_oncoming = oncoming and bool(np.any((np.abs(lat) < 1.7 * lane_w) & (np.abs(lon) < 35)))
    seen = int(valid.sum())
    fully = any(not b.border for b in trk.blobs)
    if vehicle and not fully:
        role = "traffic" if seen >= 3 else None   # never entirely in view: counted, nothing more
    elif kind == "pedestrian":
        role = "key" if dist.min() < 35 else None
    elif kind == "obstacle":
        role = "key" if bool(np.any(in_lane & (lon > 0))) else ("traffic" if dist.min() < TRAFFIC_NEAR else None)
        acts.clear()
    elif close_oncoming or (notable and dist.min() < 40.0):
        role = "key"
    elif ctx.junction and dist.min() < 25.0 and moving:
        role = "key"
    elif vehicle and not moving and np.isfinite(speed).any() and dist.min() < 25.0:
        role = "key"   # parked near the ego's path
        notes["parked"] = True
    elif seen >= 3 and vehicle:
        role = "traffic"   # any other vehicle in view: counted, not described
    else:
        role = None
    if role is None:
        return None
    if lead and vehicle and not oncoming and not crossing and not ctx.junction and \
            not (acts & {"cut_in", "merge", "overtake", "turn_left", "turn_right"}):
        rels = {"ahead_of", "same_lane"}
    if role == "traffic":
        acts, rels = set(), set()
    if "merge" in acts:
        acts -= {"lane_change_left", "lane_change_right"}   # merging is the lane change
        if "ahead_of" in rels:
            acts.add("cut_in")   # merging into the lane in front of the ego
    return {"track": trk, "kind": kind, "role": role, "actions": acts, "relations": rels, "lead": lead,
            "oncoming": oncoming, "notes": notes, "min_dist": float(dist.min()), "first_t": float(t[0])}


def _ego_actions(ctx: _Ctx, ego_speed: np.ndarray, crashed: bool) -> Tuple[set, set, Dict[str, Any]]:
    acts: set = set()
    heading = ctx.heading
    n = len(heading)
    turn = float(np.median(heading[-2:]) - np.median(heading[:2])) if n >= 4 else 0.0
    late = heading[-min(n, 4):]
    still_turning = len(late) >= 3 and abs(float(late[-1] - late[0])) > math.radians(3)
    notes: Dict[str, Any] = {"turn_deg": round(math.degrees(turn), 1)}
    if abs(turn) >= TURN_ANGLE or (ctx.junction and abs(turn) >= PARTIAL_TURN and (still_turning or crashed)):
        acts.add("turn_left" if turn > 0 else "turn_right")
    elif ctx.junction:
        acts.add("go_straight")
    if not ctx.junction:
        for _, a, b in _lane_changes(ctx.ego_lanes, 3):
            acts.add("lane_change_right" if b > a else "lane_change_left")
    if crashed:
        acts.add("collide")
    reactions: set = set()
    t = ctx.times
    fin = np.isfinite(ego_speed)
    if fin.sum() >= 4:
        brake, accel, slow = _speed_events(t, ego_speed)
        if brake:
            reactions.add("brake")
        if accel:
            reactions.add("accelerate")
        if np.nanmin(ego_speed) < STOP_SPEED and np.nanmax(ego_speed) > 3.0:
            reactions.add("stop")
        notes.update(speed_start=round(float(np.nanmedian(ego_speed[fin][:3])), 1),
                     speed_end=round(float(np.nanmedian(ego_speed[fin][-3:])), 1))
    notes["reactions"] = sorted(reactions)
    return acts, reactions, notes


# ----------------------------------------------------------------------------- language
# Every template below reads back, through dv2s_gym.pipeline.semantics.elements_from_text, as the
# elements the analysis produced (the pipeline parses the description text).
_COUNT = {1: "a", 2: "two", 3: "three", 4: "four", 5: "five", 6: "six", 7: "seven", 8: "eight"}


def _noun(kind: str, count: int = 1) -> str:
    if count == 1:
        return kind
    return {"pedestrian": "pedestrians", "obstacle": "obstacles", "truck": "trucks"}.get(kind, kind + "s")


def _clause(actor: Dict[str, Any], count: int, ref: str) -> str:
    """Subject and predicate for ``count`` identical actors; ``ref`` names the ego ("it" or "the ego car")."""
    kind, acts, rels = actor["kind"], actor["actions"], actor["relations"]
    poss = "its" if ref == "it" else "the ego car's"
    lane = "its lane" if ref == "it" else "the ego's lane"
    plural = count > 1
    n = _COUNT.get(count, str(count))
    noun = _noun(kind, count)
    art = ("an" if kind[0] in "aeiou" else "a") if not plural else n

    def verb(singular: str, plural_form: str) -> str:
        return plural_form if plural else singular

    side = "left" if "left_of" in rels else "right" if "right_of" in rels else None
    where = []
    if "ahead_of" in rels:
        where.append(f"ahead of {ref}")
    if "behind" in rels:
        where.append(f"behind {ref}")
    if side:
        where.append(f"on {poss} {side}")
    at = (" " + " ".join(where)) if where else ""
    extra: List[str] = []
    if "brake" in acts:
        extra.append(verb("suddenly brakes", "suddenly brake"))
    if "accelerate" in acts:
        extra.append(verb("accelerates", "accelerate"))
    if "stop" in acts:
        extra.append(verb("stands still", "stand still"))
    if "collide" in acts and not actor.get("hits_ego"):
        extra.append(verb("crashes", "crash"))

    def join(head: str, more: List[str]) -> str:
        return " and ".join([head] + more)

    if kind == "obstacle":
        if "same_lane" in rels:
            return f"{art} {noun} {verb('lies', 'lie')} in the ego's lane ahead"
        return f"{art} {noun} {verb('lies', 'lie')}{at}"
    if kind == "pedestrian":
        if "cross" in acts:
            return f"{art} {noun} {verb('crosses', 'cross')} the road in front of {ref}"
        return f"{art} {noun} {verb('waits', 'wait')}{at}"
    if "merge" in acts:
        if "ahead_of" in rels:
            return join(f"{art} {noun} from the on-ramp {verb('merges', 'merge')} into the lane in front of {ref}",
                        extra)
        return join(f"{art} {noun} from the on-ramp {verb('merges', 'merge')} onto the highway behind {ref}", extra)
    if "cut_in" in acts and "overtake" in acts:
        return join(f"a faster {noun} {verb('overtakes', 'overtake')} the ego car and "
                    f"{verb('pulls', 'pull')} back into the ego's lane just ahead of {ref}", extra)
    if "cut_in" in acts:
        origin = f" in the lane to the {side} of the ego car" if side else ""
        return join(f"{art} {noun}{origin} {verb('cuts', 'cut')} into the ego's lane just ahead of {ref}", extra)
    if "oncoming" in rels:
        head = f"{'an' if not plural else n} oncoming {noun}"
        if "drift" in acts:
            main = f"{verb('drifts', 'drift')} across the centre line into the ego's lane"
        elif "go_straight" in acts:
            main = f"{verb('goes', 'go')} straight on"
        elif "turn_left" in acts or "turn_right" in acts:
            main = f"{verb('turns', 'turn')} {'left' if 'turn_left' in acts else 'right'}"
        else:
            main = f"{verb('passes', 'pass')} by in the other lane"
        return join(f"{head} {main}", extra)
    if "crossing_path" in rels:
        return join(f"{art} {noun} {verb('crosses', 'cross')} the ego's path and {verb('goes', 'go')} straight on",
                    extra)
    if "turn_left" in acts or "turn_right" in acts:
        d = "left" if "turn_left" in acts else "right"
        origin = f" from the side road on {poss} {side}" if side else ""
        into = f" into the ego's lane just ahead of {ref}" if "ahead_of" in rels else ""
        return join(f"{art} {noun}{origin} {verb('turns', 'turn')} {d}{into}", extra)
    if "keep_lane" in acts and side:
        return f"{art} {noun} {verb('drives', 'drive')} alongside the ego car in the lane to {poss} {side}"
    if actor.get("notes", {}).get("parked"):
        where_p = at.replace(f"ahead of {ref}", "ahead of the ego car").replace(f"behind {ref}", "behind the ego car")
        return f"{art} {noun} {verb('is', 'are')} parked{where_p}"
    if "same_lane" in rels:
        at = f" {'ahead of' if 'ahead_of' in rels else 'behind'} {ref} in the same lane"
        if acts == {"stop"} and "ahead_of" in rels:
            return f"{art} {noun} {verb('stands', 'stand')} still in {lane} ahead"
    main: List[str] = []
    if "lane_change_left" in acts and "lane_change_right" in acts:
        main.append(f"{verb('changes', 'change')} to the left lane and back to the right lane")
    elif "lane_change_left" in acts:
        main.append(f"{verb('changes', 'change')} to the left lane")
    elif "lane_change_right" in acts:
        main.append(f"{verb('changes', 'change')} to the right lane")
    if "overtake" in acts:
        main.append(f"{verb('overtakes', 'overtake')} the ego car")
    if "go_straight" in acts:
        main.append(f"{verb('goes', 'go')} straight on")
    if "drift" in acts:
        main.append(f"{verb('drifts', 'drift')} across the centre line")
    main += extra
    if not main:
        main.append(verb("follows", "follow") if "behind" in rels and "same_lane" in rels else verb("drives on", "drive on"))
    return f"{art} {noun}{at} " + " and ".join(main)


def _groups(actors: List[Dict[str, Any]]) -> List[Tuple[Dict[str, Any], int]]:
    """Identical actors (same kind, actions, relations) together, with their count."""
    groups: List[List[Any]] = []
    keys: List[Tuple] = []
    for a in actors:
        key = (a["kind"], tuple(sorted(a["actions"])), tuple(sorted(a["relations"])), bool(a["notes"].get("parked")))
        if key in keys:
            groups[keys.index(key)][1] += 1
        else:
            keys.append(key)
            groups.append([a, 1])
    return [(a, c) for a, c in groups]


def _definite(clause: str) -> str:
    """The actor was already introduced: "a car ahead ..." -> "the car ahead ..."."""
    return re.sub(r"^(?:a|an) ", "the ", clause)


def _cap(text: str) -> str:
    return text[0].upper() + text[1:]


def _describe(road: Optional[str], ego_acts: set, actors: List[Dict[str, Any]], ego_lane: Optional[int],
              n_lanes: int) -> str:
    """Paper-style description: the ego and the key event, the other actors, where it takes place."""
    place = ROAD_PHRASES.get(road or "", "a road")
    if "turn_left" in ego_acts or "turn_right" in ego_acts:
        first = f"The ego car turns {'left' if 'turn_left' in ego_acts else 'right'} at {place}"
    elif "go_straight" in ego_acts:
        first = f"The ego car goes straight through {place}"
    elif "lane_change_left" in ego_acts or "lane_change_right" in ego_acts:
        first = f"The ego car changes to the {'left' if 'lane_change_left' in ego_acts else 'right'} lane of {place}"
    else:
        where = ""
        if n_lanes >= 2 and ego_lane is not None:
            if ego_lane == 0:
                where = "the left lane of "
            elif ego_lane == n_lanes - 1:
                where = "the right lane of "
            elif n_lanes == 3 and ego_lane == 1:
                where = "the middle lane of "
        first = f"The ego car drives in {where}{place}" if where else f"The ego car drives along {place}"
    key = [a for a in actors if a["role"] == "key"]
    key.sort(key=lambda a: (-len(a["actions"] - {"go_straight", "keep_lane", "collide"}),
                            "keep_lane" in a["actions"], a["min_dist"]))
    groups = _groups(key)
    sentences = []
    if groups:
        actor, count = groups[0]
        first += " while " + _clause(actor, count, "it")
    sentences.append(first + ".")
    for actor, count in groups[1:]:
        sentences.append(_cap(_clause(actor, count, "the ego car")) + ".")
    traffic = [a for a in actors if a["role"] == "traffic"]
    if traffic:
        counts: Dict[str, int] = {}
        for a in traffic:
            counts[a["kind"]] = counts.get(a["kind"], 0) + 1
        parts = [f"{_COUNT.get(c, str(c)) if c > 1 else 'one'} other {_noun(k, c)}" for k, c in sorted(counts.items())]
        total = sum(counts.values())
        sentences.append(_cap(" and ".join(parts)) + (" drive nearby." if total > 1 else " drives nearby."))
    partner = next((a for a in key if a.get("hits_ego")), None)
    if partner is not None:
        sentences.append(f"The {partner['kind']} collides with the ego car.")
        if "collide" in ego_acts:
            sentences.append(f"The ego car collides with the {partner['kind']}.")
    elif "collide" in ego_acts:
        sentences.append("The ego car crashes.")
    if not key and not traffic:
        sentences.append("No other road user comes near the ego car.")
    sentences.append(f"This scene takes place {ROAD_SCENES.get(road or '', 'on a road')}.")
    return " ".join(sentences)


def _answer(question: str, road, ego_acts: set, ego_react: set, actors: List[Dict[str, Any]]) -> Optional[str]:
    """A one-sentence answer to a question about the clip, when the analysis can give one."""
    q = question.lower()
    key = sorted([a for a in actors if a["role"] == "key"], key=lambda a: a["min_dist"])
    cause = next((a for a in key if a["actions"] & {"brake", "stop", "cut_in", "merge", "cross", "drift"}
                  or a["lead"] or a["kind"] in ("obstacle", "pedestrian")), None)
    if cause is None:   # yielding: to oncoming traffic when turning, to traffic crossing its path
        cause = next((a for a in key if a["relations"] & {"oncoming", "crossing_path"}), None)
    if re.search(r"\b(why|cause|reason)\b", q) and re.search(r"(brak|slow|stop|decelerat|yield|wait|halt)", q):
        if not ego_react & {"brake", "stop"}:
            return "The ego car does not visibly brake in this video."
        if cause is None:
            return "The ego car brakes, but no other road user in view explains it."
        yielding = cause["kind"] in ("car", "truck") and not (
            cause["actions"] & {"brake", "stop", "cut_in", "merge", "drift"} or cause["lead"])
        if yielding and "oncoming" in cause["relations"] and ("turn_left" in ego_acts or "turn_right" in ego_acts):
            return "The ego car brakes to yield to the oncoming traffic before it turns."
        if yielding and "crossing_path" in cause["relations"]:
            return "The ego car brakes to yield to the traffic crossing its path."
        return f"The ego car brakes because {_definite(_clause(cause, 1, 'the ego car'))}."
    if re.search(r"(collid|crash|accident|\bhit)", q):
        if "collide" in ego_acts:
            partner = next((a for a in key if a.get("hits_ego")), None)
            return f"Yes, the ego car collides with the {partner['kind']}." if partner else "Yes, the ego car crashes."
        return "No, nothing collides with the ego car in this video."
    m = re.search(r"how many (cars|vehicles|trucks|pedestrians|people)", q)
    if m:
        word = m.group(1)
        kinds = {"cars": ("car",), "vehicles": ("car", "truck"), "trucks": ("truck",),
                 "pedestrians": ("pedestrian",), "people": ("pedestrian",)}[word]
        count = sum(1 for a in actors if a["kind"] in kinds)
        return f"There are {count} {word} around the ego car."
    if re.search(r"\bturn", q):
        if "turn_left" in ego_acts:
            return "The ego car turns left."
        if "turn_right" in ego_acts:
            return "The ego car turns right."
        return "The ego car does not turn."
    if re.search(r"\b(road|where|location|place|kind of)\b", q):
        return f"The scene takes place {ROAD_SCENES.get(road or '', 'on a road')}."
    if re.search(r"\b(what|happen|describe|event)\b", q) and key:
        return f"The key event: {_definite(_clause(key[0], 1, 'the ego car'))}."
    return None


# ----------------------------------------------------------------------------- main
def _frames_and_times(clip) -> Tuple[List[np.ndarray], np.ndarray, str, Dict[str, Any]]:
    frames = list(getattr(clip, "frames", None) or [])
    path = str(getattr(clip, "path", "") or "")
    times = getattr(clip, "times", None)
    info: Dict[str, Any] = {"input_frames": len(frames)}
    if times is None or len(times) != len(frames):
        times = [i / 5.0 for i in range(len(frames))]
    times = np.asarray(times, float)
    rate = (len(times) - 1) / (times[-1] - times[0]) if len(times) > 1 and times[-1] > times[0] else 0.0
    source_fps = float(getattr(clip, "source_fps", 0.0) or 0.0)
    if rate < MIN_RESAMPLE_FPS and source_fps > rate + 0.5 and path and os.path.isfile(path):
        from dv2s_gym.pipeline.video import read_video

        options = dict(BEV_READ_OPTIONS)
        if frames:
            h, w = frames[0].shape[:2]
            options["max_pixels"] = max(w * h, 1)
        dense = read_video(path, **options)
        if len(dense.frames) > len(frames):
            info["resampled_from"] = f"{len(frames)} frames at {rate:.2f}/s"
            frames, times = list(dense.frames), np.asarray(dense.times, float)
    info["frames"] = len(frames)
    return frames, times, path, info


def analyze_bev(clip, question: Optional[str] = None) -> BevAnalysis:
    """Describe a bird's-eye clip: description, semantic elements, tracks and debug info.

    ``clip`` is a :class:`~dv2s_gym.pipeline.video.VideoClip` (or any object with
    ``frames`` and ``times``). Clips sampled below 4 frames/s whose ``path`` is a
    readable video are re-read at :data:`BEV_READ_OPTIONS`. ``question``, when
    given, adds an answer sentence (e.g. "Why did the ego vehicle brake?").

    Raises :class:`NotBirdsEyeError` when the frames are not such a render.
    """
    import cv2

    started = time.perf_counter()
    frames, times, path, input_info = _frames_and_times(clip)
    if not frames:
        raise NotBirdsEyeError(f"{path or 'the clip'} holds no frames to analyse")
    frames = [np.ascontiguousarray(f[..., :3], dtype=np.uint8) for f in frames]
    bev_stats = _check_birds_eye(frames, path)
    h, w = frames[0].shape[:2]
    hsvs = [_hsv(f) for f in frames]
    blobs_per = [_detect_blobs(f, hsv) for f, hsv in zip(frames, hsvs)]
    # the ego: the green blob at the view's fixed spot; the scale from its length
    greens = []
    for blobs in blobs_per:
        g = [b for b in blobs if b.kind == "ego" and not b.border]
        if g:
            b = max(g, key=lambda b: b.area)
            greens.append((b.x, b.y, b.length, b.width))
    if not greens:
        raise NotBirdsEyeError(f"{path or 'the video'}: no green ego vehicle found; describe real driving videos "
                               "with the VLM backend instead (--dra openai)")
    gx, gy = float(np.median([g[0] for g in greens])), float(np.median([g[1] for g in greens]))
    ego_len = float(np.median([g[2] for g in greens]))
    ego_wid = float(np.median([g[3] for g in greens]))
    # the coloured body is the rectangle minus its 1-px outline (4.5 m x 2 m in the bank, 5 m x 2 m in
    # highway-env's own envs): average the estimates from both sides
    scale = max(1.0, 0.5 * ((ego_len + 2.0) / EGO_LENGTH_M + (ego_wid + 2.0) / EGO_WIDTH_M))
    out: List[_Frame] = []
    crashed_frames = 0
    for fi, (f, hsv, blobs) in enumerate(zip(frames, hsvs, blobs_per)):
        ego, best = None, None
        for b in blobs:
            if b.kind in ("ego", "red", "car", "yellow", "truck"):
                d = math.hypot(b.x - gx, b.y - gy)
                if d < 0.6 * ego_len and (best is None or (b.kind == "ego", -d) > (best[1].kind == "ego", -best[0])):
                    best = (d, b)
        if best is not None:
            ego = best[1]
            if ego.kind == "red":
                crashed_frames += 1
        others = [b for b in blobs if b is not ego and not (b.kind == "ego" and b.area < 0.3 * ego_len * ego_len / 3)]
        for b in others:
            _fix_border_position(b, ego_len * (2.1 if b.kind == "truck" else 1.0), w, h)
        white = _mask(hsv, (0, 0, 150), (179, 59, 255)) // 255
        lines = _detect_lines(white, scale)
        if fi % 3 == 0:
            lines.segments = _straight_segments(white, scale)
        soft = cv2.resize(white.astype(np.float32), (w // 2, h // 2), interpolation=cv2.INTER_AREA)
        soft = cv2.GaussianBlur(soft, (0, 0), 0.8)
        out.append(_Frame(float(times[fi]), ego, others, lines, soft))
    t_detect = time.perf_counter() - started
    # ---- ego heading: long axis, pointed by the headlights
    axes, fronts = [], []
    last = None
    for fr in out:
        if fr.ego is not None and fr.ego.length > 1.3 * fr.ego.width:
            last = fr.ego.axis
            axes.append(last)
            fronts.append(fr.ego.front)
        else:
            axes.append(last)
            fronts.append(0)
    first = next((a for a in axes if a is not None), 0.0)
    axes = [first if a is None else a for a in axes]
    heading = _unwrap_axis(axes)
    votes = int(np.sum(_facing_votes(axes, fronts, heading)))
    if votes < 0:
        heading = heading + math.pi
    # ---- tracks
    tracks = _stitch(_track(out, scale, heading), out, scale, heading, (w, h))
    ego_len_m = ego_len / scale
    kept: List[Track] = []
    for trk in tracks:
        if len(trk.idx) < 2:
            continue
        kinds = trk.kinds
        trk.crashed = any(k == "red" for k in kinds)  # crashed vehicles turn red (often in the last frame)
        full = [b for b in trk.blobs if not b.border]
        length_m = float(np.median([b.length for b in full])) / scale if full else 0.0
        width_m = float(np.median([b.width for b in full])) / scale if full else 0.0
        counts = {k: kinds.count(k) for k in set(kinds)}
        main = max(counts, key=lambda k: counts[k] * (0.5 if k == "red" else 1.0))
        if main == "ped" or (main == "red" and length_m < 1.6 and counts.get("ped", 0) > 0):
            trk.kind = "pedestrian"
        elif main == "prop" or (main == "yellow" and full and length_m < 1.5 * max(width_m, 0.1)):
            trk.kind = "obstacle"
        elif main == "truck":
            trk.kind = "truck"
        elif main == "ego":
            continue  # a second green vehicle: not the ego, not in the vocabulary's palette
        else:
            trk.kind = "car"
        if trk.kind in ("car", "truck") and full and np.median([b.area for b in full]) < 0.15 * ego_len ** 2 / 2.4:
            continue
        trk.info["length_m"] = round(length_m, 2)
        kept.append(trk)
    tracks = kept
    ctx = _Ctx(out, times, scale, heading, np.full((len(out), 2), np.nan), None, LANE_WIDTH_M, [None] * len(out),
               False)
    for trk in tracks:
        if trk.kind in ("car", "truck"):
            _facing(trk, ctx)
    lanes_guess = float(np.median([max(len(f.lines.h_pos), len(f.lines.v_pos)) for f in out])) - 1
    speed_prior = 22.0 if lanes_guess >= 3 else 10.0
    ego_vel, known, wm_info = _world_motion(out, tracks, scale, heading, speed_prior)
    if abs(votes) < 0.5 * len(out) and known.any():
        # headlights not seen clearly: the ego faces the way it moves through the world
        alt = _world_motion(out, tracks, scale, heading + math.pi, speed_prior)
        if alt[1].any() and alt[2]["cost"] < wm_info["cost"] - 1.0:
            heading = heading + math.pi
            ego_vel, known, wm_info = alt
    wm_info["ego_facing_votes"] = votes
    measured = wm_info.pop("measured")
    ego_sure = np.array([all(measured[k] for k in (i - 1, i) if 0 <= k < len(measured)) for i in range(len(out))])
    # per-frame ego velocity (mean of the adjacent intervals), smoothed
    ego_v = np.full((len(out), 2), np.nan)
    for i in range(len(out)):
        vs = [ego_vel[k] for k in (i - 1, i) if 0 <= k < len(ego_vel) and known[k]]
        if vs:
            ego_v[i] = np.mean(vs, axis=0)
    ego_v = _smooth(times, ego_v, 0.3)
    ego_speed = np.hypot(ego_v[:, 0], ego_v[:, 1])
    # integrate the ego's position over stretches of measured motion
    ego_pos = np.zeros((len(out), 2))
    ego_seg = np.full(len(out), -1)
    seg_id, prev_known = -1, False
    for k in range(len(out) - 1):
        if known[k]:
            if not prev_known:
                seg_id += 1
                ego_seg[k] = seg_id
                ego_pos[k] = 0.0
            ego_pos[k + 1] = ego_pos[k] + ego_vel[k] * (times[k + 1] - times[k])
            ego_seg[k + 1] = seg_id
        prev_known = bool(known[k])
    t_motion = time.perf_counter() - started - t_detect
    # ---- lanes and road
    counts_l, widths, lats = [], [], []
    for i, fr in enumerate(out):
        lat = _lines_lat(fr, heading[i], scale)
        lats.append(lat)
        if lat.size >= 2:
            counts_l.append(lat.size - 1)
            widths.extend(x for x in np.diff(lat).tolist() if 2.0 < x < 6.0)
    lane_w = float(np.median(widths)) if widths else LANE_WIDTH_M
    ego_lanes: List[Optional[int]] = [_lane_of(lat, 0.0, 0.2 * lane_w) for lat in lats]
    ctx = _Ctx(out, times, scale, heading, ego_v, None, lane_w, ego_lanes, False, ego_pos, ego_seg, ego_sure)
    for trk in tracks:
        _kinematics(ctx, trk)
        if trk.kind in ("car", "truck"):
            _orient_by_motion(trk, ctx)
    oncoming_any = False
    for trk in tracks:
        hd = trk.info.get("headings")
        if trk.kind in ("car", "truck") and hd is not None and len(hd) >= 3 and trk.info.get("facing_sure"):
            diffs = [abs(_wrap(float(a - heading[i]))) for a, i in zip(hd, trk.idx)]
            if np.median(diffs) > math.radians(150):
                oncoming_any = True
    road, road_ev = _road_type(out, scale, heading, oncoming_any, (w, h))
    ctx.road = road
    ctx.junction = road in ("intersection", "t_junction", "three_way", "roundabout")
    ego_crashed = crashed_frames >= 1
    ego_acts, ego_react, ego_notes = _ego_actions(ctx, ego_speed, ego_crashed)
    ego_turn = "turn_left" if "turn_left" in ego_acts else "turn_right" if "turn_right" in ego_acts else None
    actors = []
    for trk in tracks:
        actor = _actor(ctx, trk, ego_turn)
        if actor is not None:
            actor["junction_side"] = ctx.junction
            actors.append(actor)
    blocked = any(a["kind"] == "obstacle" and "same_lane" in a["relations"] for a in actors)
    if blocked:
        # cars alongside in the next lane keep the ego from steering around the obstacle
        for a in actors:
            trk = a["track"]
            if a["role"] != "traffic" or a["kind"] not in ("car", "truck"):
                continue
            lon, lat = trk.info["lon"], trk.info["lat"]
            beside = (np.abs(lon) < 8.0) & (np.abs(lat) > 0.5 * lane_w) & (np.abs(lat) < 1.5 * lane_w)
            if int(beside.sum()) >= 3 and not a["notes"].get("lane_changes"):
                a["role"] = "key"
                a["actions"] = {"keep_lane"}
                a["relations"] = {"left_of" if float(np.median(lat[beside])) > 0 else "right_of"}
                a["alongside"] = True
    if ego_crashed:
        # the ego's crash partner: the nearest crashed actor
        crashed = sorted((a for a in actors if a["track"].crashed), key=lambda a: a["min_dist"])
        if crashed and crashed[0]["min_dist"] < 8.0:
            crashed[0]["role"] = "key"
            crashed[0]["actions"].add("collide")
            crashed[0]["hits_ego"] = True
    # ---- elements
    participants = ["ego"] + [a["kind"] for a in actors]
    actions = [["ego", x] for x in sorted(ego_acts)]
    relations = []
    for a in actors:
        actions.extend([a["kind"], x] for x in sorted(a["actions"]))
        relations.extend([a["kind"], r, "ego"] for r in sorted(a["relations"]))
    elements = normalize_elements({"road": road, "participants": participants, "actions": actions,
                                   "relations": relations})
    n_lanes = int(np.median(counts_l)) if counts_l else 0
    early = [l for l in ego_lanes[: max(3, len(ego_lanes) // 4)] if l is not None]
    ego_lane = int(np.median(early)) if early else None
    description = _describe(road, ego_acts, actors, ego_lane, n_lanes)
    answer = _answer(question, road, ego_acts, ego_react, actors) if question else None
    if answer:
        description = f"{description} {answer}"
    elapsed = time.perf_counter() - started
    track_dicts = []
    roles = {id(a["track"]): a for a in actors}
    for trk in tracks:
        a = roles.get(id(trk))
        sp = trk.info.get("speed")
        track_dicts.append({
            "id": trk.id, "kind": trk.kind, "role": a["role"] if a else None,
            "frames": [int(i) for i in trk.idx],
            "rel": [[round(x, 2), round(y, 2)] for x, y in trk.rel],
            "speed": [None if not np.isfinite(x) else round(float(x), 2) for x in sp] if sp is not None else [],
            "crashed": trk.crashed,
            "actions": sorted(a["actions"]) if a else [], "relations": sorted(a["relations"]) if a else [],
            "notes": a["notes"] if a else {},
        })
    debug = {
        "input": input_info,
        "frame_size": [w, h],
        "scale_px_per_m": round(scale, 3),
        "bev_check": bev_stats,
        "road_evidence": road_ev,
        "lane_width_m": round(lane_w, 2),
        "lanes": n_lanes,
        "ego_lane": ego_lane,
        "ego_lanes": ego_lanes,
        "ego_heading_deg": [round(math.degrees(x), 1) for x in heading],
        "ego_speed": [None if not np.isfinite(x) else round(float(x), 2) for x in ego_speed],
        "ego_notes": ego_notes,
        "ego_reactions": sorted(ego_react),
        "world_motion": wm_info,
        "timing_s": {"detect": round(t_detect, 4), "motion": round(t_motion, 4), "total": round(elapsed, 4)},
    }
    return BevAnalysis(description=description, elements=elements, answer=answer, tracks=track_dicts, debug=debug)


def analyze_bev_file(path, question: Optional[str] = None, **read_options) -> BevAnalysis:
    """Read ``path`` with :data:`BEV_READ_OPTIONS` (``read_options`` override them) and analyse it."""
    from dv2s_gym.pipeline.video import read_video

    options = dict(BEV_READ_OPTIONS)
    options.update(read_options)
    return analyze_bev(read_video(path, **options), question)
