"""The description parser's action rules (:mod:`dv2s_gym.pipeline.semantics.text`): one rule per action phrase
(lane changes, swerves, pull-outs, stops, turns, crossings, cut-ins, collisions, ...) and the triggers they read."""

from __future__ import annotations

import re
from typing import Any, Dict, List, Optional, Tuple

from dv2s_gym.pipeline.semantics.lexicon import COMPILED_ACTIONS, NEGATION, SUDDEN, PASSIVE_HIT, LANE_WORD
from dv2s_gym.pipeline.semantics.mentions import Mention, action_window, crossing_direction
from dv2s_gym.pipeline.semantics.parsed import Entity, Lane, drift_side
from dv2s_gym.pipeline.semantics.road import distance_m, time_s
from scenario_bank.elements import CAN_DO, Action, ActorKind, Relation

__all__ = ["ActionRules"]


def _conflict_partner_of(entities: List[Entity], who: Entity) -> Optional[Entity]:
    """The actor ``who`` is in conflict with: one crossing its path, oncoming, crossing, turning or going
    straight at the junction; else the first other moving actor."""
    others = [e for e in entities if e is not who and e.kind not in (ActorKind.EGO, ActorKind.OBSTACLE)]
    for e in others:
        if any(j is who and r in (Relation.CROSSING_PATH, Relation.ONCOMING) for r, j in e.relations):
            return e
    for e in others:
        if any(e.has(a) for a in ("cross", "go_straight", "turn_left", "turn_right", "pull_out", "u_turn")):
            return e
    return others[0] if others else None


