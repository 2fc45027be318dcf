"""Load a driving policy by name or path behind one batched interface.

Every policy is a :class:`Policy`: ``act(observations) -> actions`` over a batch
(one row per env). A *spec* names it:

- a registered name: ``rule`` (:class:`~policies.rule_based.CautiousDriver`),
  ``idm`` (:class:`~policies.baselines.IDMEgo`), ``keep_lane``
  (:class:`~policies.baselines.KeepLaneEgo`), ``random``, the shipped checkpoint
  ``dv2s-ppo``, or anything added with :func:`register_policy`;
- a stable-baselines3 checkpoint: ``path/to/model.zip`` (the algorithm is read from
  the model card beside it, ``model_card.json``, or found by trying PPO, DQN, SAC,
  A2C and TD3), or ``ppo:path/to/model.zip`` to name it;
- a Python object: ``package.module:attribute`` (a :class:`Policy`, a factory
  returning one, or a plain callable ``obs -> action``); a callable that needs no argument is a
  factory and is called when the spec loads, with the spec's options; a module in the current
  directory is found.

Options follow a ``?`` as ``key=value`` pairs and are passed to the factory, e.g.
``idm?time_headway=2.0``. ``action_noise=p`` works on every policy: with probability
``p`` per step the action is replaced by a uniformly random one (a deliberately
degraded copy, used to check that regression tests catch a worse policy).

Policies that read the simulator state instead of the observation
(``privileged = True``) must be bound to their envs with :meth:`Policy.bind`
before acting (the regression runner does this).
"""

from __future__ import annotations

import dataclasses
import importlib
import inspect
import json
import os
import sys
from pathlib import Path
from typing import Any, Callable, Dict, List, Mapping, Optional, Sequence, Tuple, Union
import difflib

import gymnasium as gym
import numpy as np

from envs.config_check import observation_in_force
from envs.errors import DV2SError
from scenario_bank.extras import extra_of, missing_extra_message
from scenario_bank.named_registry import Registry
from scenario_bank.plugins import import_raised, missing_attribute, module_not_found, registering_module
from scenario_bank.plugins import remember_plugin
from scenario_bank.records import RecordError
from policies.card_record import ModelCard

__all__ = [
    "Policy",
    "PolicyError",
    "PolicySpaceError",
    "StateDriverPolicy",
    "CallablePolicy",
    "RandomPolicy",
    "SB3Policy",
    "ActionNoise",
    "register_policy",
    "registered_policies",
    "registered_policy_module",
    "load_policy",
    "parse_spec",
    "SHIPPED_CHECKPOINT",
    "BUILTIN_POLICIES",
    "spec_from_file",
    "check_policy_spec",
    "check_card_observation", "SB3_ALGORITHMS", "read_model_card"]

SHIPPED_CHECKPOINT = Path(__file__).resolve().parent / "checkpoints" / "dv2s_ppo" / "model.zip"
"""The PPO checkpoint shipped with the package (``dv2s-ppo``)."""

SB3_ALGORITHMS = ("ppo", "dqn", "sac", "a2c", "td3")


class PolicyError(DV2SError, ValueError):
    """A policy spec that names nothing loadable, or a checkpoint that does not load."""


class PolicySpaceError(PolicyError):
    """A policy whose observation or action space does not match the env's."""


