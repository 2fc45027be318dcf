"""Sentences and clauses of a description read by the description parser
(:mod:`dv2s_gym.pipeline.semantics.text`): subjects, lanes, relations and which actor each action phrase belongs to."""

from __future__ import annotations

import re
from typing import Any, List, Optional, Tuple

from dv2s_gym.pipeline.semantics.lexicon import (
    NUMBERS,
    EGO,
    UNKNOWN_ACTORS,
    COLORS,
    ORDINALS,
    ROAD_PATTERNS,
    COMPILED_ACTIONS,
    FRONTED,
    NEUTRAL_WORDS,
    ON_RAMP,
    REL_PATTERNS,
    REL_IMPLICIT,
    LANE_POS,
    LANE_WORD,
    CROSS_DIR,
    CLAUSE_SPLIT,
    SENTENCE_SPLIT,
    DETERMINER_OR_NOUN,
)
from dv2s_gym.pipeline.semantics.mentions import Mention, NOUN_RE, EGO_RE
from dv2s_gym.pipeline.semantics.parsed import Entity, NO_JUNCTION_WORDS, ParsedDescription
from dv2s_gym.pipeline.semantics.road import distance_m, road_features, speed_kph, strip_absences, time_s
from scenario_bank.elements import Action, ActorKind, Relation, Road

__all__ = ["ClauseReader"]


