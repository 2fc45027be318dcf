"""The actor-bound story of a bank scenario, checked against an episode trace.

A sidecar's ``story`` block names the script's story actors and the steps each must play::

    "story": {
      "actors": {"cutter": "car"},
      "steps": [
        {"actor": "cutter", "action": "overtake", "relations": [["left_of", "ego"]]},
        {"actor": "cutter", "action": "cut_in", "relations": [["ahead_of", "ego"]], "within_s": 3.0}
      ]
    }

``actors`` maps a script object's ``name`` (``with name "cutter"``) to its vocabulary kind;
``steps`` use the actions and relations of :mod:`scenario_bank.elements`. Optional keys of a step:

* ``relations``: ``[relation, other]`` pairs, ``other`` the ego or another story actor, read at the
  moment of the step's event (see below), not at the start of the episode.
* ``within_s``: at the event the actor is ahead of the ego within this time gap: the distance from
  the ego's front to the actor over the ego's speed (floored at :data:`MIN_GAP_SPEED`, 5 m/s, so an
  ego that stands still 12.5 m short of a crossing pedestrian is 2 s from it).
* ``hold``: true when the action's state must last from the event to the end of the episode (a
  vehicle that stops and stays stopped).
* ``when``: another story actor; the step's relations are read at the moment of that actor's last step
  found (its action must be under way then): the cars that box the ego in are beside it when it
  reaches the obstacle.

Every step is required, in its order per actor (a step's event comes no earlier than the event of
the same actor's previous step). Steps of the ego (``"actor": "ego"``) are required only of the
``scenic`` ego, which drives the script's own ego behaviour.

Events of each action (times are trace steps):

* ``brake`` / ``accelerate``: the start of a 2 s window in which the speed falls / rises by 3 m/s.
* ``stop``: a moment the speed is under 0.5 m/s after driving, or while the actor stands from the
  start (parked).
* ``lane_change_left|right``: the env's lane-change event of the actor in that direction.
* ``cut_in``: a lane-change event of the actor after which (1 s later) it is in the ego's lane ahead
  of it (within 50 m). ``merge``: the same, or, for an actor that starts across the ego's heading
  (a side road), the first moment it is on the ego's path ahead of it and heading its way (within 20
  degrees).
* ``overtake``: the moment the actor passes the ego (from behind it to ahead of it).
* ``cross``: the moment the actor enters the ego's path (its lane ahead of its front bumper) from the
  side; an actor that reaches the ego's lane beside or behind the ego does not cross its path.
* ``go_straight`` / ``turn_left|right``: 1 s before entering the junction area, of a vehicle that goes
  straight through it / any moment from when the heading has turned 10 degrees until it has turned 55, of
  a vehicle that turns at least 55 degrees (a car that brakes as it starts to turn brakes, then turns).
* ``keep_lane``, ``drift``, ``swerve``, ``pull_out``, ``u_turn``, ``reverse``: as
  :mod:`dv2s_gym.pipeline.semantics.trace` reads them off the actor's track; event at the start of
  the manoeuvre (a drift's first excursion; the others when the actor first moves).
* ``collide`` and its types: a collision event of the actor.

The relation ``crossing_path`` holds when, between 1 s before the event and the end of the manoeuvre,
the actor enters the ego's path ahead of it (with ``within_s``: within that time gap), or, for a vehicle, when its
path crosses the ego's at 20 to 160 degrees with a post-encroachment time (how far apart in time the two
pass the crossing point, whichever first) within ``within_s`` (an oncoming car that strikes the side of
a car turning across its path crossed it), or when the two collide with both in the junction area; the others hold at the event: ``ahead_of``/``behind`` (more than 2 m along the other's heading), ``left_of``/``right_of``/
``same_lane`` (beyond / within half a lane sideways), ``oncoming`` (heading more than 135 degrees off).

A collision of the ego with a story actor stands in for that actor's remaining steps when the
manoeuvre of its pending step had begun before the collision (the crash ended the episode before the
trace could show the rest): a car that had started to change lanes when the ego hit it, a lead car
that had started to brake. Crossings are never credited this way: a walker must be seen entering the
ego's path in front of it (one that walks into the side of the passing ego did not cross its path).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple
from types import SimpleNamespace

import numpy as np

from scenario_bank.elements import Action, ActorKind, Relation
from scenario_bank.story import StoryError, normalize_story, step_label
from dv2s_gym.pipeline.semantics.trace import map_view, collision_type, elements_from_trace

__all__ = ["StoryError", "StoryResult", "normalize_story", "check_story", "resolve_actors", "step_label",
           "MIN_GAP_SPEED"]

MIN_GAP_SPEED = 5.0      # m/s: the ego speed a time gap is computed with at the least
LANE_HALF = 1.75         # m
EGO_FRONT = 2.5          # m from the ego's centre to its front bumper
WINDOW_S = 2.0           # s: brake / accelerate window ...
SPEED_CHANGE = 3.0       # ... and the speed change within it
STOP_SPEED = 0.5
ONSET_SPEED_CHANGE = 1.0  # m/s: a brake or speed-up has begun
ONSET_SHIFT = 0.5         # m sideways: a lane change, cut-in, merge or drift has begun
CUT_IN_AHEAD = 50.0       # m
PATH_EXTEND_M = 30.0      # m: a vehicle's path runs on this far past where the episode ends
TURN_ONSET = math.radians(10)
TURN_ANGLE = math.radians(55)
_LATERAL = frozenset({Action.LANE_CHANGE_LEFT, Action.LANE_CHANGE_RIGHT, Action.CUT_IN, Action.MERGE, Action.DRIFT,
                      Action.SWERVE, Action.PULL_OUT, Action.LANE_CHANGE})


@dataclass
class StoryResult:
    """What an episode showed of a story."""

    missed: List[Tuple[str, str]] = field(default_factory=list)
    """``(step label, why)`` of every step the episode did not play."""
    by_collision: List[str] = field(default_factory=list)
    """Labels of steps counted because the ego hit their actor after the manoeuvre had begun."""

    @property
    def played(self) -> bool:
        return not self.missed

    def problem(self) -> Optional[str]:
        """The missed steps in one line; None when the story played."""
        if not self.missed:
            return None
        return "; ".join(f"{label}: {why}" for label, why in self.missed)


@dataclass
class _Occurrence:
    onset: int
    event: int
    end: int


class _Episode:
    """Tracks (per trace step, NaN where the actor is absent), events and helpers of one trace."""

    def __init__(self, trace) -> None:
        self.trace = trace
        self.dt = 1.0 / float((trace.config or {}).get("policy_frequency", 5) or 5)
        self.n = len(trace.states)
        names: List[str] = []
        for state in trace.states:
            names.extend(n for n in state if n not in names)
        self.tracks: Dict[str, np.ndarray] = {}
        for name in names:
            rows = np.full((self.n, 4), np.nan)
            for i, state in enumerate(trace.states):
                if name in state:
                    rows[i] = state[name][:4]
            self.tracks[name] = rows
        self.kinds = dict(getattr(trace, "kinds", {}) or {})
        self._paths: Dict[Tuple[str, int], Any] = {}
        self.lane_changes: Dict[str, List[Tuple[int, str]]] = {}
        self.collisions: Dict[str, List[Tuple[int, str]]] = {}
        for event in trace.events:
            actors = list(event.get("actors") or [])
            step = self.step_of(float(event.get("time", 0.0)))
            if event.get("kind") == Action.LANE_CHANGE and actors:  # the env names the event after the action
                self.lane_changes.setdefault(actors[0], []).append((step, str(event.get("direction", ""))))
            if event.get("kind") == "collision" and len(actors) == 2:
                self.collisions.setdefault(actors[0], []).append((step, actors[1]))
                self.collisions.setdefault(actors[1], []).append((step, actors[0]))

    def step_of(self, time: float) -> int:
        return min(self.n - 1, max(0, int(round(time / self.dt))))

    def rel(self, reference: str, actor: str, i: int) -> Tuple[float, float]:
        """(ahead, leftward) of ``actor`` in ``reference``'s frame at step ``i`` (NaN when either is absent)."""
        r, a = self.tracks[reference][i], self.tracks[actor][i]
        dx, dy = a[0] - r[0], a[1] - r[1]
        c, s = math.cos(r[2]), math.sin(r[2])
        # highway-env's frame has y downward: leftward is -y rotated
        return dx * c + dy * s, dx * s - dy * c

    def present(self, name: str, i: int) -> bool:
        return not np.isnan(self.tracks[name][i, 0])

    def gap_s(self, actor: str, i: int) -> float:
        """Time gap [s] from the ego's front to ``actor`` at step ``i`` (inf when it is not ahead): along the
        ego's path when the actor is on it, else straight ahead."""
        along = self.along_path("ego", actor, i)
        if along is None:
            ahead, _ = self.rel("ego", actor, i)
            along = ahead - EGO_FRONT
        if not along > 0:
            return math.inf
        return along / max(abs(float(self.tracks["ego"][i, 3])), MIN_GAP_SPEED)

    def along_path(self, reference: str, actor: str, i: int) -> Optional[float]:
        """How far [m] ahead of ``reference``'s front ``actor`` stands on ``reference``'s path at step ``i``;
        None when the actor is not on it.

        The path is the one ``reference`` drives from step ``i`` on (so a car about to turn has the road it
        turns into ahead of it), extended :data:`PATH_EXTEND_M` along its last heading; the actor is on it when
        its centre is within half a lane of it, ahead of the reference's front bumper."""
        cache = self._paths.get((reference, i))
        if cache is None:
            track = self.tracks[reference][i:]
            track = track[~np.isnan(track[:, 0])]
            if not len(track):
                return None
            x, y, heading = track[-1, :3]
            points = np.vstack([track[:, :2], [x + PATH_EXTEND_M * math.cos(heading),
                                               y + PATH_EXTEND_M * math.sin(heading)]])
            steps = np.diff(points, axis=0)
            lengths = np.hypot(steps[:, 0], steps[:, 1])
            keep = lengths > 1e-6
            starts, steps, lengths = points[:-1][keep], steps[keep], lengths[keep]
            arc = np.concatenate([[0.0], np.cumsum(lengths)[:-1]])
            cache = (starts, steps, lengths, arc)
            self._paths[(reference, i)] = cache
        starts, steps, lengths, arc = cache
        if not len(starts) or not self.present(actor, i):
            return None
        point = self.tracks[actor][i, :2]
        u = np.clip(((point - starts) * steps).sum(axis=1) / lengths ** 2, 0.0, 1.0)
        nearest = starts + steps * u[:, None]
        distance = np.hypot(*(point - nearest).T)
        near = np.flatnonzero(distance <= LANE_HALF)
        if not near.size:
            return None
        along = float(arc[near[0]] + u[near[0]] * lengths[near[0]]) - EGO_FRONT
        return along if along > 0 else None

    def path_entries(self, actor: str, start: int = 0, end: Optional[int] = None,
                     reference: str = "ego") -> List[int]:
        """Steps at which ``actor`` comes onto ``reference``'s path ahead of it from off it (see
        :meth:`along_path`)."""
        end = self.n - 1 if end is None else end
        out = []
        for i in range(max(1, start), end + 1):
            if not (self.present(actor, i) and self.present(actor, i - 1) and self.present(reference, i)):
                continue
            if self.along_path(reference, actor, i) is None:
                continue
            if self._off_path(reference, actor, i - 1):
                out.append(i)
        return out

    def _off_path(self, reference: str, actor: str, i: int) -> bool:
        """Not on ``reference``'s path at step ``i``, nor beside or behind its front (off to the side of it)."""
        if not self.present(reference, i):
            return True
        if self.along_path(reference, actor, i) is not None:
            return False
        _, left = self.rel(reference, actor, i)
        return abs(left) > LANE_HALF or self.rel(reference, actor, i)[0] > EGO_FRONT