class Policy:
    """A driving policy: batched ``act(observations) -> actions``.

    Attributes:
        name: the spec it was loaded from (shown in reports).
        privileged: ``True`` when it reads the simulator state and needs :meth:`bind`.
        observation_space / action_space: the spaces it was made for, or ``None`` when
            it adapts to any env (checked by :meth:`check_spaces`).
    """

    name: str = "policy"
    privileged: bool = False
    observation_space: Optional[gym.Space] = None
    action_space: Optional[gym.Space] = None

    def bind(self, envs: Sequence[gym.Env]) -> None:
        """Attach the envs this policy acts in, one per batch row (checks their spaces)."""
        if not envs:
            raise PolicyError(f"policy {self.name!r}: bind() needs at least one env")
        for env in envs:
            self.check_spaces(env.observation_space, env.action_space)
            config = getattr(getattr(env, "unwrapped", env), "config", None)
            if isinstance(config, Mapping) and "observation" in config:
                self.check_env_config(config)
        self.envs = list(envs)

    def check_env_config(self, env_config: Optional[Mapping[str, Any]]) -> None:
        """Raise :class:`PolicySpaceError` when the env config (DV2S-v0 overrides, or a whole config) observes
        otherwise than the policy was made for (a policy that adapts to any env accepts every config)."""

    def reset(self, index: Optional[int] = None) -> None:
        """Forget per-episode state for batch row ``index`` (all rows when ``None``)."""

    def seed(self, seed: int) -> None:
        """Seed the policy's own randomness for the episode run with env seed ``seed``.

        :func:`~policies.evaluation.run_episode` calls it at every reset, so a stochastic
        policy (random actions, :class:`ActionNoise`) acts the same on the same episode
        whatever ran before it in the process: paired and replayed episodes stay identical.
        Deterministic policies ignore it.
        """

    def act(self, observations: np.ndarray, deterministic: bool = True) -> np.ndarray:
        """Actions for a batch of observations (first axis = env)."""
        raise NotImplementedError

    def act_one(self, observation: np.ndarray, deterministic: bool = True):
        """The action for a single (unbatched) observation from env 0."""
        return self.act(np.asarray(observation)[None], deterministic=deterministic)[0]

    def check_spaces(self, observation_space: gym.Space, action_space: gym.Space) -> None:
        """Raise :class:`PolicySpaceError` naming the space that does not match."""
        for label, mine, theirs in (("observation", self.observation_space, observation_space),
                                    ("action", self.action_space, action_space)):
            if mine is None:
                continue
            if not _spaces_match(mine, theirs):
                raise PolicySpaceError(
                    f"policy {self.name!r} was made for the {label} space {mine}, but the env has {theirs}; "
                    f"configure the env's {label} like the one the policy was trained on "
                    f"(see its model card) or use another policy")

    # SB3-style entry point so a Policy can stand where a model is expected
    def predict(self, observation: Any, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> Tuple[np.ndarray, Any]:
        """``(action, state)`` like a stable-baselines3 model; batched when ``observation`` is."""
        observation = np.asarray(observation)
        space = self.observation_space
        batched = space is not None and observation.ndim == len(space.shape) + 1
        if batched:
            return self.act(observation, deterministic), state
        return np.asarray(self.act_one(observation, deterministic)), state

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r})"


def _check_options(name: str, driver_class: type, options: Mapping[str, Any]) -> None:
    """Refuse options the driver does not take now, not in a worker's first episode (a driver with a ``SETTINGS``
    dataclass takes its fields by name)."""
    settings = getattr(driver_class, "SETTINGS", None)
    if dataclasses.is_dataclass(settings):
        accepted = [field.name for field in dataclasses.fields(settings)]
        unknown = [key for key in options if key not in accepted]
        if unknown:
            raise PolicyError(f"policy {name!r} has no option {', '.join(map(repr, unknown))}; its options are "
                              f"{', '.join(accepted)} (and action_noise, noise_seed)")
        return
    try:
        signature = inspect.signature(driver_class)
    except (TypeError, ValueError):  # pragma: no cover - a builtin without a signature
        return
    try:
        signature.bind(None, **options)  # the env comes first
    except TypeError:
        accepted = [p.name for p in list(signature.parameters.values())[1:]
                    if p.kind in (p.POSITIONAL_OR_KEYWORD, p.KEYWORD_ONLY)]
        unknown = [key for key in options if key not in accepted]
        if unknown and not any(p.kind is p.VAR_KEYWORD for p in signature.parameters.values()):
            raise PolicyError(f"policy {name!r} has no option {', '.join(map(repr, unknown))}; its options are "
                              f"{', '.join(accepted) or 'none'} (and action_noise, noise_seed)") from None
        raise


def _spaces_match(a: gym.Space, b: gym.Space) -> bool:
    if type(a) is not type(b):
        return False
    if isinstance(a, gym.spaces.Discrete):
        return int(a.n) == int(b.n)
    if isinstance(a, gym.spaces.Box):
        return a.shape == b.shape
    return a == b


