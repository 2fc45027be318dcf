"""CARLA's behaviour library (scenic.simulators.carla.behaviors) on highway-env.

``AutopilotBehavior`` is emulated by lane following (CARLA's Traffic Manager also
keeps its lane and follows the road); ``WalkForwardBehavior``, ``WalkBehavior``
and ``CrossingBehavior`` use the model's walking actions. The driving domain's
behaviours are re-exported unchanged.
"""

from scenic.domains.driving.behaviors import *
from envs.scenic_highway.carla.actions import *

behavior AutopilotBehavior(enabled = True, **kwargs):
    """Emulates CARLA's autopilot: follow the lane (and the road through junctions) at
    ``kwargs['speed']`` m/s if given, else 10 m/s; stand still when ``enabled`` is False."""
    if enabled:
        do FollowLaneBehavior(target_speed=kwargs.get('speed', 10))
    else:
        while True:
            wait

behavior WalkForwardBehavior(speed=0.5):
    """Walk straight ahead at ``speed`` m/s."""
    take SetWalkingDirectionAction(self.heading), SetWalkingSpeedAction(speed)

behavior WalkBehavior(maxSpeed=1.4):
    """CARLA's AI walker, emulated: walk straight ahead at ``maxSpeed`` m/s."""
    take SetWalkAction(True, maxSpeed)

behavior CrossingBehavior(reference_actor, min_speed=1, threshold=10, final_speed=None):
    """Cross ahead of ``reference_actor``: wait until it is within ``threshold`` m, then
    move at the speed that brings this actor to the reference actor's path when it
    arrives there (at least ``min_speed``); once it has passed, keep ``final_speed``."""
    settle = final_speed if final_speed else min_speed
    while (distance from self to reference_actor) > threshold:
        wait
    while True:
        offset = (self.position - reference_actor.position).rotatedBy(-reference_actor.heading)
        ahead, across = offset.y, offset.x
        if ahead < 0:
            break
        pace = across * reference_actor.speed / ahead if ahead > 0 else min_speed
        pace = max(pace, min_speed)
        if isinstance(self, Walks):
            do WalkForwardBehavior(pace)
        else:
            take SetSpeedAction(pace)
    if isinstance(self, Walks):
        do WalkForwardBehavior(settle)
    else:
        take SetSpeedAction(settle)
