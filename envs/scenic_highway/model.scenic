"""Scenic world model for highway-env (dv2s-gym).

It extends the simulator-agnostic driving domain (``scenic.domains.driving.model``),
so a script written for that domain runs here unchanged, and the same script runs
in CARLA or MetaDrive by changing its ``model`` line.

Global parameters:
    map: a shipped map name (``highway_straight``, ``highway_onramp``,
        ``urban_two_way``, ``urban_multilane``, ``urban_crossroads``,
        ``urban_t_junction``, ``urban_roundabout``) or a path
        to an OpenDRIVE file.

Classes: ``Car``, ``NPCCar``, ``Truck`` and ``Bus`` (longer, wider), ``Motorcycle``, ``Bicycle``,
``Pedestrian``, ``Obstacle``
(a static prop on the road).

The driving domain's behaviour library is used as is, with three repairs (see
``model_support``): ``WalkTowardsAction`` is provided, ``RegulatedControlAction``
brakes and rate-limits steering per second, and backward-pointing seam segments
are removed from the lane centerlines the behaviours steer along.
CARLA-only object attributes (``blueprint``, ``carlaActor``) raise
``envs.errors.UnsupportedConstructError`` here; scripts whose ``model`` line names
Scenic's CARLA or MetaDrive model compile against the façades that extend this
model (``envs/scenic_highway/carla/model.scenic``, ``.../metadrive/model.scenic``),
where ``blueprint`` chooses size and kind.
"""

from envs.scenic_highway.model_support import resolve_map_parameter as _resolve_map_parameter
_resolve_map_parameter()

from scenic.domains.driving.model import *

from envs.scenic_highway.model_support import (WalkTowardsAction, RegulatedControlAction,
    NoCarlaActor as _NoCarlaActor, install_driving_behavior_support as _install_support,
    remove_backward_seams as _remove_backward_seams)
from envs.scenic_highway.simulator import HighwayEnvSimulator
_install_support()
_remove_backward_seams(network)

simulator HighwayEnvSimulator(network)

class HighwayEnvActor(DrivingObject, _NoCarlaActor):
    """An object whose state highway-env simulates."""
    throttle: 0
    steer: 0
    brake: 0
    hand_brake: 0
    reverse: 0

    def setPosition(self, pos, elevation):
        simulation().set_actor_position(self, pos)

    def setVelocity(self, vel):
        simulation().set_actor_velocity(self, vel)

    def setThrottle(self, throttle):
        self.throttle = throttle

    def setSteering(self, steering):
        self.steer = steering

    def setBraking(self, braking):
        self.brake = braking

    def setHandbrake(self, handbrake):
        self.hand_brake = handbrake

    def setReverse(self, reverse):
        self.reverse = reverse

class Vehicle(Vehicle, HighwayEnvActor):
    pass

class Car(Vehicle, Steers):
    """A car."""
    @property
    def isCar(self):
        return True

class NPCCar(Car):
    """A car for which accurate physics is not required."""
    pass

class Truck(Car):
    """A truck: drawn and simulated longer and wider than a car."""
    width: 2.5
    length: 9

class Bus(Truck):
    """A bus: longer than a truck."""
    width: 2.55
    length: 12

class Motorcycle(Vehicle, Steers):
    """A motorcycle with its rider."""
    width: 0.8
    length: 2.2

class Bicycle(Vehicle, Steers):
    """A bicycle (or an e-scooter) with its rider."""
    width: 0.7
    length: 1.8

class Pedestrian(Pedestrian, HighwayEnvActor, Walks):
    """A pedestrian; walks with SetWalkingDirectionAction / SetWalkingSpeedAction."""

    def setWalkingDirection(self, heading):
        simulation().set_walking(self, heading=heading)

    def setWalkingSpeed(self, speed):
        simulation().set_walking(self, speed=speed)

class Obstacle(DrivingObject, _NoCarlaActor):
    """A static obstacle on the road (a box, a broken-down load, a barrier)."""
    regionContainedIn: roadOrShoulder
    position: new Point on road
    parentOrientation: (roadDirection at self.position)
    width: 1
    length: 1
    color: [0.5, 0.5, 0.5]