class StateDriverPolicy(Policy):
    """A privileged driver (:class:`~policies.state_driver.StateDriver`) per bound env."""

    privileged = True
    action_space = gym.spaces.Discrete(5)

    def __init__(self, name: str, driver_class: type, **kwargs: Any) -> None:
        self.name = name
        self.driver_class = driver_class
        self.kwargs = kwargs
        self.drivers: List[Any] = []
        _check_options(name, driver_class, kwargs)

    def bind(self, envs: Sequence[gym.Env]) -> None:
        super().bind(envs)
        self.drivers = [self.driver_class(env, **self.kwargs) for env in envs]

    def reset(self, index: Optional[int] = None) -> None:
        if not self.drivers:
            return
        rows = range(len(self.drivers)) if index is None else [index]
        for row in rows:
            self.drivers[row] = self.driver_class(self.envs[row], **self.kwargs)

    def act(self, observations: np.ndarray, deterministic: bool = True) -> np.ndarray:
        if not self.drivers:
            raise PolicyError(f"policy {self.name!r} reads the simulator state: call bind(envs) before act()")
        if len(observations) != len(self.drivers):
            raise PolicyError(f"policy {self.name!r}: {len(observations)} observations for "
                              f"{len(self.drivers)} bound envs")
        return np.array([driver.act() for driver in self.drivers], dtype=np.int64)


class CallablePolicy(Policy):
    """A plain function ``obs -> action`` (``batched=True``: ``obs batch -> actions``)."""

    def __init__(self, name: str, function: Callable, batched: bool = False,
                 observation_space: Optional[gym.Space] = None, action_space: Optional[gym.Space] = None) -> None:
        self.name = name
        self.function = function
        self.batched = batched
        self.observation_space = observation_space
        self.action_space = action_space

    def act(self, observations: np.ndarray, deterministic: bool = True) -> np.ndarray:
        if self.batched:
            return np.asarray(self.function(observations))
        return np.asarray([self.function(obs) for obs in observations])


class RandomPolicy(Policy):
    """Uniformly random actions from the bound env's action space (seeded)."""

    def __init__(self, name: str = "random", seed: int = 0) -> None:
        self.name = name
        self.base_seed = int(seed)
        self.rng = np.random.default_rng(self.base_seed)
        self.space: Optional[gym.Space] = None

    def seed(self, seed: int) -> None:
        self.rng = np.random.default_rng([self.base_seed, int(seed)])

    def bind(self, envs: Sequence[gym.Env]) -> None:
        super().bind(envs)
        self.space = envs[0].action_space

    def act(self, observations: np.ndarray, deterministic: bool = True) -> np.ndarray:
        space = self.space or gym.spaces.Discrete(5)
        return np.asarray([_sample(space, self.rng) for _ in range(len(observations))])


def _sample(space: gym.Space, rng: np.random.Generator):
    if isinstance(space, gym.spaces.Discrete):
        return int(space.start + rng.integers(space.n))
    if isinstance(space, gym.spaces.Box):
        return rng.uniform(space.low, space.high).astype(space.dtype)
    raise PolicyError(f"random actions for {space} are not supported")


class SB3Policy(Policy):
    """A stable-baselines3 model (PPO, DQN, SAC, ...)."""

    def __init__(self, name: str, model: Any, card: Optional[ModelCard] = None) -> None:
        self.name = name
        self.model = model
        self.card = ModelCard.from_dict(card) if card is not None else ModelCard()
        self.observation_space = model.observation_space
        self.action_space = model.action_space

    def check_env_config(self, env_config: Optional[Mapping[str, Any]]) -> None:
        """The env must observe as the env the model was trained in (:func:`check_card_observation`)."""
        check_card_observation(self.name, self.card, env_config)

    def act(self, observations: np.ndarray, deterministic: bool = True) -> np.ndarray:
        actions, _ = self.model.predict(np.asarray(observations, dtype=np.float32), deterministic=deterministic)
        return np.asarray(actions)


