"""The lexicon of the description parser (:mod:`dv2s_gym.pipeline.semantics.text`): regular expressions and word lists.

Actor nouns per participant type, the ego's aliases, road patterns, action patterns (order matters: an earlier
pattern's span hides later ones), relation patterns, lanes, clause splitting and the neutral words a clause may
hold without saying anything the parser should place. Data only; the parser's logic lives in ``semantics``.
"""

from __future__ import annotations

import re
from typing import Dict, List, Sequence, Tuple

from scenario_bank.elements import ActorKind

__all__ = ["UNKNOWN_ACTORS", "ROAD_PATTERNS", "COLLISION_KINDS",
           # the tables the description reader (text.py) reads
           "NUMBERS", "NOUNS", "EGO", "NOT_ACTOR_AFTER", "COLORS", "ORDINALS",
           "COMPILED_ACTIONS", "FRONTED", "NEUTRAL_WORDS", "MOTOR", "PLACE_NOUNS", "ON_RAMP",
           "NEGATION", "SUDDEN", "PASSIVE_HIT", "REL_PATTERNS", "REL_IMPLICIT", "LANE_POS",
           "LANE_WORD", "CROSS_DIR", "CROSS_FROM", "CLAUSE_SPLIT", "SENTENCE_SPLIT", "DETERMINER_OR_NOUN",
           "PREPOSITIONS"]


# --------------------------------------------------------------------------- lexicon

NUMBERS = {
    "a": 1, "an": 1, "one": 1, "single": 1, "two": 2, "three": 3, "four": 4, "five": 5, "six": 6,
    "seven": 7, "eight": 8, "nine": 9, "ten": 10, "both": 2, "several": 3, "multiple": 2,
    "couple": 2, "pair": 2, "few": 3, "some": 2, "many": 3,
}

