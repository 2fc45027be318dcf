"""Events in the ego's driving frame: kinematics of each track, brake/stop/accelerate, lane
changes, cut-in, merge, overtake, turns, crossing, collisions; relations to the ego."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Tuple

import numpy as np

from scenario_bank.elements import Action, ActorKind, Relation, Road
from dv2s_gym.pipeline.dra.bev.detection import _Frame
from dv2s_gym.pipeline.dra.bev.tracking import (
    Track, _facing_votes, _local_slope, _smooth, _unwrap_axis, _wrap,
)
from dv2s_gym.pipeline.dra.bev.road import _lane_changes, _lane_of, _lines_lat

__all__ = ["BRAKE_DROP", "BRAKE_RATE", "ACCEL_RISE", "STOP_SPEED", "TURN_ANGLE", "PARTIAL_TURN", "NEAR",
           "TRAFFIC_NEAR", "CLOSE_IN", "FOLLOW_GAP", "FOLLOW_HEADWAY", "ego_overtaken"]


BRAKE_DROP = 3.5            # m/s lost ...
BRAKE_RATE = 1.8            # ... at this many m/s^2 or more
ACCEL_RISE = 5.0            # m/s gained, at BRAKE_RATE or more
STOP_SPEED = 1.0            # m/s
TURN_ANGLE = math.radians(50)
PARTIAL_TURN = math.radians(8)
NEAR = 45.0                 # m: actors never closer than this are left out
TRAFFIC_NEAR = 25.0         # m: vehicles this close for a while are counted as traffic around the ego
CLOSE_IN = 8.0              # m: the gap to a vehicle ahead in the ego's lane shrinks this much: a slower lead
FOLLOW_GAP = 12.0           # m, and FOLLOW_HEADWAY s at the lead's speed: the least gap of an ego following
FOLLOW_HEADWAY = 0.8        # a moving lead (closer, the two are more likely standing than driving)


def _quick_reversals_dropped(changes: List[Tuple[int, int, int]], t: np.ndarray,
                             min_gap: float = 1.2) -> List[Tuple[int, int, int]]:
    """Lane changes without the pairs a->b, b->a less than ``min_gap`` s apart (no car changes lanes
    and back that fast: such a pair is a lane line lost for a moment, e.g. while the ego crosses lines)."""
    out = list(changes)
    i = 0
    while i + 1 < len(out):
        (k1, a1, b1), (k2, a2, b2) = out[i], out[i + 1]
        if a1 == b2 and b1 == a2 and float(t[k2] - t[k1]) < min_gap:
            del out[i:i + 2]
            i = max(0, i - 1)
        else:
            i += 1
    return out


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


@dataclass
class _ActorState:
    """One tracked actor as :func:`_actor` reads it: its motion in the ego's frame (per tracked frame) and what
    has been decided of it so far (actions, relations, notes, whether it is oncoming or crossing)."""

    trk: Track
    t: np.ndarray
    lon: np.ndarray
    lat: np.ndarray
    speed: np.ndarray
    valid: np.ndarray
    lanes: List[Optional[int]]
    ego_lanes: List[Optional[int]]
    dist: np.ndarray
    lane_w: float
    notes: Dict[str, Any]
    acts: set = field(default_factory=set)
    rels: set = field(default_factory=set)
    oncoming: bool = False
    crossing: bool = False
    came_towards: bool = False
    in_lane: Optional[np.ndarray] = None
    """Per frame: in the ego's lane (same lane index, or within half a lane of its line when a lane is unknown)."""
    k0: int = 0
    """The first frame fully in view: the set-up."""
    moving: bool = True
    start_lane: Optional[int] = None
    start_in_lane: bool = False

    @property
    def n(self) -> int:
        return len(self.t)

    @property
    def kind(self) -> str:
        return self.trk.kind

    @property
    def vehicle(self) -> bool:
        return self.trk.kind in ("car", "truck")

    @property
    def headings(self):
        return self.trk.info.get("headings")


def _actor_state(ctx: _Ctx, trk: Track) -> Optional[_ActorState]:
    """The actor's motion relative to the ego; None when it is seen too briefly or never comes near."""
    t, lon, lat, speed = trk.info["t"], trk.info["lon"], trk.info["lat"], trk.info["speed"]
    n = len(t)
    dist = np.hypot(lon, lat)
    if n < 3 or dist.min() > NEAR:
        return None
    return _ActorState(trk, t, lon, lat, speed, trk.info["valid"], trk.info["lanes"], trk.info["ego_lanes"], dist,
                       ctx.lane_w, {"frames": n, "min_dist": round(float(dist.min()), 1)})


