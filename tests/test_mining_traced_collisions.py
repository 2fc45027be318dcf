"""A mined failure's description states only the collisions its trace records.

The analyzer reads the failure video from its pixels; the trace knows every collision. The traces are built by
hand (straight highway, highway-env frame: x along the road, y to the right) and the analyzer's text is written
in the ``bev`` analyzer's own sentence forms, so each case holds exactly the collisions it is about.
"""

from __future__ import annotations

from types import SimpleNamespace

from dv2s_gym.mining.conversion import convert
from dv2s_gym.mining.conversion.interaction import failure_interaction
from dv2s_gym.mining.conversion.settings import ConversionSettings
from dv2s_gym.pipeline.semantics.text import elements_from_text
from dv2s_gym.pipeline.stages import Description
from envs.trace import EpisodeTrace
from scenario_bank.records import Failure

DT = 0.2  # the env's default policy frequency, 5 Hz


def _drive(x0: float, y0: float, speed: float, n: int):
    return [[x0 + speed * DT * i, y0, 0.0, speed] for i in range(n)]


def ego_into_obstacle_beside_a_car() -> EpisodeTrace:
    """The ego drives at 26 m/s into an obstacle standing in its lane, 40 m ahead at the start; a car drives
    alongside in the lane to its left all the way and never touches anything. One collision: ego and obstacle."""
    n = 9
    return EpisodeTrace(
        scenario="hand", source="test", seed=0, scene_seed=0, params={"map": "highway_straight"},
        config={"policy_frequency": 5}, actions=[1] * (n - 1),
        states=[{"ego": e, "blocker": b, "obstacle": [40.0, 0.0, 0.0, 0.0]}
                for e, b in zip(_drive(0.0, 0.0, 26.0, n), _drive(-1.0, -4.0, 26.0, n))],
        events=[{"time": (n - 1) * DT, "kind": "collision", "actors": ["ego", "obstacle"]}],
        kinds={"ego": "ego", "blocker": "car", "obstacle": "obstacle"})


OBSTACLE_HIT = Failure("collision", with_="obstacle", step=8)

# what the video analyzer says of such a clip when the crashed (red) obstacle reads as a crashed car
VIDEO_SAYS = ("The ego car drives in the right lane of a straight multi-lane highway while a car on its left "
              "suddenly brakes. An obstacle lies in the ego's lane ahead. The car collides with the ego car. "
              "The ego car collides with the car. This scene takes place on a highway.")


def _collisions(text: str):
    return {who for who, action in elements_from_text(text).actions if action == "collide"}


def _describe_as_a_conversion(video_text: str, trace: EpisodeTrace, failure: Failure, tmp_path, monkeypatch):
    """The description the conversion's describe stage gives a failure whose video reads as ``video_text``."""
    monkeypatch.setattr(convert.stages, "describe", lambda video, **_: Description(
        video_text, elements_from_text(video_text), "bev", video=str(video)))
    run = object.__new__(convert._Conversion)
    run.settings = ConversionSettings(policy="keep_lane")
    run.source_trace, run.interaction = trace, failure_interaction(trace, failure)
    run.video, run.conversion = tmp_path / "failure.webm", tmp_path / "conversion"
    run.out, run.details, run.stage = {"timings": {}}, {}, "video"
    run._stage_start = 0.0
    run._describe()
    return run


def test_the_description_of_an_obstacle_hit_describes_no_car_collision(tmp_path, monkeypatch):
    run = _describe_as_a_conversion(VIDEO_SAYS, ego_into_obstacle_beside_a_car(), OBSTACLE_HIT, tmp_path,
                                    monkeypatch)
    text = run.out["description"]
    assert _collisions(text) == {"ego", "obstacle"}, text
    assert "collides with the car" not in text and "The car collides" not in text, text
    # the failure's own actor and what the video saw of the others stay described
    assert "The ego vehicle collides with the obstacle." in text, text
    assert "An obstacle lies in the ego's lane ahead." in text and "a car on its left suddenly brakes" in text, text
    assert ("car", "brake") in run.description.elements.actions
    assert ("obstacle", "same_lane", "ego") in run.description.elements.relations
    # the analyzer's own words are kept beside, and what was taken out is said
    assert run.details["dra_description"] == VIDEO_SAYS
    assert run.details["untraced_collisions"] == ["The car collides with the ego car.",
                                                  "The ego car collides with the car."]
    assert (tmp_path / "conversion" / "description.txt").read_text().strip() == text.strip()


