"""Tracking the detected blobs across frames in the ego-centred view, and the world motion
(the ego's own velocity from the shift of the static line layer); small time-series helpers."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Sequence, Tuple

import numpy as np

try:
    import scipy.fft as sfft
except Exception:  # pragma: no cover - numpy's FFT instead
    sfft = None

from dv2s_gym.pipeline.dra.bev.detection import Blob, _Frame

__all__ = ["MAX_SPEED", "Track"]


MAX_SPEED = 42.0            # m/s, fastest plausible world motion


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
    if sfft is not None:
        return sfft.rfft2, sfft.irfft2, sfft.next_fast_len

    def next_len(n, real=True):  # pragma: no cover - numpy fallback
        return int(2 ** math.ceil(math.log2(max(2, n))))
    return np.fft.rfft2, np.fft.irfft2, next_len


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


def _shift_candidates(first: Tuple[Any, float], second: Tuple[Any, float], fft_shape, radius: int, axis_vec, irfft2,
                      reach: Optional[float] = None):
    """Screen shifts (dx, dy) of the half-resolution line layer between two frames, with scores; ``first`` and
    ``second`` are each frame's line-layer spectrum and line energy.

    ``reach`` (px, default ``radius``) bounds the shifts returned: the farthest the ego can move in this
    interval. A periodic pattern (dashed lines) correlates equally well at every multiple of its period,
    so every such alias within reach is returned, best first, for the caller to choose among.
    """
    import cv2

    (fa, na), (fb, nb) = first, second
    if na < 4.0 or nb < 4.0:
        return [], 0.0, True   # too few line pixels to tell a shift
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
    if reach is not None and reach < radius:
        ks_y, ks_x = np.mgrid[-radius:radius + 1, -radius:radius + 1]
        peaks &= np.hypot(ks_x, ks_y) <= reach
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
    return cands, best, False


@dataclass
class _Spectra:
    """The frames' line masks in the frequency domain, for correlating consecutive frames: each whole mask and
    its inner part (a border of ``radius`` cleared), with their energies."""

    whole: List[Any]
    inner: List[Any]
    energies: List[float]
    inner_energies: List[float]
    shape: Tuple[int, int]
    radius: int


def _line_spectra(frames: List[_Frame], radius: int, fft_shape: Tuple[int, int], rfft2) -> _Spectra:
    """The spectra of every frame's soft line mask (whole, and with a border of ``radius`` cleared)."""
    h, w = frames[0].soft.shape
    spectra = _Spectra([], [], [], [], fft_shape, radius)
    for fr in frames:
        inner = np.zeros_like(fr.soft)
        inner[radius:h - radius, radius:w - radius] = fr.soft[radius:h - radius, radius:w - radius]
        spectra.whole.append(rfft2(fr.soft, s=fft_shape))
        spectra.inner.append(rfft2(inner, s=fft_shape))
        spectra.energies.append(float((fr.soft * fr.soft).sum()))
        spectra.inner_energies.append(float((inner * inner).sum()))
    return spectra


def _static_anchors(tracks: List[Track], heading: np.ndarray, dts: np.ndarray) -> List[List[Tuple[np.ndarray, float]]]:
    """Per frame interval, the ego velocities static things tell, with their tolerance: props and (slow)
    pedestrians move by the ego's displacement, reversed (a crossing pedestrian only along the ego's heading)."""
    anchor: List[List[Tuple[np.ndarray, float]]] = [[] for _ in range(len(dts))]
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
    return anchor


def _velocity_options(spectra: _Spectra, irfft2, heading: np.ndarray, dts: np.ndarray, half_scale: float,
                      anchor: List[List[Tuple[np.ndarray, float]]]) -> Tuple[List[List[Tuple[np.ndarray, float]]], int]:
    """Per frame interval, the ego velocities the lane lines' shift allows (every alias the ego can reach in that
    interval, with a cost from its correlation) plus the static anchors none of them agrees with; and how many
    intervals the lines measured."""
    states: List[List[Tuple[np.ndarray, float]]] = []
    line_intervals = 0
    for i in range(len(dts)):
        hv = (math.cos(heading[i]), -math.sin(heading[i]))  # the ego axis on screen (y down)
        # the window is sized for the longest interval (a dropped frame doubles it): each interval keeps
        # only the shifts the ego can make in its own time, and every alias among them
        reach = MAX_SPEED * float(dts[i]) * half_scale + 3
        cands, best, flat = _shift_candidates((spectra.inner[i], spectra.inner_energies[i]),
                                              (spectra.whole[i + 1], spectra.energies[i + 1]),
                                              spectra.shape, spectra.radius, hv, irfft2, reach)
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
    return states, line_intervals


