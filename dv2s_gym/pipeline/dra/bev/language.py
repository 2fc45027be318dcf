"""Language: the three-sentence description (and answer) written from the analysis so that
:func:`dv2s_gym.pipeline.semantics.text.elements_from_text` reads the same elements back."""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any, Dict, List, Optional, Tuple

from scenario_bank.elements import Action, ActorKind, Relation, Road

__all__ = ["ROAD_PHRASES", "ROAD_SCENES"]


ROAD_PHRASES = {
    Road.HIGHWAY: "a straight multi-lane highway",
    Road.STRAIGHT_ROAD: "a two-way urban street",
    Road.INTERSECTION: "a four-way urban intersection",
    Road.T_JUNCTION: "an urban T-junction",
    Road.THREE_WAY: "a three-way junction",
    Road.ROUNDABOUT: "a roundabout",
    Road.MERGE: "a highway with an on-ramp",
}


ROAD_SCENES = {
    Road.HIGHWAY: "on a highway",
    Road.STRAIGHT_ROAD: "on a two-way urban street",
    Road.INTERSECTION: "at a four-way urban intersection",
    Road.T_JUNCTION: "at an urban T-junction",
    Road.THREE_WAY: "at a three-way junction",
    Road.ROUNDABOUT: "at a roundabout",
    Road.MERGE: "on a highway where an on-ramp joins",
}


# Every template below reads back, through dv2s_gym.pipeline.semantics.text.elements_from_text, as the
# elements the analysis produced (the pipeline parses the description text).
_COUNT = {1: "a", 2: "two", 3: "three", 4: "four", 5: "five", 6: "six", 7: "seven", 8: "eight"}


def _noun(kind: str, count: int = 1) -> str:
    if count == 1:
        return kind
    return {ActorKind.PEDESTRIAN: "pedestrians", ActorKind.OBSTACLE: "obstacles", ActorKind.TRUCK: "trucks"}.get(kind, kind + "s")


@dataclass
class _Words:
    """The words the clause templates of one group of identical actors share."""

    kind: str
    acts: set
    rels: set
    ref: str
    """The ego: "it" or "the ego car"."""
    poss: str
    """The ego's: "its" or "the ego car's"."""
    lane: str
    """The ego's lane: "its lane" or "the ego's lane"."""
    plural: bool
    n: str
    """The count in words ("two")."""
    noun: str
    art: str
    """"a"/"an", or the count of a group."""
    side: Optional[str]
    """The side of the ego the actor is on ("left", "right"), if any."""
    at: str
    """Where the actor is relative to the ego (" ahead of it on its left"), or ""."""
    extra: List[str]
    """What it does besides its main action ("suddenly brakes", "accelerates", "stands still", "crashes")."""

    def verb(self, singular: str, plural_form: str) -> str:
        """The verb form for the group's number."""
        return plural_form if self.plural else singular

    def join(self, head: str) -> str:
        """``head`` and what the actor does besides."""
        return " and ".join([head] + self.extra)


def _words(actor: Dict[str, Any], count: int, ref: str) -> _Words:
    """The shared words for ``count`` identical actors like ``actor``; ``ref`` names the ego."""
    kind, acts, rels = actor["kind"], actor["actions"], actor["relations"]
    plural = count > 1
    n = _COUNT.get(count, str(count))
    poss = "its" if ref == "it" else "the ego car's"
    side = "left" if Relation.LEFT_OF in rels else "right" if Relation.RIGHT_OF in rels else None
    where = []
    if Relation.AHEAD_OF in rels:
        where.append(f"ahead of {ref}")
    if Relation.BEHIND in rels:
        where.append(f"behind {ref}")
    if side:
        where.append(f"on {poss} {side}")
    words = _Words(kind=kind, acts=acts, rels=rels, ref=ref, poss=poss,
                   lane="its lane" if ref == "it" else "the ego's lane", plural=plural, n=n,
                   noun=_noun(kind, count), art=("an" if kind[0] in "aeiou" else "a") if not plural else n,
                   side=side, at=(" " + " ".join(where)) if where else "", extra=[])
    if Action.BRAKE in acts:
        words.extra.append(words.verb("suddenly brakes", "suddenly brake"))
    if Action.ACCELERATE in acts:
        words.extra.append(words.verb("accelerates", "accelerate"))
    if Action.STOP in acts:
        words.extra.append(words.verb("stands still", "stand still"))
    if Action.COLLIDE in acts and not actor.get("hits_ego"):
        words.extra.append(words.verb("crashes", "crash"))
    return words