def check_card_observation(name: str, card: ModelCard, env_config: Optional[Mapping[str, Any]]) -> None:
    """Raise :class:`PolicySpaceError` unless ``env_config`` observes as the env the policy ``name`` of model card
    ``card`` was trained in, by the card's ``env_config`` (no ``observation`` there: the default one): same type,
    features and options. A card without an ``env_config`` (a bare checkpoint) is checked by the observation
    space's shape only, elsewhere."""
    if card.env_config is None and "env_config" not in (card.null_fields or ()):
        return
    from envs.dv2s_env import DV2SEnv

    defaults = DV2SEnv.default_config()
    trained = observation_in_force(card.env_config or {}, defaults)
    given = observation_in_force(env_config or {}, defaults)
    if trained != given:
        differ = sorted(key for key in set(trained) | set(given) if trained.get(key) != given.get(key))
        detail = "; ".join(f"{key}: trained {trained.get(key)!r}, env {given.get(key)!r}" for key in differ)
        raise PolicySpaceError(
            f"policy {name!r} was trained with another observation than this env's ({detail}); run it "
            f"with the env config of its model card (config['observation'] = {trained_section(card)!r})")


def trained_section(card: ModelCard) -> Dict[str, Any]:
    """The ``observation`` section a model card's policy was trained with (the default's when it names none)."""
    section = (card.env_config or {}).get("observation")
    if section is None:
        from envs.dv2s_env import DV2SEnv

        section = DV2SEnv.default_config()["observation"]
    return dict(section)


class ActionNoise(Policy):
    """Wraps a policy: with probability ``probability`` an action is replaced by a random one."""

    def __init__(self, inner: Policy, probability: float, seed: int = 0) -> None:
        if not 0.0 <= probability <= 1.0:
            raise PolicyError(f"action_noise must be a probability in [0, 1], not {probability}")
        self.inner = inner
        self.probability = float(probability)
        self.base_seed = int(seed)
        self.rng = np.random.default_rng(self.base_seed)
        self.name = f"{inner.name}?action_noise={probability:g}"
        self.privileged = inner.privileged
        self.observation_space = inner.observation_space
        self.action_space = inner.action_space
        self.space: Optional[gym.Space] = inner.action_space

    def bind(self, envs: Sequence[gym.Env]) -> None:
        self.inner.bind(envs)
        self.envs = list(envs)
        self.space = envs[0].action_space

    def check_env_config(self, env_config: Optional[Mapping[str, Any]]) -> None:
        self.inner.check_env_config(env_config)

    def reset(self, index: Optional[int] = None) -> None:
        self.inner.reset(index)

    def seed(self, seed: int) -> None:
        self.inner.seed(seed)
        self.rng = np.random.default_rng([self.base_seed, int(seed)])

    def act(self, observations: np.ndarray, deterministic: bool = True) -> np.ndarray:
        actions = np.array(self.inner.act(observations, deterministic), copy=True)
        space = self.space or gym.spaces.Discrete(5)
        for row in range(len(actions)):
            if self.rng.random() < self.probability:
                actions[row] = _sample(space, self.rng)
        return actions


# --------------------------------------------------------------------------- registry
_REGISTRY: Registry[Callable[..., Any]] = Registry("policy", PolicyError,
                                                  unknown=lambda name, _: _unknown_policy(name))


def register_policy(name: str, factory: Callable[..., Any], overwrite: bool = False) -> None:
    """Make ``load_policy(name)`` call ``factory(**options)``; a name registered already needs ``overwrite=True``.

    The factory returns a :class:`Policy` or a plain callable ``obs -> action``
    (wrapped in :class:`CallablePolicy`). The module that calls this is remembered as a plug-in module: every
    worker process imports it before its first episode, so register at its import time, in a module other
    processes can import (not ``__main__``; :mod:`scenario_bank.plugins`).
    """
    if not name or any(ch in name for ch in "?:/\\") or name.endswith(".zip"):
        raise PolicyError(f"policy name {name!r} must not be empty or contain '?', ':', '/' or end in .zip")
    _REGISTRY.register(name, factory, overwrite=overwrite, module=_factory_module(factory))
    remember_plugin(f"policy {name!r}", registering_module())


def registered_policies() -> List[str]:
    """The names :func:`load_policy` knows, sorted."""
    return sorted(_REGISTRY)


