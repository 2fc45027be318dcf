"""Scenic's CARLA world model (scenic.simulators.carla.model, Scenic 3.1.1) on highway-env.

A script whose ``model`` line names ``scenic.simulators.carla.model`` is compiled
against this file, which extends ``envs/scenic_highway/model.scenic``:

* Classes as the CARLA model defines them: ``Car``, ``NPCCar``, ``Van``, ``Truck``,
  ``Bus``, ``Motorcycle``, ``Bicycle``, ``Pedestrian`` and the props (``Trash``,
  ``Cone``, ``Debris``, ``VendingMachine``, ``Chair``, ``BusStop``, ``Advertisement``,
  ``Garbage``, ``Container``, ``Table``, ``Barrier``, ``PlantPot``, ``Mailbox``,
  ``Gnome``, ``CreasedBox``, ``Case``, ``Box``, ``Bench``, ``Barrel``, ``ATM``,
  ``Kiosk``, ``IronPlate``, ``TrafficWarning``). Props are static obstacles that collide.
* ``blueprint`` chooses the size (Scenic's CARLA blueprint dimensions) and the kind in
  the trace (a truck blueprint on a ``Car`` makes a truck); ``color`` and ``rolename``
  are accepted (cosmetic).
* CARLA's behaviours and actions (see ``behaviors.scenic`` and ``actions.py``):
  emulated, no-ops with an ``envs.errors.ForeignConstructWarning``, or refused with
  an ``UnsupportedConstructError`` naming them.
* Traffic lights are not simulated: the traffic-light helpers answer "no light here"
  and warn once per scenario.
"""

from envs.scenic_highway.model import *
import envs.scenic_highway.carla.blueprints as blueprints
from envs.scenic_highway.carla.actions import *
from envs.scenic_highway.carla.behaviors import *

simulator HighwayEnvSimulator(network)

import pathlib as _pathlib
param carla_map = _pathlib.Path(globalParameters.map).stem
param weather = 'ClearNoon'

class CarlaActor(DrivingObject):
    """Properties of CARLA actors: ``blueprint`` (size and kind), ``rolename``, ``physics``."""
    blueprint: None
    rolename: None
    physics: True
    defaultKind: 'car'
    defaultWidth: 1
    defaultLength: 1
    defaultHeight: 1
    width: blueprints.width(self.blueprint, self.defaultWidth)
    length: blueprints.length(self.blueprint, self.defaultLength)
    height: blueprints.height(self.blueprint, self.defaultHeight)
    dv2sKind: blueprints.kind_of(self.blueprint, self.defaultKind)

class Car(CarlaActor, Car):
    """A car; its blueprint is drawn from CARLA's car models unless given."""
    blueprint: Uniform(*blueprints.blueprintsInCategory("car"))
    defaultWidth: 2
    defaultLength: 4.5
    defaultHeight: 1.5

class NPCCar(Car):
    """A car (no distinction from ``Car``, as in CARLA)."""
    pass

class Van(Car):
    """A van (a car in the trace)."""
    blueprint: Uniform(*blueprints.blueprintsInCategory("van"))
    defaultWidth: 2
    defaultLength: 5
    defaultHeight: 2

class Truck(CarlaActor, Truck):
    """A truck."""
    blueprint: Uniform(*blueprints.blueprintsInCategory("truck"))
    defaultKind: 'truck'
    defaultWidth: 2.5
    defaultLength: 7.5
    defaultHeight: 3

class Bus(CarlaActor, Bus):
    """A bus."""
    blueprint: Uniform(*blueprints.blueprintsInCategory("bus"))
    defaultKind: 'bus'
    defaultWidth: 4
    defaultLength: 10
    defaultHeight: 4

class Motorcycle(CarlaActor, Motorcycle):
    """A motorcycle with its rider."""
    blueprint: Uniform(*blueprints.blueprintsInCategory("motorcycle"))
    defaultKind: 'motorcycle'
    defaultWidth: 1
    defaultLength: 2
    defaultHeight: 1.5

class Bicycle(CarlaActor, Bicycle):
    """A bicycle with its rider."""
    blueprint: Uniform(*blueprints.blueprintsInCategory("bicycle"))
    defaultKind: 'bicycle'
    defaultWidth: 1
    defaultLength: 2
    defaultHeight: 1.5

class Pedestrian(CarlaActor, Pedestrian):
    """A pedestrian; CARLA walker blueprints."""
    blueprint: Uniform(*blueprints.blueprintsInCategory("walker"))
    defaultKind: 'pedestrian'
    defaultWidth: 0.5
    defaultLength: 0.5
    defaultHeight: 1.5
    carlaController: None

class Prop(CarlaActor, Obstacle):
    """A static prop on the road: an obstacle that collides."""
    regionContainedIn: road
    position: new Point on road
    parentOrientation: Range(0, 360) deg
    defaultKind: 'obstacle'
    defaultWidth: 0.5
    defaultLength: 0.5
    defaultHeight: 0.5
    physics: False

class Trash(Prop):
    blueprint: Uniform(*blueprints.blueprintsInCategory("trash"))
class Cone(Prop):
    blueprint: Uniform(*blueprints.blueprintsInCategory("cone"))
class Debris(Prop):
    blueprint: Uniform(*blueprints.blueprintsInCategory("debris"))
class VendingMachine(Prop):
    blueprint: Uniform(*blueprints.blueprintsInCategory("vendingMachine"))
class Chair(Prop):
    blueprint: Uniform(*blueprints.blueprintsInCategory("chair"))
class BusStop(Prop):
    blueprint: Uniform(*blueprints.blueprintsInCategory("busStop"))
class Advertisement(Prop):
    blueprint: Uniform(*blueprints.blueprintsInCategory("advertisement"))
class Garbage(Prop):
    blueprint: Uniform(*blueprints.blueprintsInCategory("garbage"))
class Container(Prop):
    blueprint: Uniform(*blueprints.blueprintsInCategory("container"))
class Table(Prop):
    blueprint: Uniform(*blueprints.blueprintsInCategory("table"))
class Barrier(Prop):
    blueprint: Uniform(*blueprints.blueprintsInCategory("barrier"))
class PlantPot(Prop):
    blueprint: Uniform(*blueprints.blueprintsInCategory("plantpot"))
class Mailbox(Prop):
    blueprint: Uniform(*blueprints.blueprintsInCategory("mailbox"))
class Gnome(Prop):
    blueprint: Uniform(*blueprints.blueprintsInCategory("gnome"))
class CreasedBox(Prop):
    blueprint: Uniform(*blueprints.blueprintsInCategory("creasedbox"))
class Case(Prop):
    blueprint: Uniform(*blueprints.blueprintsInCategory("case"))
class Box(Prop):
    blueprint: Uniform(*blueprints.blueprintsInCategory("box"))
class Bench(Prop):
    blueprint: Uniform(*blueprints.blueprintsInCategory("bench"))
class Barrel(Prop):
    blueprint: Uniform(*blueprints.blueprintsInCategory("barrel"))
class ATM(Prop):
    blueprint: Uniform(*blueprints.blueprintsInCategory("atm"))
class Kiosk(Prop):
    blueprint: Uniform(*blueprints.blueprintsInCategory("kiosk"))
class IronPlate(Prop):
    blueprint: Uniform(*blueprints.blueprintsInCategory("ironplate"))
class TrafficWarning(Prop):
    blueprint: Uniform(*blueprints.blueprintsInCategory("trafficwarning"))