def _obstacle_clause(actor: Dict[str, Any], w: _Words) -> Optional[str]:
    """An obstacle lies in the ego's lane ahead, or where it is."""
    if w.kind != ActorKind.OBSTACLE:
        return None
    if Relation.SAME_LANE in w.rels:
        return f"{w.art} {w.noun} {w.verb('lies', 'lie')} in the ego's lane ahead"
    return f"{w.art} {w.noun} {w.verb('lies', 'lie')}{w.at}"


def _pedestrian_clause(actor: Dict[str, Any], w: _Words) -> Optional[str]:
    """A pedestrian crosses in front of the ego, waits (only when seen standing still: "waits" reads as a stop)
    or is where it is."""
    if w.kind != ActorKind.PEDESTRIAN:
        return None
    if Action.CROSS in w.acts:
        return f"{w.art} {w.noun} {w.verb('crosses', 'cross')} the road in front of {w.ref}"
    return f"{w.art} {w.noun} {w.verb('waits', 'wait') if Action.STOP in w.acts else w.verb('is', 'are')}{w.at}"


def _merge_clause(actor: Dict[str, Any], w: _Words) -> Optional[str]:
    """A vehicle from the on-ramp merges: into the lane beside the ego, in front of it, or behind it."""
    if Action.MERGE not in w.acts:
        return None
    head = f"{w.art} {w.noun} from the on-ramp {w.verb('merges', 'merge')}"
    if w.side and Relation.AHEAD_OF not in w.rels and Relation.BEHIND not in w.rels:
        return w.join(f"{head} into the lane next to {w.ref} on {w.poss} {w.side}")
    if Relation.AHEAD_OF in w.rels:
        return w.join(f"{head} into the lane in front of {w.ref}")
    return w.join(f"{head} onto the highway behind {w.ref}")


def _cut_in_clause(actor: Dict[str, Any], w: _Words) -> Optional[str]:
    """A cut-in just ahead of the ego: after overtaking it, or from the lane on a side."""
    if Action.CUT_IN not in w.acts:
        return None
    if Action.OVERTAKE in w.acts:
        return w.join(f"a faster {w.noun} {w.verb('overtakes', 'overtake')} the ego car and "
                      f"{w.verb('pulls', 'pull')} back into the ego's lane just ahead of {w.ref}")
    origin = f" in the lane to the {w.side} of the ego car" if w.side else ""
    return w.join(f"{w.art} {w.noun}{origin} {w.verb('cuts', 'cut')} into the ego's lane just ahead of {w.ref}")


def _oncoming_clause(actor: Dict[str, Any], w: _Words) -> Optional[str]:
    """Oncoming traffic: drifts across the centre line, goes straight, turns (across the ego's path), keeps to its
    lane, or passes by."""
    if Relation.ONCOMING not in w.rels:
        return None
    head = f"{'an' if not w.plural else w.n} oncoming {w.noun}"
    if Action.DRIFT in w.acts:
        main = f"{w.verb('drifts', 'drift')} across the centre line into the ego's lane"
    elif Action.GO_STRAIGHT in w.acts:
        main = f"{w.verb('goes', 'go')} straight on"
    elif Action.TURN_LEFT in w.acts or Action.TURN_RIGHT in w.acts:
        main = f"{w.verb('turns', 'turn')} {'left' if Action.TURN_LEFT in w.acts else 'right'}"
        if Relation.CROSSING_PATH in w.rels:
            main += f" and {w.verb('crosses', 'cross')} the ego's path"
    elif Action.KEEP_LANE in w.acts:
        main = f"{w.verb('keeps', 'keep')} to its lane and {w.verb('passes', 'pass')} by on the other side"
    else:
        main = f"{w.verb('passes', 'pass')} by in the other lane"
    return w.join(f"{head} {main}")


def _crossing_path_clause(actor: Dict[str, Any], w: _Words) -> Optional[str]:
    """Traffic across the ego's path: circling a roundabout ahead, else crossing and turning or going straight."""
    if Relation.CROSSING_PATH not in w.rels:
        return None
    turns = {Action.TURN_LEFT, Action.TURN_RIGHT} & w.acts
    if actor.get("notes", {}).get("ring_ahead") and not turns:
        return w.join(f"{w.art} {w.noun} circling the roundabout {w.verb('crosses', 'cross')} the ego's path ahead "
                      f"of {w.ref}")
    then = (f"{w.verb('turns', 'turn')} {'left' if Action.TURN_LEFT in w.acts else 'right'}"
            if turns else f"{w.verb('goes', 'go')} straight on")
    return w.join(f"{w.art} {w.noun} {w.verb('crosses', 'cross')} the ego's path and {then}")


