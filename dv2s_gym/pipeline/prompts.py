"""Every prompt text of the model backends, in one place.

* Driving Record Analyzer (DRA): :func:`dra_prompt` joins a generic part (the
  camera viewpoint, what to describe, the road-section question, the answer
  length) with an optional video-specific question about the event of interest.
* Scenario Generator (SG): :data:`SG_RULES` is the fixed context (the Scenic
  authoring rules for dv2s-gym's highway-env world model, including the
  pitfalls collected while testing generated scripts); :func:`sg_messages`
  adds few-shot description→script pairs and the description to translate;
  :func:`repair_message` feeds a failed check back to the model.
* :func:`prompt_hash` fingerprints a prompt for provenance records.

Change a text here and its hash changes, so recorded provenance tells which
prompt produced which output.
"""

from __future__ import annotations

import hashlib
from typing import Dict, Iterable, List, Mapping, Optional, Sequence, Tuple
import json
from scenario_bank.errors import SettingError
from dv2s_gym.pipeline.errors import EmptyDescriptionError


__all__ = [
    "CAMERA_VIEWPOINTS",
    "CAMERA_ALIASES",
    "DRA_FRAMES_NOTE",
    "DRA_TASK",
    "DRA_ROAD_QUESTION",
    "DRA_ANSWER_FORMAT",
    "dra_prompt",
    "normalize_camera",
    "SHIPPED_MAPS",
    "SG_RULES",
    "SG_REQUEST",
    "FAILURE_HINTS",
    "sg_context",
    "sg_messages",
    "repair_message",
    "format_example_script",
    "prompt_hash",
]

# --------------------------------------------------------------------------- DRA
CAMERA_VIEWPOINTS: Dict[str, str] = {
    "front": "The frames come from a forward-looking camera fixed on the ego vehicle, seeing the road ahead of it.",
    "rear": "The frames come from a backward-looking camera fixed on the ego vehicle, seeing the road behind it.",
    "chase": "The frames come from a camera placed behind and a little above the ego vehicle, which stays in view "
             "in the lower middle of each image.",
    "bev": "The frames are a bird's-eye view from straight above the road; the ego vehicle is the car drawn in "
           "the middle of each image and the other coloured shapes are the surrounding road users.",
}
"""Viewpoint sentence of the DRA prompt, by camera."""

CAMERA_ALIASES: Dict[str, str] = {
    "dashcam": "front", "windshield": "front", "onboard": "front", "forward": "front",
    "rear_view": "rear", "backward": "rear",
    "third_person": "chase", "third-person": "chase", "follow": "chase",
    "birdseye": "bev", "top": "bev", "top_down": "bev",
}
"""Other names accepted for the cameras of :data:`CAMERA_VIEWPOINTS`."""

DRA_FRAMES_NOTE = "They were sampled from a driving video at a fixed rate and are given in temporal order."
DRA_TASK = ("Explain what the ego vehicle does and how each of the other road users around it moves "
            "and interacts with it.")
DRA_ROAD_QUESTION = ("Also tell which kind of road section the scene takes place on: an intersection, "
                     "a straight road, a highway, a T-intersection or a three-way road.")
DRA_ANSWER_FORMAT = "Keep the whole answer to three sentences."


def normalize_camera(camera: str) -> str:
    """The canonical camera name (``front``, ``rear``, ``chase``, ``bev``) of a camera or alias."""
    key = (camera or "").strip().lower()
    key = CAMERA_ALIASES.get(key, key)
    if key not in CAMERA_VIEWPOINTS:
        names = sorted(set(CAMERA_VIEWPOINTS) | set(CAMERA_ALIASES))
        raise SettingError(f"unknown camera {camera!r}; use one of: {', '.join(names)}")
    return key


def dra_prompt(camera: str = "front", question: Optional[str] = None) -> str:
    """The DRA prompt: viewpoint, optional video-specific question, then what to answer and how.

    ``question`` is the video-specific part (e.g. "Why did the ego vehicle brake hard?");
    the rest is generic, common to every video.
    """
    parts = [CAMERA_VIEWPOINTS[normalize_camera(camera)], DRA_FRAMES_NOTE]
    if question and question.strip():
        specific = " ".join(question.split())
        parts.append(specific if specific[-1] in ".?!" else specific + "?")
    parts += [DRA_TASK, DRA_ROAD_QUESTION, DRA_ANSWER_FORMAT]
    return " ".join(parts)


