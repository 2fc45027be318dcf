"""Per-frame detection: coloured blobs by hue (ego, cars, trucks, pedestrians, crashed vehicles),
props by their black outline, and white lane-line pixels split into horizontal, vertical and
other lines."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import List, Optional, Tuple

import numpy as np

from dv2s_gym.pipeline.dra.bev.frames import _mask

__all__ = ["Blob", "Lines"]


_KINDS = ("none", "red", "ped", "yellow", "ego", "car", "truck")
# every hue belongs to a colour class (no gaps): a vehicle of any colour is found; the class only hints
# at the kind (green at the view's fixed spot: the ego; red: crashed; orange: a pedestrian), trucks are
# told by their size (analyze.py, scale.py), not by the purple of the project's renderer
_HUE_RANGES = [("red", 0, 8), ("ped", 9, 23), ("yellow", 24, 36), ("ego", 37, 78), ("car", 79, 118),
               ("truck", 119, 162), ("red", 163, 179)]
_HUE_LUT = np.zeros(256, dtype=np.uint8)
for _name, _lo, _hi in _HUE_RANGES:
    _HUE_LUT[_lo:_hi + 1] = _KINDS.index(_name)


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