def registered_policy_module(name: str) -> Optional[str]:
    """The module whose code the policy registered as ``name`` runs (a state driver's class module, else the
    factory's); ``None`` when none is registered by that name or its factory names no module."""
    return _REGISTRY.module(name)


def _factory_module(factory: Callable[..., Any]) -> Optional[str]:
    module = getattr(factory, "__module__", None)
    closure = [c.cell_contents for c in (getattr(factory, "__closure__", None) or [])]
    paths = [c for c in closure if isinstance(c, str) and ":" in c]  # a state driver's class path
    return paths[0].split(":")[0] if paths else module


def _state_driver(name: str, class_path: str) -> Callable[..., Policy]:
    def factory(**options: Any) -> Policy:
        module, attribute = class_path.split(":")
        return StateDriverPolicy(name, getattr(importlib.import_module(module), attribute), **options)

    return factory


def _shipped(**options: Any) -> Policy:
    if not SHIPPED_CHECKPOINT.is_file():
        raise PolicyError(f"the shipped checkpoint {SHIPPED_CHECKPOINT} is missing; reinstall dv2s-gym")
    return _load_sb3(str(SHIPPED_CHECKPOINT), algorithm=None, name="dv2s-ppo", **options)


register_policy("rule", _state_driver("rule", "policies.rule_based:CautiousDriver"))
register_policy("idm", _state_driver("idm", "policies.baselines:IDMEgo"))
register_policy("keep_lane", _state_driver("keep_lane", "policies.baselines:KeepLaneEgo"))
register_policy("random", lambda seed=0: RandomPolicy("random", seed=int(seed)))
register_policy("dv2s-ppo", _shipped)
_REGISTRY.mark_built_in()


BUILTIN_POLICIES = ("rule", "idm", "keep_lane", "random", "dv2s-ppo")
"""The policies that ship with dv2s-gym: the only specs a file (a report, a run folder) may name."""


def spec_from_file(spec: Any, source: str, fix: str) -> str:
    """``spec`` read from a file (``source`` names it), if it is safe to load: a built-in policy
    (:data:`BUILTIN_POLICIES`) with numeric options only.

    A file is data: a ``module:attribute`` spec would import and call code, and a checkpoint is
    unpickled, so only the user may name those, on the command line. Raises :class:`PolicyError`
    naming the spec and ``fix`` (the option that passes the policy explicitly) otherwise.
    """
    text = spec if isinstance(spec, str) else repr(spec)
    refusal = PolicyError(f"{source} names the policy {text[:200]!r}, which is not a built-in policy "
                          f"({', '.join(BUILTIN_POLICIES)} with numeric options); a policy named by a file is "
                          f"not loaded: if you trust it, pass it yourself with {fix}")
    if not isinstance(spec, str):
        raise refusal
    base, _, query = spec.partition("?")
    if base not in BUILTIN_POLICIES:
        raise refusal
    for pair in filter(None, query.split("&")):
        key, sep, value = pair.partition("=")
        if not sep or not key.isidentifier():
            raise refusal
        try:
            number = float(value)
        except ValueError:
            raise refusal from None
        if number != number or number in (float("inf"), float("-inf")):
            raise refusal
    return spec


def parse_spec(spec: str) -> Tuple[str, Dict[str, Any]]:
    """Split ``"name?key=value&key2=value2"`` into the name and typed options."""
    base, _, query = str(spec).partition("?")
    options: Dict[str, Any] = {}
    for pair in filter(None, query.split("&")):
        key, sep, value = pair.partition("=")
        if not sep or not key:
            raise PolicyError(f"policy option {pair!r} in {spec!r} is not key=value")
        options[key] = _typed(value)
    return base, options


def _typed(value: str) -> Any:
    for cast in (int, float):
        try:
            return cast(value)
        except ValueError:
            pass
    return {"true": True, "false": False, "none": None}.get(value.lower(), value)