# ---------------------------------------------------------------------------- SG
SHIPPED_MAPS: Dict[str, str] = {
    "highway_straight": "a 2000 m straight one-way highway with 4 lanes, all driving in the same direction",
    "highway_onramp": "a 1500 m one-way highway with 3 lanes and a one-lane on-ramp joining from the right "
                      "through a 250 m acceleration lane (lane ids: network.elements['road1_lane0'] is the "
                      "right main lane before the ramp, 'road4_lane0' the ramp, 'road2_lane0' the "
                      "acceleration lane)",
    "urban_two_way": "a 600 m straight two-way street, one lane per direction, with a sidewalk on each side",
    "urban_parking": "a 600 m straight two-way street, one lane per direction, a parking lane at each kerb (OpenDRIVE "
                     "lane type 'parking', in network.shoulders, not network.lanes) and a sidewalk beyond it",
    "urban_multilane": "a 600 m straight two-way town street, two lanes per direction, with a sidewalk on each "
                       "side",
    "urban_crossroads": "a four-way intersection of four 150 m two-way arms with sidewalks; every "
                        "left, straight and right movement is a maneuver of network.intersections[0]",
    "urban_t_junction": "a T-junction (three-way road) of three 150 m two-way arms with sidewalks; every "
                        "movement except U-turns is a maneuver of network.intersections[0]",
    "urban_roundabout": "a single-lane roundabout, driven counter-clockwise, with four 150 m two-way arms with "
                        "sidewalks; every entry-to-exit movement (first exit: RIGHT_TURN, second: STRAIGHT, third: "
                        "LEFT_TURN) is a maneuver of network.intersections[0]",
}
"""The maps a script may name in ``param map``, with what they hold."""

_MAP_LINES = "\n".join(f"   - '{name}': {text}" for name, text in SHIPPED_MAPS.items())