# head nouns of each participant type: (singular/plural regex, is_plural)
NOUNS: Dict[str, List[Tuple[str, bool]]] = {
    "car": [
        (r"cars", True), (r"vehicles", True), (r"sedans", True), (r"suvs", True), (r"vans", True),
        (r"taxis", True), (r"pickups", True), (r"jeeps", True), (r"minivans", True),
        (r"automobiles", True), (r"adversarial (?:agents|vehicles|cars)", True), (r"npcs", True),
        (r"(?:adversarial|adversary|npc|background) (?:agent|vehicle|car|actor)(?: (?:vehicle|car))?", False),
        (r"(?:npc|agent|actor|adversary|adv|car|pov|tv) ?[1-9]", False), (r"povs", True), (r"pov", False),
        (r"target (?:car|vehicle)s", True), (r"target (?:car|vehicle)", False),
        (r"target(?! (?:pedestrian|cyclist|bicyclist|child|adult|motorcycl\w*|scooter|dummy|speed)\b)", False), (r"adversary", False), (r"npc", False),
        (r"v[2-9]", False), (r"vehicle [2-9]", False),
        (r"car", False), (r"vehicle", False), (r"sedan", False), (r"suv", False), (r"van", False),
        (r"minivan", False), (r"hatchback", False), (r"coupe", False), (r"taxi", False), (r"cab", False),
        (r"jeep", False), (r"pickup(?: truck)?", False), (r"ambulance", False), (r"police car", False),
        (r"convertible", False), (r"wagon", False), (r"automobile", False),
        (r"(?:toyota|honda|ford|tesla|bmw|audi|mercedes(?: benz)?|volkswagen|vw|nissan|chevrolet|chevy|hyundai|kia|"
         r"volvo|subaru|mazda|lexus|porsche|jaguar|fiat|renault|peugeot|skoda|opel|dodge|jeep|chrysler|"
         r"buick|cadillac|mitsubishi|suzuki|land rover|range rover)(?: (?:sedan|suv|car|van|hatchback|"
         r"model [3sxy]|prius|camry|corolla|civic|accord|golf|polo|focus|fiesta|mustang|f 150|cr v|rav4|"
         r"outback|a4|x5|c class|e class))?", False),
        (r"(?:prius|camry|corolla|civic|accord|golf|mustang|model [3sxy])", False),
    ],
    "truck": [
        (r"trucks", True), (r"lorries", True), (r"semis", True), (r"hgvs", True),
        (r"truck", False), (r"lorry", False), (r"semi(?: truck| trailer)?", False), (r"hgv", False),
        (r"tractor trailer", False), (r"trailer", False), (r"tractor", False), (r"18 wheeler", False), (r"box truck", False),
        (r"tanker", False), (r"garbage truck", False), (r"fire truck", False), (r"dump truck", False),
    ],
    "bus": [
        (r"(?<=city )bus", False),
        (r"buses", True), (r"busses", True), (r"coaches", True), (r"minibuses", True),
        (r"(?:school |city |transit |public |double decker |articulated |shuttle )?bus", False),
        (r"coach", False), (r"minibus", False), (r"shuttle", False), (r"trolleybus", False),
    ],
    "motorcycle": [
        (r"motorcycles", True), (r"motorbikes", True), (r"motorcyclists", True), (r"mopeds", True),
        (r"bikers", True), (r"motos", True), (r"moto", False), (r"motorcycle", False), (r"motorbike", False), (r"motorcyclist", False),
        (r"moped", False), (r"biker", False), (r"dirt bike", False), (r"motor scooter", False),
        (r"(?:harley|ducati|yamaha|kawasaki)(?: davidson)?", False),
    ],
    "bicycle": [
        (r"cyclists", True), (r"bicyclists", True), (r"bicycles", True), (r"bikes", True), (r"scooters", True),
        (r"e scooters", True), (r"scooter riders", True),
        (r"cyclist", False), (r"bicyclist", False), (r"pedal ?cyclists?", False), (r"bicycle", False), (r"(?:e |push |road |mountain )?bike",
                                                                        False),
        (r"scooter rider", False), (r"(?:e |electric |kick )?scooter", False),
    ],
    "pedestrian": [
        (r"(?:adult |child )pedestrians", True), (r"adults", True), (r"(?:adult|child) pedestrian", False),
        (r"adult", False), (r"pedestrians", True), (r"peds", True), (r"ped", False), (r"people", True), (r"persons", True), (r"walkers", True), (r"men", True),
        (r"women", True), (r"children", True), (r"kids", True),
        (r"joggers", True), (r"passers by", True),
        (r"pedestrian", False), (r"person", False), (r"walker", False), (r"man", False), (r"woman", False),
        (r"child", False), (r"kid", False), (r"boy", False), (r"girl", False), (r"jogger", False),
        (r"passer by", False), (r"jaywalkers?", False), (r"schoolchild", False), (r"toddler", False), (r"elderly (?:man|woman|person)", False), (r"individual", False),
    ],
    "obstacle": [
        (r"(?:deer|animals|dogs|cats|cows|horses|moose|sheep|birds|elks|kangaroos)", True),
        (r"(?:animal|dog|cat|cow|horse|bird|elk|kangaroo|fox|boar|wild boar)", False),
        (r"vending machine", False), (r"obstructions?", False), (r"trash (?:can|bin)", False), (r"mattress", False),
        (r"(?:lost |loose |fallen )?(?:tire|tyre)", False),
        (r"obstacles", True), (r"cones", True), (r"traffic cones", True), (r"barriers", True),
        (r"boxes", True), (r"barrels", True), (r"rocks", True), (r"tyres", True), (r"tires", True),
        (r"objects", True), (r"signboards", True), (r"barricades", True),
        (r"obstacle", False), (r"(?:digital |electronic |message |warning |construction |road ?works )?signboard",
                               False), (r"sign board", False),
        (r"(?:digital|electronic|message|warning|construction|road ?works) sign", False),
        (r"(?:traffic )?cone", False), (r"barrier", False), (r"debris", False), (r"box", False),
        (r"barrel", False), (r"rock", False), (r"boulder", False), (r"tyre", False), (r"tire", False),
        (r"object", False), (r"(?:lost |fallen |spilled )?load", False), (r"roadblock", False),
        (r"barricade", False), (r"crate", False), (r"pallet", False), (r"road works", False),
    ],
}
EGO = (r"(?:the |an |our |my |a )?(?:ego(?:[ ](?:car|vehicle|agent|driver|truck))?(?:'s)?|"
        r"(?:test|subject|host|tested|instrumented) (?:car|vehicle|truck)(?:'s)?|av(?:'s)?|adv(?:'s)?|"
        r"(?:automated|driverless|robotic) (?:car|vehicle|truck)(?:'s)?|robotaxi(?:'s)?|v1(?:'s)?|"
        r"vehicle (?:1|one)(?:'s)?|we|us|(?:vehicle|car|system) under test(?:'s)?|vut(?:'s)?|sut(?:'s)?|"
        r"(?:waymo|cruise|zoox|tesla|uber|apollo|baidu) (?:av|robotaxi|autonomous vehicle|self driving car)(?:'s)?|"
        r"(?:our|my|host|subject) (?:car|vehicle)(?:'s)?|(?:the )?(?:autonomous|self driving) (?:car|vehicle)(?:'s)?)")
# actor-like things the vocabulary has no type for (reported, never emitted)
UNKNOWN_ACTORS = (
    "helicopter", "airplane", "aeroplane", "plane", "drone", "tram", "streetcar", "train", "boat",
    "carriage", "ufo", "rocket", "tank",
)
NOT_ACTOR_AFTER = (r"(?! (?:lanes?(?! (?:splitting|splits|split|filtering|filters|changing|changes|change)\b)|stop|park|parks|light|lights|wash|seat|door|line|crossings|path|paths|"
                    r"rack|racks|route|shelter|station|bay|bays|dealership)\b)")

COLORS = ("red", "blue", "white", "black", "silver", "grey", "gray", "green", "yellow", "orange", "brown",
           "purple", "dark", "gold")
ORDINALS = ("first", "second", "third", "fourth", "last", "lead", "leading", "front", "rear", "following",
             "other", "parked", "oncoming", "merging", "overtaking")

# --------------------------------------------------------------------------- roads

ROAD_PATTERNS: Sequence[Tuple[str, str]] = (
    ("roundabout", r"\b(?:roundabout|traffic circle|rotary)\b"),
    ("t_junction", r"\bt (?:junction|intersection|shaped (?:junction|intersection)|crossing)\b"),
    ("three_way", r"\b(?:three|3) way\b|\by (?:junction|intersection)\b"),
    ("intersection", r"\b(?:intersection|crossroads?|four way|4 way|junction)\b"),
    ("merge", r"\b(?:on ramp|onramp|slip road|entry ramp|entrance ramp|acceleration lane|merg(?:e|ing) "
              r"(?:lane|area|section|zone|point)|ramp)\b"),
    ("straight_road", r"\b(?:(?:two|2) lane (?:\w+ )?highway|(?:rural|country|state|county) (?:\w+ )?highway|"
                      r"state route|county road|arterial|collector road)\b"),
    ("highway", r"\b(?:highway|motorway|freeway|expressway|interstate|autobahn|dual carriageway)\b"),
    ("straight_road", r"\b(?:straight (?:road|street|stretch|section)|street|avenue|boulevard|"
                      r"(?:urban|city|residential|two way|country|rural|suburban|local) road)\b"),
    ("straight_road", r"\b(?:road|roadway|carriageway)\b(?! (?:sign|works|side|user)s?\b)"),
)