def resolve_actors(story: Mapping[str, Any], names: Sequence[str]) -> Dict[str, Optional[str]]:
    """Trace actor name of each story actor: its script name, or that name with a count suffix when
    exactly one such actor is in the trace; None when the trace has none."""
    out: Dict[str, Optional[str]] = {"ego": "ego" if "ego" in names else None}
    for actor in story["actors"]:
        if actor in names:
            out[actor] = actor
            continue
        suffixed = [n for n in names if re.fullmatch(re.escape(actor) + r"\d+", n)]
        out[actor] = suffixed[0] if len(suffixed) == 1 else None
    return out


def check_story(story: Mapping[str, Any], trace, ego: str = "scenic") -> StoryResult:
    """Which steps of ``story`` (a sidecar's ``story`` block) the episode in ``trace`` played.

    ``ego``: the driver of the ego (its own steps are required only of ``scenic``).
    """
    story = normalize_story(story)
    episode = _Episode(trace)
    result = StoryResult()
    if episode.n == 0 or "ego" not in episode.tracks:
        result.missed = [(step_label(s), "the trace has no ego") for s in story["steps"]]
        return result
    names = resolve_actors(story, list(episode.tracks))
    for actor, kind in story["actors"].items():
        name = names[actor]
        if name is not None and episode.kinds.get(name, kind) != kind:
            names[actor] = None
            result.missed.append((actor, f"is a {episode.kinds[name]} in the episode, the story says {kind}"))
    detector = _Detector(episode, names)
    moments: Dict[str, int] = {}  # actor -> event step of its last step found
    # actors whose steps are read at another actor's moment ("when") come after the others
    order = sorted(["ego"] + list(story["actors"]),
                   key=lambda a: any(s.get("when") for s in story["steps"] if s["actor"] == a))
    for actor in order:
        steps = [s for s in story["steps"] if s["actor"] == actor]
        if actor == "ego" and ego != "scenic":
            continue
        if not steps:
            continue
        if names[actor] is None:
            for step in steps:
                result.missed.append((step_label(step), f"no actor named {actor!r} in the episode "
                                      f'(name it in the script: with name "{actor}")'))
            continue
        after = 0
        for k, step in enumerate(steps):
            if step.get("when"):
                moment = moments.get(step["when"])
                if moment is None:
                    result.missed.append((step_label(step), f"{step['when']}'s step was not seen"))
                    continue
                found, why = detector.find(step, 0, at=moment)
            else:
                found, why = detector.find(step, after)
            if found is not None:
                after = max(after, found)
                moments[actor] = found
                continue
            credit = detector.collision_credit(step, after)
            if credit:
                result.by_collision.extend(step_label(s) for s in steps[k:])
                break
            result.missed.append((step_label(step), why))
    return result


