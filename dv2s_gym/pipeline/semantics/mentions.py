"""Actor mentions in a clause of a description: the noun phrases, the ego, groups and pronouns the description
parser (:mod:`dv2s_gym.pipeline.semantics.text`) resolves to entities, and the helpers that read around them."""

from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Dict, List, Optional, Tuple

from dv2s_gym.pipeline.semantics.lexicon import (
    NUMBERS,
    NOUNS,
    EGO,
    NOT_ACTOR_AFTER,
    COLORS,
    ORDINALS,
    MOTOR,
    PLACE_NOUNS,
    NEGATION,
    CROSS_DIR,
    CROSS_FROM,
    PREPOSITIONS,
)
from dv2s_gym.pipeline.semantics.parsed import Entity, Lane
from scenario_bank.elements import Action, ActorKind, Relation

__all__ = [
    "Mention",
    "normalize",
    "NOUN_RE",
    "EGO_RE",
    "action_window",
    "crossing_direction",
    "cut_in_side_from_relations",
    "cut_in_lane_changes",
    "MentionReader",
]


@dataclass
class Mention:
    start: int
    end: int
    entity: Entity
    prep_object: bool
    possessive: bool
    pronoun: bool = False
    size: Optional[int] = None


def normalize(text: str) -> str:
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


NOUN_RE = _noun_regex()
EGO_RE = re.compile(r"\b" + EGO + r"\b")
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
        if Relation.CROSSING_PATH not in pending:
            pending.append("crossing_path")  # "a crossing vehicle" crosses the ego's path
    # adjectives of state before the noun: stopped car, parked truck, broken down car
    if entity.kind not in (ActorKind.EGO, ActorKind.OBSTACLE) and re.search(
            r"\b(?:stopped|stationary|broken down|stalled|standing|disabled|idle|halted)\s+"
            r"(?:\w+\s+)?$", before):
        if not NEGATION.search(before):
            entity.add_action("stop")


def action_window(clause: str, m: re.Match) -> str:
    """The words around an action phrase (30 characters before it, 25 after) that say "suddenly" or "unprotected"."""
    return clause[max(0, m.start() - 30):m.end() + 25]


def crossing_direction(clause: str, groups: Dict[str, Optional[str]]) -> Optional[str]:
    """The way a pedestrian crosses: "from left to right" in the clause, the side the phrase says it comes from
    ("from the left": left to right), "from the far side", else None."""
    dm = CROSS_DIR.search(clause)
    if dm:
        return f"{dm.group('from')}_to_{dm.group('to')}"
    if groups.get("from"):
        return f"{groups['from']}_to_{'right' if groups['from'] == Lane.LEFT else 'left'}"
    fm = CROSS_FROM.search(clause)
    if fm and (fm.group("from") or fm.group("from2")) in (Lane.LEFT, Lane.RIGHT):
        f = fm.group("from") or fm.group("from2")
        return f"{f}_to_{'right' if f == Lane.LEFT else 'left'}"
    if fm and (fm.group("from") in ("far", "other", "opposite")):
        return "far_side"
    return None


def cut_in_side_from_relations(e: Entity) -> None:
    """A cut-in with no side said comes from the side ``e`` is on (the last of its left/right relations)."""
    if e.has("cut_in") and not e.detail("cut_in").get("side"):
        for rel, j in e.relations:
            if rel in (Relation.LEFT_OF, Relation.RIGHT_OF):
                e.detail("cut_in")["side"] = rel.split("_")[0]


def cut_in_lane_changes(e: Entity, rels: set) -> None:
    """The lane changes a cut-in makes: a merge ahead of the ego is a cut-in; an overtake said as "passes" and
    a cut-in that is no pulling back are one cut-in; pulling back after an overtake is out and back; a cut-in
    from a side changes lanes toward the other."""
    if e.has("merge") and Relation.AHEAD_OF in rels and not e.has("cut_in"):
        e.add_action("cut_in")
    if e.has("cut_in") and e.has("overtake") and e.detail("overtake").get("via_pass") \
            and not e.detail("cut_in").get("back"):
        e.actions = [(a, d) for a, d in e.actions if a != Action.OVERTAKE]
    if e.has("cut_in"):
        side = e.detail("cut_in").get("side") or ("left" if Relation.LEFT_OF in rels else
                                                  "right" if Relation.RIGHT_OF in rels else None)
        if e.has("overtake") and e.detail("cut_in").get("back"):
            out_side = e.detail("overtake").get("side") or "left"
            back_side = "right" if out_side == Lane.LEFT else "left"
            e.add_action(f"lane_change_{out_side}")
            e.add_action(f"lane_change_{back_side}")
        elif side in (Lane.LEFT, Lane.RIGHT) and not e.has("merge"):
            e.add_action(f"lane_change_{'right' if side == Lane.LEFT else 'left'}")