def _facing_vehicle_motion(tracks: List[Track], dts: np.ndarray) -> List[List[Tuple[np.ndarray, np.ndarray]]]:
    """Per frame interval, the screen motion and heading of each vehicle with a reliable facing (they must not
    drive backwards)."""
    veh: List[List[Tuple[np.ndarray, np.ndarray]]] = [[] for _ in range(len(dts))]
    for trk in tracks:
        hd = trk.info.get("headings")
        if trk.kind not in ("car", "truck") or hd is None or not trk.info.get("facing_sure"):
            continue
        for k in range(1, len(trk.idx)):
            i0, i1 = trk.idx[k - 1], trk.idx[k]
            if i1 == i0 + 1 and not trk.blobs[k].border and not trk.blobs[k - 1].border:
                d = np.subtract(trk.rel[k], trk.rel[k - 1]) / dts[i0]
                veh[i0].append((d, np.array([math.cos(hd[k]), math.sin(hd[k])])))
    return veh


def _option_costs(states: List[List[Tuple[np.ndarray, float]]], heading: np.ndarray, speed_prior: float,
                  veh: List[List[Tuple[np.ndarray, np.ndarray]]],
                  anchor: List[List[Tuple[np.ndarray, float]]]) -> List[np.ndarray]:
    """The cost of each velocity option: its own, plus driving backwards, the speed prior (a tie-breaker),
    speeds no traffic here reaches, vehicles seen driving backwards, and disagreement with the anchors."""
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
    return costs


def _smoothest_velocities(frames: List[_Frame], states: List[List[Tuple[np.ndarray, float]]],
                          costs: List[np.ndarray], vel: np.ndarray, known: np.ndarray) -> float:
    """Viterbi over the measured intervals (gaps bridged: a longer gap allows a larger change of speed): the
    sequence of options of least cost and speed change is written into ``vel`` and ``known``; its total cost."""
    order = [k for k in range(len(states)) if states[k]]
    if not order:
        return 0.0
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
    return total_cost


def _cleaned_velocities(vel: np.ndarray, known: np.ndarray, heading: np.ndarray) -> np.ndarray:
    """Isolated jumps (a wrong alias or a confusing frame pair) replaced by the local median; the sideways part
    limited, as a car moves along its heading (pedestrian anchors walk across the road)."""
    if known.sum() >= 5:
        idx = np.nonzero(known)[0]
        fixed = vel.copy()
        for pos, k in enumerate(idx):
            nb = idx[max(0, pos - 3):pos + 4]
            med = np.median(vel[nb], axis=0)
            if float(np.hypot(*(vel[k] - med))) > 3.0:
                fixed[k] = med
        vel = fixed
    for k in np.nonzero(known)[0]:
        c, s_ = math.cos(heading[k]), math.sin(heading[k])
        lon_v = vel[k, 0] * c + vel[k, 1] * s_
        lat_v = -vel[k, 0] * s_ + vel[k, 1] * c
        cap = 0.1 * abs(lon_v) + 0.3
        lat_v = max(-cap, min(cap, lat_v))
        vel[k] = (lon_v * c - lat_v * s_, lon_v * s_ + lat_v * c)
    return vel


def _interpolate_gaps(vel: np.ndarray, known: np.ndarray) -> None:
    """Short gaps between measured intervals (up to 6, or up to 30 when the speed barely changes across them) are
    interpolated, in place."""
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
    spectra = _line_spectra(frames, radius, fft_shape, rfft2)
    anchor = _static_anchors(tracks, heading, dts)
    states, line_intervals = _velocity_options(spectra, irfft2, heading, dts, half_scale, anchor)
    costs = _option_costs(states, heading, speed_prior, _facing_vehicle_motion(tracks, dts), anchor)
    total_cost = _smoothest_velocities(frames, states, costs, vel, known)
    vel = _cleaned_velocities(vel, known, heading)
    measured = known.copy()
    _interpolate_gaps(vel, known)
    return vel, known, {"line_intervals": line_intervals, "anchor_intervals": int(sum(1 for a in anchor if a)),
                        "measured_intervals": int(measured.sum()), "interpolated_intervals":
                        int(known.sum() - measured.sum()), "intervals": m, "cost": round(total_cost, 3),
                        "measured": measured}