class _Detector:
    """Occurrences of each action by an actor, and the checks of a step against them."""

    def __init__(self, episode: _Episode, names: Mapping[str, Optional[str]]) -> None:
        self.e = episode
        self.names = names
        self._junction_masks: Dict[str, np.ndarray] = {}

    # ------------------------------------------------------------------ steps
    def find(self, step: Mapping[str, Any], after: int, at: Optional[int] = None) -> Tuple[Optional[int], str]:
        """The event step of the first occurrence at or after ``after`` that satisfies ``step``; else why not.

        ``at``: read the step at this moment instead (an occurrence under way then)."""
        name = self.names[step["actor"]]
        occurrences = [o for o in self.occurrences(name, step["action"]) if o.event >= after]
        if at is not None:
            occurrences = [_Occurrence(o.onset, at, o.end) for o in self.occurrences(name, step["action"])
                           if o.onset <= at <= o.end][:1]
            if not occurrences:
                return None, f"not under way at {at * self.e.dt:.1f} s, when {step['when']} does its step"
        if not occurrences:
            return None, "not seen" + (f" after {after * self.e.dt:.1f} s" if after else "")
        reasons = []
        for occ in occurrences:
            why = self._fails(step, name, occ)
            if why is None:
                return occ.event, ""
            reasons.append(why)
        return None, reasons[0]

    def _fails(self, step: Mapping[str, Any], name: str, occ: _Occurrence) -> Optional[str]:
        e, at = self.e, occ.event
        when = f"at {at * e.dt:.1f} s"
        within = step.get("within_s")
        for relation, other in step.get("relations", []):
            ref = self.names.get(other)
            if ref is None:
                return f"no actor named {other!r} in the episode"
            if relation == Relation.CROSSING_PATH:
                entries = self._path_entries_of(ref, name, occ)
                gap = min((e.gap_s(name, i) for i in entries), default=math.inf) if ref == "ego" else 0.0
                if entries and (within is None or gap <= within):
                    continue
                if e.kinds.get(name) != ActorKind.PEDESTRIAN:
                    pet = self._encroachment(ref, name)
                    if pet is not None and (within is None or pet <= within) or self._met_in_junction(ref, name):
                        continue
                    if pet is not None:
                        return (f"{when}: crosses the path of {other} {pet:.1f} s apart from it "
                                f"(more than {within:g} s)")
                if not entries:
                    return f"{when}: never enters the path of {other} ahead of it"
                return f"{when}: enters the ego's path {gap:.1f} s ahead of it (more than {within:g} s)"
            if not (e.present(name, at) and e.present(ref, at)):
                return f"{when}: {other} is not in the episode then"
            if not self._relation(relation, ref, name, at):
                return f"{when}: not {relation} {other}"
        if within is not None and not any(r == Relation.CROSSING_PATH for r, _ in step.get("relations", [])):
            gap = e.gap_s(name, at)
            if gap > within:
                where = "not ahead of the ego" if math.isinf(gap) else f"{gap:.1f} s ahead of the ego"
                return f"{when}: {where} (needs within {within:g} s)"
        if step.get("hold") and not self._holds(step["action"], name, at):
            return f"{when}: does not last to the end of the episode"
        return None

    def _met_in_junction(self, ref: str, name: str) -> bool:
        """Whether ``name`` collided with ``ref`` while both were in the junction area: their paths met there with
        no time between them, whatever the angle (a car barely into its turn is struck almost head-on)."""
        hits = [i for i, other in self.e.collisions.get(name, []) if other == ref]
        if not hits:
            return False
        inside_a, inside_b = self._in_junction(ref), self._in_junction(name)
        return any(inside_a[i] and inside_b[i] for i in hits)

    def _encroachment(self, ref: str, name: str) -> Optional[float]:
        """Post-encroachment time [s] where the paths of ``name`` and ``ref`` cross (at 20 to 160 degrees): how
        far apart in time the two pass the crossing point, whichever comes first; the smallest over their
        crossings. None when the paths do not cross where ``name`` really drove (or crashed into ``ref``).

        Each path runs on :data:`PATH_EXTEND_M` past its end at the last speed (at least
        :data:`MIN_GAP_SPEED`), so a car that stands short of the crossing, or one the episode ended on,
        is timed as if it drove on."""
        a, b = self._timed_path(ref), self._timed_path(name)
        if a is None or b is None:
            return None
        hit_ref = any(other == ref for _, other in self.e.collisions.get(name, []))
        (pa, ta, _), (pb, tb, eb) = a, b
        ra, rb = np.diff(pa, axis=0), np.diff(pb, axis=0)
        qa, qb = pa[:-1], pb[:-1]
        denom = ra[:, None, 0] * rb[None, :, 1] - ra[:, None, 1] * rb[None, :, 0]
        diff = qb[None, :, :] - qa[:, None, :]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = (diff[..., 0] * rb[None, :, 1] - diff[..., 1] * rb[None, :, 0]) / denom
            v = (diff[..., 0] * ra[:, None, 1] - diff[..., 1] * ra[:, None, 0]) / denom
        dot = ra[:, None, 0] * rb[None, :, 0] + ra[:, None, 1] * rb[None, :, 1]
        angle = np.abs(np.arctan2(denom, dot))
        ok = (np.abs(denom) > 1e-9) & (u >= 0) & (u <= 1) & (v >= 0) & (v <= 1)
        ok &= (angle >= math.radians(20)) & (angle <= math.radians(160))
        if not hit_ref:
            ok &= ~eb[None, :]  # the actor really got there, not only its extension
        i, j = np.nonzero(ok)
        if not i.size:
            return None
        time_a = ta[i] + u[i, j] * (ta[i + 1] - ta[i])
        time_b = tb[j] + v[i, j] * (tb[j + 1] - tb[j])
        return float(np.min(np.abs(time_a - time_b)))

    def _timed_path(self, name: str) -> Optional[Tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """(points, times [s], per segment: is it the extension) of an actor's path, extended past its end."""
        track = self.e.tracks[name]
        valid = np.flatnonzero(~np.isnan(track[:, 0]))
        if valid.size < 2:
            return None
        points, times = track[valid, :2], valid * self.e.dt
        x, y, heading, speed = track[valid[-1]]
        end = [x + PATH_EXTEND_M * math.cos(heading), y + PATH_EXTEND_M * math.sin(heading)]
        points = np.vstack([points, end])
        times = np.append(times, times[-1] + PATH_EXTEND_M / max(abs(speed), MIN_GAP_SPEED))
        extension = np.zeros(len(points) - 1, dtype=bool)
        extension[-1] = True
        return points, times, extension

    def _path_entries_of(self, ref: str, name: str, occ: _Occurrence) -> List[int]:
        """Steps of the occurrence at which ``name`` comes onto ``ref``'s path ahead of it."""
        lead_in = int(round(1.0 / self.e.dt))  # an actor on the ego's path just before its event counts
        return self.e.path_entries(name, max(0, occ.event - lead_in), occ.end, reference=ref)

    def _relation(self, relation: str, ref: str, name: str, i: int) -> bool:
        holds = _RELATION_HOLDS.get(relation)
        if holds is None:
            raise StoryError(f"unknown relation {relation!r}")
        return holds(self.e, ref, name, i)

    def _holds(self, action: str, name: str, at: int) -> bool:
        track = self.e.tracks[name][at:]
        track = track[~np.isnan(track[:, 0])]
        if action == Action.STOP:
            return bool(len(track)) and bool(np.all(np.abs(track[:, 3]) < STOP_SPEED))
        return True

    # ------------------------------------------------------------- collisions
    def collision_credit(self, step: Mapping[str, Any], after: int) -> bool:
        """Whether the ego hit the step's actor after the step's manoeuvre began (and after ``after``)."""
        name = self.names[step["actor"]]
        if step["action"] == Action.CROSS or name == "ego":
            return False
        if any(r == Relation.CROSSING_PATH for r, _ in step.get("relations", [])):
            return False
        hits = [i for i, other in self.e.collisions.get(name, []) if other == "ego" and i >= after]
        if not hits:
            return False
        onset = self.onset(name, step["action"], after)
        return onset is not None and onset <= hits[0]

    def onset(self, name: str, action: str, after: int = 0) -> Optional[int]:
        """The first step (at or after ``after``) at which the actor had begun ``action`` (:data:`_ONSETS`; an
        action without a rule there has begun at the actor's first step)."""
        speed = np.abs(self.e.tracks[name][:, 3])
        valid = ~np.isnan(speed)
        idx = [i for i in range(after, self.e.n) if valid[i]]
        if not idx:
            return None
        begun = _ONSETS.get(action)
        return idx[0] if begun is None else begun(self, name, action, idx)

    def _slowing_onset(self, name: str, action: str, idx: List[int]) -> Optional[int]:
        """A brake (or stop) has begun: the speed is down by :data:`ONSET_SPEED_CHANGE` from its peak (a stop: or
        under :data:`STOP_SPEED`)."""
        speed = np.abs(self.e.tracks[name][:, 3])
        peak = -math.inf
        for i in idx:
            peak = max(peak, speed[i])
            if peak - speed[i] >= ONSET_SPEED_CHANGE or (action == Action.STOP and speed[i] < STOP_SPEED):
                return i
        return None

    def _speeding_onset(self, name: str, action: str, idx: List[int]) -> Optional[int]:
        """A speed-up has begun: the speed is up by :data:`ONSET_SPEED_CHANGE` from its low."""
        speed = np.abs(self.e.tracks[name][:, 3])
        low = math.inf
        for i in idx:
            low = min(low, speed[i])
            if speed[i] - low >= ONSET_SPEED_CHANGE:
                return i
        return None

    def _lateral_onset_from_start(self, name: str, action: str, idx: List[int]) -> Optional[int]:
        """A sideways manoeuvre has begun: the actor is :data:`ONSET_SHIFT` sideways of where it was."""
        track = self.e.tracks[name]
        start = track[idx[0]]
        for i in idx:
            if abs(_frame(start, track[i])[1]) >= ONSET_SHIFT:
                return i
        return None

    def _overtake_onset(self, name: str, action: str, idx: List[int]) -> Optional[int]:
        """An overtake has begun: the actor is within two ego lengths behind the ego's front."""
        e = self.e
        for i in idx:
            if e.present("ego", i) and e.rel("ego", name, i)[0] > -EGO_FRONT * 2:
                return i
        return None

    def _turn_onset(self, name: str, action: str, idx: List[int]) -> Optional[int]:
        """A turn has begun: the heading has turned :data:`TURN_ONSET`."""
        track = self.e.tracks[name]
        for i in idx:
            if _angle(track[i, 2] - track[idx[0], 2]) >= TURN_ONSET:
                return i
        return None

    def _straight_onset(self, name: str, action: str, idx: List[int]) -> Optional[int]:
        """Going straight has begun: the actor is in the junction area."""
        inside = self._in_junction(name)
        hits = [i for i in idx if inside[i]]
        return hits[0] if hits else None

    # ------------------------------------------------------------ occurrences
    def occurrences(self, name: str, action: str) -> List[_Occurrence]:
        """Every occurrence of ``action`` by the actor (:data:`_OCCURRENCES`; an action without a rule there is read
        off the whole track by the trace semantics)."""
        track = self.e.tracks[name]
        valid = np.flatnonzero(~np.isnan(track[:, 0]))
        if valid.size < 2:
            return []
        first, last = int(valid[0]), int(valid[-1])
        return _OCCURRENCES.get(action, _Detector._whole_track)(self, name, action, first, last)

    def _speed_changes(self, name: str, action: str, first: int, last: int) -> List[_Occurrence]:
        """Brakes / speed-ups: the start of each window in which the speed falls / rises by :data:`SPEED_CHANGE`."""
        speed = np.abs(self.e.tracks[name][:, 3])
        window = max(1, int(round(WINDOW_S / self.e.dt)))
        sign = 1.0 if action == Action.BRAKE else -1.0
        out = []
        for i in range(first, last):
            ahead = speed[i + 1: min(last, i + window) + 1]
            if ahead.size and np.nanmax(sign * (speed[i] - ahead)) >= SPEED_CHANGE:
                out.append(_Occurrence(i, i, last))
        return out

    def _stops(self, name: str, action: str, first: int, last: int) -> List[_Occurrence]:
        """Standing still after driving, or from the start (parked) until it first drives."""
        speed = np.abs(self.e.tracks[name][:, 3])
        out, driven, standing = [], False, True
        for i in range(first, last + 1):
            driven = driven or speed[i] > 2.0
            standing = standing and speed[i] < STOP_SPEED
            if speed[i] < STOP_SPEED and (driven or standing):
                out.append(_Occurrence(i, i, last))
        return out

    def _directed_lane_changes(self, name: str, action: str, first: int, last: int) -> List[_Occurrence]:
        """The env's lane-change events of the actor in the action's direction."""
        side = action.rsplit("_", 1)[1]
        return [_Occurrence(self._lateral_onset(name, i), i, last)
                for i, direction in self.e.lane_changes.get(name, []) if direction == side]

    def _lane_changes(self, name: str, action: str, first: int, last: int) -> List[_Occurrence]:
        """The env's lane-change events of the actor, either way."""
        return [_Occurrence(self._lateral_onset(name, i), i, last) for i, _ in self.e.lane_changes.get(name, [])]

    def _cut_ins(self, name: str, action: str, first: int, last: int) -> List[_Occurrence]:
        """Lane changes into the ego's lane ahead of it; a merge also from a side road onto the ego's path."""
        e = self.e
        track = e.tracks[name]
        out = []
        for i, _ in e.lane_changes.get(name, []):
            j = min(last, i + int(round(1.0 / e.dt)))
            if e.present("ego", j):
                ahead, left = e.rel("ego", name, j)
                if abs(left) <= LANE_HALF and 0 < ahead < CUT_IN_AHEAD:
                    out.append(_Occurrence(self._lateral_onset(name, i), i, last))
        if action == Action.MERGE and e.present("ego", first):
            gap = _angle(track[first, 2] - e.tracks["ego"][first, 2])
            if math.radians(45) <= gap <= math.radians(135):
                for i in range(first, last + 1):
                    if e.present("ego", i) and e.along_path("ego", name, i) is not None \
                            and _angle(track[i, 2] - e.tracks["ego"][i, 2]) <= math.radians(20):
                        out.append(_Occurrence(first, i, last))
                        break
        return sorted(out, key=lambda o: o.event)

    def _overtakes(self, name: str, action: str, first: int, last: int) -> List[_Occurrence]:
        """The moments the actor passes the ego, from behind it to ahead of it."""
        e = self.e
        out, behind = [], False
        for i in range(first, last + 1):
            if not e.present("ego", i):
                continue
            ahead, _ = e.rel("ego", name, i)
            if ahead < -2.0:
                behind = True
            elif behind and ahead >= 0.0:
                out.append(_Occurrence(self.onset(name, Action.OVERTAKE, first) or i, i, last))
                behind = False
        return out

    def _crossings(self, name: str, action: str, first: int, last: int) -> List[_Occurrence]:
        """The moments the actor enters the ego's path from the side."""
        speed = np.abs(self.e.tracks[name][:, 3])
        moving = [i for i in range(first, last + 1) if speed[i] > 0.2]
        onset = moving[0] if moving else first
        return [_Occurrence(onset, i, min(last, i + 1)) for i in self.e.path_entries(name, first, last)]

    def _collisions(self, name: str, action: str, first: int, last: int) -> List[_Occurrence]:
        """The actor's collision events (of the action's collision type, for a typed one)."""
        out = []
        for i, other in self.e.collisions.get(name, []):
            if action == Action.COLLIDE or self._collision_type(name, other, i) == action:
                out.append(_Occurrence(i, i, i))
        return out

    def _collision_type(self, name: str, other: str, i: int) -> Optional[str]:
        for k in range(i, -1, -1):
            if self.e.present(name, k) and self.e.present(other, k):
                return collision_type(self.e.tracks[name][k], self.e.tracks[other][k])
        return None

    def _lateral_onset(self, name: str, event: int) -> int:
        """Where the sideways move that ends in the lane change at ``event`` began."""
        track = self.e.tracks[name]
        back = max(0, event - int(round(4.0 / self.e.dt)))
        base = track[back]
        if np.isnan(base[0]):
            return event
        for i in range(back, event + 1):
            if not np.isnan(track[i, 0]) and abs(_frame(base, track[i])[1]) >= ONSET_SHIFT:
                return i
        return event

    def _in_junction(self, name: str) -> np.ndarray:
        """Per step, whether the actor is in the map's junction area (read once per actor; callers do not write it)."""
        if name in self._junction_masks:
            return self._junction_masks[name]
        view = map_view(self.e.trace)
        track = self.e.tracks[name]
        inside = np.zeros(self.e.n, dtype=bool)
        if view is not None:
            valid = ~np.isnan(track[:, 0])
            inside[valid] = view.in_junction(track[valid])
        self._junction_masks[name] = inside
        return inside

    def _junction_way(self, name: str, action: str, first: int, last: int) -> List[_Occurrence]:
        track = self.e.tracks[name]
        inside = self._in_junction(name)
        entries = [i for i in range(first + 1, last + 1) if inside[i] and not inside[i - 1]]
        if not entries:
            return []
        enter = entries[0]
        exits = [i for i in range(enter + 1, last + 1) if not inside[i]]
        leave = exits[0] if exits else last
        turned = float((track[leave, 2] - track[max(first, enter - 1), 2] + math.pi) % (2 * math.pi) - math.pi)
        crashed = [i for i, _ in self.e.collisions.get(name, []) if enter <= i <= leave]
        if action == Action.GO_STRAIGHT:
            approach = max(first, enter - int(round(1.0 / self.e.dt)))
            if abs(turned) < math.radians(30) and (exits or crashed):
                return [_Occurrence(approach, approach, leave)]
            return []
        want = 1.0 if action == Action.TURN_RIGHT else -1.0  # a growing heading turns right (y drawn downward)
        full = track[last, 2] - track[first, 2]
        net = float((full + math.pi) % (2 * math.pi) - math.pi)
        if want * net >= TURN_ANGLE or (crashed and want * turned >= math.radians(20)):
            # the turn is under way from its onset until it has turned TURN_ANGLE: any moment of it is its event
            start = self.onset(name, action, first) or enter
            done = next((i for i in range(start, last + 1)
                         if want * _signed(track[i, 2] - track[first, 2]) >= TURN_ANGLE), last)
            return [_Occurrence(start, i, last) for i in range(start, done + 1)]
        return []

    def _whole_track(self, name: str, action: str, first: int, last: int) -> List[_Occurrence]:
        """Actions read off the whole track by the trace semantics (keep_lane, drift, swerve, pull_out...)."""
        shown = _actor_elements(self.e.trace, name)
        if action not in shown:
            return []
        start = self.onset(name, action, first) if action in _LATERAL | {Action.U_TURN} else first
        return [_Occurrence(start if start is not None else first, start if start is not None else first, last)]


def _oncoming(episode: _Episode, ref: str, name: str, i: int) -> bool:
    """``name`` heads more than 135 degrees off ``ref``'s heading at step ``i``."""
    gap = abs((episode.tracks[name][i, 2] - episode.tracks[ref][i, 2] + math.pi) % (2 * math.pi) - math.pi)
    return gap > math.radians(135)


_RELATION_HOLDS: Dict[Relation, Callable[[_Episode, str, str, int], bool]] = {
    Relation.AHEAD_OF: lambda e, ref, name, i: e.rel(ref, name, i)[0] > 2.0,
    Relation.BEHIND: lambda e, ref, name, i: e.rel(ref, name, i)[0] < -2.0,
    Relation.LEFT_OF: lambda e, ref, name, i: e.rel(ref, name, i)[1] > LANE_HALF,
    Relation.RIGHT_OF: lambda e, ref, name, i: e.rel(ref, name, i)[1] < -LANE_HALF,
    Relation.SAME_LANE: lambda e, ref, name, i: abs(e.rel(ref, name, i)[1]) <= LANE_HALF,
    Relation.ONCOMING: _oncoming,
}
"""Whether a relation holds of an actor to another (``ref``) at a trace step; ``crossing_path`` is read over the
manoeuvre instead (``_Detector._fails``)."""

_Onset = Callable[[_Detector, str, str, List[int]], Optional[int]]
_ONSETS: Dict[Action, _Onset] = {
    Action.BRAKE: _Detector._slowing_onset, Action.STOP: _Detector._slowing_onset,
    Action.ACCELERATE: _Detector._speeding_onset,
    **{action: _Detector._lateral_onset_from_start for action in _LATERAL},
    Action.OVERTAKE: _Detector._overtake_onset,
    Action.TURN_LEFT: _Detector._turn_onset, Action.TURN_RIGHT: _Detector._turn_onset,
    Action.U_TURN: _Detector._turn_onset,
    Action.GO_STRAIGHT: _Detector._straight_onset,
}
"""How the start of each action's manoeuvre is found (``_Detector.onset``), over the steps the actor is in."""

_Occurrences = Callable[[_Detector, str, str, int, int], List[_Occurrence]]
_OCCURRENCES: Dict[Action, _Occurrences] = {
    Action.BRAKE: _Detector._speed_changes, Action.ACCELERATE: _Detector._speed_changes,
    Action.STOP: _Detector._stops,
    Action.LANE_CHANGE_LEFT: _Detector._directed_lane_changes,
    Action.LANE_CHANGE_RIGHT: _Detector._directed_lane_changes,
    Action.LANE_CHANGE: _Detector._lane_changes,
    Action.CUT_IN: _Detector._cut_ins, Action.MERGE: _Detector._cut_ins,
    Action.OVERTAKE: _Detector._overtakes,
    Action.CROSS: _Detector._crossings,
    Action.GO_STRAIGHT: _Detector._junction_way, Action.TURN_LEFT: _Detector._junction_way,
    Action.TURN_RIGHT: _Detector._junction_way,
    **{action: _Detector._collisions for action in (Action.COLLIDE, Action.COLLIDE_REAR_END, Action.COLLIDE_SIDE,
                                                    Action.COLLIDE_HEAD_ON)},
}
"""How the occurrences of each action are found (``_Detector.occurrences``), between the actor's first and last
step in the trace; the other actions are read off the whole track (``_Detector._whole_track``)."""


def _actor_elements(trace, name: str) -> set:
    """Actions the trace semantics read for actor ``name`` alone (the trace cut down to it and the ego)."""
    kinds = dict(getattr(trace, "kinds", {}) or {})
    marker = "story_actor"
    states = [{k: v for k, v in s.items() if k in ("ego", name)} for s in trace.states]
    states = [{("ego" if k == "ego" else marker): v for k, v in s.items()} for s in states]
    events = []
    for event in trace.events:
        actors = list(event.get("actors") or [])
        if actors and set(actors) <= {"ego", name}:
            events.append({**event, "actors": ["ego" if a == "ego" else marker for a in actors]})
    kind = kinds.get(name, "car")
    cut = SimpleNamespace(states=states, events=events, config=trace.config, params=trace.params,
                          kinds={"ego": "ego", marker: kind})
    shown = elements_from_trace(cut)
    return {a for k, a in shown.actions if k == kind}


def _frame(reference: np.ndarray, other: np.ndarray) -> Tuple[float, float]:
    dx, dy = other[0] - reference[0], other[1] - reference[1]
    c, s = math.cos(reference[2]), math.sin(reference[2])
    return dx * c + dy * s, dx * s - dy * c


def _signed(a: float) -> float:
    return float((a + math.pi) % (2 * math.pi) - math.pi)


def _angle(a: float) -> float:
    return abs(float((a + math.pi) % (2 * math.pi) - math.pi))