# --------------------------------------------------------------------------- actions
# (action, regex, detail) ; detail names a group that refines the action later
_A = r"(?:s|es|ed|d|ing)?"
_CRASH_INTO = (r"(?:crash(?:es|ed|ing)?|slam(?:s|med|ming)?|smash(?:es|ed|ing)?|plow(?:s|ed|ing)?|"
               r"bump(?:s|ed|ing)?|ram(?:s|med|ming)?) into|hit(?:s|ting)?|strik(?:e|es|ing)|struck|impact(?:s|ed|ing)?|"
               r"collid(?:e|es|ed|ing) with")
"""Verb phrases of a collision followed by the part of the vehicle hit ("hits the side of")."""
_ACTION_PATTERNS: Sequence[Tuple[str, str]] = (
    # braking / slowing
    ("brake", r"\b(?:slam(?:s|med|ming)? on|hit(?:s|ting)?|step(?:s|ped|ping)? on|appl(?:y|ies|ied|ying)) "
              r"(?:the |its |his |her )?brakes?\b"),
    ("brake", r"\bbrak(?:e|es|ed|ing)\b(?! lights?)"),
    ("brake", r"\bdecelerat(?:e|es|ed|ing)\b"),
    ("brake", r"(?<!a )(?<!an )(?<!the )(?<!very )\bslow(?:s|ed|ing)?(?: (?:down|sharply|abruptly|suddenly|quickly))?\b"
              r"(?! (?:car|vehicle|truck|lane|traffic|moving|speed|tractor|bus|cyclist|van|lorry))"),
    ("brake", r"\b(?:hard|emergency|sudden|harsh|heavy) brak(?:e|ing)\b"),
    ("brake", r"\b(?:reduc(?:e|es|ed|ing)|drop(?:s|ped|ping)?|cut(?:s|ting)?) (?:its |his |her |their )?speed\b"),
    # stopping
    ("stop", r"\b(?:come|comes|came|coming|brought|bring|brings) to a (?:\w+ )?(?:stop|halt|standstill)\b"),
    ("brake_stop", r"\b(?:brak(?:e|es|ed|ing)|slow(?:s|ed|ing)?(?: down)?|decelerat(?:e|es|ed|ing)) to a (?:\w+ )?"
                   r"(?:stop|halt|standstill)\b"),
    ("stop", r"\b(?:remain|remains|remained|remaining|stand|stands|stood|standing|stay|stays|stayed|is|was|are|were"
             r"|sits|sat) (?:completely |fully )?(?:stationary|stopped|still|motionless|immobile|"
             r"at a standstill|stalled|broken down)\b"),
    ("stop", r"(?<!way )\b(?:(?<!bus )stop|stops|stopped|stopping)\b(?! (?:sign|line|light|lights|bar)s?\b)"),
    ("stop", r"\bhalt(?:s|ed|ing)\b"),
    ("pull_over", r"\bpull(?:s|ed|ing)? (?:over|off the road|onto the (?:hard )?shoulder)\b"),
    ("stop", r"\bwait(?:s|ed)?\b(?! for)|\b(?:is|are|was|were|be|remains?) waiting\b(?! for)|\byield(?:s|ed|ing)? (?:to|for)\b|\bgiv(?:e|es|ing) way\b|\bgave way\b|\bwait(?:s|ed|ing)? for\b"),
    # accelerating
    ("accelerate", r"\baccelerat(?:e|es|ed|ing)\b(?! lane)"),
    ("accelerate", r"\b(?:speed(?:s|ing)? up|sped up|pick(?:s|ed|ing)? up speed|gain(?:s|ed|ing)? speed|"
                   r"increas(?:e|es|ed|ing) (?:its |his |her |their )?speed)\b"),
    # lane changes, cut-ins, merges
    # leaving a parking spot, turning round, driving backwards
    ("pull_out", r"\b(?:merg(?:e|es|ed|ing)|rid(?:e|es|ing)|rode|com(?:e|es|ing)|came|pull(?:s|ed|ing)?|nos(?:e|es|ed|ing)|edg(?:e|es|ed|ing)|creep(?:s|ing)?|crept|driv(?:e|es|ing)|"
                 r"drove|back(?:s|ed|ing)?|revers(?:e|es|ed|ing)) (?:out|away) (?:of|from) (?:a |an |the |its |his |her "
                 r"|their )?(?:\w+ )?(?:parking|parked|driveway|curb|kerb|shoulder|space|spot|bay|lay by|alley|garage|"
                 r"car park|side of the road|roadside|bus stop|stop)\w*\b"),
    ("pull_out", r"\bmerg(?:e|es|ed|ing) (?:in)?to (?:the )?traffic from (?:a |an |the |its )?(?:\w+ )?(?:parking|parked|"
                 r"driveway|curb|kerb|shoulder|space|spot|bay|lay by)\w*\b"),
    ("pull_out", r"\b(?:leav(?:e|es|ing)|left|exit(?:s|ed|ing)?|depart(?:s|ed|ing)?(?: from)?) (?:a |an |the |its |his |"
                 r"her |their )?(?:\w+ )?(?:parking (?:spot|space|bay|lot|place)|driveway|parking lane|curbside|"
                 r"kerbside)\b"),
    ("pull_out", r"\bpull(?:s|ed|ing)? (?:out|away)\b(?! (?:in front|of the way|to (?:overtake|pass)|into the "
                 r"(?:left|right|oncoming|opposite|adjacent|next|other|passing)))(?P<generic>)"),
    ("pull_out", r"\bpull(?:s|ed|ing)? (?:out|away) (?:in)?to (?:the )?(?:left|right|travel|traffic|main) lane\b(?P<generic3>)"),
    ("pull_out", r"\b(?:pull(?:s|ed|ing)?|enter(?:s|ed|ing)?|rejoin(?:s|ed|ing)?) (?:(?:in)?to )?(?:the )?(?:flow of )?traffic\b"
                 r"(?P<generic2>)"),
    ("u_turn", r"\bu turn(?:s|ed|ing)?\b|\bturn(?:s|ed|ing)? (?:a)?round\b|\bturn(?:s|ed|ing)? back\b|"
               r"\b(?:three|3) point turn\b|\bturn(?:s|ed|ing)? about\b"),
    ("reverse", r"\brevers(?:e|es|ed|ing)\b(?! (?:gear|lights?|the decision))|\b(?:backs|backed|backing|(?<=to )back|"
                r"(?<=must )back) (?:up|out|away|down)\b|\b(?:backs|backed|backing|revers(?:es|ed|ing))(?= into\b)|\b(?:driv(?:e|es|ing)|drove|roll(?:s|ed|ing)?|mov(?:e|es|ed|ing)) (?:slowly )?backwards?\b|"
                r"\bin reverse\b"),
    ("emerge", r"\b(?:(?:emerg(?:e|es|ed|ing)|appear(?:s|ed|ing)?|pop(?:s|ped|ping)? out|com(?:e|es|ing) out|came out|"
               r"step(?:s|ped|ping)? out|walk(?:s|ed|ing)? out|run(?:s|ning)? out|ran out|dash(?:es|ed|ing)? out|"
               r"dart(?:s|ed|ing)? out|jump(?:s|ed|ing)? out|rush(?:es|ed|ing)? out|burst(?:s|ing)? out|"
               r"sprint(?:s|ed|ing)? out|leap(?:s|ed|ing)? out|emerg\w+) (?:suddenly |quickly )?(?:from behind\b)?|"
               r"(?:dash|dart|rush|sprint|run|ran|jump|leap|burst)\w* (?:out )?(?:in)?to (?:the )?(?:road|street|"
               r"roadway|lane|crosswalk|traffic)\b|(?:dash|dart|rush|sprint|run|ran|jump|leap|burst)\w* "
               r"(?:out )?(?:in front of|from behind)\b)"),
    ("swerve", r"\b(?:swerv(?:e|es|ed|ing)|jerk(?:s|ed|ing)?) (?:\w+ )?(?:to(?:wards?)? the |to )?(?P<dir>left|right)\b"
               r"(?! ?(?:most )?lane)"),
    ("cut_in", r"\bcut(?:s|ting)? (?:(?:the |an? )?\w+ )?off\b(?! (?:the (?:engine|power)|point))"),
    ("cut_in", r"\bcut(?:s|ting)? (?:back )?in(?:to)?\b|\bcut in\b|\bsqueez(?:e|es|ed|ing) in\b"),
    ("cut_in", r"\bpull(?:s|ed|ing)? (?:back |right )?(?:in|into (?:the ego's|its|the) lane|out in front)\b"),
    ("cut_in", r"\b(?:chang(?:e|es|ed|ing)|mov(?:e|es|ed|ing)|swerv(?:e|es|ed|ing)|steer(?:s|ed|ing)?|"
               r"switch(?:es|ed|ing)?|veer(?:s|ed|ing)?|return(?:s|ed|ing)?|swing(?:s|ing)?|swung) (?:lanes? |back |wide )?(?:in)?to "
               r"(?:the ego(?: vehicle| car)?'s|its|the same|our|my) lane\b"),
    ("merge", r"\bmerg(?:e|es|ed|ing)\b(?! (?:lane|area|section|zone|point|ramp)s?\b)(?! (?:left|right)\b)(?! (?:in)?to the "
              r"(?:left|right|middle|center|centre) lane)"),
    ("merge", r"\bjoin(?:s|ed|ing)? the (?:highway|motorway|freeway|main road|traffic)\b"),
    ("lane_change", r"\b(?:chang(?:e|es|ed|ing)|switch(?:es|ed|ing)?|mov(?:e|es|ed|ing)|shift(?:s|ed|ing)?|"
                    r"steer(?:s|ed|ing)?|swerv(?:e|es|ed|ing)|merg(?:e|es|ed|ing)|pull(?:s|ed|ing)?|"
                    r"veer(?:s|ed|ing)?|go(?:es)?|went) (?:also |back |over |quickly |suddenly |abruptly )?"
                    r"(?:lanes? )?(?:(?:in)?to|towards?) the (?P<dir>left|right|middle|center|centre|inner|outer|"
                    r"fast|slow|passing)(?: lane|most lane| side)?\b"),
    ("lane_change", r"\b(?:chang(?:e|es|ed|ing)|switch(?:es|ed|ing)?) lanes? (?:to the )?(?P<dir>left|right)\b"),
    ("lane_change", r"\b(?P<dir>left|right)(?:ward)? lane change\b|\blane change to the (?P<dir2>left|right)\b"),
    ("lane_change", r"\b(?P<weave>weav(?:e|es|ed|ing)|zig ?zag(?:s|ged|ging)?)\b(?! around)(?: (?:in and out of|"
                    r"through|between|across) (?:the )?(?:traffic|lanes|cars|vehicles))?"),
    ("lane_change", r"\b(?:merg(?:e|es|ed|ing)|mov(?:e|es|ed|ing)|shift(?:s|ed|ing)?|chang(?:e|es|ed|ing)|"
                    r"switch(?:es|ed|ing)?) (?P<dir>left|right)\b(?! (?:turn|lane|side))"),
    ("lane_change", r"\breturn(?:s|ed|ing)? (?:back )?to (?:its|his|her|their|the) (?:original|own|previous|initial|"
                    r"former) lane\b"),
    ("lane_change", r"\b(?:chang(?:e|es|ed|ing)|switch(?:es|ed|ing)?|swap(?:s|ped|ping)?) lanes?\b|\blane change\b|"
                    r"\b(?:mov(?:e|es|ed|ing)|shift(?:s|ed|ing)?|switch(?:es|ed|ing)?|pull(?:s|ed|ing)?|"
                    r"steer(?:s|ed|ing)?|go(?:es)?|went) (?:over )?(?:in)?to (?:the |an |another )?(?:adjacent|"
                    r"neighbou?ring|next|other|another|free|open|empty) lane\b"),
    # turns
    ("turn", r"\b(?P<unprot>unprotected|protected) (?P<dir>left|right)(?: hand)?(?: turn(?:s|ing)?)?\b(?! lane)"),
    ("turn", r"\bturn(?:s|ed|ing)? (?:to the )?(?P<dir>left|right)\b(?! (?:lane|only|signal|arrow|pocket|bay))"),
    ("turn", r"\b(?:make|makes|made|making|perform|performs|performed|performing|execute|executes|executed|"
             r"attempt|attempts|attempted|attempting|initiate|initiates|initiated|initiating|"
             r"executing|take|takes|took|taking|complete|completes|completed|completing|do|does|did|doing)"
             r" an? (?:\w+ )?(?P<dir>left|right)(?: hand)? turn\b(?! (?:lane|only|signal|arrow|pocket|bay|light))"),
    ("turn", r"\b(?P<dir>left|right)(?: hand)? turning\b(?! (?:lane|traffic|only))"),
    # crossing, straight
    ("go_straight", r"\b(?:go|goes|going|went|gone|drive|drives|driving|drove|driven|continu(?:e|es|ed|ing)|"
                    r"proceed(?:s|ed|ing)?|head(?:s|ed|ing)?|keep(?:s|ing)?|kept|travel(?:s|ed|led|ing|ling)?|"
                    r"mov(?:e|es|ed|ing)|pass(?:es|ed|ing)?) (?:on |straight on |directly )?straight\b"),
    ("go_straight", r"\bstraight (?:through|across) (?:the |a )?(?:intersection|junction|crossroads?)\b"),
    ("go_straight", r"\b(?:cross(?:es|ed|ing)?|pass(?:es|ed|ing)? through|driv(?:e|es|ing) through|"
                    r"go(?:es|ing)? through|went through) (?:the |a )(?:intersection|junction|crossroads?)\b"),
    ("drift", r"\b(?:drift(?:s|ed|ing)?|wander(?:s|ed|ing)?|encroach(?:es|ed|ing)?|invad(?:e|es|ed|ing))\b"),
    ("drift", r"\b(?:depart(?:s|ed|ing)?|leav(?:e|es|ing)|left|run(?:s|ning)? off|ran off|go(?:es)? off|went off) "
              r"(?:the )?(?:road|roadway|road edge|carriageway)\b|\broad (?:edge )?departure\b"),
    ("drift", r"\b(?:cross(?:es|ed|ing)?|over) (?:the )?(?:centre|center|middle|dividing|median|double|"
              r"solid|lane) (?:line|marking)s?\b"),
    ("drift", r"\b(?:veer|veers|veered|veering|swerv(?:e|es|ed|ing)|stray(?:s|ed|ing)?) (?:in)?to "
              r"(?:the )?(?:oncoming|opposite|opposing|wrong)\b"),
    ("cross", r"\bcross(?:es|ed|ing)?\b(?! (?:the |a )?(?:centre|center|middle|dividing|median|lane) line)"
              r"(?! (?:the |a )(?:intersection|junction|crossroads?))(?! (?:the ego(?: vehicle| car)?'s|its|their|"
              r"his|her|our|the) path)"),
    ("cross", r"\b(?:walk(?:s|ed|ing)?|run(?:s|ning)?|ran|dash(?:es|ed|ing)?|dart(?:s|ed|ing)?|rush(?:es|ed|ing)?|"
              r"hurr(?:y|ies|ied|ying)|go(?:es|ing)?|went) (?:out )?(?:across|into the (?:road|street))\b"),
    ("cross", r"\bstep(?:s|ped|ping)? (?:out|off|onto|into|down)\b"),
    ("cross", r"\bjaywalk(?:s|ed|ing)?\b"),
    ("cross", r"\bgo(?:es|ing)? from (?:the )?(?P<from>left|right) to (?:the )?(?:left|right)\b"),
    # collisions with their type (scenario_bank.elements.COLLISION_TYPES); each also states "collide"
    ("collide_rear_end", r"\bfront to rear\b|\brear ?end(?:s|ed|ing)?\b(?: (?:collision|crash|impact)s?\b)?|"
                         r"\b(?:" + _CRASH_INTO + r") the (?:back|rear|tail) of\b"),
    ("collide_head_on", r"\bcollid(?:e|es|ed|ing) front to front\b|\bfront to front\b|\bhead ?on (?:collision|crash|impact)s?\b|\b(?:collid(?:e|es|ed|ing)|crash(?:es|ed|ing)?|"
                        r"hit(?:s|ting)?|strik(?:e|es|ing)|struck|smash(?:es|ed|ing)?) (?:\w+ ){0,3}head ?on\b"),
    ("collide_side", r"\bside (?:on )?(?:collision|crash|impact)s?\b|\bt ?bon(?:e|es|ed|ing)\b|"
                     r"\bsideswip(?:e|es|ed|ing)\b|\bbroadsid(?:e|es|ed|ing)\b|"
                     r"\b(?:" + _CRASH_INTO + r") the (?:\w+ )?side of\b(?! the (?:road|street|highway|lane))|"
                     r"\b(?:hit|struck|impacted|broadsided) (?:on|in) (?:the|its|his|her) (?:\w+ )?side\b|"
                     r"\b(?:hit(?:s|ting)?|strik(?:e|es|ing)|struck|impact(?:s|ed|ing)?) (?:its|his|her|their) (?:\w+ )?side\b|"
                     r"(?:(?<=backs )|(?<=backed )|(?<=backing )|(?<=reverses )|(?<=reversed )|(?<=reversing ))into the (?:\w+ )?side of\b"),
    # collisions
    ("collide", r"\bcollid(?:e|es|ed|ing)\b|\bcollision with\b|\bimpact(?:s|ed|ing)\b|"
                r"\b(?:made|makes|make|making) contact with\b|(?:(?<=backs )|(?<=backed )|(?<=backing )|(?<=reverses )|(?<=reversed )|(?<=reversing ))into\b(?! (?:a|the|its) "
                r"(?:parking|space|spot|bay|driveway|garage))"),
    ("collide", r"\bcrash(?:es|ed|ing)?\b|\bsmash(?:es|ed|ing)? into\b|\bslam(?:s|med|ming)? into\b|"
                r"\bbump(?:s|ed|ing)? into\b|\bplow(?:s|ed|ing)? into\b"),
    ("collide", r"\b(?:hit|hits|hitting)\b(?! (?:the |its |his |her )?brakes?\b)|\bstrik(?:e|es|ing)\b|\bstruck\b|"
                r"\brear ?end(?:s|ed|ing)?\b|\b(?:run|runs|ran|running) over\b"),
    # lane keeping
    ("keep_lane", r"\b(?:keep(?:s|ing)?|kept|stay(?:s|ed|ing)?|remain(?:s|ed|ing)?|maintain(?:s|ed|ing)?|"
                  r"hold(?:s|ing)?|held|continu(?:e|es|ed|ing)(?: driving)?|follow(?:s|ed|ing)?) "
                  r"(?:in |to )?(?:its|his|her|their|the same|the|its own|their own) lanes?\b"),
    ("keep_lane", r"\blane keeping\b|\bdriv(?:e|es|ing) alongside\b"),
    # overtaking
    ("overtake", r"\bovert(?:ake|akes|aking|aken|ook)\b|\bby ?pass(?:es|ed|ing)?\b(?! (?:road|lane))"),
    ("overtake", r"\b(?:manoeuvr|maneuver)(?:e|es|ed|s|ing)? around\b|\b(?:steer(?:s|ed|ing)?|swerv(?:e|es|ed|ing)|"
                 r"go(?:es)?|went|drive|drives|drove|driving|mov(?:e|es|ed|ing)|weav(?:e|es|ed|ing)|"
                 r"navigat(?:e|es|ed|ing)) around\b(?! (?:a |the )?(?:roundabout|corner|bend|curve|block|city|town|"
                 r"circle|traffic circle|rotary|loop)\b)"),
    ("overtake", r"\bpass(?:es|ed|ing)?\b(?= (?:the |a |an |another |it\b|him\b|them\b|ego\b|our |slower |"
                 r"stopped |stationary ))(?! (?:the |a |an )?(?:intersection|junction|crossroads?|road|street))"),
)
_ACTION_PATTERNS = tuple(_ACTION_PATTERNS) + (
    ("drift", r"\b(?:los(?:e|es|ing)|lost) control\b|\bspin(?:s|ning)? out\b|\bspun out\b|\bskid(?:s|ded|ding)?\b|"
              r"\bfishtail(?:s|ed|ing)?\b|\bhydroplan(?:e|es|ed|ing)\b|\b(?:leav(?:e|es|ing)|left) (?:its|his|her|their|the) "
              r"lane\b"),
    # leaving the lane without a lane change: "veers into the lane to its left", "slides into the left lane",
    # "runs onto the shoulder", "overshoots the lane"
    ("drift", r"\b(?:veer(?:s|ed|ing)?|slid(?:e|es|ing)?|skid(?:s|ded|ding)?|run(?:s|ning)?|ran|overshoot(?:s|ing)?|"
              r"overshot) (?:in|on)?to (?:the )?(?:lane to (?:its|his|her|their|the) (?:left|right)|(?:left|right|next|"
              r"adjacent|other|neighbouring|neighboring) lane|(?:hard )?shoulder|verge|ditch|road edge|edge of the "
              r"road)\b|\bovershoot(?:s|ing)? (?:the|its) (?:target )?lane\b|\bovershot (?:the|its) (?:target )?lane\b"),
    ("swerve", r"\bswerv(?:e|es|ed|ing)\b|\bevasive (?:steering|manoeuvre|maneuver|swerve)\b|"
               r"\bjerk(?:s|ed|ing)? (?:the wheel|sideways)\b"),
)
COMPILED_ACTIONS = [(a, re.compile(p)) for a, p in _ACTION_PATTERNS]
FRONTED = re.compile(r"(?:after|before|while|when|upon|once|having|on|since|whilst)\s+(?:\w+ly\s+)?\w+(?:ing|ed)\b|"
                      r"\w+ing\b(?! (?:car|vehicle|truck|bus|traffic|pedestrian|cyclist)s?\b)")