SG_RULES = f"""You are the Scenario Generator of dv2s-gym. You translate the description of a driving \
video into a Scenic 3 script that dv2s-gym compiles and runs in the highway-env simulator. The \
simulator loads a Scenic world model that extends Scenic's simulator-independent driving domain, so \
only the driving domain and the classes listed below exist. Think of these rules as the manual of \
the language; the example pairs that follow show descriptions and the scripts that reproduce them.

SCRIPT LAYOUT
Start with a one-line docstring summarising the scenario, then four sections, each opened by its \
comment, in this order:
# 1. Map and global parameters
# 2. Adversarial behaviours
# 3. Road geometry
# 4. Spawn positions

SECTION 1: MAP AND GLOBAL PARAMETERS
1. The first statement after the docstring is `param map = '<name>'` with one of the shipped map names (a plain string, \
never a file path or localPath(...)):
{_MAP_LINES}
   Choose the map whose road matches the description: highway scenes on a highway map, a street with \
pedestrians on 'urban_two_way', an intersection on 'urban_crossroads', a T-intersection or three-way \
road on 'urban_t_junction', a merge or insertion on 'highway_onramp'.
2. Then `model scenic.domains.driving.model` (exactly this line; dv2s-gym substitutes its highway-env model).
3. Optionally `param weather = Uniform('ClearNoon', 'CloudyNoon', 'WetNoon')`.
4. Every quantity that could vary between runs is a global parameter with a range: \
`param ego_speed = Range(20, 28)` (speeds in m/s, distances in m, times in s), read later as \
`globalParameters.ego_speed`. Use Uniform(a, b, ...) to pick among discrete options.

SECTION 2: ADVERSARIAL BEHAVIOURS
5. Define what the other road users do with `behavior Name(arguments):`. Inside a behaviour use \
`do OtherBehavior(...)`, `do OtherBehavior(...) for 2.5 seconds` (a duration always has the unit \
`seconds` or `steps`), `do OtherBehavior(...) until <condition>`, `take <action>`, `wait`, `while`, \
`if`, and `try: ... interrupt when <condition>: ...`. A `take` lasts one simulation step: to hold an \
action, repeat it in a `while True:` loop. `take` and `do` appear only inside a behaviour.
6. Behaviours you can call (keyword names must match exactly):
   FollowLaneBehavior(target_speed=10, laneToFollow=None, is_oppositeTraffic=False)
   LaneChangeBehavior(laneSectionToSwitch, is_oppositeTraffic=False, target_speed=10)
   FollowTrajectoryBehavior(target_speed=10, trajectory=None, turn_speed=None)  # trajectory: a list of lanes
   TurnBehavior(trajectory, target_speed=6)
   DriveAvoidingCollisions(target_speed=25, avoidance_threshold=10)
   AccelerateForwardBehavior(), ConstantThrottleBehavior(x), WalkForwardBehavior()
7. Actions you can take: SetThrottleAction(0..1), SetBrakeAction(0..1), SetSteerAction(-1..1), \
SetSpeedAction(speed), SetVelocityAction(xVel, yVel), RegulatedControlAction(throttle, steer, pastSteer) \
(a negative throttle brakes), SetWalkingSpeedAction(speed), SetWalkingDirectionAction(heading).
8. Useful expressions in conditions: `(distance from self to ego)`, `(distance past ego of self)` \
(how far self is ahead of the ego), `self.speed`, `ego.speed`, `self.lane`, `self.laneSection`, \
`self.laneSection.laneToLeft` / `.laneToRight`, `self.position in network.sidewalkRegion`.
   A sudden brake: `do FollowLaneBehavior(target_speed=v) for t seconds`, then \
`while True: take SetThrottleAction(0), SetBrakeAction(1)`.
   A lane change: `do LaneChangeBehavior(laneSectionToSwitch=self.laneSection.laneToLeft, target_speed=v)`.

SECTION 3: ROAD GEOMETRY
9. `network` is the loaded map. Pick the lanes, roads and junction maneuvers the scenario needs: \
`network.lanes`, `network.roads`, `network.intersections`, `network.elements['<id>']`; a lane has \
`centerline`, `sections`, `road`; a lane section has `laneToLeft`, `laneToRight` (use `_laneToLeft` / \
`_laneToRight`, which may be None, when filtering); a maneuver `m` of `intersection.maneuvers` has \
`m.type` (ManeuverType.LEFT_TURN, RIGHT_TURN, STRAIGHT), `m.startLane`, `m.connectingLane`, \
`m.endLane`, `m.conflictingManeuvers`.
10. Choose among candidates at random with `Uniform(*candidates)`, e.g. `egoLane = Uniform(*network.lanes)` \
or a filtered list `[lane for lane in network.lanes if lane.sections[0]._laneToLeft is not None]`.

SECTION 4: SPAWN POSITIONS
11. The ego comes first and is always `ego = new Car ...`. Place actors on lanes directly so that \
sampling is fast: `ego = new Car at egoLane.centerline.pointAlongBy(Range(50, 400)), with speed \
globalParameters.ego_speed`; keep the range inside the lane (under 1800 m on 'highway_straight', \
under 500 m on 'urban_two_way'; on junction arms use \
`new Car following roadDirection from lane.centerline.end for -Range(10, 40)`).
12. Place the others relative to the ego over short distances (under about 100 m, so they stay on \
the same road): `new Car following roadDirection from ego for Range(20, 40)` (negative for behind), \
`new Car at otherLane.centerline.pointAlongBy(s)`, or a point first, \
`spot = new OrientedPoint following roadDirection from ego for 40`, then `left of spot by 3.5` / \
`right of spot by 3.5`, `facing spot.heading + 90 deg`. Keep vehicles at least 8 m apart along a \
lane so they do not overlap.
13. Classes: Car, NPCCar (background traffic), Truck (9 m long), Pedestrian (only where there are \
sidewalks, on the urban maps; start them on a sidewalk facing the road: from a point on the centre \
of the ego's lane of 'urban_two_way', `right of spot by Range(2.2, 3.4)` is the near sidewalk and \
`left of spot by Range(5.5, 6.2)` the far one), Obstacle (a static object on the road; set `with width w, with length l`). Give moving \
actors `with speed ...` and `with behavior ...`.
14. Prefer exact placements over `require` statements; if you add a `require`, it must hold for most \
samples or scene sampling fails.

PITFALLS (each of these has broken generated scripts)
- Write no imports and no other model line: `import carla`, `from scenic.simulators.carla ...`, \
`import os`, `import numpy` and `model scenic.simulators.carla.model` fail here (max, min and abs \
need no import). Names such as \
`carla`, `Vector3`, `SetAutopilotAction`, `blueprint`, `Town05` and other CARLA or MetaDrive \
constructs do not exist.
- `param map = localPath('...xodr')` or any path: the file does not exist; use a shipped map name.
- Scenic 3 creates objects with `new`: write `ego = new Car at ...`, never `ego = Car` or `ego = Car at ...`.
- `take` inside a behaviour holds for a single step; `behavior X(): take SetBrakeAction(1)` brakes \
for one time step only. Loop it.
- Names must be defined before use: every variable, parameter and behaviour you reference must be \
assigned or defined earlier in the script (read parameters as `globalParameters.name`).
- Exact spellings: `centerline` (not centreline), `pointAlongBy`, `laneToLeft`, `FollowLaneBehavior` \
(American spelling in identifiers), `target_speed=` (not speed=).
- Do not set a property twice: `at`, `following`, `left of`, `right of` and `offset by` all set the \
position, so use one of them per object.
- No invented coordinates (`at (100, 200)`): positions come from the network's lanes.
- No file, process or network access, no exec, eval, open, getattr, no names starting with `__`: \
a script failing the safety check is rejected.

OUTPUT
Answer with exactly one fenced code block that starts with ```scenic and holds the whole script \
(docstring and the four sections). Put nothing else in code blocks."""
"""The fixed context of the Scenario Generator (system message)."""

