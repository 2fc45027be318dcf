"""Checks of a ``DV2S-v0`` config against the keys and values the env and highway-env accept.

Every key of ``config=`` is checked, nested ones included: a misspelt reward term, observation or
action option would otherwise be ignored without a word and the env would run with the default.
The options an observation or action type takes are read from the signature of its highway-env
class, so a new highway-env version is checked against its own options.
"""

from __future__ import annotations

import difflib
import inspect
import json
import math
from typing import Any, Iterable, Mapping, Sequence

from envs.errors import ACTION_TYPES, OBSERVATION_TYPES, UnknownConfigKeyError, UnknownRenderModeError

__all__ = ["EGO_POLICIES", "NUMBERS", "RENDER_MODES", "check_config", "check_render_mode", "observation_in_force",
           "type_options"]

EGO_POLICIES = ("agent", "scenic")
"""Values of ``ego_policy``: the action drives the ego, or the script's ego behaviour does."""

RENDER_MODES = ("human", "rgb_array")
"""Values of ``render_mode`` besides ``None`` (no rendering)."""

REQUIRED_OBSERVATION_KEYS = {
    "GrayscaleObservation": {"observation_shape": (128, 64), "stack_size": 4, "weights": [0.2989, 0.5870, 0.1140]},
}
"""Keys an observation type cannot do without, each with an example value (highway-env has no default)."""

_CLASS_NAMES = {
    "observation": {"Kinematics": "KinematicObservation", "OccupancyGrid": "OccupancyGridObservation",
                    "TimeToCollision": "TimeToCollisionObservation", "LidarObservation": "LidarObservation",
                    "GrayscaleObservation": "GrayscaleObservation"},
    "action": {name: name for name in ACTION_TYPES},
}
"""The highway-env class each supported type name builds (``observation_factory`` / ``action_factory``)."""


def _did_you_mean(value: Any, choices: Iterable[str], *, prefix: bool = False) -> str:
    """`` (did you mean 'x'?)`` with the closest choice, or nothing; with ``prefix``, a choice that starts with
    ``value`` is close too (``rgb`` for ``rgb_array``, too short a part of it for difflib)."""
    choices = [str(c) for c in choices]
    close = difflib.get_close_matches(str(value), choices, n=1)
    if not close and prefix and len(str(value)) >= 2:
        close = [c for c in choices if c.startswith(str(value))][:1]
    return f" (did you mean {close[0]!r}?)" if close else ""


def _check_type(config: Mapping[str, Any], key: str, choices: Sequence[str]) -> None:
    section = config.get(key)
    if section is None:
        return
    if not isinstance(section, Mapping) or "type" not in section:
        raise UnknownConfigKeyError(f"config[{key!r}] must be a dict with a 'type' (one of {', '.join(choices)}), "
                                    f"e.g. {{'type': {choices[0]!r}}}; got {section!r}")
    if section["type"] not in choices:
        raise UnknownConfigKeyError(f"unknown {key} type {section['type']!r}{_did_you_mean(section['type'], choices)}"
                                    f"; DV2S-v0 supports {', '.join(choices)}")


def _forwards_keywords(init) -> bool:
    """Whether ``init`` passes its ``**kwargs`` on (to its base class), judged from its source."""
    parameters = inspect.signature(init).parameters.values()
    name = next((p.name for p in parameters if p.kind is inspect.Parameter.VAR_KEYWORD), None)
    if name is None:
        return False
    try:
        source = inspect.getsource(init)
    except (OSError, TypeError):
        return True  # no source to read: accept what a base class takes rather than refuse a valid key
    return source.count(f"**{name}") > 1  # once in the signature, once more in a call


def type_options(section: str, type_name: str) -> set:
    """The keys a highway-env observation (``section="observation"``) or action type takes: ``type`` and
    the named parameters of its class's ``__init__`` (and of its bases' when it passes ``**kwargs`` on)."""
    if section == "observation":
        from highway_env.envs.common import observation as module
    else:
        from highway_env.envs.common import action as module
    cls = getattr(module, _CLASS_NAMES[section][type_name])
    keys = {"type"}
    for klass in cls.__mro__:
        init = klass.__dict__.get("__init__")
        if init is None:
            continue
        keys |= {p.name for p in list(inspect.signature(init).parameters.values())[1:]
                 if p.name != "env" and p.kind not in (inspect.Parameter.VAR_KEYWORD, inspect.Parameter.VAR_POSITIONAL)}
        if not _forwards_keywords(init):
            break
    return keys