NEUTRAL_WORDS = frozenset("""
a an the this that these those its their his her our my it they he she there here is are was were be been being
has have had does do did will would can could may might must should also then and or but while whilst as when so
after before until because although though where meanwhile which who just still now already
on in at of to into onto from by with along down up through across over under near nearby towards toward around
about beside between past behind ahead front side same other another one two three some both each all
drive drives driving drove driven travel travels traveling travelling travelled traveled move moves moving moved
approach approaches approaching approached head heads heading headed proceed proceeds proceeding proceeded cruise
cruises cruising come comes coming came go goes going went present exist exists located positioned visible
normal normally steady steadily slow slowly constant constantly moderate speed speeds direction lane lanes road
street scene scenario situation shows show depicts depict begins starts start takes take place occurs happen
happens happened clear sunny daytime day night weather dry wet time traffic flow usual usually follow follows
following followed scene's view camera image video frame driver driver's seen see sees appears visible
nothing multi lane urban city residential rural suburban country way one two divided median shoulder hard parking
turn turning left right middle center centre only junction intersection shaped wide narrow per each either km h
kph kmh mph m s meters metres seconds feet hour speed limit posted around approximately about roughly
north south east west northbound southbound eastbound westbound parked double idling located situated
encounter encounters encountering enter enters entering entered exit exits exiting exited arrive arrives arriving
arrived reach reaches reaching heavy light dense sparse busy congested moderate free flowing walk walks walking
stand stands standing ride rides riding first green red amber yellow signal signals signalized signalised
unsignalized unsignalised controlled uncontrolled already inside outside next no
involved involving hidden concealed obscured static
""".split())
MOTOR = (ActorKind.CAR, ActorKind.TRUCK, ActorKind.BUS, ActorKind.MOTORCYCLE)
PLACE_NOUNS = frozenset(("highway", "motorway", "freeway", "expressway", "roadway", "way", "alley", "driveway",
                          "parkway", "causeway", "gateway", "entryway", "byway", "interstate", "city", "valley"))