def _turn_clause(actor: Dict[str, Any], w: _Words) -> Optional[str]:
    """A turn, from the side road on a side of the ego, into the ego's lane when it ends up ahead."""
    if Action.TURN_LEFT not in w.acts and Action.TURN_RIGHT not in w.acts:
        return None
    d = "left" if Action.TURN_LEFT in w.acts else "right"
    origin = f" from the side road on {w.poss} {w.side}" if w.side else ""
    into = f" into the ego's lane just ahead of {w.ref}" if Relation.AHEAD_OF in w.rels else ""
    return w.join(f"{w.art} {w.noun}{origin} {w.verb('turns', 'turn')} {d}{into}")


def _alongside_clause(actor: Dict[str, Any], w: _Words) -> Optional[str]:
    """A vehicle keeping its lane on a side of the ego drives alongside it."""
    if Action.KEEP_LANE not in w.acts or not w.side:
        return None
    return f"{w.art} {w.noun} {w.verb('drives', 'drive')} alongside the ego car in the lane to {w.poss} {w.side}"


def _parked_clause(actor: Dict[str, Any], w: _Words) -> Optional[str]:
    """A parked vehicle is parked where it is (relative to "the ego car", whatever the reference)."""
    if not actor.get("notes", {}).get("parked"):
        return None
    where = w.at.replace(f"ahead of {w.ref}", "ahead of the ego car").replace(f"behind {w.ref}", "behind the ego car")
    return f"{w.art} {w.noun} {w.verb('is', 'are')} parked{where}"


def _slower_lead_clause(actor: Dict[str, Any], w: _Words) -> Optional[str]:
    """A slower vehicle ahead in the ego's lane that only keeps its lane."""
    if not (actor.get("notes", {}).get("slower_lead") and w.acts == {Action.KEEP_LANE} and Relation.AHEAD_OF in w.rels):
        return None
    return (f"{'a' if not w.plural else w.n} slower {w.noun} ahead of {w.ref} in the same lane "
            f"{w.verb('keeps', 'keep')} to {w.verb('its', 'their')} lane")


def _standing_clause(actor: Dict[str, Any], w: _Words) -> Optional[str]:
    """A vehicle that only stands still ahead in the ego's lane."""
    if not (Relation.SAME_LANE in w.rels and w.acts == {Action.STOP} and Relation.AHEAD_OF in w.rels):
        return None
    return f"{w.art} {w.noun} {w.verb('stands', 'stand')} still in {w.lane} ahead"


_CLAUSE_RULES = (_obstacle_clause, _pedestrian_clause, _merge_clause, _cut_in_clause, _oncoming_clause,
                 _crossing_path_clause, _turn_clause, _alongside_clause, _parked_clause, _slower_lead_clause,
                 _standing_clause)
"""The clause templates of the cases, in order: the first that applies to an actor writes its clause."""


def _moves_clause(actor: Dict[str, Any], w: _Words) -> str:
    """Any other vehicle: where it is (in the same lane ahead of or behind the ego, else as placed) and what it
    does: lane changes, overtaking, going straight, drifting, braking...; else it follows or drives on."""
    at = f" {'ahead of' if Relation.AHEAD_OF in w.rels else 'behind'} {w.ref} in the same lane" if Relation.SAME_LANE in w.rels \
        else w.at
    main: List[str] = []
    if Action.LANE_CHANGE_LEFT in w.acts and Action.LANE_CHANGE_RIGHT in w.acts:
        main.append(f"{w.verb('changes', 'change')} to the left lane and back to the right lane")
    elif Action.LANE_CHANGE_LEFT in w.acts:
        main.append(f"{w.verb('changes', 'change')} to the left lane")
    elif Action.LANE_CHANGE_RIGHT in w.acts:
        main.append(f"{w.verb('changes', 'change')} to the right lane")
    if Action.OVERTAKE in w.acts:
        main.append(f"{w.verb('overtakes', 'overtake')} the ego car")
    if Action.GO_STRAIGHT in w.acts:
        main.append(f"{w.verb('goes', 'go')} straight on")
    if Action.DRIFT in w.acts:
        main.append(f"{w.verb('drifts', 'drift')} across the centre line")
    main += w.extra
    if not main:
        main.append(w.verb("follows", "follow") if Relation.BEHIND in w.rels and Relation.SAME_LANE in w.rels
                    else w.verb("drives on", "drive on"))
    return f"{w.art} {w.noun}{at} " + " and ".join(main)