def observation_in_force(config: Any, defaults: Mapping[str, Any]) -> dict:
    """The observation a config runs: its ``observation`` section (a section given replaces the default whole),
    else the default's, every option it leaves out filled with its highway-env class's default, as plain JSON
    values (two configs observe alike exactly when these are equal)."""
    section = (config or {}).get("observation") if isinstance(config, Mapping) else None
    section = dict(section if section is not None else defaults["observation"])
    class_name = _CLASS_NAMES["observation"].get(section.get("type"))
    if class_name is not None:
        from highway_env.envs.common import observation as module

        for klass in getattr(module, class_name).__mro__:
            init = klass.__dict__.get("__init__")
            if init is None:
                continue
            for parameter in list(inspect.signature(init).parameters.values())[1:]:
                if parameter.default is not inspect.Parameter.empty and parameter.name not in section:
                    section[parameter.name] = parameter.default
            if not _forwards_keywords(init):
                break
    return json.loads(json.dumps(section, sort_keys=True, default=str))


def _check_options(config: Mapping[str, Any], section: str) -> None:
    given = config.get(section)
    if given is None:
        return
    kind = given["type"]
    options = type_options(section, kind)
    unknown = sorted(str(key) for key in given if key not in options)
    if unknown:
        key = unknown[0]
        raise UnknownConfigKeyError(
            f"config[{section!r}] has {key!r}{_did_you_mean(key, options - {'type'})}, which highway-env's {kind} "
            f"{section} does not take (it would be ignored); its keys are {', '.join(sorted(options))}")


def _check_required_observation_keys(config: Mapping[str, Any]) -> None:
    observation = config.get("observation") or {}
    needed = REQUIRED_OBSERVATION_KEYS.get(observation.get("type"), {})
    missing = [key for key in needed if key not in observation]
    if missing:
        example = {"type": observation["type"], **needed}
        raise UnknownConfigKeyError(f"the {observation['type']} observation needs {', '.join(map(repr, missing))}; "
                                    f"e.g. config['observation'] = {example!r}")


def _check_kinematic_features(config: Mapping[str, Any]) -> None:
    """A ``Kinematics`` feature name highway-env does not compute would be a column of NaN: refused, like a
    misspelt key."""
    observation = config.get("observation") or {}
    if observation.get("type") != "Kinematics" or observation.get("features") is None:  # None: highway-env's own
        return
    from envs.observations import KINEMATIC_FEATURES

    features = observation["features"]
    if isinstance(features, str) or not isinstance(features, Sequence) or not features \
            or not all(isinstance(f, str) for f in features):
        raise UnknownConfigKeyError(f"config['observation']['features'] must be a non-empty list of feature names "
                                    f"(of {', '.join(KINEMATIC_FEATURES)}); got {features!r}")
    for feature in features:
        if feature not in KINEMATIC_FEATURES:
            raise UnknownConfigKeyError(
                f"unknown Kinematics feature {feature!r}{_did_you_mean(feature, KINEMATIC_FEATURES)} in "
                f"config['observation']['features']; the features are {', '.join(KINEMATIC_FEATURES)}")
    repeated = sorted({f for f in features if list(features).count(f) > 1})
    if repeated:
        raise UnknownConfigKeyError(f"config['observation']['features'] names {', '.join(map(repr, repeated))} "
                                    "more than once")


def _check_reward_weights(config: Mapping[str, Any], defaults: Mapping[str, Any]) -> None:
    weights = config.get("reward_weights")
    terms = sorted((defaults.get("reward_weights") or {}))
    if weights is None or not terms:
        return
    if not isinstance(weights, Mapping):
        raise UnknownConfigKeyError(f"config['reward_weights'] must be a dict of reward term to weight, e.g. "
                                    f"{{'collision': -1.0}}; got {weights!r}")
    for term, weight in weights.items():
        if term not in terms:
            raise UnknownConfigKeyError(f"unknown reward term {term!r}{_did_you_mean(term, terms)} in "
                                        f"config['reward_weights']; the terms are {', '.join(terms)}")
        if isinstance(weight, bool) or not isinstance(weight, (int, float)) or weight != weight \
                or weight in (float("inf"), float("-inf")):
            raise UnknownConfigKeyError(f"config['reward_weights'][{term!r}] must be a finite number, not {weight!r}")


def _check_ego_policy(config: Mapping[str, Any]) -> None:
    if "ego_policy" in config and config["ego_policy"] not in EGO_POLICIES:
        value = config["ego_policy"]
        raise UnknownConfigKeyError(f"unknown ego_policy {value!r}{_did_you_mean(value, EGO_POLICIES)}; it is "
                                    f"{' or '.join(map(repr, EGO_POLICIES))}")


NUMBERS = {
    "simulation_frequency": ("a number of Hz", 0, False),
    "policy_frequency": ("a number of Hz", 0, False),
    "duration": ("a number of seconds", 0, False),
    "step_time_limit": ("a number of seconds (or None for no limit)", 0, False),
    "ttc_threshold": ("a number of seconds", 0, True),
    "off_road_margin": ("a number of metres", 0, True),
    "scaling": ("a number of pixels per metre", 0, False),
    "max_sample_iterations": ("a whole number", 0, False),
    "screen_width": ("a whole number of pixels", 0, False),
    "screen_height": ("a whole number of pixels", 0, False),
}
"""Numeric config keys: what the value is, the bound and whether the bound itself is allowed (``> 0`` or
``>= 0``). A wrong type would fail only at the first ``step`` and a negative duration would end the episode
after one step without a word."""

