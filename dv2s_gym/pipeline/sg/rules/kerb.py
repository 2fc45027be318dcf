"""Vehicles at the kerb or on the shoulder: one pulling (or backing) out of a parking space."""

from __future__ import annotations

from dv2s_gym.pipeline.sg.rules.frame import CLASS, ActorFrame
from dv2s_gym.pipeline.sg.rules.roads import HIGHWAY_MAPS, PARKING_KERB, PARKING_STREET, at_kerb
from dv2s_gym.pipeline.sg.rules.script import Script
from scenario_bank.elements import Action, Relation

__all__ = ["spawn_puller"]


def spawn_puller(s: Script, actor: ActorFrame, ego_speed: str, two_way: bool) -> None:
    """A vehicle parked at the kerb (shoulder) right of the ego's lane, ahead of the ego: once the ego is near
    it backs up (when it reverses) and steers into the lane ahead of the ego."""
    n = actor.name
    urban = s.frame.map not in HIGHWAY_MAPS  # town speeds and distances; parked at a kerb, not on a shoulder
    gap = s.param(f"{n}_gap", ("Range(54, 60)" if urban else "Range(100, 110)") if actor.has("collide") and
                  actor.has("reverse") else "Range(30, 42)" if urban else "Range(55, 75)")
    backing = actor.has("reverse")
    if actor.has("collide"):
        # it is still half in the lane when the ego gets there (backing out first takes about 2 s more)
        trigger = s.param(f"{n}_trigger", ("Range(47, 53)" if urban else "Range(85, 100)") if backing
                          else ("Range(20, 26)" if urban else "Range(40, 50)"))
    else:
        trigger = s.param(f"{n}_trigger", ("Range(20, 26)" if urban else "Range(40, 50)") if actor.sudden
                          else ("Range(26, 34)" if urban else "Range(50, 62)"))
    # (`right of` puts the vehicle's left side that far from the lane centre)
    kerb = PARKING_KERB if s.frame.map == PARKING_STREET else "Range(1.4, 1.7)" if urban else "Range(1.8, 2.2)"
    speed = s.param(f"{n}_speed", "Range(6, 9)" if urban else "Range(12, 16)")
    back = "Range(2.5, 3.5)" if actor.has("reverse") else "0"
    s.use("PullOutWhenNear")
    for i in range(actor.count):
        var = n if actor.count == 1 else f"{n}_{i + 1}"
        s.spawn += at_kerb(var, CLASS[actor.kind], f"egoS + {gap} + {12 * i}", kerb,
                           f"PullOutWhenNear(egoLane.centerline, -{kerb}, {speed}, {trigger}, {back}, Range(2.2, 3.0))")
    shown = [a for a in actor.actions if a in (Action.PULL_OUT, Action.REVERSE, Action.COLLIDE)]
    if Action.PULL_OUT not in shown:
        shown.append("pull_out")
    rels = ["ahead_of", "right_of"] + [r for r in actor.relations if r == Relation.CROSSING_PATH]
    s.show(actor.kind, shown, rels, actor.count)