class ClauseReader:
    """The description parser's reading of sentences and clauses: subjects, lanes, relations and the
    attribution of action phrases (mixed into the parser of :mod:`dv2s_gym.pipeline.semantics.text`)."""

    # ---------------------------------------------------------------- main
    def parse(self) -> ParsedDescription:
        text, absent, no_junction, removed = strip_absences(self.text)
        self.text = text
        self.out.absent = absent
        self.out.absent_phrases = [r for r in removed if not NO_JUNCTION_WORDS.search(r)]
        for road, pattern in ROAD_PATTERNS:
            if road == Road.MERGE and re.search(r"\b(?:off ramp|exit ramp|offramp)\b", text) and not re.search(
                    r"\b(?:on ramp|onramp|entry ramp|entrance ramp|acceleration lane)\b", text):
                continue  # leaving the motorway: the road is the motorway
            if road == Road.MERGE and not ON_RAMP.search(text) and re.search(
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
                self.sentence_index += 1
        self.finish()
        self._counts_add_up()
        kph = speed_kph(text)
        if kph is not None and self.out.ego is not None and "speed_kph" not in self.out.ego.attrs:
            self.out.ego.attrs["speed_kph"] = kph
        seen = set()
        for phrase in self.unplaced_phrases:
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
        vehicles = (ActorKind.EGO, ActorKind.CAR, ActorKind.TRUCK, ActorKind.BUS, ActorKind.MOTORCYCLE, ActorKind.BICYCLE)
        for group in [e for e in self.out.entities if e.attrs.get("generic")]:
            if group.actions or group.relations or any(j is group for e in self.out.entities for _, j in e.relations):
                continue
            first = next(((s, i) for s, i, e in self.mention_log if e is group), None)
            if first is None:
                continue
            later: List[Entity] = []
            for s, i, e in self.mention_log:
                if s == first[0] and i > first[1] and e is not group and e.kind in vehicles and \
                        all(e is not x for x in later):
                    later.append(e)
            named_later = sum(e.count for e in later)
            if later and named_later >= group.count and any(e.kind != ActorKind.EGO for e in later):
                self.out.entities = [e for e in self.out.entities if e is not group]

    def _sentence(self, sentence: str) -> None:
        self.sentence_text = sentence
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
                self.unplaced_phrases.append(clause)
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
        nm = NOUN_RE.search(clause)
        if nm is None:
            return False
        group = next(k for k, v in nm.groupdict().items() if v)
        kind = group.split("_")[0]
        key = re.sub(r"vehicle ", "v", named.group(0).replace(" ", ""))
        entity = self.out.ego if key in ("v1", "ego", "theego", "theav", "thesubjectvehicle") else self.named_entities.get(key)
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
        if not (NOUN_RE.search(clause) or EGO_RE.search(clause)):
            return False
        if any(rx.search(clause) for _, rx in COMPILED_ACTIONS):
            return False
        rest = NOUN_RE.sub(" ", EGO_RE.sub(" ", clause))
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
                len(self.unplaced_phrases), self.negated, self.placed_count)

    def _said_elsewhere(self, clause: str) -> bool:
        """A clause that adds nothing new is still placed when it only names the road, a known actor with a
        neutral verb (drives, approaches, is present), or filler."""
        if road_features(clause, self.out.road) or "nothing" in clause.split():
            return True  # a road fact, or an absence ("no other vehicles are involved")
        rest = NOUN_RE.sub(" ", EGO_RE.sub(" ", clause))
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
        mentions = self.find_mentions(clause, inherited)
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
        self.read_actions(clause, mentions, subject)
        self.coordinated_subjects(clause, mentions, subject, before_actions)
        self._done_by_all(clause, subject, before_actions)
        real = [mm for mm in mentions if not isinstance(mm.entity, tuple)]
        if real:
            self.last_mentioned = real[-1].entity
        self._clause_speed(clause, mentions, subject)
        self._crossing_directions(clause, mentions, subject)
        return subject

    @staticmethod
    def _said_subject(clause: str, mentions: List[Mention], body_start: int) -> Optional[Entity]:
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
        verb_first = bool(re.fullmatch(r"[a-z]+(?:s|ed|ing)", first)) and not NOUN_RE.fullmatch(first) \
            and first not in ("this", "his", "its", "as", "is", "was", "has", "does", "thus", "always")
        if subordinate and self.last_mentioned is not None:
            return self.last_mentioned
        if subordinate or verb_first or not DETERMINER_OR_NOUN.search(head) or \
                re.match(r"\s*(?:it|they|he|she)\b", head):
            return inherited
        return None

    def _resolved_mentions(self, mentions: List[Mention], subject: Optional[Entity]) -> List[Mention]:
        """The clause's mentions with their pending pronouns resolved (an object pronoun is the last other
        actor mentioned, else the subject; one left unresolved is dropped); every actor mentioned, and the
        subject, becomes the most recent."""
        for mm in mentions:
            if isinstance(mm.entity, tuple):
                mm.entity = self._other_than(subject) or subject
        mentions = [mm for mm in mentions if mm.entity is not None]
        for mm in mentions:
            self.touch(mm.entity)
        if subject is not None:
            self.touch(subject)
        return mentions

    def _ahead_until_reached(self, clause: str, inherited: Optional[Entity]) -> None:
        """"... before the ego reaches it": the actor of the clause before is ahead of the ego."""
        if inherited is not None and inherited.kind != ActorKind.EGO and \
                re.match(r"before (?:the ego(?: car| vehicle)?|it) (?:reaches|catches up with|gets to) (?:it|them)\b",
                         clause):
            ego = self.out.ego
            if ego is not None:
                self.relate(inherited, "ahead_of", ego)

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
        self.placed_count += 1
        return True

    def _done_by_all(self, clause: str, subject: Optional[Entity], before_actions: List[str]) -> None:
        """"A car in the left lane and another in the right lane both cut in": every actor of the subject's kind
        named in the sentence does what the clause gave the subject (without its side or partner)."""
        if subject is None or not re.search(r"\b(?:both|all of them|each of them|all three|both of them)\b", clause):
            return
        new = [(a, d) for a, d in subject.actions if a not in before_actions]
        same = [e for s_, _, e in self.mention_log if s_ == self.sentence_index and e.kind == subject.kind
                and e is not subject]
        for e in same:
            for a, d in new:
                if a.startswith("lane_change") or a == Action.CUT_IN:
                    e.add_action(a, **{k: v for k, v in d.items() if k not in ("side", "with")})
                else:
                    e.add_action(a, **{k: v for k, v in d.items() if k != "with"})

    @staticmethod
    def _clause_speed(clause: str, mentions: List[Mention], subject: Optional[Entity]) -> None:
        """A speed said in the clause belongs to its subject (else the first actor that is no preposition's
        object) and to the actions it has."""
        kph = speed_kph(clause)
        if kph is not None:
            owner = subject or next((mm.entity for mm in mentions if not mm.prep_object), None)
            if owner is not None:
                owner.attrs.setdefault("speed_kph", kph)
                for _, d in owner.actions:
                    d.setdefault("speed_kph", kph)

    def _crossing_directions(self, clause: str, mentions: List[Mention], subject: Optional[Entity]) -> None:
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

    def _attach(self, pos: int, mentions: List[Mention], subject: Optional[Entity],
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

    def object_at(self, clause: str, pos: int, mentions: List[Mention]) -> Optional[Entity]:
        for mm in mentions:
            if mm.start >= pos and mm.start - pos <= 22:
                return mm.entity
        return None

    def _lanes(self, clause: str, mentions: List[Mention], subject: Optional[Entity]) -> None:
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

    def _relations(self, clause: str, mentions: List[Mention], subject: Optional[Entity]) -> None:
        ego = self.out.ego
        for rel, pattern in REL_PATTERNS:
            for m in re.finditer(pattern, clause):
                target = self.object_at(clause, m.end(), mentions)
                if target is None:
                    continue
                tm = next((mm for mm in mentions if mm.start >= m.end() and mm.entity is target), None)
                if tm is not None and tm.pronoun and subject is not None and subject is not target and \
                        self._attach(m.start(), mentions, subject) is target:
                    target = subject  # "the ego hits the car in front of it": "it" is the ego
                owner = self._attach(m.start(), mentions, subject, exclude=target)
                if owner is None or owner is target:
                    continue
                if rel == Relation.BEHIND and re.search(r"\bfrom\s+$", clause[:m.start()]):
                    continue  # "appears from behind a parked van": occlusion, not a position
                if rel == Relation.BEHIND and owner.kind in (ActorKind.PEDESTRIAN, ActorKind.BICYCLE) and \
                        re.search(r"\b(?:hidden|concealed|obscured|occluded|hiding|waiting|standing)\s+$", clause[:m.start()]):
                    owner.attrs["from_behind"] = target  # "a pedestrian hidden behind a parked truck"
                    continue
                if rel == Relation.AHEAD_OF and m.group(0).strip() == "before":
                    continue
                if rel == "follow":
                    if owner.kind == ActorKind.EGO and target.kind != ActorKind.EGO:
                        self.relate(target, "ahead_of", owner)  # "the test vehicle follows a target car"
                    elif target.kind == ActorKind.EGO:
                        self.relate(owner, "behind", target)
                    continue
                if rel == "toward":
                    if owner.kind == ActorKind.EGO and target.kind != ActorKind.EGO:
                        self.relate(target, "ahead_of", owner)  # "the ego drives towards a stopped car"
                    continue
                if owner.kind == ActorKind.EGO and target.kind != ActorKind.EGO and \
                        rel in (Relation.BEHIND, Relation.AHEAD_OF):
                    # "the ego drives behind a truck": the truck is ahead of the ego
                    self.relate(target, "ahead_of" if rel == Relation.BEHIND else "behind", owner)
                    continue
                self.relate(owner, rel, target)
        for rel, pattern in REL_IMPLICIT:
            for m in re.finditer(pattern, clause):
                if rel == Relation.ONCOMING:
                    owner = self._attach_forward(m, clause, mentions, subject)
                elif rel in (Relation.AHEAD_OF, Relation.BEHIND) and m.group(0).startswith(
                        ("lead", "leading", "preceding", "front", "following", "trailing", "rear", "tailgating")):
                    owner = self._attach_forward(m, clause, mentions, subject)
                else:
                    owner = self._attach(m.start(), mentions, subject, allow_ego=False)
                if owner is None or owner.kind == ActorKind.EGO:
                    continue
                if rel in (Relation.LEFT_OF, Relation.RIGHT_OF) and re.search(
                        r"\b(?:chang\w*|switch\w*|mov\w*|steer\w*|swerv\w*|turn\w*|veer\w*|shift\w*|lanes?|"
                        r"pull\w*|merg\w*)\s+(?:\w+\s+)?$", clause[:m.start()]) and m.group(0).startswith("to"):
                    continue
                if rel in (Relation.LEFT_OF, Relation.RIGHT_OF) and m.group(0).startswith("from the") and not (
                        owner.has("cut_in") or re.search(r"\bcut|pull|merg|swerv|mov|chang|approach|come|overt",
                                                          clause)):
                    if owner.kind == ActorKind.PEDESTRIAN and not re.search(
                            r"\bfrom the (?:left|right)(?: (?:side|kerb|curb|sidewalk|pavement))?\b", m.group(0) + clause[m.end():m.end() + 12]):
                        continue
                if rel == Relation.SAME_LANE and re.search(r"\binto\s+(?:the ego|its|our|my)",
                                                           clause[max(0, m.start() - 8):m.end()]):
                    continue
                if rel == Relation.BEHIND and "from behind" in m.group(0) and owner.kind == ActorKind.PEDESTRIAN:
                    continue
                if ego is not None:
                    self.relate(owner, rel, ego)
                else:
                    owner.attrs.setdefault("pending_relations", []).append(rel)

    def _attach_forward(self, m: re.Match, clause: str, mentions: List[Mention],
                        subject: Optional[Entity]) -> Optional[Entity]:
        """Adjectives ("oncoming cars", "the lead vehicle") describe the noun right after them."""
        for mm in mentions:
            if mm.start >= m.end() and mm.start - m.end() <= 25 and mm.entity.kind != ActorKind.EGO:
                return mm.entity
        return self._attach(m.start(), mentions, subject, allow_ego=False)

    def relate(self, owner: Entity, rel: str, target: Entity) -> None:
        if owner is target:
            return
        if not any(r == rel and t is target for r, t in owner.relations):
            owner.relations.append((rel, target))
