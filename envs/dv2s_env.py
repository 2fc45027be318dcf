"""``DV2S-v0``: a Scenic scenario sampled into a highway-env episode.

Each ``reset`` samples a scene from a Scenic script (seeded), builds the
highway-env road from the script's OpenDRIVE map, and starts the Scenic
simulation; each ``step`` applies the agent's action to the ego through a
highway-env action type while every other actor runs its Scenic behaviour.

The configuration follows highway-env: :meth:`DV2SEnv.default_config` documents
every key, and ``config=`` overrides any of them.
"""

from __future__ import annotations

import copy
import math
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Union
import warnings

import numpy as np
from highway_env import utils as hw_utils
from highway_env.envs.common.abstract import AbstractEnv
from highway_env.envs.common.observation import KinematicObservation

import envs.rendering  # noqa: F401  (sets SDL/XDG variables before any viewer starts pygame)
from envs.config_check import RENDER_MODES, check_config, check_render_mode
from envs.errors import InvalidActionError, InvalidSeedError, ResetNeededError, SceneSamplingError
from scenario_bank.errors import WrongTypeError
from envs.hw_road import EventRoad
from envs.observations import FastKinematicObservation
from envs.safety_metrics import STANDING_SPEED, path_is_free, time_to_collision
from envs.scenarios import (
    CompiledScenario,
    compile_scenario,
    looks_like_source,
    read_scenario_file,
    runtime_construct_error,
    step_timeout_error,
)
from envs.scenic_highway.simulator import ActorEvent, HighwayEnvSimulator
from envs.scenic_highway import stepping
from envs.scenic_highway.stepping import ExternalStepper, StepOutcome, StepOvertime, step_watchdog
from envs.trace import EpisodeTrace, actor_state
from envs.jailed_env import JailedDV2SEnv
from envs.road_network import load_road_network
from scenario_bank import scenario_path, select_scenarios
from scenario_bank.jail import require_jail
from scenario_bank.maps import list_maps
from scenario_bank.shipped import is_shipped_text
from scenario_bank.scenic2 import upgrade_scenic2
from scenario_bank.errors import MissingFileError, SettingError
from scenario_bank.elements import Action
from envs.rendering import DV2SViewer

__all__ = ["DV2SEnv", "ScenarioRef", "check_env_config", "resolve_scenarios"]

if getattr(sys.excepthook, "__module__", "") == "scenic.core.errors":
    # Scenic replaces Python's default excepthook on import (only the default one); a user's own tracebacks
    # stay Python's, while Scenic's errors still name the script's line in their message
    sys.excepthook = sys.__excepthook__

ScenarioSpec = Union[None, str, os.PathLike, Sequence[str]]


@dataclass(frozen=True)
class ScenarioRef:
    """One scenario the env can run: its name and either a file path or source text."""

    name: str
    path: Optional[str] = None
    source: Optional[str] = None

    def text(self) -> str:
        return self.source if self.source is not None else read_scenario_file(self.path)


def resolve_scenarios(spec: ScenarioSpec, bank_dir: Optional[str] = None) -> List[ScenarioRef]:
    """Turn the ``scenario=`` argument into the list of scenarios episodes sample from.

    ``None`` is the whole bank; a string is a bank name, ``tag:<tag>``, a path to a
    ``.scenic`` file or Scenic source text; a list combines names and tags.
    """
    if isinstance(spec, (list, tuple)) and spec and all(isinstance(item, ScenarioRef) for item in spec):
        return list(spec)
    if isinstance(spec, os.PathLike):
        spec = os.fspath(spec)
    if isinstance(spec, str):
        if len(spec) > 4096 or looks_like_source(spec):  # no file name is that long: text (and a bounded regex)
            return [ScenarioRef(name="<string>", source=spec)]
        if spec.endswith(".scenic") or os.sep in spec:
            path = Path(spec)
            if not path.is_file():
                raise MissingFileError(
                    f"scenario file {spec!r} does not exist; pass an existing .scenic path, "
                    "a bank name or Scenic source text"
                )
            name = path.parent.name if path.name == "scenario.scenic" else path.stem  # bank entry folder
            return [ScenarioRef(name=name, path=str(path.resolve()))]
    elif spec is not None and (
        not isinstance(spec, Sequence) or not all(isinstance(item, str) for item in spec)
    ):
        raise WrongTypeError(
            f"scenario must be None, a bank name, 'tag:<tag>', a .scenic path, Scenic source text "
            f"or a list of bank names/tags, not {spec!r}"
        )
    names = select_scenarios(spec, bank_dir)
    return [ScenarioRef(name=n, path=str(scenario_path(n, bank_dir))) for n in names]