SG_REQUEST = """Description of the driving video:
{description}

Write the dv2s-gym Scenic script that reproduces this scenario: the same kind of road, the same road \
users, their positions relative to the ego and their actions, with speeds, distances and timings as \
ranged parameters. Answer with one ```scenic block."""
"""The SG's dynamic input; ``{description}`` is the DRA's output."""

FEW_SHOT_REQUEST = "Description of the driving video:\n{description}\n\nWrite the dv2s-gym Scenic script."

FAILURE_HINTS: Dict[str, str] = {
    "no_script": "Your answer held no ```scenic block. Answer with the whole script in one ```scenic block.",
    "unsafe_code": "The script uses something the safety check forbids (an import, file/process/network "
                   "access, exec/eval or a dunder name). Remove it: Scenic's driving domain needs no imports.",
    "undefined_symbol": "A name is used before anything defines it. Define the variable, parameter or "
                        "behaviour earlier in the script, or use the name that was defined.",
    "api_hallucination": "The script uses a class, behaviour, action, attribute or map that does not exist "
                         "here. Use only the classes, behaviours, actions and maps listed in the rules.",
    "function_misuse": "A statement, specifier or call is malformed (syntax, wrong or missing arguments, a "
                       "property given twice). Follow the signatures and the syntax of the rules.",
    "geometric_infeasibility": "No valid scene could be placed: objects overlap, leave their lane or road, or "
                               "a requirement is rarely true. Place actors on lanes with pointAlongBy or short "
                               "`following roadDirection` distances, keep them apart, and drop tight requires.",
    "other": "The script failed when run. Simplify the behaviours and keep to the constructs of the rules.",
}
"""What the repair message tells the model, by failure category."""

REPAIR_REQUEST = """Your script did not pass dv2s-gym's checks (attempt {attempt}).
Check that failed: {stage}
Failure category: {category}
Error: {message}
{hint}
Answer with the complete corrected script in one ```scenic block."""


def format_example_script(script: str) -> str:
    """A script as the assistant's answer of a few-shot pair."""
    return "```scenic\n" + script.strip("\n") + "\n```"


def sg_context(examples: Sequence[Tuple[str, str]] = ()) -> List[Dict[str, str]]:
    """The fixed part of the SG conversation: the rules, then one user/assistant turn per example.

    ``examples`` are ``(description, script)`` pairs.
    """
    messages = [{"role": "system", "content": SG_RULES}]
    for description, script in examples:
        messages.append({"role": "user", "content": FEW_SHOT_REQUEST.format(description=description.strip())})
        messages.append({"role": "assistant", "content": format_example_script(script)})
    return messages


def sg_messages(description: str, examples: Sequence[Tuple[str, str]] = ()) -> List[Dict[str, str]]:
    """The full first SG request: fixed context, then the description to translate."""
    if not description or not description.strip():
        raise EmptyDescriptionError("the description to turn into a scenario is empty")
    return sg_context(examples) + [
        {"role": "user", "content": SG_REQUEST.format(description=description.strip())}
    ]


def repair_message(attempt: int, stage: str, category: str, message: str) -> Dict[str, str]:
    """The user turn that feeds a failed check back to the model."""
    text = " ".join(str(message).split())
    if len(text) > 1200:
        text = text[:1197] + "..."
    return {
        "role": "user",
        "content": REPAIR_REQUEST.format(
            attempt=attempt, stage=stage, category=category, message=text,
            hint=FAILURE_HINTS.get(category, FAILURE_HINTS["other"]),
        ),
    }


# ------------------------------------------------------------------ provenance
def prompt_hash(text: str | Iterable[Mapping[str, object]], length: int = 12) -> str:
    """Short SHA-256 of a prompt (a string, or a list of chat messages) for provenance."""
    if not isinstance(text, str):
        text = json.dumps(list(text), sort_keys=True, ensure_ascii=False)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:length]