def load_policy(spec: Union[str, os.PathLike, Policy, Callable], **options: Any) -> Policy:
    """The :class:`Policy` a spec names (see the module docstring); options override the spec's."""
    if isinstance(spec, Policy):
        policy = spec
        noise = options.pop("action_noise", None)
    elif callable(spec) and not isinstance(spec, (str, os.PathLike)):
        noise = options.pop("action_noise", None)
        policy = CallablePolicy(getattr(spec, "__name__", "callable"), spec, **options)
    else:
        base, parsed = parse_spec(os.fspath(spec))
        parsed.update(options)
        noise = _option_number("action_noise", parsed.pop("action_noise", None), float)
        noise_seed = _option_number("noise_seed", parsed.pop("noise_seed", 0), int)
        policy = _load_base(base, parsed)
        if noise:
            return ActionNoise(policy, noise, seed=noise_seed)
        return policy
    return ActionNoise(policy, float(noise)) if noise else policy


def _option_number(name: str, value: Any, cast: type) -> Any:
    """``value`` as a ``cast`` number, or a :class:`PolicyError` naming the option."""
    if value is None:
        return None
    kind = "an integer" if cast is int else "a number"
    if isinstance(value, bool) or not isinstance(value, (int, float)) or (cast is int and value != int(value)):
        raise PolicyError(f"{name} must be {kind}, not {value!r}")
    return cast(value)


def _load_base(base: str, options: Dict[str, Any]) -> Policy:
    if base in _REGISTRY:
        made = _REGISTRY.get(base)(**options)
        return made if isinstance(made, Policy) else CallablePolicy(base, made)
    prefix, sep, rest = base.partition(":")
    if sep and prefix.lower() in SB3_ALGORITHMS:
        return _load_sb3(rest, algorithm=prefix.lower(), name=base, **options)
    path = Path(base)
    if path.suffix == ".zip" or path.is_dir():
        return _load_sb3(base, algorithm=None, name=base, **options)
    if sep and "/" not in prefix and "\\" not in prefix:
        return _load_object(prefix, rest, base, options)
    raise _unknown_policy(base)


def _unknown_policy(base: str) -> PolicyError:
    close = difflib.get_close_matches(base, registered_policies(), n=1)
    return PolicyError(
        f"unknown policy {base!r}" + (f" (did you mean {close[0]!r}?)" if close else "")
        + f": use one of {', '.join(registered_policies())}, an SB3 checkpoint (model.zip, or ppo:/dqn:/sac:PATH), "
        "or module:attribute")


def check_policy_spec(spec: Union[str, os.PathLike]) -> None:
    """Raise the :class:`PolicyError` :func:`load_policy` would for a spec whose shape names no policy (an
    unknown name, with a suggestion) or whose options are not ``key=value``, without loading anything: a
    command checks its specs this way before its slow start-up. A checkpoint or ``module:attribute`` is
    only checked when it loads."""
    base, _ = parse_spec(os.fspath(spec))
    if base in _REGISTRY:
        return
    prefix, sep, _ = base.partition(":")
    if (sep and (prefix.lower() in SB3_ALGORITHMS or ("/" not in prefix and "\\" not in prefix))) \
            or Path(base).suffix == ".zip" or Path(base).is_dir():
        return
    raise _unknown_policy(base)


def import_policy_module(module_name: str) -> Any:
    """Import a ``module:attribute`` spec's module; a module in the current directory is found too."""
    try:
        return importlib.import_module(module_name)
    except ModuleNotFoundError as error:
        here = os.getcwd()
        top = module_name.split(".")[0]
        if error.name != top or here in sys.path or not (
                Path(here, f"{top}.py").is_file() or Path(here, top, "__init__.py").is_file()):
            raise
        sys.path.append(here)
        return importlib.import_module(module_name)


def _is_factory(target: Callable) -> bool:
    """A callable that needs no argument is a factory (called to make the policy); one that needs an
    observation is the policy itself (``obs -> action``)."""
    try:
        parameters = inspect.signature(target).parameters.values()
    except (TypeError, ValueError):
        return False
    return not any(p.default is p.empty and p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)
                   for p in parameters)


def _policy_module(module_name: str, spec: str) -> Any:
    """The module of a ``module:attribute`` spec, or the error that tells a module not found (the path advice)
    from a module whose own code raised."""
    try:
        return import_policy_module(module_name)
    except Exception as error:  # whatever the module's own code raises at import time is reported, not a fault here
        if module_not_found(module_name, error):
            raise PolicyError(f"policy {spec!r}: cannot import module {module_name!r} ({error}); run from the "
                              "folder that holds the module or put its folder on PYTHONPATH") from error
        raise PolicyError(f"policy {spec!r}: module {module_name!r} was found, but "
                          f"{import_raised(module_name, error)}") from error


