"""Events in the ego's driving frame: kinematics of each track, brake/stop/accelerate, lane
changes, cut-in, merge, overtake, turns, crossing, collisions; relations to the ego."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Tuple

import numpy as np

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
        came_towards = len(diffs) >= 3 and bool(np.median(diffs[:3]) > math.radians(135))
        crossing = not oncoming and bool(np.median(first) > math.radians(50))
        if oncoming and np.isfinite(speed).sum() >= 3 and float(np.nanmedian(speed)) < 1.5:
            oncoming = False   # parked facing the ego: not coming towards it
        notes["facing_diff_deg"] = round(math.degrees(float(np.median(diffs))), 1)
    else:
        crossing = came_towards = False
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
                if came_towards and not oncoming:
                    # it came towards the ego and then turned: an oncoming car turning, not a crossing one
                    oncoming, crossing = True, False
                    notes.update(oncoming=True, crossing=False, turned_from_oncoming=True)
    # ---- lane changes, cut-in, merge, overtake
    cut_in = False
    start_lane = lanes[k0]
    start_in_lane = bool(in_lane[k0])
    if vehicle and not oncoming and not ctx.junction and not crossing:
        changes = _quick_reversals_dropped(_lane_changes(lanes), t)
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
    both = np.isfinite(lon) & np.isfinite(lat)
    k_cross = int(np.argmin(np.where(both, np.abs(lat), np.inf))) if both.any() else -1
    if ctx.road == "roundabout" and vehicle and crossing and "go_straight" in acts and k_cross >= 0 \
            and float(lon[k_cross]) > 0:
        # a car circling the ring that passes across the ego's course ahead of it (the ego enters behind
        # it): it does not "go straight on", it drives round ahead of the ego
        acts.discard("go_straight")
        notes["ring_ahead"] = True
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
        if ego_turn == "turn_left" or (ego_turn is None and "turn_left" in acts):
            rels.add("crossing_path")   # a left turn across the oncoming lane (the ego's or the other's)
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
        elif crossing and notes.get("ring_ahead"):
            rels.update({"ahead_of", "crossing_path"})
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
    # a vehicle that holds its lane ahead of the ego while the ego closes in on it: a slower lead
    ahead = in_lane & (lon > 0) & valid
    slower_lead = (lead and vehicle and not oncoming and not crossing and not ctx.junction and not acts
                   and moving and float(lon[ahead][0] - lon[ahead].min()) >= CLOSE_IN)
    if slower_lead:
        # a gap shorter than a follower keeps: a stopped car and the ego waiting behind it, its speed measured
        # off by a whole period of the dashed lines (or not measured at all)
        lead_speed = float(np.nanmedian(speed[ahead])) if np.isfinite(speed[ahead]).any() else 0.0
        slower_lead = float(lon[ahead].min()) >= max(FOLLOW_GAP, FOLLOW_HEADWAY * lead_speed)
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
    elif slower_lead and dist.min() < 40.0:
        role = "key"
        acts = {"keep_lane"}
        notes["slower_lead"] = True
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
    elif vehicle and oncoming and not ctx.junction and not (acts - {"accelerate"}):
        acts = {"keep_lane"}   # an oncoming car that only drives past holds its own lane
    if "merge" in acts:
        acts -= {"lane_change_left", "lane_change_right"}   # merging is the lane change
        if "ahead_of" in rels and bool(np.any(in_lane[k0:])):
            acts.add("cut_in")   # merging into the ego's lane
        elif "ahead_of" in rels:
            # merging into the lane beside the ego's: the text says "into the lane next to it" (a merge
            # "ahead of" the ego reads back as a cut-in), so the relation kept is the side
            rels = {"right_of" if float(lat[k0]) <= 0 else "left_of"}
            notes["merged_beside"] = True
    return {"track": trk, "kind": kind, "role": role, "actions": acts, "relations": rels, "lead": lead,
            "started_ahead_in_lane": bool(in_lane[k0] and lon[k0] > 3.0),
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


def ego_overtaken(ego_acts: set, actors: List[Dict[str, Any]]) -> Optional[Dict[str, Any]]:
    """The vehicle the ego passes after changing lanes (it drove ahead of the ego in its lane and ends
    behind it), or None."""
    if not ego_acts & {"lane_change_left", "lane_change_right"}:
        return None
    for a in actors:
        if a["kind"] not in ("car", "truck") or a["oncoming"] or not a.get("started_ahead_in_lane"):
            continue
        lon, valid = a["track"].info["lon"], a["track"].info["valid"]
        seen = np.nonzero(valid)[0]
        if len(seen) >= 3 and float(lon[seen[-1]]) < -3.0:
            return a
    return None
