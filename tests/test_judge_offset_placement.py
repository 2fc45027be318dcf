"""The conversion judge reads a placement offset in an oriented point's frame (``offset by X @ Y``, ``offset along
roadDirection by X @ Y``, ``at P offset by X @ Y``, ``offset by Vector(X, Y)``): ``Y`` is the distance ahead, ``X``
the distance to the right; ``Y`` runs between the two centres, so it is compared with ``ahead of`` (between faces)
less half of each length (4.5 m for two cars).

The failure: the ego ran into a slow car ``lead_gap`` = 110 m ahead (ego_speed 25). A converted script that puts the
slow car about 40 m ahead is another scene and must be rejected at the parameter check, however the placement is
written; one that puts it where the failure had it must pass.
"""

from __future__ import annotations

import pytest

from dv2s_gym.mining.conversion.interaction import FailureInteraction
from dv2s_gym.mining.conversion.judge import judge_conversion
from dv2s_gym.mining.conversion.parameters import compare_parameters
from dv2s_gym.mining.conversion.param_meaning import fixed_quantities, quantity_uses

HEAD = """param map = 'highway_straight'
model scenic.domains.driving.model

param ego_speed = Range(22, 30)
{params}
lane = Uniform(*network.lanes)
egoS = Range(40, 300)

ego = new Car at lane.centerline.pointAlongBy(egoS),
    with speed globalParameters.ego_speed
{before}slow = new Car {placement},
    with name "slow",
    with speed 5,
    with behavior FollowLaneBehavior(target_speed=5)
"""

PARENT = HEAD.format(params="param lead_gap = Range(10, 150)", before="",
                     placement="ahead of ego by globalParameters.lead_gap")
FAILING = {"ego_speed": 25.0, "lead_gap": 110.0}
INTERACTION = FailureInteraction(kind="car", actor="slow", manoeuvres=())
REPRODUCED = {"k": 10, "reproduced": 10, "rate": 1.0, "interaction_shown": 10}


def script(placement: str, params: str = "", before: str = "") -> str:
    return HEAD.format(params=params, before=before, placement=placement)


def judged(new_script: str, parent: str = PARENT, failing=None):
    """The parameter comparison and the judge's rejections of ``new_script`` as a conversion of the failure."""
    parameters = compare_parameters(failing or FAILING, new_script, parent, INTERACTION)
    rejections = judge_conversion({"reproduction": REPRODUCED, "parameters": parameters},
                                  INTERACTION, {"type": "collision", "with_kind": "car"}, 0.3)
    return parameters, [str(r) for r in rejections]


MOVED = {
    "specifier offset by, a number": script("offset by 0 @ 40"),
    "at ego offset by, a Range": script("at ego offset by 0 @ Range(35, 45)"),
    "at (ego offset by ...) in brackets": script("at (ego offset by 0 @ Range(35, 45))"),
    "a parameter of its own": script("at ego offset by 0 @ globalParameters.near_gap",
                                     params="param near_gap = Range(30, 50)"),
    "the failing parameter shifted": script("at ego offset by 0 @ (globalParameters.lead_gap - 70)",
                                            params="param lead_gap = Range(10, 150)"),
    "the failing parameter halved": script("at ego offset by 0 @ (globalParameters.lead_gap / 2)",
                                           params="param lead_gap = Range(10, 150)"),
    "specifier offset along roadDirection": script("offset along roadDirection by 0 @ 40"),
    "at ego offset along roadDirection, a parameter": script(
        "at ego offset along roadDirection by 0 @ globalParameters.near_gap", params="param near_gap = Range(30, 50)"),
    "through a placing point": script("at spot", before="spot = new OrientedPoint offset by 0 @ 40\n"),
    "offset to the side as well": script("at ego offset by -3.5 @ Range(35, 45)"),
}


@pytest.mark.parametrize("name", sorted(MOVED))
def test_a_script_that_moves_the_gap_with_an_offset_is_rejected_at_the_parameters(name):
    parameters, rejections = judged(MOVED[name])
    assert rejections, (name, parameters)
    assert all(r.startswith("parameters:") for r in rejections)
    assert any("lead_gap" in r for r in rejections)


