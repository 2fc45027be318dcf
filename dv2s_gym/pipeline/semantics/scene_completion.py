"""The last step of the description parser (:mod:`dv2s_gym.pipeline.semantics.text`): collisions completed,
absolute lanes, and the relations to the ego (crossing paths, occluders, cross traffic) a scene implies."""

from __future__ import annotations

from typing import Optional

from dv2s_gym.pipeline.semantics.lexicon import MOTOR, COLLISION_KINDS
from dv2s_gym.pipeline.semantics.mentions import cut_in_side_from_relations, cut_in_lane_changes
from dv2s_gym.pipeline.semantics.parsed import Entity, Lane
from scenario_bank.elements import Action, ActorKind, Relation, Road

__all__ = ["SceneCompletion"]


class SceneCompletion:
    """What the description parser adds once every sentence is read: collisions, absolute lanes and the
    relations to the ego a scene implies (mixed into the parser of :mod:`dv2s_gym.pipeline.semantics.text`)."""

    def _collisions(self) -> None:
        """Every participant of a collision collides, with one type (scenario_bank.elements): the type said,
        else rear-end for one behind the other in a lane, head-on for oncoming, side for anything else."""
        ego = self.out.ego
        for e in list(self.out.entities):
            if not e.has("collide"):
                continue
            other = e.detail("collide").get("with")
            if other is None:
                others = [x for x in self.out.entities if x is not e and x.kind != ActorKind.OBSTACLE or
                          x is not e and x.attrs.get("animal")]
                if e is not ego and ego is not None and not any(x.has("collide") for x in others if x is not ego):
                    other = ego
                elif e is ego and len(others) == 1:
                    other = others[0]
            kinds = [a for a in COLLISION_KINDS if e.has(a) or other is not None and other.has(a)]
            if kinds:
                kind = kinds[0]
            elif other is None:
                continue
            else:
                rels = {r for r, j in e.relations if j is other} | {r for r, j in other.relations if j is e}
                if {e.kind, other.kind} & {ActorKind.PEDESTRIAN, ActorKind.BICYCLE, ActorKind.OBSTACLE}:
                    kind = "collide_side"
                elif Relation.ONCOMING in rels:
                    kind = "collide_head_on"
                elif rels & {Relation.AHEAD_OF, Relation.BEHIND, Relation.SAME_LANE} and Relation.CROSSING_PATH not in rels:
                    kind = "collide_rear_end"
                else:
                    kind = "collide_side"
            for x in (e, other):
                if x is None:
                    continue
                x.add_action("collide")
                x.add_action(kind)
                if x.detail("collide").get("with") is None:
                    x.detail("collide")["with"] = e if x is other else other

    def _absolute_lanes(self) -> None:
        """Absolute lanes of two actors give a relation (left lane vs the ego's middle lane: left_of)."""
        ego = self.out.ego
        if ego is not None and ego.lane in (Lane.LEFT, Lane.MIDDLE, Lane.RIGHT):
            order = {Lane.LEFT: 0, Lane.MIDDLE: 1, Lane.RIGHT: 2}
            for e in self.out.entities:
                if e is ego or e.lane not in order or e.kind == ActorKind.PEDESTRIAN:
                    continue
                if order[e.lane] < order[ego.lane]:
                    self.relate(e, "left_of", ego)
                elif order[e.lane] > order[ego.lane]:
                    self.relate(e, "right_of", ego)

    def finish(self) -> None:
        """What the whole text settles once every sentence is read: lanes to relations, collisions, lane changes
        to the middle lane, cut-in sides, relations to the ego that actions imply, conflicts, occluders, cross
        traffic at junctions, and animals that are no driving scene."""
        self._absolute_lanes()  # first, so cut-ins get their side from it
        self._collisions()
        ego = self.out.ego
        for e in self.out.entities:
            self._middle_lane_direction(e, ego)
            if e.kind == ActorKind.PEDESTRIAN and e.has("cross"):
                e.actions = [(a, d) for a, d in e.actions if a != Action.STOP or d.get("keep")]
            cut_in_side_from_relations(e)
        for e in self.out.entities:
            if e.kind == ActorKind.EGO or ego is None:
                continue
            rels = self._relations_said_to_ego(e, ego)
            cut_in_lane_changes(e, rels)
            self._relations_implied_to_ego(e, ego, rels)
        for e in self.out.entities:
            # an undirected lane change said next to a directed one adds nothing
            if e.has("lane_change") and (e.has("lane_change_left") or e.has("lane_change_right")) and \
                    not e.detail("lane_change").get("weave"):
                e.actions = [(a, d) for a, d in e.actions if a != Action.LANE_CHANGE]
            # "must stop" at a junction with no object: the conflict is the actor crossing, turning or oncoming
            for a, d in e.actions:
                trig = d.get("trigger")
                if a in (Action.STOP, Action.BRAKE) and trig and trig.get("kind") == "conflict" and \
                        trig.get("with") is None:
                    trig["with"] = self.conflict_partner(e)
        self._absolute_lanes()
        self._occluders_ahead(ego)
        self._cross_traffic(ego)
        # animals alone in a text with no road and no vehicle are not a driving scene ("the lazy dog")
        if self.out.road is None and all(e.attrs.get("animal") or e.kind == ActorKind.PEDESTRIAN
                                         for e in self.out.entities):
            self.out.entities = [e for e in self.out.entities if not e.attrs.get("animal")]
        # a pedestrian crossing in front of the ego; "one ... and the two others" count directions
        for e in self.out.entities:
            if e.kind == ActorKind.PEDESTRIAN and e.has("cross"):
                dirs = e.detail("cross").get("directions") or []
                e.detail("cross")["directions"] = dirs

    def _middle_lane_direction(self, e: Entity, ego: Optional[Entity]) -> None:
        """"Switches to the middle lane": a lane change to the left or right from the lane ``e`` is on (or its
        side of the ego); unresolved when neither is known."""
        for i, (a, d) in enumerate(list(e.actions)):
            if a == "lane_change_pending":
                direction = {Lane.LEFT: "right", Lane.RIGHT: "left"}.get(e.lane or "")
                if direction is None and ego is not None and e is not ego:
                    for rel, j in e.relations:
                        if rel in (Relation.LEFT_OF, Relation.RIGHT_OF) and j is ego:
                            direction = "right" if rel == Relation.LEFT_OF else "left"
                e.actions.pop(i)
                if direction:
                    e.add_action(f"lane_change_{direction}", **d)
                else:
                    self.out.unresolved.append(f"{e.kind}: lane change to the middle lane from an unknown lane")
                break

    def _relations_said_to_ego(self, e: Entity, ego: Entity) -> set:
        """``e``'s relations to the ego: those its words left pending ("a crossing vehicle"), and right of the
        ego for an actor on the ramp that has no side yet."""
        for rel in e.attrs.pop("pending_relations", []):
            self.relate(e, rel, ego)
        rels = {r for r, j in e.relations if j is ego}
        if e.lane == Lane.RAMP and not rels & {Relation.LEFT_OF, Relation.RIGHT_OF}:
            self.relate(e, "right_of", ego)
            rels.add("right_of")
        return rels

    def _relations_implied_to_ego(self, e: Entity, ego: Entity, rels: set) -> None:
        """Relations to the ego that ``e``'s kind, actions and other relations (``rels``) imply: a vehicle ahead
        and on no side is in the same lane, an obstacle in the lane is ahead, a crossing pedestrian, cyclist or
        animal is ahead and across the path, oncoming traffic crosses the path of an ego turning left."""
        if e.kind in MOTOR and Relation.AHEAD_OF in rels and not rels & {Relation.LEFT_OF, Relation.RIGHT_OF, Relation.ONCOMING} \
                and not (e.has("cut_in") and not e.detail("cut_in").get("back")) and not e.has("merge"):
            self.relate(e, "same_lane", ego)
        if e.kind == ActorKind.OBSTACLE and Relation.SAME_LANE in rels:
            self.relate(e, "ahead_of", ego)
        if (e.kind in (ActorKind.PEDESTRIAN, ActorKind.BICYCLE) or e.attrs.get("animal")) and e.has("cross"):
            self.relate(e, "ahead_of", ego)
            self.relate(e, "crossing_path", ego)
        if e.kind in MOTOR + (ActorKind.BICYCLE,) and Relation.ONCOMING in rels and ego.has("turn_left"):
            self.relate(e, "crossing_path", ego)

    def _occluders_ahead(self, ego: Optional[Entity]) -> None:
        """An actor something emerges from behind is ahead of the ego, on the emerging actor's side; the one that
        emerges is no longer behind it."""
        for e in self.out.entities:
            occluder = e.attrs.get("from_behind")
            if ego is None or occluder is None or occluder is ego or e is ego:
                continue
            self.relate(occluder, "ahead_of", ego)
            for rel, j in list(e.relations):
                if j is ego and rel in (Relation.LEFT_OF, Relation.RIGHT_OF):
                    self.relate(occluder, rel, ego)
            e.relations = [(r, j) for r, j in e.relations if not (r == Relation.BEHIND and j is occluder)]

    def _cross_traffic(self, ego: Optional[Entity]) -> None:
        """Cross traffic at a junction: a vehicle from the left or right, not oncoming, not changing lanes, not
        joining the ego's way by a right turn, crosses the ego's path; so does an oncoming one turning left
        when the ego does not."""
        if ego is None or self.out.road not in (Road.INTERSECTION, Road.T_JUNCTION, Road.THREE_WAY, Road.ROUNDABOUT):
            return
        for e in self.out.entities:
            if e is ego or e.kind not in MOTOR + (ActorKind.BICYCLE,):
                continue
            rels = {r for r, j in e.relations if j is ego}
            lane_moves = ("cut_in", "lane_change", "lane_change_left", "lane_change_right", "overtake", "merge")
            joins = Relation.RIGHT_OF in rels and e.has("turn_right")  # a right turn from the right joins the ego's way
            if rels & {Relation.LEFT_OF, Relation.RIGHT_OF} and Relation.ONCOMING not in rels \
                    and not any(e.has(a) for a in lane_moves) and not joins \
                    and (e.attrs.get("side_road") or any(e.has(a) for a in ("go_straight", "turn_left",
                                                                              "turn_right", "collide"))
                         or not e.actions):
                self.relate(e, "crossing_path", ego)
            if Relation.ONCOMING in rels and e.has("turn_left") and not ego.has("turn_left"):
                self.relate(e, "crossing_path", ego)
