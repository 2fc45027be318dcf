"""Scenic simulator interface for highway-env.

A :class:`HighwayEnvSimulation` creates one highway-env object per Scenic object
(vehicles, pedestrians, static props), applies the driving-domain actions of
Scenic behaviours as low-level controls, advances highway-env's physics for one
Scenic time step and reads the new state back into Scenic.

The ego is special: when an :class:`EgoDriver` is given (the Gymnasium env is
one), it creates the ego vehicle (e.g. an ``MDPVehicle`` for highway-env's
``DiscreteMetaAction``) and applies the agent's action at the start of every
step; the ego's Scenic behaviour is then ignored. Without one, the ego is driven
by its Scenic behaviour like every other agent.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Dict, List, Optional, Protocol

import numpy as np
from scenic.core.simulators import SimulationCreationError
from scenic.core.vectors import Vector
from scenic.domains.driving.actions import Steers, Walks
from scenic.domains.driving.controllers import (
    PIDLateralController,
    PIDLongitudinalController,
)
from scenic.domains.driving.simulators import DrivingSimulation, DrivingSimulator

from envs.coordinates import (
    hw_to_scenic_heading,
    hw_to_scenic_position,
    hw_to_scenic_velocity,
    scenic_to_hw_heading,
    scenic_to_hw_position,
    scenic_to_hw_velocity,
    wrap_angle,
)
from envs.hw_road import EventRoad
from envs.scenic_highway.actors import Pedestrian, Prop, ScenicVehicle

__all__ = ["EgoDriver", "HighwayEnvSimulator", "HighwayEnvSimulation", "ActorEvent"]


class EgoDriver(Protocol):
    """Who drives the ego when it is not its Scenic behaviour."""

    def create_ego(self, road: EventRoad, position: np.ndarray, heading: float, speed: float, obj: Any):
        """Create and return the highway-env vehicle for the ego (not yet added to the road)."""

    def before_physics(self, simulation: "HighwayEnvSimulation") -> None:
        """Called at the start of every step; applies the agent's action to the ego."""


@dataclass
class ActorEvent:
    """Something that happened during a step: a collision, a lane change, leaving the road."""

    time: float
    kind: str
    actors: List[str]
    detail: Dict[str, Any] = field(default_factory=dict)

    def as_dict(self) -> Dict[str, Any]:
        return {"time": round(self.time, 6), "kind": self.kind, "actors": list(self.actors), **self.detail}


class HighwayEnvSimulator(DrivingSimulator):
    """Runs Scenic driving-domain scenarios in highway-env.

    Args:
        network: the Scenic road network of the scenario (``network`` in the model).
        simulation_frequency: physics steps per second; Scenic's time step is split
            into ``simulation_frequency * timestep`` physics steps.
        road_factory: builds the highway-env road for a scene; defaults to
            converting ``network`` with :func:`envs.road_network.load_road_network`.
        ego_driver: drives the ego instead of its Scenic behaviour (see :class:`EgoDriver`).
    """

    def __init__(
        self,
        network=None,
        *,
        simulation_frequency: int = 15,
        road_factory: Optional[Callable[[Any], EventRoad]] = None,
        ego_driver: Optional[EgoDriver] = None,
    ) -> None:
        super().__init__()
        self.network = network
        self.simulation_frequency = int(simulation_frequency)
        self.road_factory = road_factory or self._default_road
        self.ego_driver = ego_driver

    def _default_road(self, scene) -> EventRoad:
        from envs.road_network import load_road_network

        converted = load_road_network(scene.params["map"])
        return EventRoad(network=converted.hw_network, np_random=np.random.default_rng(0))

    def createSimulation(self, scene, **kwargs) -> "HighwayEnvSimulation":
        if kwargs.get("timestep") is None:
            kwargs["timestep"] = 0.2
        return HighwayEnvSimulation(scene, self, **kwargs)


def _key(obj) -> int:
    """Identity of a Scenic object shared by it and its dynamic proxy (behaviours see the proxy)."""
    return id(object.__getattribute__(obj, "_dynamicProxy"))


def _object_label(obj) -> str:
    return type(obj).__name__