def _all_shipped(texts: Sequence[str], config: Optional[dict]) -> bool:
    map_override = (config or {}).get("map")
    if map_override is not None and map_override not in list_maps():
        return False  # a map file of the user's is parsed by Scenic: in the jail
    return all(is_shipped_text(text) for text in texts)


def _is_shipped(text: str) -> bool:
    return is_shipped_text(text)


def _copy_state(state: Dict[str, Any]) -> Dict[str, Any]:
    """Copy of an object's ``__dict__`` whose containers are not shared with the original."""
    return {k: (v.copy() if isinstance(v, (list, dict, set)) else v) for k, v in state.items()}


class _SceneStepper(ExternalStepper):
    """An :class:`ExternalStepper` that also sets aside the running state of the scene's
    shared Scenic objects.

    Scenes sampled from one compiled scenario share objects that hold the state of
    a running simulation: the scenario's single ``DynamicScenario`` (running flag,
    bound objects, requirement monitors, elapsed time), every behaviour whose
    arguments are not random (``with behavior FollowLaneBehavior(target_speed=10)``
    is one object for all scenes) and the monitors. Several envs of the same
    scenario in one process (``SyncVectorEnv``, ``DummyVecEnv``) each keep a
    suspended simulation, so that state is swapped with the rest of Scenic's
    globals: saved when another simulation takes over, restored when this one resumes.
    """

    def __init__(self, make_simulation, scene) -> None:
        super().__init__(make_simulation)
        shared = [scene.dynamicScenario, *(o.behavior for o in scene.objects), *scene.monitors]
        self._shared = list({id(x): x for x in shared if x is not None}.values())
        self._idle_states: Optional[List[Dict[str, Any]]] = None
        self._running_states: Optional[List[Dict[str, Any]]] = None

    def _run(self) -> StepOutcome:
        stepping.release_veneer()  # any other simulation of this scenario is set aside: all is idle
        self._idle_states = [_copy_state(x.__dict__) for x in self._shared]
        return super()._run()

    def _install(self) -> None:
        resuming = stepping.installed_stepper() is not self
        super()._install()
        if resuming and self._running_states is not None:
            for x, state in zip(self._shared, self._running_states):
                x.__dict__.clear()
                x.__dict__.update(state)
            self._running_states = None

    def _save_globals(self) -> None:
        super()._save_globals()
        if self._idle_states is not None:
            self._running_states = [dict(x.__dict__) for x in self._shared]
            for x, state in zip(self._shared, self._idle_states):
                x.__dict__.clear()
                x.__dict__.update(_copy_state(state))


def weights_standing(config: Dict[str, Any]) -> bool:
    """Whether the reward has a ``standing`` term (computing it costs a pass over the actors)."""
    return bool(config["reward_weights"].get("standing"))


def _jsonable(value: Any) -> Any:
    if isinstance(value, (bool, int, str)) or value is None:
        return value
    if isinstance(value, float):
        return value if math.isfinite(value) else str(value)
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (np.floating,)):
        return float(value)
    if isinstance(value, np.ndarray):  # e.g. a ContinuousAction action
        return _jsonable(value.tolist())
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    try:
        return float(value)
    except (TypeError, ValueError):
        return str(value)