COLLISION_KINDS = ("collide_rear_end", "collide_head_on", "collide_side")
ON_RAMP = re.compile(r"\b(?:on ramp|onramp|slip road|entry ramp|entrance ramp|acceleration lane|ramp)\b")
NEGATION = re.compile(
    r"\b(?:not|never|no|avoid|avoids|avoided|avoiding|without|nearly|almost|narrowly|prevent|prevents|"
    r"prevented|preventing|fail|fails|failed|failing|instead of|rather than|refus\w+|unable to|doesn't|didn't|"
    r"don't|isn't|wasn't|can't|cannot|risk of|about to|would have)\b(?:\s+\w+){0,2}\s*$")
SUDDEN = re.compile(r"\b(?:sudden(?:ly)?|abrupt(?:ly)?|hard|harsh(?:ly)?|sharp(?:ly)?|emergency|quick(?:ly)?|"
                     r"unexpected(?:ly)?|without warning|aggressive(?:ly)?|rapid(?:ly)?|heavily|violently)\b")
PASSIVE_HIT = re.compile(r"\b(?:is|was|were|are|gets?|got|being|been) (?:\w+ )?(?:hit|struck|rear ?ended|run over|"
                          r"crashed into|collided with|t ?boned|sideswiped|broadsided) by\b")