def test_a_crash_the_trace_does_not_record_is_cut_from_its_sentence_and_the_rest_kept(tmp_path, monkeypatch):
    said = ("The ego car drives along a straight multi-lane highway while two cars ahead of it in the same lane "
            "suddenly brake and crash. This scene takes place on a highway.")
    run = _describe_as_a_conversion(said, ego_into_obstacle_beside_a_car(), OBSTACLE_HIT, tmp_path, monkeypatch)
    text = run.out["description"]
    assert text.startswith("The ego car drives along a straight multi-lane highway while two cars ahead of it in "
                           "the same lane suddenly brake. This scene takes place on a highway."), text
    assert _collisions(text) == {"ego", "obstacle"}, text
    assert run.details["untraced_collisions"] == ["and crash"]


def test_collisions_the_trace_records_are_described_word_for_word(tmp_path, monkeypatch):
    """A car brakes hard ahead of the ego, a second car runs into it, then the ego hits the braking car: the
    analyzer's crash sentences all have their collision in the trace and stay as it wrote them."""
    n = 9
    trace = EpisodeTrace(
        scenario="hand", source="test", seed=0, scene_seed=0, params={"map": "highway_straight"},
        config={"policy_frequency": 5}, actions=[1] * (n - 1),
        states=[{"ego": e, "cutter": [30.0 + 5.0 * DT * i, 0.0, 0.0, 5.0], "Car1": [26.0 + 10.0 * DT * i, 0.0, 0.0, 10.0]}
                for i, e in enumerate(_drive(0.0, 0.0, 25.0, n))],
        events=[{"time": 0.8, "kind": "collision", "actors": ["cutter", "Car1"]},
                {"time": 1.6, "kind": "collision", "actors": ["ego", "cutter"]}],
        kinds={"ego": "ego", "cutter": "car", "Car1": "car"})
    said = ("The ego car drives along a straight multi-lane highway while two cars ahead of it in the same lane "
            "suddenly brake and crash. The car collides with the ego car. The ego car collides with the car. "
            "This scene takes place on a highway.")
    run = _describe_as_a_conversion(said, trace, Failure("collision", with_="cutter", step=8), tmp_path, monkeypatch)
    assert run.out["description"].startswith(said), run.out["description"]
    assert "untraced_collisions" not in run.details


def test_without_the_trace_account_the_untraced_collision_is_still_not_described(tmp_path, monkeypatch):
    monkeypatch.setattr(convert.stages, "describe", lambda video, **_: Description(
        VIDEO_SAYS, elements_from_text(VIDEO_SAYS), "bev", video=str(video)))
    run = object.__new__(convert._Conversion)
    run.settings = SimpleNamespace(dra="bev", llm_config=None, describe_events=False)
    trace = ego_into_obstacle_beside_a_car()
    run.source_trace, run.interaction = trace, failure_interaction(trace, OBSTACLE_HIT)
    run.video, run.conversion = tmp_path / "failure.webm", tmp_path / "conversion"
    run.out, run.details, run.stage, run._stage_start = {"timings": {}}, {}, "video", 0.0
    run._describe()
    assert run.out["description"] == ("The ego car drives in the right lane of a straight multi-lane highway while a "
                                      "car on its left suddenly brakes. An obstacle lies in the ego's lane ahead. "
                                      "This scene takes place on a highway.")