def _facing_against_ego(ctx: _Ctx, s: _ActorState) -> None:
    """Whether a vehicle faces against the ego (oncoming), came towards it at first, or crosses its course,
    compared with the ego's heading before it turns (an oncoming car stays oncoming while the ego turns)."""
    hd = s.headings
    if not (s.vehicle and hd is not None):
        s.crossing = s.came_towards = False
        return
    trk, n = s.trk, s.n
    ego_start = float(ctx.heading[0])
    early = [k for k, i in enumerate(trk.idx) if abs(float(ctx.heading[i]) - ego_start) < math.radians(30)]
    own = [k for k in range(n) if not trk.blobs[k].border] or list(range(n))
    sel = [k for k in early if k in own] or own
    ref = [float(ctx.heading[trk.idx[k]]) if early else ego_start for k in sel]
    diffs = np.array([abs(_wrap(float(hd[k]) - r)) for k, r in zip(sel, ref)])
    first = diffs[: max(3, len(diffs) // 3)]
    s.oncoming = bool(np.median(diffs) > math.radians(135))
    s.came_towards = len(diffs) >= 3 and bool(np.median(diffs[:3]) > math.radians(135))
    s.crossing = not s.oncoming and bool(np.median(first) > math.radians(50))
    if s.oncoming and np.isfinite(s.speed).sum() >= 3 and float(np.nanmedian(s.speed)) < 1.5:
        s.oncoming = False   # parked facing the ego: not coming towards it
    s.notes["facing_diff_deg"] = round(math.degrees(float(np.median(diffs))), 1)


def _place_in_lanes(s: _ActorState) -> None:
    """Per frame whether the actor is in the ego's lane; the set-up frame, the lane it starts in, whether it
    moves at all."""
    lanes, ego_lanes, lat, lane_w = s.lanes, s.ego_lanes, s.lat, s.lane_w
    s.in_lane = np.array([(lanes[k] is not None and ego_lanes[k] is not None and lanes[k] == ego_lanes[k]) or
                          ((lanes[k] is None or ego_lanes[k] is None) and abs(lat[k]) < 0.5 * lane_w)
                          for k in range(s.n)])
    s.k0 = next((k for k in range(s.n) if s.valid[k]), 0)
    s.moving = bool(np.nanmax(s.speed) > 2.0) if np.isfinite(s.speed).any() else True
    s.start_lane = lanes[s.k0]
    s.start_in_lane = bool(s.in_lane[s.k0])


def _speed_actions(ctx: _Ctx, s: _ActorState) -> None:
    """A vehicle's brake, stop and accelerate from its speed (frames fully in view, when there are enough); a
    vehicle whose speed cannot be measured stops when the ego closes in fast and then waits behind it."""
    if not s.vehicle:
        return
    t, lon, acts = s.t, s.lon, s.acts
    sp = np.where(s.valid, s.speed, np.nan) if s.valid.sum() >= 4 else s.speed
    brake, accel, slow = _speed_events(t, sp)
    fin = np.isfinite(sp)
    s.notes.update(speed_start=round(float(np.nanmedian(sp[fin][:3])), 1) if fin.any() else None,
                   speed_end=round(float(np.nanmedian(sp[fin][-3:])), 1) if fin.any() else None,
                   slow_share=round(slow, 2))
    stopped_from_start = fin.sum() >= 3 and bool(np.all(sp[fin][:3] < STOP_SPEED + 0.5))
    still_at_end = fin.sum() >= 3 and bool(np.all(sp[fin][-3:] < STOP_SPEED + 0.5))
    in_lane_ahead = bool(np.any(s.in_lane & (lon > 0)))
    if brake:
        acts.add("brake")   # braking hard, possibly to a standstill
    elif slow >= 0.6 or (stopped_from_start and slow >= 0.4):
        # waiting at a junction and driving off is not a stop; a car parked off the ego's lane is just parked
        if (not ctx.junction or still_at_end) and in_lane_ahead:
            acts.add("stop")
    elif not fin.any() and in_lane_ahead and not s.oncoming and not s.crossing:
        # no world reference to measure speeds: the ego closing in fast and then waiting behind it
        vr = _local_slope(t, lon, 0.5)
        ok = np.isfinite(vr)
        if ok.sum() >= 6:
            closing = -float(np.median(vr[ok][:3]))
            settle = abs(float(np.median(vr[ok][-3:])))
            s.notes["closing_speed"] = round(closing, 1)
            if closing >= 5.0 and settle < 0.8 and float(lon[-1]) < 15.0:
                acts.add("stop")
    if accel and not brake and Action.STOP not in acts and not ctx.junction and not stopped_from_start:
        acts.add("accelerate")


def _turn_actions(s: _ActorState) -> None:
    """A moving vehicle's turn from its heading (whole, lengthwise blobs); one that came towards the ego and then
    turned is an oncoming car turning, not a crossing one."""
    hd, trk = s.headings, s.trk
    if not (s.vehicle and hd is not None):
        return
    good = [k for k in range(s.n) if not trk.blobs[k].border and trk.blobs[k].length > 1.3 * trk.blobs[k].width]
    if len(good) >= 4:
        un = np.array(hd)[good]
        turn = float(np.median(un[-2:]) - np.median(un[:2]))
        s.notes["turn_deg"] = round(math.degrees(turn), 1)
        if abs(turn) >= TURN_ANGLE and s.moving:
            s.acts.add("turn_left" if turn > 0 else "turn_right")
            if s.came_towards and not s.oncoming:
                s.oncoming, s.crossing = True, False
                s.notes.update(oncoming=True, crossing=False, turned_from_oncoming=True)


def _lane_changes_and_cut_in(ctx: _Ctx, s: _ActorState) -> Tuple[List[Tuple[int, int, int]], bool]:
    """A vehicle's lane changes (quick out-and-back noise dropped), merges from the ramp's lane, and whether one
    of them ends in the ego's lane near it (a cut-in); without a lane change counted, a shift of most of a lane
    across the lines near the ego is one."""
    t, lon, lat, lanes, lane_w = s.t, s.lon, s.lat, s.lanes, s.lane_w
    cut_in = False
    changes = _quick_reversals_dropped(_lane_changes(lanes), t)
    for k, a, b in changes:
        s.acts.add("lane_change_right" if b > a else "lane_change_left")
        later = range(k, min(s.n, k + 8))
        if s.ego_lanes[k] is not None and b == s.ego_lanes[k] and any(-2.0 < lon[m] < 40.0 for m in later):
            cut_in = True
            s.notes["cut_in_t"] = round(float(t[k]), 2)
        if ctx.road == Road.MERGE and b < a and (s.start_lane is None or a == max(l for l in lanes if l is not None)):
            s.acts.add("merge")
    near_lanes = bool(np.all(np.abs(lat[s.valid]) < 1.6 * lane_w)) if s.valid.any() else False
    if not changes and near_lanes:
        ok = np.isfinite(lat) & s.valid
        if ok.sum() >= 6:
            lat_s = _smooth(t[ok], lat[ok], 0.5)
            shift = float(lat_s[-1] - lat_s[0])
            if abs(shift) >= 0.75 * lane_w:
                s.acts.add("lane_change_left" if shift > 0 else "lane_change_right")
                if abs(lat_s[-1]) < 0.5 * lane_w and lon[ok][-1] > -2.0:
                    cut_in = True
    return changes, cut_in


def _lane_actions(ctx: _Ctx, s: _ActorState) -> None:
    """Lane changes, cut-in, merge and overtake of a vehicle that is neither oncoming nor crossing, away from
    junctions; the lane it starts in is the one before its first lane change."""
    if not (s.vehicle and not s.oncoming and not ctx.junction and not s.crossing):
        return
    lon, lanes, in_lane, k0 = s.lon, s.lanes, s.in_lane, s.k0
    changes, cut_in = _lane_changes_and_cut_in(ctx, s)
    if ctx.road == Road.MERGE and Action.MERGE not in s.acts and s.start_lane is None and any(
            l is not None for l in lanes[k0 + 2:]) and s.lat[k0] < -1.0 * s.lane_w:
        s.acts.add("merge")
        if any(in_lane[k] and lon[k] > -2 for k in range(k0, s.n)):
            cut_in = True
    if cut_in:
        s.acts.add("cut_in")
    # overtaking: from behind to ahead, pulling out of a lane and back into it
    passed = lon[k0] < -2.0 and lon[-1] > 3.0
    out_and_back = any(changes[i][1] == changes[j][2] for i in range(len(changes))
                       for j in range(i + 1, len(changes)))
    beside = [k for k in range(s.n) if abs(lon[k]) < 3.0]
    if passed and out_and_back and beside and not all(in_lane[k] for k in beside):
        s.acts.add("overtake")
    s.notes["lane_changes"] = [(round(float(s.t[k]), 1), a, b) for k, a, b in changes]
    if changes:
        s.start_lane = changes[0][1]
        s.start_in_lane = s.ego_lanes[changes[0][0]] is not None and s.start_lane == s.ego_lanes[changes[0][0]]
        k_side = max(0, changes[0][0] - 1)
        if not s.start_in_lane:
            la_side = float(s.lat[k_side])
            side_hint = "left_of" if la_side > 0 else "right_of"
            s.notes["side_before_change"] = side_hint


def _drift_and_crossing_actions(ctx: _Ctx, s: _ActorState) -> None:
    """An oncoming vehicle inside the ego's lane ahead (away from junctions) has drifted over the centre line; a
    pedestrian that travels across the lanes crosses; a crashed actor (turned red) collides."""
    lon, lat, lane_w = s.lon, s.lat, s.lane_w
    if s.vehicle and s.oncoming and not ctx.junction:
        inside = (np.abs(lat) < 0.5 * lane_w) & (lon > 0) & (lon < 40) & s.valid
        if int(inside.sum()) >= 2:
            s.acts.add("drift")
    if s.kind == ActorKind.PEDESTRIAN:
        ok = np.isfinite(lat)
        lat_s = _smooth(s.t[ok], lat[ok], 0.5) if ok.sum() else lat
        travel = float(np.nanmax(lat_s) - np.nanmin(lat_s)) if len(lat_s) else 0.0
        lane_seq = [l for l in s.lanes if l is not None]
        crossed = len(set(lane_seq)) >= 2 or (s.lanes[0] is None and lane_seq)
        if travel >= 2.0 and (crossed or travel >= 3.0):
            s.acts.add("cross")
        s.notes["lateral_travel"] = round(travel, 2)
    if s.trk.crashed:
        s.acts.add("collide")   # crashed vehicles turn red


def _junction_actions(ctx: _Ctx, s: _ActorState) -> None:
    """At a junction: a moving vehicle that does not turn goes straight (on a roundabout, one circling the ring
    across the ego's course ahead of it does not); yielding and slowing for turns are no braking."""
    lon, lat, acts = s.lon, s.lat, s.acts
    if ctx.junction and s.vehicle and s.moving and not ({Action.TURN_LEFT, Action.TURN_RIGHT} & acts):
        acts.add("go_straight")
    both = np.isfinite(lon) & np.isfinite(lat)
    k_cross = int(np.argmin(np.where(both, np.abs(lat), np.inf))) if both.any() else -1
    if ctx.road == Road.ROUNDABOUT and s.vehicle and s.crossing and Action.GO_STRAIGHT in acts and k_cross >= 0 \
            and float(lon[k_cross]) > 0:
        # a car circling the ring that passes across the ego's course ahead of it (the ego enters behind
        # it): it does not "go straight on", it drives round ahead of the ego
        acts.discard("go_straight")
        s.notes["ring_ahead"] = True
    if ctx.junction and (s.crossing or s.oncoming or int(np.sum(s.in_lane & (lon > 0))) < 4):
        acts.discard("brake")   # yielding and slowing for turns are part of crossing a junction


def _start_relations(ctx: _Ctx, s: _ActorState, ego_turn: Optional[str]) -> None:
    """Relations to the ego where the actor starts (and where a cut-in or merge ends): by kind and by what it
    does (pedestrian, oncoming, cutting in or merging, at a junction, in the ego's lane, beside it)."""
    acts, rels = s.acts, s.rels
    lo0, la0 = float(s.lon[s.k0]), float(s.lat[s.k0])
    side = ("left_of" if la0 > 0 else "right_of") if abs(la0) > 0.5 * s.lane_w else None
    if s.notes.get("side_before_change"):
        side = s.notes["side_before_change"]
    if s.kind == ActorKind.PEDESTRIAN:
        if Action.CROSS in acts:
            rels.update({"ahead_of", "crossing_path"})
        else:
            rels.add("ahead_of" if lo0 > 0 else "behind")
            if side:
                rels.add(side)
    elif s.vehicle and s.oncoming:
        rels.add("oncoming")
        if ego_turn == Action.TURN_LEFT or (ego_turn is None and Action.TURN_LEFT in acts):
            rels.add("crossing_path")   # a left turn across the oncoming lane (the ego's or the other's)
    elif Action.CUT_IN in acts or Action.MERGE in acts:
        rels.add("ahead_of")
        if s.start_in_lane and not (Action.MERGE in acts):
            rels.add("same_lane")
        elif Action.MERGE in acts:
            rels.add("right_of" if la0 <= 0 else "left_of")
        elif side:
            rels.add(side)
    elif ctx.junction and s.vehicle:
        _junction_relations(s, side, lo0)
    elif s.start_in_lane:
        rels.add("same_lane")
        rels.add("ahead_of" if lo0 > 0 else "behind")
    else:
        if side:
            rels.add(side)
        if abs(lo0) > 10.0 and not (Action.OVERTAKE in acts):
            rels.add("ahead_of" if lo0 > 0 else "behind")


def _junction_relations(s: _ActorState, side: Optional[str], lo0: float) -> None:
    """A vehicle's relations at a junction: turned into the ego's lane ahead, circling the ring ahead, across the
    ego's course (from one side of its heading line to the other), in its lane, or beside it."""
    acts, rels, lon, lat = s.acts, s.rels, s.lon, s.lat
    turned_in = bool(({Action.TURN_LEFT, Action.TURN_RIGHT} & acts) and s.in_lane[-1] and lon[-1] > 0)
    if turned_in:
        rels.add("ahead_of")
        if side:
            rels.add(side)
    elif s.crossing and s.notes.get("ring_ahead"):
        rels.update({"ahead_of", "crossing_path"})
    elif s.crossing:
        # across the ego's course: it passes from one side of the ego's heading line to the other, ahead
        ahead = lon > -2.0
        if ahead.any() and (np.nanmax(lat[ahead]) > 0.5 * s.lane_w and np.nanmin(lat[ahead]) < -0.5 * s.lane_w
                            or Action.GO_STRAIGHT in acts):
            rels.add("crossing_path")
        elif side:
            rels.add(side)
    elif s.start_in_lane:
        rels.update({"ahead_of" if lo0 > 0 else "behind", "same_lane"})
    else:
        if side:
            rels.add(side)
        rels.add("ahead_of" if lo0 > 0 else "behind")


def _is_slower_lead(ctx: _Ctx, s: _ActorState, lead: bool) -> bool:
    """A moving vehicle that holds its lane ahead of the ego while the ego closes in on it, at a gap a follower
    keeps (shorter: a stopped car and the ego waiting behind it, its speed measured off by a whole period of the
    dashed lines, or not measured at all)."""
    ahead = s.in_lane & (s.lon > 0) & s.valid
    slower_lead = (lead and s.vehicle and not s.oncoming and not s.crossing and not ctx.junction and not s.acts
                   and s.moving and float(s.lon[ahead][0] - s.lon[ahead].min()) >= CLOSE_IN)
    if slower_lead:
        lead_speed = float(np.nanmedian(s.speed[ahead])) if np.isfinite(s.speed[ahead]).any() else 0.0
        slower_lead = float(s.lon[ahead].min()) >= max(FOLLOW_GAP, FOLLOW_HEADWAY * lead_speed)
    return slower_lead


def _role(ctx: _Ctx, s: _ActorState) -> Tuple[Optional[str], bool]:
    """Whether the actor interacts with the ego: ``"key"`` (described), ``"traffic"`` (counted) or None (left
    out); and whether it leads the ego in its lane. Speeding up alone is no part of the story; an obstacle does
    nothing; a parked vehicle and a slower lead are noted."""
    dist, lon, speed = s.dist, s.lon, s.speed
    lead = int(np.sum(s.in_lane & (lon > 0) & (lon < 40.0) & s.valid)) >= 4 and not s.oncoming
    notable = bool(s.acts & {Action.BRAKE, Action.STOP, Action.CUT_IN, Action.MERGE, Action.LANE_CHANGE_LEFT, Action.LANE_CHANGE_RIGHT,
                             Action.TURN_LEFT, Action.TURN_RIGHT, Action.CROSS, Action.COLLIDE, Action.DRIFT, Action.OVERTAKE})
    if not (s.acts - {Action.ACCELERATE}):
        s.acts.discard("accelerate")  # speeding up alone is not part of the scene's story
    close_oncoming = s.oncoming and bool(np.any((np.abs(s.lat) < 1.7 * s.lane_w) & (np.abs(lon) < 35)))
    slower_lead = _is_slower_lead(ctx, s, lead)
    seen = int(s.valid.sum())
    fully = any(not b.border for b in s.trk.blobs)
    if s.vehicle and not fully:
        role = "traffic" if seen >= 3 else None   # never entirely in view: counted, nothing more
    elif s.kind == ActorKind.PEDESTRIAN:
        role = "key" if dist.min() < 35 else None
    elif s.kind == ActorKind.OBSTACLE:
        role = "key" if bool(np.any(s.in_lane & (lon > 0))) else ("traffic" if dist.min() < TRAFFIC_NEAR else None)
        s.acts.clear()
    elif close_oncoming or (notable and dist.min() < 40.0):
        role = "key"
    elif ctx.junction and dist.min() < 25.0 and s.moving:
        role = "key"
    elif s.vehicle and not s.moving and np.isfinite(speed).any() and dist.min() < 25.0:
        role = "key"   # parked near the ego's path
        s.notes["parked"] = True
    elif slower_lead and dist.min() < 40.0:
        role = "key"
        s.acts = {"keep_lane"}
        s.notes["slower_lead"] = True
    elif seen >= 3 and s.vehicle:
        role = "traffic"   # any other vehicle in view: counted, not described
    else:
        role = None
    return role, lead


def _settle_story(ctx: _Ctx, s: _ActorState, role: str, lead: bool) -> None:
    """The actions and relations told: a lead is ahead in the same lane; traffic is only counted; an oncoming
    car that only drives past keeps its lane; a merge is its own lane change, and a cut-in when it ends in the
    ego's lane (else the side it merges beside)."""
    if lead and s.vehicle and not s.oncoming and not s.crossing and not ctx.junction and \
            not (s.acts & {Action.CUT_IN, Action.MERGE, Action.OVERTAKE, Action.TURN_LEFT, Action.TURN_RIGHT}):
        s.rels = {"ahead_of", "same_lane"}
    if role == "traffic":
        s.acts, s.rels = set(), set()
    elif s.vehicle and s.oncoming and not ctx.junction and not (s.acts - {Action.ACCELERATE}):
        s.acts = {"keep_lane"}   # an oncoming car that only drives past holds its own lane
    if Action.MERGE in s.acts:
        s.acts -= {"lane_change_left", "lane_change_right"}   # merging is the lane change
        if Relation.AHEAD_OF in s.rels and bool(np.any(s.in_lane[s.k0:])):
            s.acts.add("cut_in")   # merging into the ego's lane
        elif Relation.AHEAD_OF in s.rels:
            # merging into the lane beside the ego's: the text says "into the lane next to it" (a merge
            # "ahead of" the ego reads back as a cut-in), so the relation kept is the side
            s.rels = {"right_of" if float(s.lat[s.k0]) <= 0 else "left_of"}
            s.notes["merged_beside"] = True


def _actor(ctx: _Ctx, trk: Track, ego_turn: Optional[str]) -> Optional[Dict[str, Any]]:
    """What one tracked actor does, relative to the ego; None when it is too far to matter."""
    s = _actor_state(ctx, trk)
    if s is None:
        return None
    _facing_against_ego(ctx, s)
    s.notes.update(oncoming=s.oncoming, crossing=s.crossing)
    _place_in_lanes(s)
    _speed_actions(ctx, s)
    _turn_actions(s)
    _lane_actions(ctx, s)
    _drift_and_crossing_actions(ctx, s)
    _junction_actions(ctx, s)
    _start_relations(ctx, s, ego_turn)
    role, lead = _role(ctx, s)
    if role is None:
        return None
    _settle_story(ctx, s, role, lead)
    in_lane, lon, k0 = s.in_lane, s.lon, s.k0
    return {"track": trk, "kind": s.kind, "role": role, "actions": s.acts, "relations": s.rels, "lead": lead,
            "started_ahead_in_lane": bool(in_lane[k0] and lon[k0] > 3.0),
            "oncoming": s.oncoming, "notes": s.notes, "min_dist": float(s.dist.min()), "first_t": float(s.t[0])}


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


def ego_overtaken(ego_acts: set, actors: List[Dict[str, Any]]) -> Optional[Dict[str, Any]]:
    """The vehicle the ego passes after changing lanes (it drove ahead of the ego in its lane and ends
    behind it), or None."""
    if not ego_acts & {Action.LANE_CHANGE_LEFT, Action.LANE_CHANGE_RIGHT}:
        return None
    for a in actors:
        if a["kind"] not in (ActorKind.CAR, ActorKind.TRUCK) or a["oncoming"] or not a.get("started_ahead_in_lane"):
            continue
        lon, valid = a["track"].info["lon"], a["track"].info["valid"]
        seen = np.nonzero(valid)[0]
        if len(seen) >= 3 and float(lon[seen[-1]]) < -3.0:
            return a
    return None