class DV2SEnv(AbstractEnv):
    """Gymnasium environment running Scenic scenarios in highway-env.

    Args:
        scenario: a bank name, ``tag:<tag>``, a path to a ``.scenic`` file, Scenic
            source text, or a list of bank names/tags (one is sampled per episode).
            ``None`` samples the whole bank.
        config: overrides of :meth:`default_config`.
        render_mode: ``"rgb_array"`` (headless) or ``"human"``.
        bank_dir: a bank folder other than the shipped one.
        trusted: run the scripts in this process, skipping the jail. Only for scripts you
            wrote or reviewed: a Scenic script is Python and can do anything you can. The
            allowlist check of what a script may use (:mod:`scenario_bank.safety`) is not
            skipped: every script passes it, trusted or not.
        jail: ``True`` runs even the shipped scenarios in the jail; ``None`` (default)
            runs the package's own scripts (recognised by content hash) here and every
            other script in the jail, where it cannot reach this process, your files,
            the network or your environment. Without a jail on this machine, untrusted
            scripts are refused with an error naming the fix.
        jail_limits: the jailed worker's limits (:class:`scenario_bank.jail.JailLimits`).

    Untrusted scenarios make ``DV2SEnv(...)`` return a
    :class:`~envs.jailed_env.JailedDV2SEnv` (same interface) instead.
    """

    metadata = {"render_modes": list(RENDER_MODES), "render_fps": 15}
    runs_in_jail = False

    def __new__(
        cls,
        scenario: ScenarioSpec = None,
        config: Optional[dict] = None,
        render_mode: Optional[str] = None,
        bank_dir: Optional[str] = None,
        trusted: bool = False,
        jail: Optional[bool] = None,
        jail_limits: Any = None,
    ):
        check_render_mode(render_mode)
        # Decide where the simulation runs before anything of the scripts is compiled:
        # the package's own scripts (by content hash) here, everything else in the jail.
        if trusted or os.environ.get("DV2S_IN_JAIL") == "1":
            return super().__new__(cls)
        refs = resolve_scenarios(scenario, bank_dir)
        texts = [ref.source if ref.source is not None else read_scenario_file(ref.path) for ref in refs]
        frozen = [ScenarioRef(name=ref.name, path=ref.path, source=text) for ref, text in zip(refs, texts)]
        if jail is not True and _all_shipped(texts, config):
            env = super().__new__(cls)
            env._frozen_refs = frozen  # the text checked is the text compiled: files are not read again
            return env

        require_jail(f"scenario {refs[0].name!r}" if len(refs) == 1 else f"{len(refs)} scenarios")
        return JailedDV2SEnv(frozen, texts, config=config, render_mode=render_mode, limits=jail_limits,
                             default_config=cls.default_config())

    def __init__(
        self,
        scenario: ScenarioSpec = None,
        config: Optional[dict] = None,
        render_mode: Optional[str] = None,
        bank_dir: Optional[str] = None,
        trusted: bool = False,
        jail: Optional[bool] = None,
        jail_limits: Any = None,
    ) -> None:
        frozen = self.__dict__.pop("_frozen_refs", None)
        # trust is decided per text at compile time: explicit, or a script the package ships
        self._trusted = bool(trusted) or os.environ.get("DV2S_IN_JAIL") == "1"
        self._scenario_refs = frozen if frozen is not None else resolve_scenarios(scenario, bank_dir)
        self._bank_dir = bank_dir
        self._compiled: Dict[ScenarioRef, CompiledScenario] = {}
        self._stepper: Optional[ExternalStepper] = None
        self._simulation = None
        self._outcome: Optional[StepOutcome] = None
        self._trace: Optional[EpisodeTrace] = None
        self._episode: Dict[str, Any] = {}
        self._lane_of: Dict[int, Any] = {}
        self._step_events: List[Dict[str, Any]] = []
        self._reset_seed: Optional[int] = None
        self._running_compiled: Optional[CompiledScenario] = None
        super().__init__(config, render_mode)  # configure() checks config before anything is built

    # ------------------------------------------------------------------ config
    def configure(self, config: Optional[dict]) -> None:
        """highway-env's ``configure`` (update the config), after :func:`envs.config_check.check_config`: a
        misspelt key or a value of the wrong type or range is refused here, not at the first ``step``."""
        check_config({**config, **_frequencies(self.config, config)} if isinstance(config, dict) else config,
                     self.default_config())
        super().configure(config)

    @classmethod
    def default_config(cls) -> dict:
        """Default configuration; every key can be overridden with ``config=``.

        Every key given is checked, nested ones too (:func:`envs.config_check.check_config`): a misspelt
        key, reward term or observation/action option is an error naming it and the choices, and so is a number
        of the wrong type or range. A section given replaces the default one whole (a reward term left out weighs 0).

        - ``observation``: highway-env's; ``Kinematics`` (default; route features: :mod:`envs.observations`),
          ``OccupancyGrid``, ``TimeToCollision``, ``LidarObservation`` and ``GrayscaleObservation`` work.
        - ``action``: highway-env action config; ``DiscreteMetaAction`` (default,
          target speeds 0-30 m/s), ``ContinuousAction`` or ``DiscreteAction``.
        - ``simulation_frequency`` / ``policy_frequency`` [Hz]: physics steps and
          agent decisions per second; Scenic behaviours run at the policy frequency.
        - ``duration`` [s]: episode length before truncation.
        - ``ego_policy``: ``"agent"`` (the action drives the ego) or ``"scenic"``
          (the script's ego behaviour drives; actions are ignored).
        - ``map``: override the script's map (a shipped map name or an .xodr path).
        - ``max_sample_iterations``: Scenic rejection-sampling budget per scene.
        - ``step_time_limit`` [s]: CPU-time limit of one simulation step (the first includes
          setting up the scene); a step over it (a behaviour that loops without taking an
          action) raises :class:`~envs.errors.StepTimeoutError` naming the script line.
          Enforced in the main thread (``SIGPROF``); ``None`` disables it.
        - ``upgrade_scenic2``: upgrade Scenic 2 syntax in the scripts to Scenic 3
          before compiling (:mod:`scenario_bank.scenic2`), each rewrite reported
          in a ``UserWarning``; off by default.
        - ``reward_weights``: weight of each reward term (``collision``, ``off_road``,
          ``high_speed``, ``lane_change``, ``low_ttc``, ``standing``: the ego stands
          with nothing 40 m ahead in its strip, the stall the failure miner reports;
          weight 0 by default); ``reward_speed_range`` [m/s]
          maps speed to ``high_speed``; ``ttc_threshold`` [s] triggers ``low_ttc``;
          ``normalize_reward`` maps the sum to [0, 1].
        - ``terminate_on_collision``, ``terminate_off_road``, ``off_road_margin`` [m].
        - rendering: ``screen_width``, ``screen_height``, ``scaling`` [px/m],
          ``centering_position``, ``offscreen_rendering``, ``show_trajectories``.
        """
        config = super().default_config()
        config.update(
            {
                "observation": {
                    "type": "Kinematics",
                    "vehicles_count": 8,
                    "features": ["presence", "x", "y", "vx", "vy", "cos_h", "sin_h"],
                    "absolute": False,
                    "normalize": True,
                    "see_behind": True,
                },
                "action": {
                    "type": "DiscreteMetaAction",
                    "target_speeds": [0.0, 5.0, 10.0, 15.0, 20.0, 25.0, 30.0],
                },
                "simulation_frequency": 15,
                "policy_frequency": 5,
                "duration": 20.0,
                "ego_policy": "agent",
                "map": None,
                "max_sample_iterations": 2000,
                "step_time_limit": 60.0,
                "upgrade_scenic2": False,
                "reward_weights": {
                    "collision": -1.0,
                    "off_road": -1.0,
                    "high_speed": 0.4,
                    "lane_change": -0.05,
                    "low_ttc": -0.1,
                    "standing": 0.0,
                },
                "reward_speed_range": [10.0, 30.0],
                "ttc_threshold": 2.0,
                "normalize_reward": True,
                "terminate_on_collision": True,
                "terminate_off_road": True,
                "off_road_margin": 1.0,
                "screen_width": 600,
                "screen_height": 600,
                "scaling": 5.5,
                "centering_position": [0.5, 0.5],
                "offscreen_rendering": None,
            }
        )
        return config

    def define_spaces(self) -> None:
        """Observation and action types from the config (Kinematics is computed without pandas).

        highway-env builds new space objects on every reset; an unchanged space keeps
        its previous object, so ``env.action_space.seed(s)`` before ``reset`` still
        holds afterwards (Gymnasium's contract that spaces are stable).
        """
        previous = {name: getattr(self, name, None) for name in ("action_space", "observation_space")}
        super().define_spaces()
        for name, space in previous.items():
            if space is not None and space == getattr(self, name):
                setattr(self, name, space)
        if type(self.observation_type) is KinematicObservation:
            self.observation_type.__class__ = FastKinematicObservation

    # ------------------------------------------------------------------- reset
    def reset(self, *, seed: Optional[int] = None, options: Optional[dict] = None):
        """Sample a new scene and start its simulation.

        ``seed`` fixes the scenario choice, the Scenic sample and highway-env's
        randomness. ``options={"scene_seed": s, "scenario": name}`` replays a
        specific scene (used by traces); ``options={"params": {name: value}}`` fixes
        the script's random global parameters (``param x = Range(a, b)``) for this
        scene (used by failure mining; see ``CompiledScenario.parameter_ranges``).
        """
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, int) or seed < 0):
            raise InvalidSeedError(f"reset(seed={seed!r}): a seed is an integer >= 0 (the same seed gives the same "
                                   "scene), or None for a fresh random one")
        self._reset_seed = seed
        self._reset_options = dict(options or {})
        obs, info = super().reset(seed=seed, options=options)
        # highway-env fills the reset info with an (unseeded) sample of the action
        # space; no action was taken, and a random value would break reproducibility.
        info["action"] = None
        info["sample_iterations"] = int(getattr(self._running_compiled, "last_iterations", 0) or 0)
        return obs, info

    def _reset(self) -> None:
        self._close_simulation()
        options = getattr(self, "_reset_options", {}) or {}
        ref = self._choose_scenario(options.get("scenario"))
        compiled = self._compile(ref)
        self._running_compiled = compiled
        scene_seed = int(options.get("scene_seed", self.np_random.integers(0, 2**31 - 1)))
        timestep = 1.0 / self.config["policy_frequency"]
        for attempt in range(20):
            scene = compiled.sample(scene_seed, self.config["max_sample_iterations"], params=options.get("params"))
            road = EventRoad(
                network=self._network_for(compiled),
                np_random=np.random.default_rng(scene_seed),
                record_history=self.config["show_trajectories"],
            )
            simulator = HighwayEnvSimulator(
                simulation_frequency=self.config["simulation_frequency"],
                road_factory=lambda _scene, road=road: road,
                ego_driver=self,
            )
            self.road = road
            stepper = _SceneStepper(
                lambda st, scene=scene: simulator.createSimulation(
                    scene,
                    maxSteps=None,
                    name=ref.name,
                    verbosity=0,
                    timestep=timestep,
                    replay=None,
                    enableReplay=False,
                    enableDivergenceCheck=False,
                    divergenceTolerance=0,
                    continueAfterDivergence=False,
                    allowPickle=False,
                ),
                scene,
            )
            self._stepper = stepper
            outcome = self._run_scenic(stepper.start)
            if outcome.status != "rejected":
                break
            # A requirement failed at time 0: this scene is invalid, draw another.
            scene_seed = int(np.random.default_rng(scene_seed).integers(0, 2**31 - 1))
        else:
            raise SceneSamplingError(
                f"scenario {ref.name!r}: 20 sampled scenes were all rejected when the simulation "
                f"started ({outcome.reason}); check the script's `require` statements"
            )
        self._outcome = outcome
        self._simulation = stepper.simulation or self._simulation
        sim = self._current_simulation()
        self.controlled_vehicles = [sim.ego_vehicle]
        self._lane_of = {id(v): v.lane_index for v in self.road.vehicles}
        params = {k: _jsonable(v) for k, v in scene.params.items()}
        self._episode = {
            "scenario": ref.name,
            "seed": self._reset_seed,
            "scene_seed": scene_seed,
            "params": params,
            "collisions": [],
            "lane_changes": 0,
            "min_ttc": math.inf,
            "min_ttc_time": None,
            "min_ttc_with": None,
            "off_road": False,
        }
        self._step_events = []
        self._trace = EpisodeTrace(
            scenario=ref.name,
            source=compiled.source,
            scenario_path=ref.path,
            seed=self._reset_seed,
            scene_seed=scene_seed,
            params=params,
            config=_jsonable({k: v for k, v in self.config.items()}),
            fixed_params=_jsonable(dict(options.get("params") or {})),
        )
        self._record_state()

    def _run_scenic(self, call, *args) -> StepOutcome:
        """Start or advance the simulation; a name a behaviour uses but nothing defines
        (e.g. a CARLA-only action) becomes an :class:`UnsupportedConstructError`."""
        try:
            with step_watchdog(self.config.get("step_time_limit")):
                return call(*args)
        except NameError as error:
            self._close_simulation()
            raise runtime_construct_error(error, self._running_compiled) from None
        except StepOvertime as overtime:
            self._close_simulation()
            raise step_timeout_error(overtime, self._running_compiled) from None

    def _choose_scenario(self, name: Optional[str]) -> ScenarioRef:
        if name is not None:
            for ref in self._scenario_refs:
                if ref.name == name:
                    return ref
            if not self._trusted:
                raise SettingError(
                    f"reset(options={{'scenario': {name!r}}}): this env was made with "
                    f"{', '.join(repr(r.name) for r in self._scenario_refs)}; a scenario it was not made with "
                    f"needs its own env: gym.make('DV2S-v0', scenario={name!r})")

            return ScenarioRef(name=name, path=str(scenario_path(name, self._bank_dir)))
        if len(self._scenario_refs) == 1:
            return self._scenario_refs[0]
        return self._scenario_refs[int(self.np_random.integers(len(self._scenario_refs)))]

    def _compile(self, ref: ScenarioRef) -> CompiledScenario:
        if ref not in self._compiled:
            text, path, origin = ref.text(), ref.path, None
            if self.config.get("upgrade_scenic2"):
                upgrade = upgrade_scenic2(text)
                if upgrade.changed or upgrade.notes:
                    warnings.warn(f"scenario {ref.name!r}: " + "; ".join(upgrade.report()), UserWarning, stacklevel=3)
                if upgrade.changed:  # compile the upgraded text, not the file (localPath still resolves there)
                    text, path, origin = upgrade.source, None, ref.path
            self._compiled[ref] = compile_scenario(
                text, name=ref.name, path=path, origin=origin, map_override=self.config["map"],
                trusted=self._trusted or _is_shipped(text),
            )
        return self._compiled[ref]

    def _network_for(self, compiled: CompiledScenario):
        self._converted = load_road_network(compiled.map_path)
        return self._converted.hw_network

    def _current_simulation(self):
        if self._stepper is not None and self._stepper.simulation is not None:
            return self._stepper.simulation
        return self._simulation

    # ------------------------------------------------------------- EgoDriver
    def create_ego(self, road, position, heading, speed, obj):
        """Create the agent's vehicle with the action type's vehicle class (EgoDriver protocol)."""
        if self.config["ego_policy"] == "scenic":
            return None
        vehicle = self.action_type.vehicle_class(road, position, heading, speed)
        if hasattr(vehicle, "target_speed"):
            # highway-env snaps a new vehicle's target to the action type's speed grid (0, 5, ... 30 m/s);
            # the script's speed is the one the ego holds until the policy asks for FASTER or SLOWER
            vehicle.target_speed = float(speed)
        vehicle.LENGTH, vehicle.WIDTH = float(obj.length), float(obj.width)
        vehicle.diagonal = math.hypot(vehicle.LENGTH, vehicle.WIDTH)
        route = getattr(obj, "route", None)
        if route and hasattr(vehicle, "route"):
            # `with route [lane, ...]` in the script: the agent's vehicle follows it through junctions.
            vehicle.route = self._converted.route_for(route)
        return vehicle

    def before_physics(self, simulation) -> None:
        """Wait for the agent's action and apply it to the ego (EgoDriver protocol)."""
        self._simulation = simulation
        action = self._stepper.handoff()
        if action is not None and self.config["ego_policy"] != "scenic":
            self.action_type.act(action)

    # -------------------------------------------------------------------- step
    def step(self, action):
        """Apply ``action`` for one policy period; Gymnasium's 5-tuple."""
        if self._stepper is None:
            raise ResetNeededError("step() was called before reset(): call reset() to start an episode first")
        if not self.action_space.contains(self._as_space_action(action)):
            raise InvalidActionError(
                f"action {action!r} is outside the action space {self.action_space} "
                f"of {self.config['action']['type']}; sample from env.action_space"
            )
        return super().step(action)

    def _as_space_action(self, action):
        if isinstance(action, np.ndarray) and action.shape == () and np.issubdtype(action.dtype, np.integer):
            return int(action)
        if isinstance(action, (list, tuple)):
            return np.asarray(action, dtype=np.float32)
        if isinstance(action, np.ndarray) and np.issubdtype(action.dtype, np.floating):
            return action.astype(np.float32)
        return action

    def _simulate(self, action=None) -> None:
        self._step_events = []
        if self._stepper.done:
            return
        simulation = self._current_simulation()
        n_events = len(simulation.events)
        self._outcome = self._run_scenic(self._stepper.advance, action)
        self.steps += simulation.frames
        new = [e.as_dict() for e in simulation.events[n_events:]]
        self._detect_lane_changes(new)
        ego = self.vehicle
        for event in new:
            if event["kind"] == "collision" and "ego" in event["actors"]:
                other = [a for a in event["actors"] if a != "ego"]
                for name in other:
                    if name not in self._episode["collisions"]:
                        self._episode["collisions"].append(name)
        for a, b in self.road.new_collisions:
            for v in (a, b):
                v.color = (220, 30, 30)
        off_road = self._is_off_road(ego)
        if off_road and not self._episode["off_road"]:
            new.append({"time": round(self.time, 6), "kind": "off_road", "actors": ["ego"]})
        self._episode["off_road"] = off_road
        ttc, other = time_to_collision(ego, self.road.vehicles + self.road.objects)
        self._ttc = ttc
        if ttc < self._episode["min_ttc"]:
            self._episode.update(min_ttc=ttc, min_ttc_time=round(self.time, 6), min_ttc_with=other)
        if self._outcome.status != "running":
            new.append({"time": round(self.time, 6), "kind": f"scenic_{self._outcome.status}",
                        "actors": [], "reason": self._outcome.reason})
        self._step_events = new
        self._trace.actions.append(_jsonable(action))
        self._trace.events.extend(new)
        self._record_state()

    def _detect_lane_changes(self, events: List[Dict[str, Any]]) -> None:
        for v in self.road.vehicles:
            before = self._lane_of.get(id(v))
            now = v.lane_index
            self._lane_of[id(v)] = now
            if before is None or now is None or before == now:
                continue
            if before[:2] == now[:2]:
                direction = "right" if now[2] > before[2] else "left"
                name = getattr(v, "name", "")
                events.append({"time": round(self.time, 6), "kind": "lane_change",
                               "actors": [name], "direction": direction})
                if name == "ego":
                    self._episode["lane_changes"] += 1

    def _is_off_road(self, vehicle) -> bool:
        lane = vehicle.lane
        if lane is None:
            return True
        s, lat = lane.local_coordinates(vehicle.position)
        width = lane.width_at(s)
        off = abs(lat) > width / 2 + self.config["off_road_margin"] or not (-vehicle.LENGTH <= s <= lane.length + vehicle.LENGTH)
        if off and getattr(self, "_converted", None) is not None:
            # a parking lane or hard shoulder is road too (not a highway-env lane: see ConvertedNetwork.on_shoulder)
            return not self._converted.on_shoulder(vehicle.position)
        return off

    def _record_state(self) -> None:
        actors = self.road.vehicles + self.road.objects
        states = {getattr(v, "name", str(i)): actor_state(v) for i, v in enumerate(actors)}
        if not self._trace.kinds:
            self._trace.kinds = {getattr(v, "name", str(i)): getattr(v, "kind", "car") for i, v in enumerate(actors)}
        self._trace.states.append(states)

    # ----------------------------------------------------------------- rewards
    def _rewards(self, action) -> Dict[str, float]:
        ego = self.vehicle
        forward = ego.speed * math.cos(ego.heading - ego.lane.heading_at(ego.lane.local_coordinates(ego.position)[0])) if ego.lane else ego.speed
        low, high = self.config["reward_speed_range"]
        return {
            "collision": float(ego.crashed),
            "off_road": float(self._episode.get("off_road", False)),
            "high_speed": float(np.clip(hw_utils.lmap(forward, [low, high], [0, 1]), 0, 1)),
            "lane_change": float(any(e["kind"] == Action.LANE_CHANGE and e["actors"] == ["ego"]
                                     for e in self._step_events)),
            "low_ttc": float(getattr(self, "_ttc", math.inf) < self.config["ttc_threshold"]),
            "standing": float(self._standing_with_free_path(ego)) if weights_standing(self.config) else 0.0,
        }

    def _standing_with_free_path(self, ego) -> bool:
        if ego.speed >= STANDING_SPEED:
            return False
        state = (float(ego.position[0]), float(ego.position[1]), float(ego.heading))
        return path_is_free(state, (o.position for o in self.road.vehicles + self.road.objects if o is not ego))

    def _reward(self, action) -> float:
        weights = self.config["reward_weights"]
        terms = self._rewards(action)
        reward = sum(weights.get(name, 0.0) * value for name, value in terms.items())
        if self.config["normalize_reward"]:
            worst = sum(w for w in weights.values() if w < 0)
            best = sum(w for w in weights.values() if w > 0)
            if best > worst:
                reward = hw_utils.lmap(reward, [worst, best], [0, 1])
        return float(reward)

    def _is_terminated(self) -> bool:
        ego = self.vehicle
        return bool(
            (self.config["terminate_on_collision"] and ego.crashed)
            or (self.config["terminate_off_road"] and self._episode.get("off_road", False))
            or (self._outcome is not None and self._outcome.status == "finished")
        )

    def _is_truncated(self) -> bool:
        return bool(
            self.time >= self.config["duration"] - 1e-6
            or (self._outcome is not None and self._outcome.status == "rejected")
        )

    def _info(self, obs, action=None) -> dict:
        ego = self.vehicle
        episode = self._episode
        return {
            "scenario": episode.get("scenario"),
            "seed": episode.get("seed"),
            "scene_seed": episode.get("scene_seed"),
            "params": copy.deepcopy(episode.get("params", {})),
            "speed": float(ego.speed),
            "crashed": bool(ego.crashed),
            "collisions": list(episode.get("collisions", [])),
            "lane_changes": int(episode.get("lane_changes", 0)),
            "min_ttc": float(episode.get("min_ttc", math.inf)),
            "min_ttc_time": episode.get("min_ttc_time"),
            "min_ttc_with": episode.get("min_ttc_with"),
            "off_road": bool(episode.get("off_road", False)),
            "events": list(self._step_events),
            "scenic_status": self._outcome.status if self._outcome else "running",
            "scenic_reason": self._outcome.reason if self._outcome else "",
            "rewards": self._rewards(action),
            "action": _jsonable(action),
        }

    # --------------------------------------------------------------- rendering
    def render(self):
        """Render a frame (``rgb_array``) or draw the window (``human``)."""
        if self.render_mode is None:
            return super().render()
        if self.viewer is None:
            self.viewer = DV2SViewer(self)
        return super().render()

    # ------------------------------------------------------------------ traces
    @property
    def trace(self) -> Optional[EpisodeTrace]:
        """The trace of the current episode (seed, scene, per-step states, events)."""
        return self._trace

    def save_trace(self, path: Union[str, os.PathLike]) -> Path:
        """Write the current episode's trace to ``path`` (JSON, ``.gz`` compresses)."""
        if self._trace is None:
            raise ResetNeededError("no episode to save: call reset() (and step()) first")
        return self._trace.save(path)

    # ---------------------------------------------------------------- cleanup
    def _close_simulation(self) -> None:
        if self._stepper is not None:
            self._stepper.close()
        self._stepper = None
        self._simulation = None

    def close(self) -> None:
        """Stop the running simulation and close the viewer."""
        self._close_simulation()
        super().close()

    def __del__(self):
        try:
            self._close_simulation()
        except Exception:
            pass


def _frequencies(current: Optional[dict], given: Optional[dict]) -> dict:
    """The simulation and policy frequencies ``given`` leaves as they are in ``current``, so that a
    ``configure`` of one of them is checked against the other's value in force."""
    if not current or not isinstance(given, dict) or not ({"simulation_frequency", "policy_frequency"} & set(given)):
        return {}
    return {key: current[key] for key in ("simulation_frequency", "policy_frequency")
            if key in current and key not in given}


def check_env_config(config: Any) -> None:
    """:func:`envs.config_check.check_config` against :meth:`DV2SEnv.default_config`: the check a run that builds
    its envs in worker processes makes once, before any worker starts."""
    check_config(config, DV2SEnv.default_config())
