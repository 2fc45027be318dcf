"""The space failure mining samples from: which scenario, and the values of its Scenic parameters.

Each scenario's random global parameters (``param x = Range(a, b)``, ``DiscreteRange``,
``Uniform`` over constants; see :meth:`envs.scenarios.CompiledScenario.parameter_ranges`) are
the features. VerifAI samplers need one fixed feature space, so the space is

- ``scenario``: a discrete feature, the index of the scenario in :attr:`SceneSpace.scenarios`;
- ``u``: a point of the unit box ``[0, 1]^D``, ``D`` the largest parameter count of any
  scenario; coordinate ``i`` is the position of the scenario's ``i``-th parameter (sorted by
  name) inside its range. Coordinates a scenario does not use are ignored.

Everything else in a scene (positions drawn in the script, other random values) comes
from the episode seed, so ``(scenario, params, seed)`` names one scene exactly.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Sequence

from dv2s_gym.mining.errors import MiningError
from envs.jailed_env import parameter_ranges_of
from scenario_bank import select_scenarios

__all__ = ["SceneSpec", "SceneSpace", "IGNORED_PARAMS"]

IGNORED_PARAMS = frozenset({"weather", "time", "timeOfDay", "render", "map", "carla_map", "address", "port"})
"""Parameters the highway-env model does not read: sampling them would only waste the budget."""


@dataclass
class SceneSpec:
    """One point of the space: a scenario and values for its parameters."""

    scenario: str
    params: Dict[str, Any]
    point: List[float] = field(default_factory=list)
    """The unit-box coordinates the parameters came from (one per parameter, sorted by name)."""
    proposal: Optional[Dict[str, float]] = None
    """The density the sampler drew this scene with: ``{"scenario": probability of the scenario, "params":
    density of ``point`` in the scenario's unit box}`` (``None``: unknown; see :mod:`dv2s_gym.mining.sampling.rate`)."""


class SceneSpace:
    """The scenarios of a bank (or a selection) and their parameter ranges as a VerifAI feature space.

    Args:
        scenarios: bank names or ``tag:<tag>`` selections (``None``: the whole bank).
        bank_dir: the bank folder (``None``: the shipped bank).
    """

    def __init__(self, scenarios: Optional[Sequence[str]] = None, bank_dir: Optional[str] = None) -> None:
        from envs.dv2s_env import resolve_scenarios

        if scenarios:  # bank names and tags only: an unknown one's error says so, with the bank's near names
            select_scenarios(list(scenarios), bank_dir, command="dv2s mine")
        refs = resolve_scenarios(list(scenarios) if scenarios else None, bank_dir)
        if not refs:
            raise MiningError("no scenarios to mine: the selection is empty; check --scenarios and --bank")
        self.bank_dir = bank_dir
        self.scenarios: List[str] = [ref.name for ref in refs]
        self._ranges: Dict[str, Dict[str, Any]] = {}
        for name, all_ranges in parameter_ranges_of(refs).items():
            ranges = {k: v for k, v in all_ranges.items() if k not in IGNORED_PARAMS}
            self._ranges[name] = dict(sorted(ranges.items()))
        self.dimension = max([len(r) for r in self._ranges.values()] + [1])
        self._feature_space = None

    def param_ranges(self, scenario: str) -> Dict[str, Any]:
        """``{name: ParamRange}`` of the parameters mined in ``scenario`` (sorted by name)."""
        try:
            return self._ranges[scenario]
        except KeyError:
            raise MiningError(f"scenario {scenario!r} is not in the mined selection "
                              f"({', '.join(self.scenarios)})") from None

    @property
    def feature_space(self):
        """The VerifAI ``FeatureSpace`` (``scenario``: DiscreteBox index, ``u``: unit Box)."""
        if self._feature_space is None:
            from verifai.features import Box, DiscreteBox, Feature, FeatureSpace

            self._feature_space = FeatureSpace({
                "scenario": Feature(DiscreteBox([0, len(self.scenarios) - 1])),
                "u": Feature(Box(*[[0.0, 1.0]] * self.dimension)),
            })
        return self._feature_space

    def decode(self, point) -> SceneSpec:
        """The scene a VerifAI sample stands for."""
        index = int(round(float(_first(point.scenario))))
        index = min(max(index, 0), len(self.scenarios) - 1)
        name = self.scenarios[index]
        u = [float(x) for x in point.u]
        ranges = self._ranges[name]
        params = {key: _plain(r.from_unit(u[i])) for i, (key, r) in enumerate(ranges.items())}
        return SceneSpec(scenario=name, params=params, point=[round(u[i], 6) for i in range(len(ranges))])

    def unit_point(self, scenario: str, params: Dict[str, Any]) -> List[float]:
        """The unit-box coordinates of ``params`` in ``scenario`` (for clustering and reports)."""
        ranges = self.param_ranges(scenario)
        return [ranges[key].to_unit(params[key]) for key in ranges if key in params]

    def describe(self) -> Dict[str, Any]:
        """JSON-safe description: the scenarios and their parameter ranges."""
        return {name: {key: r.as_dict() for key, r in ranges.items()} for name, ranges in self._ranges.items()}


def _first(value):
    return value[0] if isinstance(value, (tuple, list)) else value


def _plain(value: Any) -> Any:
    if hasattr(value, "item"):
        return value.item()
    return value
