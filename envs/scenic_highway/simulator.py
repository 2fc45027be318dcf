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
from envs.scenic_highway.readback import update_objects
from envs.errors import UnsupportedConstructError
from envs.road_network import load_road_network
from scenario_bank.elements import ActorKind

__all__ = [
    "EgoDriver",
    "HighwayEnvSimulator",
    "HighwayEnvSimulation",
    "ActorEvent",
    "SpeedScheduledLateralController",
]


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
        # A script's `with name "cutter"` names its actor exactly "cutter" when no other object has that
        # name; the others are counted per label (Car1, Car2, ...; two objects named "walker": walker1, walker2).
        others = [obj for obj in self.scene.objects if obj is not self.scene.egoObject]
        given = [getattr(obj, "name", None) for obj in others]
        counts: Dict[str, int] = {}
        for obj in self.scene.objects:
            if obj is self.scene.egoObject:
                self.names[id(obj)] = "ego"
            else:
                label = getattr(obj, "name", None) or _object_label(obj)
                counts[label] = counts.get(label, 0) + 1
                self.names[id(obj)] = f"{label}{counts[label]}"
        taken = set(self.names.values())
        for obj, name in zip(others, given):
            if name and name != "ego" and given.count(name) == 1 and name not in taken:
                self.names[id(obj)] = name
                taken.add(name)
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
        _reject_carla_only_properties(obj)
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
        hw.kind = "ego" if is_ego else _vocabulary_kind(obj)
        hw.color = _hw_color(obj, is_ego)
        if is_ego:
            self.ego_vehicle = hw
        self.hw_of[key] = hw
        self._last_heading[key] = hw.heading
        self._angular_speed[key] = 0.0
        if getattr(obj, "elevation", None) is None:
            obj.elevation = 0.0

    def updateObjects(self) -> None:
        if self._replayOut or self.replaying:
            super().updateObjects()  # Scenic's replay recording and divergence checks
        else:
            update_objects(self, self.getProperties)
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
        if isinstance(hw, Pedestrian) and _along_heading(vel, obj.heading):
            # ``SetSpeedAction`` builds its velocity from the heading at the start
            # of the step; a walking direction set in the same step must survive.
            hw.set_walking(None, math.hypot(vel[0], vel[1]))
            return
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
    # Lateral gains are those at SpeedScheduledLateralController.REFERENCE_SPEED
    # (10 m/s); tuned on highway_straight (10-40 m/s, starting off-centre), the
    # CARLA towns (FollowLaneBehavior through junctions and corners) and the
    # urban_crossroads turns. The longitudinal controllers are Scenic's without
    # the integral term: throttle maps straight to acceleration here and nothing
    # (drag, slope) needs a steady throttle, so the integral only made the speed
    # overshoot its target by 10% and oscillate.
    def getLaneFollowingControllers(self, agent):
        dt = self.timestep
        if agent.isCar:
            return (
                PIDLongitudinalController(K_P=0.5, K_D=0.1, K_I=0.0, dt=dt),
                SpeedScheduledLateralController(agent, K_P=0.3, K_D=0.06, K_I=0.0, dt=dt),
            )
        return super().getLaneFollowingControllers(agent)

    def getTurningControllers(self, agent):
        dt = self.timestep
        if agent.isCar:
            return (
                PIDLongitudinalController(K_P=0.5, K_D=0.1, K_I=0.0, dt=dt),
                SpeedScheduledLateralController(agent, K_P=0.5, K_D=0.06, K_I=0.0, dt=dt),
            )
        return super().getTurningControllers(agent)

    def getLaneChangingControllers(self, agent):
        dt = self.timestep
        if agent.isCar:
            # Gains stop growing below 10 m/s: a slow car changes lanes at a
            # moderate angle instead of in the same time as a fast one.
            return (
                PIDLongitudinalController(K_P=0.5, K_D=0.1, K_I=0.0, dt=dt),
                SpeedScheduledLateralController(agent, K_P=0.1, K_D=0.06, K_I=0.0, dt=dt, min_speed=10.0),
            )
        return super().getLaneChangingControllers(agent)

    # ------------------------------------------------------------------ state
    def actor_name(self, obj) -> str:
        """The name events and traces use for a Scenic object (``ego``, ``Car1``, ...)."""
        return self.names[_key(obj)]

    def hw_object(self, obj):
        """The highway-env object standing for a Scenic object."""
        return self.hw_of[_key(obj)]


