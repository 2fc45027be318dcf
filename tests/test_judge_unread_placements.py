"""Placements the conversion judge reads or refuses, and the Scenic 3.1.1 facts a reading must respect (run against
the installed Scenic).

The failure of ``test_judge_offset_placement``: a slow car ``lead_gap`` = 110 m ahead; a car placed ``behind ego by
back_gap`` (failing 20 m) for the opposite relation. A converted script that places the car by a form the judge
cannot read as that gap is rejected (``parameters``: a key quantity placed by another quantity or form), never kept
with the gap unchecked; a form it reads is read as Scenic places it: ``offset by 0 @ D`` between centres, ``ahead
of``/``behind`` between faces, a negative ``ahead of`` as a distance behind.
"""

from __future__ import annotations

import math

import pytest

from test_judge_offset_placement import judged, script

BEHIND_PARENT = script("behind ego by globalParameters.back_gap", params="param back_gap = Range(10, 50)")
BEHIND_FAILING = {"ego_speed": 25.0, "back_gap": 20.0}

UNREAD_AHEAD = {
    "a plain world-frame vector from the ego's position": (script("at ego.position + Vector(0, 40)"),
                                                           "a point in the world's frame"),
    "an offset along 90 deg": (script("offset along 90 deg by 0 @ 40"), "an offset along a direction"),
    "left of instead of ahead of": (script("left of ego by 110"), "a distance to the side"),
}
UNREAD = "parameters: a key quantity (of the failure's interaction) is placed by another quantity or form"


@pytest.mark.parametrize("name", sorted(UNREAD_AHEAD))
def test_a_gap_placed_by_a_form_the_judge_does_not_read_is_rejected_as_unread(name):
    new_script, form = UNREAD_AHEAD[name]
    parameters, rejections = judged(new_script)
    assert "lead_gap" not in parameters["compared"] and list(parameters["key_unread"]) == ["lead_gap"], name
    assert len(rejections) == 1 and rejections[0].startswith(UNREAD), (name, rejections)
    assert "lead_gap (the Car slow's longitudinal placement" in rejections[0] and form in rejections[0], rejections


def test_an_offset_by_a_vector_is_read_like_an_offset_by_x_at_y():
    """``offset by Vector(0, 40)`` is ``offset by 0 @ 40`` in Scenic: a gap of 40 - 4.5 m between faces, far from the
    failing 110 m; ``Vector(0, 114.5)`` holds it."""
    parameters, rejections = judged(script("at ego offset by Vector(0, 40)"))
    assert list(parameters["key_fixed_outside"]) == ["lead_gap"] and "key_unread" not in parameters
    assert len(rejections) == 1 and "fixes at (40) - 4.5 without a parameter" in rejections[0], rejections
    assert judged(script("at ego offset by Vector(0, 114.5)"))[1] == []


def test_a_negative_distance_ahead_far_from_the_failing_gap_behind_is_rejected():
    """``ahead of ego by Range(-60, -50)`` puts the car 50 - 9 .. 60 - 9 m behind (between faces, two cars of 4.5 m):
    outside the failing 20 m; ``Range(-34, -28)`` (19..25 m behind) holds it."""
    parameters, rejections = judged(script("ahead of ego by Range(-60, -50)"), BEHIND_PARENT, BEHIND_FAILING)
    assert list(parameters["key_fixed_outside"]) == ["back_gap"], parameters
    assert len(rejections) == 1 and "fixes at -(Range(-60, -50)) - 9 without a parameter" in rejections[0], rejections
    assert judged(script("ahead of ego by Range(-34, -28)"), BEHIND_PARENT, BEHIND_FAILING)[1] == []


def test_a_distance_ahead_set_by_a_parameter_for_the_parents_behind_is_rejected_as_unread():
    parameters, rejections = judged(script("ahead of ego by -globalParameters.gap", params="param gap = Range(15, 30)"),
                                    BEHIND_PARENT, BEHIND_FAILING)
    assert list(parameters.get("key_unread", {})) == ["back_gap"], parameters
    assert any(r.startswith(UNREAD) and "a distance in the other direction" in r for r in rejections), rejections