KEPT = {
    "fixed at the failing value, between centres": script("offset by 0 @ 114.5"),
    "the failing parameter itself": script("at ego offset by 0 @ globalParameters.lead_gap",
                                           params="param lead_gap = Range(10, 150)"),
    "a parameter of its own, shifted, holding the value": script(
        "at (ego offset by 0 @ (globalParameters.far_gap + 60))", params="param far_gap = Range(20, 80)"),
    "along roadDirection, the failing parameter": script(
        "offset along roadDirection by 0 @ globalParameters.lead_gap", params="param lead_gap = Range(10, 150)"),
}


@pytest.mark.parametrize("name", sorted(KEPT))
def test_a_script_that_keeps_the_gap_with_an_offset_passes_and_the_gap_is_checked(name):
    new_script = KEPT[name]
    parameters, rejections = judged(new_script)
    assert rejections == [], (name, rejections)
    # read, not passed for want of reading it: the gap is compared, or fixed where the judge sees it
    fixed = fixed_quantities(new_script).get(("slow", "Car", "longitudinal"))
    assert "lead_gap" in parameters["compared"] or (
        fixed == "(114.5) - 4.5" and not parameters["key_fixed_outside"]), (name, parameters)


def test_the_offsets_components_are_read_ahead_and_to_the_right():
    """``X @ Y``: the second component is the distance ahead, the first the distance to the right; each component
    takes only its own parameters."""
    new_script = script("at ego offset by globalParameters.side @ globalParameters.near_gap",
                        params="param side = Range(-1, 1)\nparam near_gap = Range(30, 50)")
    uses = quantity_uses(new_script)
    assert set(uses["near_gap"]) == {("slow", "Car", "longitudinal")}
    assert set(uses["side"]) == {("slow", "Car", "lateral:right")}
    fixed = fixed_quantities(script("offset by 1.5 @ Range(35, 45)"))
    assert fixed[("slow", "Car", "longitudinal")] == "(Range(35, 45)) - 4.5"  # between faces: two half cars
    assert fixed[("slow", "Car", "lateral:right")] == "1.5"


def test_an_offset_that_is_not_in_an_oriented_points_frame_is_not_read_as_a_distance_ahead():
    """``ego.position offset by V`` is a sum of vectors in the world's frame, ``offset along 30 deg`` turns the frame,
    and ``0 @ g - 90`` is ``(0 @ g) - 90`` in Scenic: none of them sets the distance ahead; the same offset from the
    ego is read."""
    from_ego = fixed_quantities(script("at ego offset by 0 @ 40"))
    assert from_ego[("slow", "Car", "longitudinal")] == "(40) - 4.5"  # between faces: less two half cars
    assert from_ego[("slow", "Car", "lateral:right")] == "0"
    for placement in ("at ego.position offset by 0 @ 40", "offset along 30 deg by 0 @ 40"):
        assert ("slow", "Car", "longitudinal") not in fixed_quantities(script(placement)), placement
    unbracketed = script("at ego offset by 0 @ globalParameters.near_gap - 90", params="param near_gap = Range(30, 50)")
    assert ("slow", "Car", "longitudinal") not in quantity_uses(unbracketed).get("near_gap", {})
    assert ("slow", "Car", "longitudinal") in quantity_uses(
        script("at ego offset by 0 @ (globalParameters.near_gap - 90)", params="param near_gap = Range(30, 50)"))[
        "near_gap"]


def test_a_sideways_offset_is_compared_with_a_placement_to_the_right():
    """The parent places a car ``right of ego by side_gap`` (failing 3.5 m); an offset 5.5 m to the right is
    rejected, one at 3.5 m passes."""
    parent = script("right of ego by globalParameters.side_gap", params="param side_gap = Range(2, 6)")
    failing = {"ego_speed": 25.0, "side_gap": 3.5}
    _, rejected = judged(script("offset by 5.5 @ 0"), parent, failing)
    assert rejected and all(r.startswith("parameters:") for r in rejected) and "side_gap" in rejected[0]
    parameters, kept = judged(script("offset by globalParameters.side_gap @ 0", params="param side_gap = Range(2, 6)"),
                              parent, failing)
    assert kept == [] and "side_gap" in parameters["compared"]