class ActionRules:
    """The description parser's rules for action phrases, one per action, and the triggers and
    coordinated subjects they read (mixed into the parser of :mod:`dv2s_gym.pipeline.semantics.text`)."""

    def read_actions(self, clause: str, mentions: List[Mention], subject: Optional[Entity]) -> None:
        self.clause_mentions = mentions
        self.clause_subject = subject
        spans: List[Tuple[int, int]] = []
        for action, rx in COMPILED_ACTIONS:
            for m in rx.finditer(clause):
                if any(not (m.end() <= s or m.start() >= e) for s, e in spans):
                    continue
                before = clause[:m.start()]
                if NEGATION.search(before[-45:]):
                    spans.append((m.start(), m.end()))
                    self.negated += 1  # understood: said not to happen
                    continue
                owner = self._action_subject(m.start(), mentions, subject, clause)
                if re.match(r"(?:stopped|stationary|parked|stalled|broken down|waiting|standing|[a-z]+ing)\b",
                            m.group(0)):
                    right_before = [mm for mm in mentions if 0 <= m.start() - mm.end <= 1
                                    and not isinstance(mm.entity, tuple)]
                    if right_before:
                        owner = right_before[-1].entity  # "a bus stopped at the stop": the bus
                if re.search(r"\bor\s+(?:\w+\s+)?$", before) or re.match(r"\s*(?:\w+\s+){0,3}or\b", clause[m.end():]):
                    spans.append((m.start(), m.end()))
                    continue  # "turns right or goes straight": neither is stated
                if action == Action.CUT_IN and re.search(r"\b(?:is|was|were|are|gets?|got|being|been) (?:\w+ )?$",
                                                         before) and re.match(r"\s*by\b", clause[m.end():]):
                    agent = self.object_at(clause, m.end(), mentions)
                    if agent is not None:
                        owner = agent  # "the ego is cut off by a van"
                if action.startswith("collide"):
                    passive = PASSIVE_HIT.search(clause[max(0, m.start() - 25):m.end() + 4])
                    late_by = re.match(r"(?:\s+\w+){0,5}?\s+by\b", clause[m.end():])
                    if not passive and late_by and re.search(r"\b(?:is|was|were|are|gets?|got|being|been) (?:\w+ )?$",
                                                             before):
                        passive = late_by  # "was struck on the right side by V2"
                    if passive:
                        agent = self.object_at(clause, m.end() + (late_by.end() if late_by and passive is late_by
                                                                   else 0), mentions)
                        if agent is not None:
                            owner = agent
                spans.append((m.start(), m.end()))
                if action.startswith("collide"):
                    bm = re.match(r"\s*(?:\w+\s+){0,3}?(?:between|involving)\s", clause[m.end():])
                    if bm:
                        pair = [mm.entity for mm in mentions if mm.start >= m.end() + bm.end() - 1
                                and not isinstance(mm.entity, tuple)][:2]
                        if len(pair) == 2 and pair[0] is not pair[1]:
                            # "a side-impact crash between the ego and a bus": both collide, with each other
                            for one, other in (pair, pair[::-1]):
                                self._record(one, action, m, clause)
                                one.detail("collide")["with"] = other
                            continue
                if owner is None:
                    continue
                self._record(owner, action, m, clause)

    def _next_mention(self, clause: str, pos: int, mentions: List[Mention], exclude: Optional[Entity] = None,
                      limit: int = 30) -> Optional[Entity]:
        """The first actor mentioned after ``pos`` (within ``limit`` characters), other than ``exclude``."""
        for mm in mentions:
            if mm.start >= pos and mm.start - pos <= limit and mm.entity is not exclude and \
                    not isinstance(mm.entity, tuple):
                return mm.entity
        return None

    def _trigger(self, owner: Entity, action: str, m: re.Match, clause: str) -> None:
        """What sets off a stop or a brake: a conflict with another actor, a distance or a time."""
        after = clause[m.end():]
        before = clause[:m.start()]
        detail: Dict[str, Any] = {}
        fm = re.match(r"\s*(?:\w+ly )?(?:for|to|because of|due to|to let|to allow|to avoid|until)\b", after)
        if fm:
            other = self._next_mention(clause, m.end() + fm.end(), self.clause_mentions, exclude=owner, limit=35)
            if other is not None:
                detail = {"kind": "conflict", "with": other}
        if not detail and (re.search(r"\b(?:must|has to|have to|had to|needs? to|forced to|required to|should)\s+"
                                     r"(?:\w+ly\s+)?$", before) or m.group(0).startswith(("yield", "giv", "gave",
                                                                                              "wait"))):
            detail = {"kind": "conflict", "with": None}
        if not detail:
            dist = distance_m(clause)
            if dist is not None:
                detail = {"kind": "distance", "meters": dist}
            else:
                sec = time_s(clause)
                if sec is not None and re.search(r"\b(?:after|within|in|for)\b", clause):
                    detail = {"kind": "time", "seconds": sec}
        if detail:
            existing = owner.detail(action)
            owner.add_action(action)
            owner.detail(action).setdefault("trigger", detail) if existing is not None else None

    def coordinated_subjects(self, clause: str, mentions: List[Mention], subject: Optional[Entity],
                     before_actions: List[str]) -> None:
        """"Two pedestrians and a cyclist cross": the actors joined to the subject by "and" do what it does."""
        if subject is None:
            return
        new = [(a, d) for a, d in subject.actions if a not in before_actions]
        if not new:
            return
        idx = next((i for i, mm in enumerate(mentions) if mm.entity is subject), None)
        if idx is None:
            return
        for prev, mm in zip(mentions[idx:], mentions[idx + 1:]):
            gap = clause[prev.end:mm.start]
            if not re.fullmatch(r"\s*(?:,\s*)?(?:and|or|as well as|along with|plus)\s+(?:\w+\s+){0,2}", gap) or \
                    isinstance(mm.entity, tuple) or mm.entity is subject:
                break
            for a, d in new:
                if mm.entity.kind == ActorKind.PEDESTRIAN and a not in CAN_DO[ActorKind.PEDESTRIAN]:
                    continue
                mm.entity.add_action(a, **{k: v for k, v in d.items() if k != "with"})

    def conflict_partner(self, who: Entity) -> Optional[Entity]:
        return _conflict_partner_of(self.out.entities, who)

    def _action_subject(self, pos: int, mentions: List[Mention], subject: Optional[Entity],
                        clause: str = "") -> Optional[Entity]:
        rel = re.search(r"\b(?:that|which|who)\s+(?:\w+ly\s+|also\s+|then\s+)?$", clause[:pos])
        if rel:
            before = [mm for mm in mentions if mm.end <= rel.start() and rel.start() - mm.end <= 2]
            if before and not before[-1].possessive:
                return before[-1].entity
        candidates = [mm for mm in mentions if mm.end <= pos and not mm.prep_object and not mm.possessive]
        if candidates:
            # the nearest subject-like mention, unless a verb (an action) sits between: then the clause subject
            return candidates[-1].entity if subject is None or candidates[-1].entity is subject or \
                self._is_subject_like(candidates[-1], subject) else subject
        return subject

    @staticmethod
    def _is_subject_like(mention: Mention, subject: Optional[Entity]) -> bool:
        # a non-prepositional mention after the clause subject is usually a verb object ("overtakes the ego")
        return subject is None

    def _record(self, owner: Entity, action: str, m: re.Match, clause: str) -> None:
        """Record ``action`` of ``owner``; each action it adds keeps the words it was read from (``phrase``)."""
        before = {a for a, _ in owner.actions}
        self._record_action(owner, action, m, clause)
        for name, detail in owner.actions:
            if name not in before:
                detail.setdefault("phrase", m.group(0))

    def _record_action(self, owner: Entity, action: str, m: re.Match, clause: str) -> None:
        """Record one action phrase read for ``owner``. An action read onto a static object is not placed; a rule
        per action (:attr:`_ACTION_RULES`) records what the phrase means; without one (or when the rule leaves it),
        the action is recorded as read, with whether it was sudden."""
        self.placed_count += 1
        sudden = bool(SUDDEN.search(action_window(clause, m)))
        if self._static_object_acts(owner, action, clause):
            return
        if action in (Action.LANE_CHANGE, Action.CUT_IN) and m.group(0).startswith("merg") and \
                owner.kind != ActorKind.PEDESTRIAN:
            owner.add_action("merge", sudden=sudden)  # "merges left", "merged into its lane": the text says merge
        rule = self._ACTION_RULES.get("collide" if action.startswith("collide") else action)
        if rule is None or not rule(self, owner, action, m, clause, sudden):
            owner.add_action(action, sudden=sudden)

    def _static_object_acts(self, owner: Entity, action: str, clause: str) -> bool:
        """Whether ``action`` was read onto a static object (an obstacle that does not collide, and is no animal
        crossing, emerging or stopping): then the clause is listed as not placed."""
        if owner.kind == ActorKind.OBSTACLE and not (owner.attrs.get("animal")
                                                    and action in (Action.CROSS, "emerge", Action.STOP)) \
                and not action.startswith("collide"):
            if clause not in self.unplaced_phrases:
                self.unplaced_phrases.append(clause)
            return True
        return False

    # Each rule below reads one action phrase of ``owner`` and returns whether it recorded it (False: the action is
    # recorded as read).

    def _lane_change_rule(self, owner: Entity, action: str, m: re.Match, clause: str, sudden: bool) -> bool:
        """A lane change: to the side said (left/right, or a lane named: "the middle lane" waits for the lane the
        actor is on); undirected (``weave`` for weaving) when no side is said; a pedestrian changes no lane."""
        groups = m.groupdict()
        d = groups.get("dir") or groups.get("dir2")
        if not d:
            if owner.kind == ActorKind.PEDESTRIAN:
                return True
            if groups.get("weave"):
                owner.add_action("lane_change", sudden=sudden, weave=True)
            else:
                owner.add_action("lane_change", sudden=sudden)
            return True
        side = LANE_WORD.get(d, d) if d in LANE_WORD else d
        if d in (Lane.LEFT, Lane.RIGHT) and "side" not in m.group(0):
            owner.add_action(f"lane_change_{d}", sudden=sudden, target=d)
        elif side == Lane.MIDDLE:
            owner.add_action("lane_change_pending", sudden=sudden, target="middle")
        elif side in (Lane.LEFT, Lane.RIGHT):
            owner.add_action(f"lane_change_{side}", sudden=sudden, target=side)
        return True

    def _swerve_rule(self, owner: Entity, action: str, m: re.Match, clause: str, sudden: bool) -> bool:
        """A swerve is always sudden, to the side said; a pedestrian does not swerve."""
        if owner.kind != ActorKind.PEDESTRIAN:
            owner.add_action("swerve", sudden=True, side=m.groupdict().get("dir"))
        return True

    def _pull_out_rule(self, owner: Entity, action: str, m: re.Match, clause: str, sudden: bool) -> bool:
        """Pulling out (from a parking place, the kerb, a driveway): it ends a stop; backing out also reverses.
        A generic "pulls out" with no parked actor or parking place near it is not placed."""
        groups = m.groupdict()
        if any(groups.get(g) is not None for g in ("generic", "generic2", "generic3")) and not (
                "parked" in owner.descriptors or re.search(
                    r"\b(?:park\w*|curb|kerb|driveway|shoulder|roadside|side of the road|lay by)\b",
                    self.sentence_text if groups.get("generic3") is not None else clause)):
            self.unplaced_phrases.append(clause)
            return True
        if owner.kind == ActorKind.PEDESTRIAN:
            return True
        owner.actions = [(a, d) for a, d in owner.actions if a != Action.STOP]
        owner.add_action("pull_out", sudden=sudden)
        if re.match(r"(?:back|revers)", m.group(0)):
            owner.add_action("reverse")
        return True

    def _emerge_rule(self, owner: Entity, action: str, m: re.Match, clause: str, sudden: bool) -> bool:
        """Emerging (from behind an occluder, which is kept): a pedestrian, cyclist or animal that emerges
        crosses, suddenly when it dashes or runs."""
        behind = None
        bm = re.search(r"\bfrom behind\b", clause[m.start():])
        if bm:
            behind = self._next_mention(clause, m.start() + bm.end(), self.clause_mentions, exclude=owner)
        if behind is not None:
            owner.attrs["from_behind"] = behind
        if owner.kind in (ActorKind.PEDESTRIAN, ActorKind.BICYCLE) or owner.attrs.get("animal"):
            quick = bool(re.match(r"(?:dash|dart|rush|sprint|run|ran|jump|leap|burst|pop)", m.group(0)))
            owner.add_action("cross", sudden=sudden or quick, directions=[])
            if behind is not None:
                owner.detail("cross")["from_behind"] = behind
        return True

    def _brake_stop_rule(self, owner: Entity, action: str, m: re.Match, clause: str, sudden: bool) -> bool:
        """Braking to a stop: both."""
        owner.add_action("brake", sudden=sudden)
        owner.add_action("stop", sudden=sudden)
        return True

    def _pull_over_rule(self, owner: Entity, action: str, m: re.Match, clause: str, sudden: bool) -> bool:
        """Pulling over: a lane change to the right and a stop (not for a pedestrian)."""
        if owner.kind != ActorKind.PEDESTRIAN:
            owner.add_action("lane_change_right", sudden=sudden)
            owner.add_action("stop", sudden=sudden)
        return True

    def _stop_rule(self, owner: Entity, action: str, m: re.Match, clause: str, sudden: bool) -> bool:
        """A stop, with its trigger; the ego parking is not one."""
        self._trigger(owner, action, m, clause)
        return bool(re.match(r"park", m.group(0))) and owner.kind == ActorKind.EGO

    def _brake_rule(self, owner: Entity, action: str, m: re.Match, clause: str, sudden: bool) -> bool:
        """A brake, with its trigger."""
        self._trigger(owner, action, m, clause)
        return False

    def _turn_rule(self, owner: Entity, action: str, m: re.Match, clause: str, sudden: bool) -> bool:
        """A turn to the side said, ``unprotected`` when the words around say so; a pedestrian does not turn."""
        d = m.groupdict().get("dir")
        if owner.kind in (ActorKind.PEDESTRIAN,):
            return True
        owner.add_action(f"turn_{d}", sudden=sudden)
        if m.groupdict().get("unprot") == "unprotected" or re.search(r"\bunprotected\b", action_window(clause, m)):
            owner.detail(f"turn_{d}")["unprotected"] = True
        return True

    def _cross_rule(self, owner: Entity, action: str, m: re.Match, clause: str, sudden: bool) -> bool:
        """A pedestrian crosses in the directions said (each phrase adds one); a vehicle crosses when the road,
        street or lanes are said (a cyclist always), else the clause is not placed; others as read."""
        if owner.kind == ActorKind.PEDESTRIAN:
            direction = crossing_direction(clause, m.groupdict())
            d = owner.detail("cross")
            if owner.has("cross") and direction:
                d.setdefault("directions", []).append(direction)
            else:
                owner.add_action("cross", sudden=sudden, directions=[direction] if direction else [])
            return True
        if owner.kind in (ActorKind.CAR, ActorKind.TRUCK, ActorKind.BUS, ActorKind.MOTORCYCLE, ActorKind.BICYCLE,
                          ActorKind.EGO):
            if re.match(r"cross(?:es|ed|ing)? (?:the |a )?(?:road|street|lanes?|highway)\b", m.group(0) +
                        clause[m.end():m.end() + 20].lstrip().join([" ", ""])) or owner.kind == ActorKind.BICYCLE:
                owner.add_action("cross", sudden=sudden)  # (a cyclist crossing in front: like a pedestrian)
            elif clause not in self.unplaced_phrases:
                self.unplaced_phrases.append(clause)  # "crosses" of a vehicle that says not what: warned
            return True
        return False

    def _cut_in_rule(self, owner: Entity, action: str, m: re.Match, clause: str, sudden: bool) -> bool:
        """A cut-in, from the side said, ``back`` when it pulls back in."""
        side = None
        sm = re.search(r"\bfrom the (left|right)\b|\bfrom (?:its|the) (left|right)\b", clause)
        if sm:
            side = sm.group(1) or sm.group(2)
        owner.add_action("cut_in", sudden=sudden, side=side, back="back" in m.group(0))
        return True

    def _overtake_rule(self, owner: Entity, action: str, m: re.Match, clause: str, sudden: bool) -> bool:
        """An overtake, on the side said; ``around`` (an obstacle) and ``via_pass`` ("passes") as worded."""
        side = None
        sm = re.search(r"\bon the (left|right)\b|\bvia the (left|right)\b|\bon (?:its|the ego's) (left|right)\b",
                       clause)
        if sm:
            side = next(g for g in sm.groups() if g)
        owner.add_action("overtake", sudden=sudden, side=side,
                         around=" around" in m.group(0), via_pass=m.group(0).startswith("pass"))
        return True

    def _drift_rule(self, owner: Entity, action: str, m: re.Match, clause: str, sudden: bool) -> bool:
        """A drift, to the side the words after it say (see :func:`drift_side`)."""
        owner.add_action("drift", sudden=sudden)
        side = drift_side(clause[m.start():m.end() + 60])
        if side and not owner.detail("drift").get("side"):
            owner.detail("drift")["side"] = side
        return True

    def _merge_rule(self, owner: Entity, action: str, m: re.Match, clause: str, sudden: bool) -> bool:
        """A pedestrian does not merge."""
        return owner.kind == ActorKind.PEDESTRIAN

    def _collide_rule(self, owner: Entity, action: str, m: re.Match, clause: str, sudden: bool) -> bool:
        """A collision (and its type when said), with the next actor named after it, else the clause subject
        ("the ego ... is struck by a van": the van hits the ego)."""
        other = self._next_mention(clause, m.end(), self.clause_mentions, exclude=owner, limit=40)
        if other is None and self.clause_subject is not None and self.clause_subject is not owner:
            other = self.clause_subject
        owner.add_action("collide", sudden=sudden)
        if other is not None and not owner.detail("collide").get("with"):
            owner.detail("collide")["with"] = other
        if action != Action.COLLIDE:
            owner.add_action(action)
        return True

    _ACTION_RULES = {"lane_change": _lane_change_rule, "swerve": _swerve_rule, "pull_out": _pull_out_rule,
                     "emerge": _emerge_rule, "brake_stop": _brake_stop_rule, "pull_over": _pull_over_rule,
                     "stop": _stop_rule, "brake": _brake_rule, "turn": _turn_rule, "cross": _cross_rule,
                     "cut_in": _cut_in_rule, "overtake": _overtake_rule, "drift": _drift_rule, "merge": _merge_rule,
                     "collide": _collide_rule}
    """Action -> the rule that records its phrase (every ``collide*`` action has the collision rule)."""