def test_an_offset_is_measured_between_centres_and_ahead_of_between_faces():
    """The failing 110 m is ``ahead of ego by 110`` (between faces); ``offset by 0 @ 110`` puts the car 4.5 m nearer
    (between centres: two half cars), which the 2.8 m tolerance does not hold, and ``offset by 0 @ 114.5`` is the
    failing scene."""
    assert judged(script("ahead of ego by 110"))[1] == []
    parameters, rejections = judged(script("offset by 0 @ 110"))
    assert list(parameters["key_fixed_outside"]) == ["lead_gap"]
    assert len(rejections) == 1 and "fixes at (110) - 4.5 without a parameter" in rejections[0], rejections
    assert judged(script("offset by 0 @ 114.5"))[1] == []
    # with lengths the script fixes: a 9 m long car ahead of a 5 m ego sits 7 m further between centres
    longer = script("offset by 0 @ 117", before="").replace("with name \"slow\",", "with name \"slow\", with length 9,")
    longer = longer.replace("with speed globalParameters.ego_speed", "with speed globalParameters.ego_speed, with length 5")
    assert "with length 9" in longer and judged(longer)[1] == []
    assert judged(longer.replace("0 @ 117", "0 @ 112"))[1] != []  # 105 m between faces


def test_an_offset_with_a_length_the_judge_does_not_know_is_rejected_as_unread():
    unknown = script("offset by 0 @ 114.5").replace("with name \"slow\",", "with name \"slow\", with length Range(4, 6),")
    parameters, rejections = judged(unknown)
    assert list(parameters.get("key_unread", {})) == ["lead_gap"], parameters
    assert rejections and rejections[0].startswith(UNREAD)


def test_the_default_lengths_are_the_models():
    """The lengths the judge assumes (``DEFAULT_LENGTHS``) are the classes' in the model scripts compile against."""
    from pathlib import Path

    from dv2s_gym.mining.conversion.param_meaning import DEFAULT_LENGTHS
    model = (Path(__file__).resolve().parents[1] / "envs" / "scenic_highway" / "model.scenic").read_text()
    for kind in ("Truck", "Bus", "Motorcycle", "Bicycle", "Obstacle"):
        block = model.split(f"class {kind}(", 1)[1].split("\nclass ", 1)[0]
        assert f"length: {DEFAULT_LENGTHS[kind]:g}" in block, kind
    # Car and Pedestrian take theirs from Scenic's driving model (a Car is a Vehicle there); a Car sampled in the model
    import scenic
    from envs.scenarios import compile_scenario

    driving = (Path(scenic.__file__).parent / "domains" / "driving" / "model.scenic").read_text()
    for kind, base in (("Car", "Vehicle"), ("Pedestrian", "Pedestrian")):
        block = driving.split(f"class {base}(", 1)[1].split("\nclass ", 1)[0]
        assert f"length: {DEFAULT_LENGTHS[kind]:g}" in block, kind
    scene = compile_scenario(script("ahead of ego by 110"), trusted=True).scenario.generate(maxIterations=2000)[0]
    assert [obj.length for obj in scene.objects] == [DEFAULT_LENGTHS["Car"]] * 2


def _forward(placement: str) -> float:
    """The distance ahead of the ego (heading 30 deg, 4.5 m long) of a 5 m object's centre placed by ``placement``,
    in one scene sampled by Scenic."""
    import scenic

    source = (f"ego = new Object at (0 @ 0), facing 30 deg, with length 4.5, with width 2\n"
              f"c = new Object {placement}, with length 5, with width 2\n")
    scene = scenic.scenarioFromString(source).generate(maxIterations=10)[0]
    ego, other = scene.objects
    d = other.position - ego.position
    return -d.x * math.sin(ego.heading) + d.y * math.cos(ego.heading)


def test_scenic_ahead_and_behind_measure_between_faces_and_a_vector_sum_is_in_the_worlds_frame():
    """``ahead of ego by -20`` is not ``behind ego by 20``: the two measure from opposite faces (the centres differ
    by the two half lengths on each side, 9.5 m here); ``offset by 0 @ Y`` measures between centres; ``ego.position +
    Vector(0, 40)`` is 40 m north, not 40 m ahead of an ego heading 30 deg."""
    assert _forward("ahead of ego by -20") == pytest.approx(-20 + 2.25 + 2.5)
    assert _forward("behind ego by 20") == pytest.approx(-20 - 2.25 - 2.5)
    assert _forward("offset by 0 @ -20") == pytest.approx(-20)
    assert _forward("at ego.position + Vector(0, 40)") == pytest.approx(40 * math.cos(math.radians(30)))
