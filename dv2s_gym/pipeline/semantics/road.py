"""Road features, absences, speeds and trigger numbers said in a description (rule layer).

These are text-level facts that do not belong to one actor: the road's lanes,
turn/parking lanes and shoulders, the shape of a junction, "without an
intersection", "no other vehicles" and the speeds and distances a description
gives. :mod:`dv2s_gym.pipeline.semantics.text` calls :func:`road_features`,
:func:`strip_absences` and :func:`speed_kph` on lower-cased, hyphen-free text
(its ``_normalize`` form).

Everything here is a regular expression over domain phrases: precision first,
what is not said is not returned.
"""

from __future__ import annotations

import re
from typing import Any, Dict, List, Optional, Tuple

from scenario_bank.elements import Road

__all__ = ["road_features", "strip_absences", "speed_kph", "distance_m", "time_s", "VEHICLE_KINDS"]

VEHICLE_KINDS = ["car", "truck", "bus", "motorcycle"]
"""What "no other vehicles / no traffic" rules out (bicycles and pedestrians are said on their own)."""

_COUNT_WORDS = {"one": 1, "single": 1, "two": 2, "three": 3, "four": 4, "five": 5, "six": 6, "eight": 8}
_N = r"(?P<n>\d+|one|single|two|three|four|five|six|eight)"

# "no other vehicles", "without any other traffic", "no pedestrians are around"
_ABSENT_PATTERNS: Tuple[Tuple[str, List[str]], ...] = (
    (r"\b(?:no|without(?: any)?|not any|zero|free of(?: any)?|absence of(?: any)?) (?:other |further |additional |"
     r"surrounding |background |nearby |oncoming )?(?:vehicles?|cars?|traffic|road users|actors|agents)\b"
     r"(?! (?:lights?|signals?|signs?|control|cones?|jams?|islands?|calming|police))",
     VEHICLE_KINDS),
    (r"\b(?:no|without(?: any)?|not any|zero|free of(?: any)?) (?:other )?(?:pedestrians?|people|persons|walkers)\b",
     ["pedestrian"]),
    (r"\b(?:no|without(?: any)?|not any|zero) (?:other )?(?:cyclists?|bicycles?|bikes?|bicyclists?)\b", ["bicycle"]),
    (r"\b(?:no|without(?: any)?|not any|zero) (?:other )?(?:trucks?|lorries)\b", ["truck"]),
    (r"\b(?:no|without(?: any)?|not any|zero) (?:other )?(?:obstacles?|objects?)\b", ["obstacle"]),
    (r"\b(?:empty|deserted) (?:road|street|highway|motorway|lane)s?\b", VEHICLE_KINDS),
)
_NO_JUNCTION = re.compile(
    r"\b(?:no|without(?: an?| any)?|not (?:at|near|in) (?:an?|any)|away from(?: any| an?)?|far from(?: any| an?)?|"
    r"no nearby) (?:intersections?|junctions?|crossroads?)\b")


def strip_absences(text: str) -> Tuple[str, List[str], bool, List[str]]:
    """Remove negated presence phrases from ``text``.

    Returns ``(text without them, absent participant kinds, no_junction, removed phrases)``.
    The phrases are blanked (replaced by ``nothing``) so the actor and road
    patterns do not see "no other vehicles" as vehicles or "without an
    intersection" as an intersection.
    """
    absent: List[str] = []
    removed: List[str] = []
    for pattern, kinds in _ABSENT_PATTERNS:
        for m in re.finditer(pattern, text):
            removed.append(m.group(0))
            for k in kinds:
                if k not in absent:
                    absent.append(k)
        if kinds is not VEHICLE_KINDS or not pattern.startswith(r"\b(?:empty"):
            text = re.sub(pattern, "nothing", text)
    no_junction = False
    for m in _NO_JUNCTION.finditer(text):
        no_junction = True
        removed.append(m.group(0))
    text = _NO_JUNCTION.sub("nothing", text)
    return text, absent, no_junction, removed


def _count(word: str) -> Optional[int]:
    if word.isdigit():
        return int(word)
    return _COUNT_WORDS.get(word)