# --------------------------------------------------------------------------- relations
REL_PATTERNS: Sequence[Tuple[str, str]] = (
    ("ahead_of", r"\b(?:in front of|ahead of|just ahead of|right in front of|in the path of|before) "),
    ("behind", r"\b(?:is|are|was|were|been|keeps) (?:closely )?(?:following|tailgating|trailing) "),
    ("follow", r"\bfollow(?:s|ed|ing)? (?=(?:a|an|the)\b)"),
    ("toward", r"\b(?:towards?|approach(?:es|ed|ing)?|clos(?:es|ed|ing) in on|catch(?:es|ing)? up (?:with|to)|"
               r"caught up (?:with|to)) "),
    ("behind", r"\b(?:behind|in the back of|to the rear of|at the rear of) "),
    ("left_of", r"\b(?:to|on|at|in) the left (?:side )?of |\bleft of "),
    ("right_of", r"\b(?:to|on|at|in) the right (?:side )?of |\bright of "),
)
REL_IMPLICIT: Sequence[Tuple[str, str]] = (
    ("ahead_of", r"\b(?:in front|ahead|up ahead|further ahead)\b(?! of)"),
    ("ahead_of", r"\b(?:lead|leading|preceding|front) (?=(?:\w+ )?(?:car|vehicle|truck|sedan|suv|van|lorry|bus))"),
    ("behind", r"\b(?:from behind|behind)\b(?! (?:it|the|a|an|him|her|them|us|me|ego|our)\b)"),
    ("behind", r"(?<!is )(?<!are )(?<!was )(?<!were )(?<!been )(?<!keeps )\b(?:following|trailing|rear|tailgating) "
               r"(?=(?:\w+ )?(?:car|vehicle|truck|sedan|suv|van|lorry|bus))"),
    ("left_of", r"\b(?:on|to|from|at) (?:its|the ego(?: vehicle| car)?'s|his|her|our|my|the) left\b(?! lane)(?! of)"
                r"|\b(?:in|on|from) the (?:adjacent |neighbou?ring |next |other )?(?:lane|lanes) (?:to|on) (?:its|the ego(?: vehicle| car)?'s|the) left\b"
                r"|\b(?:in|on|from) the (?:adjacent|neighbou?ring|next) left lane\b"
                r"|\bfrom the left\b(?! (?:to|sidewalk|side|curb|kerb|pavement))"),
    ("right_of", r"\b(?:on|to|from|at) (?:its|the ego(?: vehicle| car)?'s|his|her|our|my|the) right\b(?! lane)(?! of)"
                 r"|\b(?:in|on|from) the (?:adjacent |neighbou?ring |next |other )?(?:lane|lanes) (?:to|on) (?:its|the ego(?: vehicle| car)?'s|the) right\b"
                 r"|\b(?:in|on|from) the (?:adjacent|neighbou?ring|next) right lane\b"
                 r"|\bfrom the right\b(?! (?:to|sidewalk|side|curb|kerb|pavement))"),
    ("left_of", r"\bat the far (?:curb|kerb|side)\b"),
    ("ahead_of", r"\bbefore (?:the ego(?: car| vehicle)?|it) (?:reaches|catches up with|gets to) (?:it|them)\b"),
    ("crossing_path", r"\bacross the path of\b"),
    ("crossing_path", r"\bfrom (?:a |the )?perpendicular (?:approach(?:es)?|road|street|direction)\b|\bcross traffic\b"),
    ("oncoming", r"\b(?:oncoming|on coming|opposing|opposite directions?|other direction|opposite lane|"
                 r"head on|wrong way|facing traffic|coming towards?|approaching from the front|"
                 r"from the other side|(?:comes|coming|came|drives|driving|goes|going|travels|travelling|traveling)"
                 r" the other way|the other way)\b"),
    ("same_lane", r"\b(?:in|on|within|occupying|blocking|blocks|blocked|occupies) (?:the same lane|the ego(?: vehicle| car)?'s (?:own )?lane|"
                  r"its lane|our lane|my lane)\b|\bsame lane\b"),
    ("crossing_path", r"\b(?:cross(?:es|ed|ing)?|cut(?:s|ting)? across|across|into|in|through|block(?:s|ed|ing)?) "
                      r"(?:the ego(?: vehicle| car)?'s|its|our|my) (?:path|way|trajectory)\b|\bcrossing paths\b"),
)
LANE_POS = re.compile(r"\b(?:on|in|from|of|at|along|using|occupying) the (?P<pos>left|leftmost|middle|center|centre|"
                       r"right|rightmost|fast|slow|passing|inner|outer)(?:most)? lane\b")