class HighwayEnvSimulation(DrivingSimulation):
    """One Scenic simulation running in highway-env (see :class:`HighwayEnvSimulator`)."""

    def __init__(self, scene, simulator: HighwayEnvSimulator, **kwargs) -> None:
        self.simulator = simulator
        self.road: EventRoad = simulator.road_factory(scene)
        self.ego_driver = simulator.ego_driver
        self.hw_of: Dict[int, Any] = {}
        self.names: Dict[int, str] = {}
        self.events: List[ActorEvent] = []
        self.ego_vehicle = None
        self._agent_drives = False
        self._collided_pairs = set()
        self._parent_yaw: Dict[int, Any] = {}
        self._ego_behavior_set_aside = False
        self._last_heading: Dict[int, float] = {}
        self._angular_speed: Dict[int, float] = {}
        timestep = kwargs["timestep"]
        self.frames = max(1, int(round(simulator.simulation_frequency * timestep)))
        self.dt = timestep / self.frames
        super().__init__(scene, **kwargs)

    # ---------------------------------------------------------------- creation
    def setup(self) -> None:
        counts: Dict[str, int] = {}
        for obj in self.scene.objects:
            if obj is self.scene.egoObject:
                self.names[id(obj)] = "ego"
            else:
                label = getattr(obj, "name", None) or _object_label(obj)
                counts[label] = counts.get(label, 0) + 1
                self.names[id(obj)] = f"{label}{counts[label]}"
        super().setup()

    def _createObject(self, obj) -> None:
        # Same steps as Scenic's Simulation._createObject, but the dynamic proxy (the
        # mutable stand-in behaviours see) is a shallow copy of the sampled object:
        # Scenic's own copy re-resolves every default property through the road
        # network, which cost ~7 ms per object and dominated reset().
        self.objects.append(obj)
        if obj.behavior:
            self.agents.append(obj)
        proxy = object.__new__(type(obj))
        object.__getattribute__(proxy, "__dict__").update(object.__getattribute__(obj, "__dict__"))
        object.__setattr__(proxy, "_dynamicProxy", proxy)
        object.__setattr__(obj, "_dynamicProxy", proxy)
        self.createObjectInSimulator(obj)
        obj.startDynamicSimulation()

    def createObjectInSimulator(self, obj) -> None:
        position = scenic_to_hw_position(obj.position[0], obj.position[1])
        heading = scenic_to_hw_heading(obj.heading)
        velocity = obj.velocity
        speed = max(math.hypot(velocity[0], velocity[1]), float(getattr(obj, "speed", 0.0) or 0.0))
        name = self.names.pop(id(obj), None) or f"{_object_label(obj)}{len(self.hw_of) + 1}"
        key = _key(obj)
        self.names[key] = name
        is_ego = obj is self.scene.egoObject
        hw = None
        if is_ego and self.ego_driver is not None:
            hw = self.ego_driver.create_ego(self.road, position, heading, speed, obj)
            if hw is not None and not isinstance(obj, Steers):
                raise SimulationCreationError(
                    f"the ego is a {_object_label(obj)}, but an agent can only drive a vehicle; "
                    "make the ego a Car (or run with ego_policy='scenic')"
                )
        if hw is not None:
            hw.name = "ego"
            self._agent_drives = True
            self.road.vehicles.append(hw)
        elif isinstance(obj, Walks):
            hw = Pedestrian(self.road, position, heading, speed, length=obj.length, width=obj.width, name=name)
            hw.set_walking(heading, speed)
            self.road.vehicles.append(hw)
        elif isinstance(obj, Steers) or getattr(obj, "isVehicle", False):
            hw = ScenicVehicle(self.road, position, heading, speed, length=obj.length, width=obj.width, name=name)
            self.road.vehicles.append(hw)
        else:
            hw = Prop(self.road, position, heading, length=obj.length, width=obj.width, name=name)
            self.road.objects.append(hw)
        hw.scenic_kind = _object_label(obj)
        hw.color = _hw_color(obj, is_ego)
        if is_ego:
            self.ego_vehicle = hw
        self.hw_of[key] = hw
        self._last_heading[key] = hw.heading
        self._angular_speed[key] = 0.0
        if getattr(obj, "elevation", None) is None:
            obj.elevation = 0.0

    def updateObjects(self) -> None:
        super().updateObjects()
        if self._agent_drives and not self._ego_behavior_set_aside:
            # Scenic starts every behaviour before the first step; once started, the
            # agent-driven ego's own behaviour is stopped and never stepped.
            self._ego_behavior_set_aside = True
            ego = self.scene.egoObject
            if ego.behavior is not None:
                if ego.behavior._isRunning:
                    ego.behavior._stop()
                ego.behavior = None

    # ------------------------------------------------------------------ actions
    def executeActions(self, allActions) -> None:
        super().executeActions(allActions)
        for agent in allActions:
            hw = self.hw_of.get(_key(agent))
            if isinstance(hw, ScenicVehicle) and isinstance(agent, Steers):
                hw.set_controls(agent.throttle, agent.brake, agent.steer, agent.hand_brake, agent.reverse)

    def set_actor_position(self, obj, pos) -> None:
        """Teleport an actor (``SetPositionAction``)."""
        hw = self.hw_of[_key(obj)]
        hw.position = scenic_to_hw_position(pos[0], pos[1])
        if hasattr(hw, "on_state_update"):
            hw.on_state_update()

    def set_actor_velocity(self, obj, vel) -> None:
        """Set an actor's velocity (``SetVelocityAction``, ``SetSpeedAction``)."""
        hw = self.hw_of[_key(obj)]
        if hasattr(hw, "set_velocity"):
            vx, vy = scenic_to_hw_velocity(vel[0], vel[1])
            hw.set_velocity(vx, vy)

    def set_walking(self, obj, heading=None, speed=None) -> None:
        """Set a pedestrian's walking direction (Scenic heading) and/or speed."""
        hw = self.hw_of[_key(obj)]
        hw.set_walking(None if heading is None else scenic_to_hw_heading(heading), speed)

    # --------------------------------------------------------------------- step
    def step(self) -> None:
        if self.ego_driver is not None:
            self.ego_driver.before_physics(self)
        road = self.road
        t0 = self.currentTime * self.timestep
        for frame in range(self.frames):
            road.act()
            road.step(self.dt)
            for a, b in road.new_collisions:
                pair = frozenset((id(a), id(b)))
                if pair in self._collided_pairs:
                    continue
                self._collided_pairs.add(pair)
                self.events.append(
                    ActorEvent(t0 + (frame + 1) * self.dt, "collision", [_hw_name(a), _hw_name(b)])
                )
        for key, hw in self.hw_of.items():
            previous = self._last_heading[key]
            self._angular_speed[key] = -wrap_angle(hw.heading - previous) / self.timestep
            self._last_heading[key] = hw.heading

    def getProperties(self, obj, properties) -> Dict[str, Any]:
        hw = self.hw_of[_key(obj)]
        x, y = hw_to_scenic_position(hw.position[0], hw.position[1])
        heading = hw_to_scenic_heading(hw.heading)
        key = _key(obj)
        parent_yaw = self._parent_yaw.get(key)
        if parent_yaw is None:
            parent = obj.parentOrientation
            # In 2D scenes the parent orientation is a pure yaw; then the local yaw is a
            # difference of angles (Scenic's general quaternion path costs ~0.8 ms).
            flat = abs(parent.pitch) < 1e-12 and abs(parent.roll) < 1e-12
            parent_yaw = self._parent_yaw[key] = parent.yaw if flat else False
        if parent_yaw is False:
            yaw, _, _ = obj.parentOrientation.globalToLocalAngles(heading, 0, 0)
        else:
            yaw = wrap_angle(heading - parent_yaw)
        vx, vy = hw_to_scenic_velocity(*hw.velocity)
        angular = self._angular_speed[key]
        values = dict(
            position=Vector(x, y, 0.0),
            yaw=yaw,
            pitch=0.0,
            roll=0.0,
            velocity=Vector(vx, vy, 0.0),
            speed=abs(float(hw.speed)),
            angularSpeed=angular,
            angularVelocity=Vector(0.0, 0.0, angular),
        )
        if "elevation" in properties:
            values["elevation"] = 0.0
        return values

    # ---------------------------------------------------------- controllers
    def getLaneFollowingControllers(self, agent):
        dt = self.timestep
        if agent.isCar:
            return (
                PIDLongitudinalController(K_P=0.5, K_D=0.1, K_I=0.7, dt=dt),
                PIDLateralController(K_P=0.3, K_D=0.2, K_I=0.0, dt=dt),
            )
        return super().getLaneFollowingControllers(agent)

    def getTurningControllers(self, agent):
        dt = self.timestep
        if agent.isCar:
            return (
                PIDLongitudinalController(K_P=0.5, K_D=0.1, K_I=0.7, dt=dt),
                PIDLateralController(K_P=0.6, K_D=0.2, K_I=0.0, dt=dt),
            )
        return super().getTurningControllers(agent)

    def getLaneChangingControllers(self, agent):
        dt = self.timestep
        if agent.isCar:
            return (
                PIDLongitudinalController(K_P=0.5, K_D=0.1, K_I=0.7, dt=dt),
                PIDLateralController(K_P=0.2, K_D=0.2, K_I=0.0, dt=dt),
            )
        return super().getLaneChangingControllers(agent)

    # ------------------------------------------------------------------ state
    def actor_name(self, obj) -> str:
        """The name events and traces use for a Scenic object (``ego``, ``Car1``, ...)."""
        return self.names[_key(obj)]

    def hw_object(self, obj):
        """The highway-env object standing for a Scenic object."""
        return self.hw_of[_key(obj)]


_KIND_COLORS = {
    "Pedestrian": (255, 140, 0),
    "Truck": (150, 100, 200),
}
_EGO_COLOR = (50, 200, 0)
_CAR_COLOR = (100, 200, 255)
_PROP_COLOR = (120, 120, 120)


def _hw_color(obj, is_ego: bool):
    if is_ego:
        return _EGO_COLOR
    for cls in type(obj).__mro__:
        if cls.__name__ in _KIND_COLORS:
            return _KIND_COLORS[cls.__name__]
    if isinstance(obj, (Steers,)) or getattr(obj, "isVehicle", False):
        return _CAR_COLOR
    return _PROP_COLOR


def _hw_name(hw) -> str:
    return getattr(hw, "name", None) or type(hw).__name__