_WHOLE = ("max_sample_iterations", "screen_width", "screen_height")
_SECTION_COUNTS = {"observation": ("vehicles_count", "stack_size", "cells")}
"""Counts inside a section (whole numbers > 0) that would otherwise fail deep inside highway-env."""
_PAIRS = {"reward_speed_range": "[low, high] speeds in m/s with low < high", "centering_position": "[x, y] fractions"}


def _is_number(value: Any) -> bool:
    return not isinstance(value, bool) and isinstance(value, (int, float)) and math.isfinite(value)


def _bad_value(key: str, value: Any, expected: str, defaults: Mapping[str, Any]) -> UnknownConfigKeyError:
    return UnknownConfigKeyError(f"config[{key!r}] is {value!r}; it must be {expected}, e.g. {defaults[key]!r} "
                                 "(the default)")


def _check_numbers(config: Mapping[str, Any], defaults: Mapping[str, Any]) -> None:
    for key, (what, bound, inclusive) in NUMBERS.items():
        if key not in config or key not in defaults or (key == "step_time_limit" and config[key] is None):
            continue
        value = config[key]
        whole = key in _WHOLE
        sign = ">=" if inclusive else ">"
        expected = f"{what} {sign} {bound}"
        if not _is_number(value) or (whole and not isinstance(value, int)) \
                or (value < bound if inclusive else value <= bound):
            raise _bad_value(key, value, expected, defaults)
    for key, expected in _PAIRS.items():
        if key not in config or key not in defaults:
            continue
        value = config[key]
        if not isinstance(value, (list, tuple)) or len(value) != 2 or not all(_is_number(v) for v in value) \
                or (key == "reward_speed_range" and not value[0] < value[1]):
            raise _bad_value(key, value, expected, defaults)
    for section, keys in _SECTION_COUNTS.items():
        given = config.get(section) or {}
        for key in keys:
            value = given.get(key) if isinstance(given, Mapping) else None
            if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value <= 0):
                raise UnknownConfigKeyError(f"config[{section!r}][{key!r}] is {value!r}; it must be a whole number "
                                            "> 0")
    simulation = config.get("simulation_frequency", defaults.get("simulation_frequency"))
    policy = config.get("policy_frequency", defaults.get("policy_frequency"))
    if _is_number(simulation) and _is_number(policy) and policy > simulation:
        raise UnknownConfigKeyError(f"config['policy_frequency'] is {policy!r}, above the simulation_frequency "
                                    f"{simulation!r}; an agent cannot decide more often than the simulation steps: "
                                    "lower policy_frequency or raise simulation_frequency")


def check_config(config: Any, defaults: Mapping[str, Any]) -> None:
    """Raise :class:`~envs.errors.UnknownConfigKeyError` (one line, with a did-you-mean) for the first
    problem of ``config``: a key not in ``defaults``, an observation or action type DV2S-v0 does not
    support or an option its highway-env type does not take, a ``Kinematics`` feature it does not compute
    (:data:`envs.observations.KINEMATIC_FEATURES`), a reward term not in
    ``defaults["reward_weights"]`` or a weight that is not a finite number, an ``ego_policy`` that is not
    ``agent`` or ``scenic``, a numeric value (:data:`NUMBERS`, ``reward_speed_range``, ``centering_position``)
    of the wrong type or out of range, a policy frequency above the simulation frequency."""
    config = config or {}
    _check_type(config, "observation", OBSERVATION_TYPES)
    _check_type(config, "action", ACTION_TYPES)
    _check_required_observation_keys(config)
    unknown = sorted(set(config) - set(defaults), key=str)
    if unknown:
        hints = [f"{key!r}{_did_you_mean(key, defaults)}" for key in unknown]
        raise UnknownConfigKeyError(f"unknown config key(s) {', '.join(hints)}; DV2SEnv.default_config() lists "
                                    "the keys")
    _check_options(config, "observation")
    _check_options(config, "action")
    _check_kinematic_features(config)
    _check_reward_weights(config, defaults)
    _check_ego_policy(config)
    _check_numbers(config, defaults)


def check_render_mode(render_mode: Any) -> None:
    """Raise :class:`~envs.errors.UnknownRenderModeError` naming a ``render_mode`` DV2S-v0 does not have."""
    if render_mode is not None and render_mode not in RENDER_MODES:
        hint = _did_you_mean(render_mode, RENDER_MODES, prefix=True)
        raise UnknownRenderModeError(f"unknown render_mode {render_mode!r}{hint}; "
                                    f"DV2S-v0 renders {' or '.join(map(repr, RENDER_MODES))}, or nothing with None")