class MentionReader:
    """The description parser's actor mentions: nouns, the ego, "another", groups and pronouns resolved
    to the entities of the scene (mixed into the parser of :mod:`dv2s_gym.pipeline.semantics.text`)."""

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
        self.mention_order += 1
        entity.attrs["sentence"] = self.sentence_index
        entity.attrs["order"] = self.mention_order
        self.out.entities.append(entity)
        return entity

    def touch(self, entity: Entity) -> None:
        if entity in self.recent:
            self.recent.remove(entity)
        self.recent.append(entity)
        if entity.count > 1:
            self.last_group = entity

    # ---------------------------------------------------------------- mentions
    def find_mentions(self, clause: str, base_subject: Optional[Entity]) -> List[Mention]:
        """The actor mentions of a clause, in text order: the ego, nouns, "another", group references and
        pronouns (a pronoun the clause subject resolves is left ``("pending", start)``); each span is read once."""
        mentions: List[Mention] = []
        taken: List[Tuple[int, int]] = []
        self._ego_mentions(clause, mentions, taken)
        for m in NOUN_RE.finditer(clause):
            if _free(taken, m.start(), m.end()):
                self._noun_mention(clause, m, mentions, taken)
        self._another_mentions(clause, mentions, taken)
        self._group_mentions(clause, mentions, taken)
        self._pronoun_mentions(clause, base_subject, mentions, taken)
        mentions.sort(key=lambda mm: mm.start)
        return mentions

    def _ego_mentions(self, clause: str, mentions: List[Mention], taken: List[Tuple[int, int]]) -> None:
        """The ego named in the clause ("the ego vehicle", "our car", "us"): its mentions and its noun."""
        for m in EGO_RE.finditer(clause):
            if not _free(taken, m.start(), m.end()):
                continue
            possessive = m.group(0).endswith("'s") or clause[m.end():m.end() + 2] == "'s"
            taken.append((m.start(), m.end()))
            ego_entity = self._entity_for("ego", 1, True, set(), False)
            self.mention_log.append((self.sentence_index, len(self.mention_log), ego_entity))
            ego_entity.attrs.setdefault("noun", re.sub(r"^(?:the|an|a|our|my) |'s$", "", m.group(0)))
            mentions.append(Mention(m.start(), m.end(), ego_entity,
                                     _prep_before(clause, m.start()) or m.group(0) == "us", possessive))

    def _noun_mention(self, clause: str, m: re.Match, mentions: List[Mention], taken: List[Tuple[int, int]]) -> None:
        """One actor noun: the entity it names (new or known), what the words around it say of that entity."""
        phrase = _noun_phrase(clause, m)
        if phrase.kind == ActorKind.OBSTACLE and re.search(r"'s\s+(?:\w+\s+)?$", clause[:m.start()]):
            return  # "the ego vehicle's tire": a part of a vehicle, not an obstacle
        if self._names_the_ego_vehicle(clause, m, phrase):
            mentions.append(Mention(m.start(), m.end(), self.out.ego, _prep_before(clause, m.start()), False))
            taken.append((m.start(), m.end()))
            return  # "the test vehicle ... the vehicle approaches": the ego
        entity = self._noun_entity(clause, m, phrase)
        possessive = m.group(0).endswith("'s") or m.group(0).endswith("s'")
        taken.append((m.start(), m.end()))
        entity.attrs.setdefault("noun", phrase.surface)
        if phrase.kind == ActorKind.OBSTACLE and re.fullmatch(r"(?:deer|animals?|dogs?|cats?|cows?|horses?|moose|sheep|"
                                                      r"birds?|elks?|kangaroos?|fox|boar|wild boar)", phrase.surface):
            entity.attrs["animal"] = True
        self.mention_log.append((self.sentence_index, len(self.mention_log), entity))
        if phrase.kind == ActorKind.CAR and phrase.surface in ("vehicles", "vehicle") and \
                (phrase.count > 1 or re.match(r"\s*(?:crash|collision|pile ?up|accident)", clause[m.end():])):
            entity.attrs["generic"] = True
        mentions.append(Mention(m.start(), m.end(), entity, _prep_before(clause, m.start()), possessive))
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
            entity = self.named_entities.get(key)
            if entity is None:
                entity = self.named_entities[key] = self._new("car", 1, {key})
            return entity
        if phrase.kind == ActorKind.CAR and self._is_ego_alias(clause, m.start()):
            return self._entity_for("ego", 1, True, set(), False)
        if phrase.plural and phrase.definite and self.last_group is not None and self.last_group.kind == phrase.kind:
            return self.last_group
        entity = self._entity_for(phrase.kind, phrase.count, phrase.definite, phrase.descriptors, phrase.new)
        if phrase.plural and entity.count < phrase.count:
            entity.count = phrase.count
        return entity

    def _another_mentions(self, clause: str, mentions: List[Mention], taken: List[Tuple[int, int]]) -> None:
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
            self.mention_log.append((self.sentence_index, len(self.mention_log), entity))
            mentions.append(Mention(m.start(), m.end(), entity, _prep_before(clause, m.start()), False))

    def _group_mentions(self, clause: str, mentions: List[Mention], taken: List[Tuple[int, int]]) -> None:
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
            mentions.append(Mention(m.start(), m.end(), self.last_group, False, False, pronoun=True, size=size))

    def _pronoun_mentions(self, clause: str, base_subject: Optional[Entity], mentions: List[Mention],
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
            mentions.append(Mention(m.start(), m.end(), entity, objective, possessive, pronoun=True))

    def _is_ego_alias(self, clause: str, start: int) -> bool:
        return bool(re.search(r"\b(?:ego|our|my|host|subject)\s+$", clause[:start]))