def _attribute(module: Any, attribute: str, spec: str) -> Any:
    try:
        return getattr(module, attribute)
    except AttributeError:
        raise PolicyError(f"policy {spec!r}: {missing_attribute(module, attribute)}") from None


def _load_object(module_name: str, attribute: str, spec: str, options: Dict[str, Any]) -> Policy:
    target = _attribute(_policy_module(module_name, spec), attribute, spec)
    if isinstance(target, Policy):
        return target
    if isinstance(target, type) and issubclass(target, Policy):
        try:
            return target(**options)
        except TypeError as error:
            raise PolicyError(f"policy {spec!r}: {error}") from None
    if callable(target):
        if not options and not _is_factory(target):
            return CallablePolicy(spec, target)
        try:
            made = target(**options)
        except TypeError as error:
            raise PolicyError(f"policy {spec!r}: the factory {attribute} refused its options ({error})") from None
        if isinstance(made, Policy):
            return made
        if not callable(made):
            raise PolicyError(f"policy {spec!r}: the factory {attribute} returned {_a(type(made).__name__)}, not a "
                              "Policy or a callable obs -> action")
        return CallablePolicy(spec, made)
    raise PolicyError(f"policy {spec!r} is {_a(type(target).__name__)}, not a Policy or a callable")


def _a(noun: str) -> str:
    """``noun`` with its indefinite article (``an int``, ``a str``)."""
    return f"{'an' if noun[:1].lower() in 'aeiou' else 'a'} {noun}"


def read_model_card(checkpoint: Union[str, os.PathLike]) -> ModelCard:
    """The model card (``model_card.json``) beside a checkpoint (a ``model.zip`` or the folder holding one), or the
    empty card (:attr:`ModelCard.exists` false) when there is none."""
    path = Path(checkpoint)
    card = (path if path.is_dir() else path.parent) / "model_card.json"
    if not card.is_file():
        return ModelCard()
    try:
        data = json.loads(card.read_text(encoding="utf-8"))
    except (OSError, ValueError) as error:
        raise PolicyError(f"model card {card} is not readable JSON ({error}); fix or delete it") from error
    try:
        return ModelCard.from_dict(data)
    except RecordError as error:
        raise PolicyError(f"model card {card}: {error}; fix or delete it") from error


def _load_sb3(path: str, algorithm: Optional[str], name: str, **options: Any) -> Policy:
    checkpoint = Path(path)
    if checkpoint.is_dir():
        checkpoint = checkpoint / "model.zip"
    if not checkpoint.is_file():
        raise PolicyError(f"checkpoint {checkpoint} does not exist; train one with `dv2s train` or check the path")
    card = read_model_card(checkpoint)
    algorithm = (algorithm or card.algorithm or "").lower() or None
    try:
        import stable_baselines3 as sb3
    except ImportError as error:  # the core install has no rl extra
        missing = error.name if isinstance(error, ModuleNotFoundError) and extra_of(error.name or "") else \
            "stable_baselines3"
        raise PolicyError(missing_extra_message(missing, "loading SB3 checkpoints")) from error
    candidates = [algorithm] if algorithm else list(SB3_ALGORITHMS)
    errors = []
    for candidate in candidates:
        if candidate not in SB3_ALGORITHMS:
            raise PolicyError(f"checkpoint {checkpoint}: unknown algorithm {candidate!r}; use one of {SB3_ALGORITHMS}")
        try:
            model = getattr(sb3, candidate.upper()).load(str(checkpoint), device="cpu", **options)
        except Exception as error:  # SB3 raises many types on a file of another algorithm or a corrupt zip
            errors.append(f"{candidate}: {type(error).__name__}: {error}")
            continue
        return SB3Policy(name, model, card.with_algorithm(candidate))
    raise PolicyError(f"checkpoint {checkpoint} does not load as an SB3 model ({'; '.join(errors)[:500]}); "
                      "is it a stable-baselines3 .zip saved by model.save()?")