def _clause(actor: Dict[str, Any], count: int, ref: str) -> str:
    """Subject and predicate for ``count`` identical actors; ``ref`` names the ego ("it" or "the ego car")."""
    w = _words(actor, count, ref)
    for rule in _CLAUSE_RULES:
        clause = rule(actor, w)
        if clause is not None:
            return clause
    return _moves_clause(actor, w)


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
    if Action.TURN_LEFT in ego_acts or Action.TURN_RIGHT in ego_acts:
        first = f"The ego car turns {'left' if Action.TURN_LEFT in ego_acts else 'right'} at {place}"
    elif Action.GO_STRAIGHT in ego_acts:
        first = f"The ego car goes straight through {place}"
    elif Action.LANE_CHANGE_LEFT in ego_acts or Action.LANE_CHANGE_RIGHT in ego_acts:
        first = f"The ego car changes to the {'left' if Action.LANE_CHANGE_LEFT in ego_acts else 'right'} lane of {place}"
        if Action.OVERTAKE in ego_acts:
            first += " and overtakes"
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
    key.sort(key=lambda a: (-len(a["actions"] - {Action.GO_STRAIGHT, Action.KEEP_LANE, Action.COLLIDE}),
                            Action.KEEP_LANE in a["actions"], a["min_dist"]))
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
        if Action.COLLIDE in ego_acts:
            sentences.append(f"The ego car collides with the {partner['kind']}.")
    elif Action.COLLIDE in ego_acts:
        sentences.append("The ego car crashes.")
    if not key and not traffic:
        sentences.append("No other road user comes near the ego car.")
    sentences.append(f"This scene takes place {ROAD_SCENES.get(road or '', 'on a road')}.")
    return " ".join(sentences)


def _answer(question: str, road, ego_acts: set, ego_react: set, actors: List[Dict[str, Any]]) -> Optional[str]:
    """A one-sentence answer to a question about the clip, when the analysis can give one."""
    q = question.lower()
    key = sorted([a for a in actors if a["role"] == "key"], key=lambda a: a["min_dist"])
    cause = next((a for a in key if a["actions"] & {Action.BRAKE, Action.STOP, Action.CUT_IN, Action.MERGE, Action.CROSS, Action.DRIFT}
                  or a["lead"] or a["kind"] in (ActorKind.OBSTACLE, ActorKind.PEDESTRIAN)), None)
    if cause is None:   # yielding: to oncoming traffic when turning, to traffic crossing its path
        cause = next((a for a in key if a["relations"] & {Relation.ONCOMING, Relation.CROSSING_PATH}), None)
    if re.search(r"\b(why|cause|reason)\b", q) and re.search(r"(brak|slow|stop|decelerat|yield|wait|halt)", q):
        if not ego_react & {Action.BRAKE, Action.STOP}:
            return "The ego car does not visibly brake in this video."
        if cause is None:
            return "The ego car brakes, but no other road user in view explains it."
        yielding = cause["kind"] in (ActorKind.CAR, ActorKind.TRUCK) and not (
            cause["actions"] & {Action.BRAKE, Action.STOP, Action.CUT_IN, Action.MERGE, Action.DRIFT} or cause["lead"])
        if yielding and Relation.ONCOMING in cause["relations"] and (Action.TURN_LEFT in ego_acts or Action.TURN_RIGHT in ego_acts):
            return "The ego car brakes to yield to the oncoming traffic before it turns."
        if yielding and Relation.CROSSING_PATH in cause["relations"]:
            return "The ego car brakes to yield to the traffic crossing its path."
        return f"The ego car brakes because {_definite(_clause(cause, 1, 'the ego car'))}."
    if re.search(r"(collid|crash|accident|\bhit)", q):
        if Action.COLLIDE in ego_acts:
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
        if Action.TURN_LEFT in ego_acts:
            return "The ego car turns left."
        if Action.TURN_RIGHT in ego_acts:
            return "The ego car turns right."
        return "The ego car does not turn."
    if re.search(r"\b(road|where|location|place|kind of)\b", q):
        return f"The scene takes place {ROAD_SCENES.get(road or '', 'on a road')}."
    if re.search(r"\b(what|happen|describe|event)\b", q) and key:
        return f"The key event: {_definite(_clause(key[0], 1, 'the ego car'))}."
    return None