LANE_WORD = {"left": "left", "leftmost": "left", "fast": "left", "passing": "left", "inner": "left",
              "middle": "middle", "center": "middle", "centre": "middle",
              "right": "right", "rightmost": "right", "slow": "right", "outer": "right"}
CROSS_DIR = re.compile(r"\bfrom (?:the )?(?P<from>left|right)(?: side| sidewalk| curb| kerb| pavement)?"
                        r"(?: of the (?:road|street))? to (?:the )?(?P<to>left|right)\b")
CROSS_FROM = re.compile(r"\bfrom the (?P<from>left|right|far|near|other|opposite) (?:side|sidewalk|curb|kerb|"
                         r"pavement)\b|\bfrom (?:the )?(?P<from2>left|right)\b")

CLAUSE_SPLIT = re.compile(
    r"\s*(?:,|;|:|\(|\))\s*|\s+(?=(?:and|while|whilst|whereas|but|as|when|then|so|after|before|until|"
    r"because|although|though|where|meanwhile|which|who)\b)")
SENTENCE_SPLIT = re.compile(r"(?<=[.!?])\s+|\n+")
DETERMINER_OR_NOUN = re.compile(r"\b(?:the|a|an|this|that|these|those|another|its|their|his|her|some|each|"
                                 r"[a-z]+s)\b")
PREPOSITIONS = ("of", "by", "to", "around", "with", "past", "from", "into", "toward", "towards", "than", "behind",
                 "beside", "for", "at", "near", "onto", "between", "like", "alongside", "overtakes", "passes",
                 "hits", "follows", "over", "under", "in", "on", "avoid", "approaches", "approaching", "reaches",
                 "reaching", "overtaking", "passing", "hitting", "following")
