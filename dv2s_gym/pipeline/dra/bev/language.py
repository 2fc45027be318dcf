"""Language: the three-sentence description (and answer) written from the analysis so that
:func:`dv2s_gym.pipeline.semantics.text.elements_from_text` reads the same elements back."""

from __future__ import annotations

import re
from typing import Any, Dict, List, Optional, Tuple

__all__ = ["ROAD_PHRASES", "ROAD_SCENES"]


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


# Every template below reads back, through dv2s_gym.pipeline.semantics.text.elements_from_text, as the
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
        # "waits" reads as a stop: only a pedestrian seen standing still is said to wait
        return f"{art} {noun} {verb('waits', 'wait') if 'stop' in acts else verb('is', 'are')}{at}"
    if "merge" in acts:
        if side and "ahead_of" not in rels and "behind" not in rels:
            return join(f"{art} {noun} from the on-ramp {verb('merges', 'merge')} into the lane next to {ref} "
                        f"on {poss} {side}", extra)
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
            if "crossing_path" in rels:
                main += f" and {verb('crosses', 'cross')} the ego's path"
        elif "keep_lane" in acts:
            main = f"{verb('keeps', 'keep')} to its lane and {verb('passes', 'pass')} by on the other side"
        else:
            main = f"{verb('passes', 'pass')} by in the other lane"
        return join(f"{head} {main}", extra)
    if "crossing_path" in rels and actor.get("notes", {}).get("ring_ahead") and not {"turn_left", "turn_right"} & acts:
        return join(f"{art} {noun} circling the roundabout {verb('crosses', 'cross')} the ego's path ahead of {ref}",
                    extra)
    if "crossing_path" in rels:
        then = (f"{verb('turns', 'turn')} {'left' if 'turn_left' in acts else 'right'}"
                if {"turn_left", "turn_right"} & acts else f"{verb('goes', 'go')} straight on")
        return join(f"{art} {noun} {verb('crosses', 'cross')} the ego's path and {then}", extra)
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
    if actor.get("notes", {}).get("slower_lead") and acts == {"keep_lane"} and "ahead_of" in rels:
        return (f"{'a' if not plural else n} slower {noun} ahead of {ref} in the same lane "
                f"{verb('keeps', 'keep')} to {verb('its', 'their')} lane")
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
        if "overtake" in ego_acts:
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