class SpeedScheduledLateralController(PIDLateralController):
    """Scenic's PID on the cross-track error, with gains scheduled by speed.

    In highway-env's kinematic bicycle model the lateral acceleration a steering
    angle produces grows with the square of the speed, so fixed gains that track
    well at town speeds oscillate and diverge at highway speeds (Scenic's
    behaviours run at 5 Hz). The gains given are those at :attr:`REFERENCE_SPEED`;
    the proportional and integral gains are scaled by ``(REFERENCE_SPEED / v) ** 2``,
    which keeps the closed loop's bandwidth the same at every speed ``v``, and the
    derivative gain by ``REFERENCE_SPEED / v``: the sideslip makes the measured
    cross-track rate respond to the steering within one step, in proportion to
    ``v``, and a larger derivative gain makes that loop ring at 2.5 Hz. The speed
    is floored at :attr:`MIN_SPEED`.

    The derivative term starts at zero instead of kicking on the first step. As a
    safety net for path glitches (``signedDistanceTo`` returns the right distance
    with the wrong sign on a segment pointing backwards, as Scenic's CARLA-town
    centerlines had at geometry seams, see
    :func:`~envs.scenic_highway.model_support.remove_backward_seams`), a sign flip
    of the error larger than the car could have moved sideways in one step is
    undone, for at most :attr:`MAX_SIGN_CORRECTIONS` steps in a row.
    """

    REFERENCE_SPEED = 10.0
    MIN_SPEED = 3.0
    MAX_SIGN_CORRECTIONS = 2

    def __init__(self, agent, K_P=0.3, K_D=0.2, K_I=0.0, dt=0.1, min_speed=None):
        super().__init__(K_P=K_P, K_D=K_D, K_I=K_I, dt=dt)
        self.agent = agent
        if min_speed is not None:
            self.MIN_SPEED = float(min_speed)
        self.base_gains = (K_P, K_D, K_I)
        self._previous: Optional[float] = None
        self._corrections = 0

    def _speed(self) -> float:
        try:
            speed = float(self.agent.speed or 0.0)
        except (AttributeError, TypeError):
            speed = 0.0
        return max(abs(speed), self.MIN_SPEED)

    def _deglitch(self, cte: float, speed: float) -> float:
        previous = self._previous
        if previous is None:
            # Scenic's controller starts from a previous error of 0, so a lane
            # change (starting 3.5 m off) would begin with a derivative kick.
            self.last_error = cte
        elif (
            cte * previous < 0
            and abs(cte) + abs(previous) > 1.5 * speed * self.dt + 0.2
            and self._corrections < self.MAX_SIGN_CORRECTIONS
        ):
            cte = -cte
            self._corrections += 1
        else:
            self._corrections = 0
        self._previous = cte
        return cte

    def run_step(self, cte):
        speed = self._speed()
        cte = self._deglitch(float(cte), speed)
        ratio = self.REFERENCE_SPEED / speed
        k_p, k_d, k_i = self.base_gains
        self.Kp, self.Kd, self.Ki = k_p * ratio**2, k_d * ratio, k_i * ratio**2
        return super().run_step(cte)


_KIND_COLORS = {
    "Pedestrian": (255, 140, 0),
    "Bus": (150, 100, 200),
    "Truck": (150, 100, 200),
    "Motorcycle": (230, 60, 170),
    "Bicycle": (230, 60, 170),
}
_EGO_COLOR = (50, 200, 0)
_CAR_COLOR = (100, 200, 255)
_PROP_COLOR = (120, 120, 120)


_FACADE_KIND_CLASSES = {ActorKind.PEDESTRIAN: "Pedestrian", ActorKind.BUS: "Bus", ActorKind.TRUCK: "Truck",
                        ActorKind.MOTORCYCLE: "Motorcycle", ActorKind.BICYCLE: "Bicycle"}


def _facade_kind(obj):
    """The kind a CARLA-façade object's blueprint chose (``dv2sKind``), or None for other objects."""
    try:
        kind = object.__getattribute__(obj, "dv2sKind")
    except AttributeError:
        return None
    return kind if isinstance(kind, str) else None


def _hw_color(obj, is_ego: bool):
    if is_ego:
        return _EGO_COLOR
    kind = _facade_kind(obj)
    if kind is not None:
        if kind in _FACADE_KIND_CLASSES:
            return _KIND_COLORS[_FACADE_KIND_CLASSES[kind]]
        return _CAR_COLOR if kind == ActorKind.CAR else _PROP_COLOR
    for cls in type(obj).__mro__:
        if cls.__name__ in _KIND_COLORS:
            return _KIND_COLORS[cls.__name__]
    if isinstance(obj, (Steers,)) or getattr(obj, "isVehicle", False):
        return _CAR_COLOR
    return _PROP_COLOR


_CARLA_ONLY_PROPERTIES = {
    "blueprint": "the CARLA blueprint of an actor",
    "rolename": "the CARLA role name of an actor",
}


def _reject_carla_only_properties(obj) -> None:
    """Fail clearly on properties only Scenic's CARLA interface understands (``with blueprint ...``)."""
    if _facade_kind(obj) is not None:
        return  # a class of the CARLA/MetaDrive façade (envs/scenic_highway/carla): blueprint maps to size and kind
    for name, meaning in _CARLA_ONLY_PROPERTIES.items():
        value = getattr(obj, name, None)
        if value is not None:
            raise UnsupportedConstructError(
                f"unsupported construct `{name}` ({_object_label(obj)} with {name} {value!r}): "
                f"`{name}` is {meaning} in Scenic's CARLA interface (scenic.simulators.carla) "
                "and has no highway-env equivalent. Remove it; set width and length to size "
                "an object."
            )


def _along_heading(vel, heading: float) -> bool:
    """True when a (Scenic) velocity points along a (Scenic) heading."""
    vx, vy = float(vel[0]), float(vel[1])
    speed = math.hypot(vx, vy)
    if speed < 1e-9:
        return True
    return abs(wrap_angle(math.atan2(-vx, vy) - heading)) < 1e-6


def _vocabulary_kind(obj) -> str:
    """The element-vocabulary type of a Scenic object (``scenario_bank.elements.PARTICIPANTS``)."""
    kind = _facade_kind(obj)
    if kind is not None:
        return kind
    names = {cls.__name__ for cls in type(obj).__mro__}
    if isinstance(obj, Walks) or "Pedestrian" in names:
        return "pedestrian"
    for cls_name, kind in (("Bus", "bus"), ("Motorcycle", "motorcycle"), ("Bicycle", "bicycle")):
        if cls_name in names:
            return kind
    if "Truck" in names:
        return "truck"
    if isinstance(obj, Steers) or getattr(obj, "isVehicle", False):
        return "car"
    return "obstacle"


def _hw_name(hw) -> str:
    return getattr(hw, "name", None) or type(hw).__name__