def road_features(text: str, road: Optional[str]) -> Dict[str, Any]:
    """Road features said in ``text`` (keys of the sg contract: lanes, one_way, multi_lane, turn_lane,
    parking_lane, shoulder, junction_shape, divided, ramp). ``road`` is the road type already found."""
    f: Dict[str, Any] = {}
    m = re.search(_N + r" lanes? (?:in )?(?:each|per|every|one|either) (?:direction|way|side)\b", text)
    if m:
        f["lanes"] = _count(m.group("n"))
    else:
        m = re.search(_N + r" lane (?:urban |city |one way |two way |divided |wide |residential )*"
                      r"(?P<what>road|street|highway|motorway|freeway|avenue|boulevard|carriageway|expressway)\b", text)
        if m and _count(m.group("n")):
            n = _count(m.group("n"))
            one_way = bool(re.search(r"\bone way\b", text))
            motorway = m.group("what") in ("highway", "motorway", "freeway", "expressway") or road == Road.HIGHWAY
            # a "four-lane road" is two lanes each way; a "three-lane motorway" gives its lanes per direction
            f["lanes"] = n if (one_way or motorway) else max(1, n // 2)
    if re.search(r"\bone way\b", text):
        f["one_way"] = True
    if re.search(r"\bmulti ?(?:ple )?lanes?\b(?! change)|\bmultilane\b|\bseveral lanes\b", text) or \
            (f.get("lanes", 0) >= 2 and road != Road.HIGHWAY):
        if road != Road.HIGHWAY:
            f["multi_lane"] = True
        elif "lanes" not in f:
            f["multi_lane"] = True
    m = re.search(r"\b(?P<d>left|right) turn(?:ing)? (?:only )?(?:lane|pocket|bay)\b|"
                  r"\b(?:turn|turning) lane (?:for|to the) (?P<d2>left|right)\b", text)
    if m:
        f["turn_lane"] = m.group("d") or m.group("d2")
    elif re.search(r"\bturn(?:ing)? lane\b", text):
        f["turn_lane"] = "left"
    if re.search(r"\bparking (?:lane|strip|bay|bays|spaces?|spots?)\b|\bon street parking\b|\b(?:cars|vehicles) (?:are )?parked (?:along|on|at)\b|\bparked (?:cars|vehicles)"
                 r" (?:along|line|lining|on)\b|\bkerbside parking\b|\bcurbside parking\b|\bparallel parked\b", text):
        f["parking_lane"] = True
    if re.search(r"\b(?:hard )?shoulder\b|\bbreakdown lane\b|\bemergency lane\b|\bverge\b", text):
        f["shoulder"] = True
    if re.search(r"\by (?:shaped )?(?:junction|intersection|split)\b|\bfork(?:s|ed)? in the road\b|\broad forks\b",
                 text):
        f["junction_shape"] = "y"
    elif re.search(r"\bt (?:shaped )?(?:junction|intersection)\b", text):
        f["junction_shape"] = "t"
    elif re.search(r"\b(?:four|4) (?:way|leg(?:ged)?|arm(?:ed)?) (?:junction|intersection|stop|crossing)?|"
                   r"\bcrossroads?\b", text):
        f["junction_shape"] = "four_way"
    if re.search(r"\b(?:no|without(?: any)?) (?:traffic )?(?:lights?|signals?)\b|\b(?:un|non ?)signali[sz]ed\b|"
                 r"\buncontrolled\b",
                 text):
        f["signals"] = False
    elif re.search(r"\btraffic (?:lights?|signals?)\b|\bsignali[sz]ed\b|\b(?:red|green|amber|yellow) light\b|"
                   r"\bturns? (?:red|green)\b", text):
        f["signals"] = True
    if re.search(r"\bdivided (?:road|highway|street|carriageway)\b|\b(?:central )?median\b|\bcentral reservation\b|"
                 r"\bdual carriageway\b", text):
        f["divided"] = True
    if re.search(r"\b(?:off ramp|exit ramp|offramp|exit lane|slip road off|deceleration lane)\b", text):
        f["ramp"] = "off"
    elif re.search(r"\b(?:on ramp|onramp|entry ramp|entrance ramp|acceleration lane|slip road)\b", text):
        f["ramp"] = "on"
    return f


_SPEED = re.compile(r"\b(?P<v>\d+(?:\.\d+)?) ?(?P<u>km ?/ ?h|kph|kmh|km per hour|kilometers per hour|"
                    r"kilometres per hour|mph|miles per hour|m ?/ ?s|meters per second|metres per second)\b")
_DIST = re.compile(r"\b(?P<v>\d+(?:\.\d+)?) ?(?P<u>m|meters|metres|ft|feet|yards)\b(?! ?/)")
_TIME = re.compile(r"\b(?P<v>\d+(?:\.\d+)?) ?(?P<u>s|sec|secs|seconds?)\b")


def speed_kph(text: str) -> Optional[float]:
    """The first speed in ``text`` in km/h ("50 km/h", "30 mph", "10 m/s"), or None."""
    m = _SPEED.search(text)
    if not m:
        return None
    v, u = float(m.group("v")), m.group("u").replace(" ", "")
    if u in ("mph", "milesperhour"):
        return round(v * 1.609344, 1)
    if u in ("m/s", "meterspersecond", "metrespersecond"):
        return round(v * 3.6, 1)
    return v


def distance_m(text: str) -> Optional[float]:
    """The first distance in ``text`` in metres ("20 m", "50 feet"), or None."""
    m = _DIST.search(text)
    if not m:
        return None
    v, u = float(m.group("v")), m.group("u")
    if u in ("ft", "feet"):
        return round(v * 0.3048, 1)
    if u == "yards":
        return round(v * 0.9144, 1)
    return v


def time_s(text: str) -> Optional[float]:
    """The first duration in ``text`` in seconds ("2 s", "3 seconds"), or None."""
    m = _TIME.search(text)
    return float(m.group("v")) if m else None
