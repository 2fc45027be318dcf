"""VerifAI's samplers over the mining space, with their own random state.

VerifAI samplers draw from Python's and NumPy's global generators. :class:`SceneSampler`
keeps a private copy of both and swaps it in around every call, so the points a run
draws depend only on its seed and on the outcomes fed back, never on what else ran in
the process; its state (sampler and generators) is saved to and restored from a file,
which is how an interrupted run resumes.

Samplers (``name``: VerifAI's):

- ``random``: uniform (``FeatureSampler.randomSamplerFor``);
- ``halton``: a Halton low-discrepancy sequence over the parameters (``haltonSamplerFor``);
- ``cross-entropy``: moves probability to the parameter buckets where failures
  (robustness below 0) occurred (``crossEntropySamplerFor``);
- ``bandit``: the multi-armed-bandit sampler, which balances that against buckets
  tried less often (``multiArmedBanditSamplerFor``);
- ``split``: VerifAI domain samplers composed differently
  (:class:`~dv2s_gym.mining.sampling.split_sampler.ScenarioSplitSampler`): VerifAI's discrete cross-entropy
  sampler picks the scenario, and each scenario has its own VerifAI Halton sampler over its own
  parameters; it learns by default from ``novelty`` feedback (a repeat of a failure cluster
  already found counts as an easy scene), and by default (``avoid=81``) draws a scenario's Halton
  points past the cells of the parameter grid (:func:`~dv2s_gym.mining.cluster.region_of`) where that scenario
  already failed. It finds the most of those grid cells of these samplers (``python -m bench.bench_mine --part
  samplers``); on the behaviour clusters the reports count it beats random sampling only for policies that fail
  rarely (``--part breadth``, bench/RESULTS.md).
- ``novelty-bandit``: not one of VerifAI's (:class:`~dv2s_gym.mining.sampling.novelty_sampler.NoveltyBanditSampler`):
  the scenario with the highest estimated rate of *new* failures (a failure whose continuous failure-state
  descriptor, :mod:`~dv2s_gym.mining.failure_state`, is far from every earlier one's in the scenario; its
  ``state-novelty`` feedback), mixed with uniform draws (``explore``, default 0.2, so no scenario's chance falls
  below ``explore / S``), parameters uniform; every draw's density is known, so the failure-rate estimate
  (:mod:`dv2s_gym.mining.sampling.rate`) holds. It is fed neither behaviour clusters nor (scenario, failure type) pairs,
  the breadth it is scored on (``python -m bench.bench_mine --part breadth``).

The adaptive samplers (``cross-entropy``, ``bandit``) take VerifAI's parameters as
``options`` (:data:`SAMPLER_OPTIONS`): ``alpha`` (how much one failure moves the
distribution: each update multiplies it by ``alpha``, VerifAI's default 0.9), ``buckets``
(buckets per continuous parameter, default 5; 1 leaves the parameters uniform and adapts
only which scenario is drawn) and ``thres`` (robustness below which an outcome counts
as a failure, default 0). ``split`` takes them too (defaults :data:`SPLIT_DEFAULTS`: alpha 0.9,
thres 0, buckets 3, the last only used by bucketed parameter samplers), and ``chooser``
(``cross-entropy``, ``ucb``, ``epsilon-greedy``), ``params`` (``halton``, ``random``, ``bandit``,
``cross-entropy``), ``warmup`` (tries of every scenario before the chooser draws, default 0), ``avoid``
(redraws of a scenario's parameters past cells where it already failed, default 81; 0 turns the
redraws off).
"""

from __future__ import annotations

import io
import random
from dataclasses import dataclass
from typing import Any, Callable, Dict, List, Optional, Tuple

import numpy as np

from dv2s_gym.mining.sampling.checkpoint_mac import seal, unseal
from dv2s_gym.mining.errors import MiningError
from scenario_bank.named_registry import Registry
from scenario_bank.plugins import registering_module, remember_code

__all__ = ["proposal_density", "scene_proposal", "SAMPLERS", "SAMPLER_OPTIONS", "SPLIT", "SPLIT_DEFAULTS", "NOVELTY",
           "SceneSampler", "SamplerRecord", "default_feedback", "make_sampler", "sampler_params", "is_adaptive",
           "is_uniform", "register_sampler", "registered_samplers", "UNSEALED", "SAMPLER_METHODS"]


@dataclass(frozen=True)
class SamplerRecord:
    """One scene sampler: how it is built and what a mining run needs to know of it."""

    build: Callable[[Any, Any, Any], Any]
    """``build(space, feature_space, params)``: the sampler over the space, an object with the two methods the miner
    calls, as VerifAI's samplers have them: ``getSample() -> (point, info)`` (the next point of the feature space and
    what the sampler wants back with its outcome) and ``update(point, info, rho)`` (that point's robustness ``rho``,
    below 0 a failure; a sampler that does not learn ignores it); called with the sampler's seed set on Python's and
    NumPy's global generators. :func:`make_sampler` refuses a built object without them."""
    params: Callable[[Dict[str, Any]], Any] = lambda options: None
    """``params(options)``: the checked settings ``build`` gets (the option names are checked before)."""
    options: Tuple[str, ...] = ()
    """The options it takes (``--sampler-options``)."""
    default_feedback: str = "robustness"
    """What it learns from when the run does not say (``mine(feedback=None)``)."""
    adaptive: bool = False
    """Its next draws depend on the outcomes fed back (the miner streams episodes through a window)."""
    uniform: bool = False
    """Its scenes are uniform over the scenarios and their unit boxes (importance weight 1 without a record); its
    proposal density (:func:`proposal_density`) is the uniform one, read off the built sampler's ``space`` (VerifAI's
    ``FeatureSpace``, as VerifAI's feature samplers hold it)."""
    density: Optional[Callable[[Any, Any], Optional[Dict[str, Any]]]] = None
    """``density(sampler, point)``: the density the built ``sampler`` drew ``point`` with, at the moment it drew it,
    as :meth:`SceneSampler.proposal` describes it, or ``None`` when it cannot tell (:func:`proposal_density`);
    ``None`` here: the uniform density for a ``uniform`` sampler, none for the others."""


def _verifai(method: str, with_params: bool) -> Callable[[Any, Any, Any], Any]:
    def build(space: Any, feature_space: Any, params: Any):
        from verifai.samplers.feature_sampler import FeatureSampler

        factory = getattr(FeatureSampler, method)
        return factory(feature_space, params) if with_params else factory(feature_space)

    return build


SPLIT = "split"
"""The sampler split into a scenario chooser and one parameter sampler per scenario
(:mod:`dv2s_gym.mining.sampling.split_sampler`)."""

NOVELTY = "novelty-bandit"
"""The sampler that spreads the budget over scenarios by their rate of new failures
(:mod:`dv2s_gym.mining.sampling.novelty_sampler`)."""

SPLIT_DEFAULTS: Dict[str, Any] = {"chooser": "cross-entropy", "params": "halton", "alpha": 0.9, "thres": 0.0,
                                  "buckets": 3, "warmup": 0, "avoid": 81}
"""The settings of :data:`SPLIT` when no option is given."""



def default_feedback(name: str) -> str:
    """The feedback (:data:`dv2s_gym.mining.miner.FEEDBACKS`) sampler ``name`` gets unless told otherwise."""
    record = _REGISTRY.get(name, None)
    return record.default_feedback if record else "robustness"


def is_adaptive(name: str) -> bool:
    """True for samplers whose next draws depend on the outcomes fed back (``cross-entropy``, ``bandit``,
    ``split``, ``novelty-bandit``)."""
    record = _REGISTRY.get(name, None)
    return bool(record and record.adaptive)


def is_uniform(name: str) -> bool:
    """True for samplers whose scenes are uniform over the scenarios and their unit boxes (``random``, ``halton``)."""
    record = _REGISTRY.get(name, None)
    return bool(record and record.uniform)


def register_sampler(name: str, record: SamplerRecord, overwrite: bool = False) -> None:
    """Make ``make_sampler(name, ...)`` (and ``--sampler name``) build ``record``'s sampler; a name registered
    already needs ``overwrite=True``. The calling module (``__main__`` too) is part of a run's code identity
    (:func:`scenario_bank.plugins.remember_code`); the workers need nothing of it."""
    _REGISTRY.register(name, record, overwrite=overwrite)
    remember_code(f"sampler {name!r}", registering_module())


def registered_samplers() -> List[str]:
    """The sampler names :func:`make_sampler` accepts, the shipped ones (:data:`SAMPLERS`) first."""
    return list(_REGISTRY)


def sampler_params(name: str, options: Optional[Dict[str, Any]] = None):
    """VerifAI's parameter ``DotMap`` for sampler ``name`` with ``options`` applied (``None``: VerifAI's defaults).

    Raises :class:`MiningError` for an option the sampler does not take or a value out of range.
    """
    options = dict(options or {})
    record = _REGISTRY.get(name, None)
    allowed = record.options if record else ()
    unknown = sorted(set(options) - set(allowed))
    if unknown:
        takes = f"it takes {', '.join(allowed)}" if allowed else "it takes none"
        raise MiningError(f"sampler {name!r} has no option {', '.join(map(repr, unknown))}; {takes}")
    return record.params(options) if record else None


def _verifai_params(kind: str) -> Callable[[Dict[str, Any]], Any]:
    """The parameters of VerifAI's adaptive sampler ``kind`` (``ce``, ``mab``) with the options applied."""
    return lambda options: _apply_verifai_options(kind, options)


def _apply_verifai_options(kind: str, options: Dict[str, Any]):
    from verifai.samplers.feature_sampler import default_sampler_params

    params = default_sampler_params(kind)
    _check_numbers(options)
    if "alpha" in options:
        params.alpha = float(options["alpha"])
    if "buckets" in options:
        params.cont.buckets = int(options["buckets"])
    if "thres" in options:
        params.thres = float(options["thres"])
    return params


def _split_params(options: Dict[str, Any]) -> Dict[str, Any]:
    from dv2s_gym.mining.sampling.split_sampler import CHOOSERS, PARAM_SAMPLERS

    _check_numbers(options)
    params = {**SPLIT_DEFAULTS, **options}
    if params["chooser"] not in CHOOSERS:
        raise MiningError(f"sampler option chooser must be one of {', '.join(CHOOSERS)}, not {params['chooser']!r}")
    if params["params"] not in PARAM_SAMPLERS:
        raise MiningError(f"sampler option params must be one of {', '.join(PARAM_SAMPLERS)}, "
                          f"not {params['params']!r}")
    warmup = params["warmup"]
    if isinstance(warmup, bool) or not isinstance(warmup, int) or warmup < 0:
        raise MiningError(f"sampler option warmup must be a whole number >= 0, not {warmup!r}")
    avoid = params["avoid"]
    if isinstance(avoid, bool) or not isinstance(avoid, int) or avoid < 0:
        raise MiningError(f"sampler option avoid must be a whole number >= 0 (0: off), not {avoid!r}")
    params["alpha"], params["thres"], params["buckets"] = (float(params["alpha"]), float(params["thres"]),
                                                           int(params["buckets"]))
    return params


def _novelty_params(options: Dict[str, Any]) -> Dict[str, float]:
    from dv2s_gym.mining.sampling.novelty_sampler import NOVELTY_DEFAULTS

    params = {**NOVELTY_DEFAULTS, **options}
    try:
        params = {key: float(value) for key, value in params.items()}
    except (TypeError, ValueError):
        raise MiningError(f"sampler options of {NOVELTY} are numbers; got {options!r}") from None
    if not 0.0 < params["explore"] <= 1.0:
        raise MiningError(f"sampler option explore must be in (0, 1] (the uniform share; 0 would leave scenarios "
                          f"undrawn and the failure-rate estimate without weights), not {options.get('explore')!r}")
    for key in ("prior_new", "prior_old"):
        if not params[key] > 0.0:
            raise MiningError(f"sampler option {key} must be > 0 (a Beta prior), not {options.get(key)!r}")
    if not (params["cover"] >= 0 and params["cover"] == int(params["cover"])) or isinstance(options.get("cover"), bool):
        raise MiningError(f"sampler option cover must be a whole number >= 0 (scenes of every scenario drawn before "
                          f"the scores rank them), not {options.get('cover')!r}")
    params["cover"] = int(params["cover"])
    return params


def _check_numbers(options: Dict[str, Any]) -> None:
    if "alpha" in options:
        alpha = float(options["alpha"])
        if not 0.0 < alpha < 1.0:
            raise MiningError(f"sampler option alpha must be between 0 and 1 (exclusive), not {options['alpha']!r}")
    if "buckets" in options:
        buckets = options["buckets"]
        if isinstance(buckets, bool) or not isinstance(buckets, int) or buckets < 1:
            raise MiningError(f"sampler option buckets must be a whole number >= 1, not {buckets!r}")
    if "thres" in options:
        float(options["thres"])


class SceneSampler:
    """A VerifAI feature sampler with a private random state.

    Use :meth:`draw` for the next points and :meth:`feed` with each point's robustness
    (below 0: a failure) in the order they were drawn.
    """

    def __init__(self, name: str, sampler: Any, seed: int) -> None:
        self.name = name
        self._sampler = sampler
        state = random.Random(seed)
        self._py_state = state.getstate()
        self._np_state = np.random.RandomState(seed % (2**32)).get_state()
        self.fed = 0
        """How many outcomes have been fed back."""
        self.drawn = 0
        """How many points have been drawn (the next draw's index in the run)."""
        self.proposals: Dict[int, Optional[Dict[str, Any]]] = {}
        """Draw index -> the proposal density the point was drawn from (:meth:`proposal`)."""

    def _swap(self, fn: Callable, *args):
        saved_py, saved_np = random.getstate(), np.random.get_state()
        random.setstate(self._py_state)
        np.random.set_state(self._np_state)
        try:
            return fn(*args)
        finally:
            self._py_state, self._np_state = random.getstate(), np.random.get_state()
            random.setstate(saved_py)
            np.random.set_state(saved_np)

    def draw(self, count: int) -> List[Tuple[Any, Any]]:
        """The next ``count`` ``(point, info)`` pairs; ``info`` goes back with :meth:`feed`."""
        pairs = []
        for _ in range(count):
            point, info = self._swap(self._sampler.getSample)
            self.proposals[self.drawn] = proposal_density(self.name, self._sampler, point)
            self.drawn += 1
            pairs.append((point, info))
        return pairs

    def proposal(self, index: int) -> Optional[Dict[str, Any]]:
        """The density the point of draw ``index`` was drawn from, at the moment it was drawn:
        ``{"scenario": probability of its scenario, "coords": [density of each coordinate of u], "floor": the
        smallest scenario probability times the scenario count, "floors": [per coordinate, its smallest bucket
        density]}`` (the density of the scenario's own parameters is the product of its first coordinates; a
        floor far below 1 says the sampler had almost stopped drawing some region), or ``None`` when the sampler
        has no density to tell (:func:`proposal_density`)."""
        return getattr(self, "proposals", {}).get(int(index))

    def feed(self, point: Any, info: Any, rho: float) -> None:
        """Tell the sampler the robustness of a drawn point (adaptive samplers learn from it)."""
        self._swap(self._sampler.update, point, info, float(rho))
        self.fed += 1

    def dumps(self) -> bytes:
        """The whole state (sampler and generators) as bytes (:meth:`loads` restores it), sealed with this
        user's MAC (:mod:`~dv2s_gym.mining.sampling.checkpoint_mac`)."""
        import dill

        buffer = io.BytesIO()
        dill.dump(self, buffer)
        return seal(buffer.getvalue())

    @staticmethod
    def loads(data: bytes) -> "SceneSampler":
        """Inverse of :meth:`dumps`; :class:`MiningError` (nothing unpickled) unless ``data`` carries this user's
        MAC."""
        import dill

        payload = unseal(data)
        if payload is None:
            raise MiningError(UNSEALED)
        sampler = dill.loads(payload)
        if not isinstance(sampler, SceneSampler):
            raise MiningError("the sampler checkpoint holds no sampler; delete sampler.pkl to rebuild it from "
                              "episodes.jsonl")
        return sampler


UNSEALED = ("the sampler checkpoint was not written by this user's dv2s-gym (no valid MAC), so it is not "
            "loaded; delete sampler.pkl to rebuild it from episodes.jsonl, or start a new run with another --out")


def proposal_density(name: str, sampler: Any, point: Any) -> Optional[Dict[str, Any]]:
    """The density ``sampler`` (the built sampler called ``name``) draws ``point`` with right now, for importance
    weights: its record's :attr:`SamplerRecord.density`, else the uniform density for a
    :attr:`SamplerRecord.uniform` sampler, else ``None`` (as for a name no sampler is registered under).

    ``random`` and ``halton`` draw the scenario uniformly and the unit box uniformly (Halton's sequence is
    a quasi-random uniform cover: density 1); ``cross-entropy`` draws the scenario from its discrete
    distribution and each coordinate from its bucket distribution (density ``dist[bucket] * buckets``);
    ``split`` with the cross-entropy chooser and no cell avoidance (``avoid=0``) draws the scenario from the
    chooser's distribution and the parameters from its own sampler (uniform for ``halton``/``random``,
    bucketed for ``cross-entropy``); ``novelty-bandit`` draws the scenario from its mixture of uniform and the
    best-scoring scenarios and the parameters uniformly. ``None`` when there is no density to tell: ``bandit`` and the ``ucb``
    chooser pick deterministically, cell avoidance never draws some cells, a warm-up round follows a fixed order.
    """
    record = _REGISTRY.get(name, None)
    if record is None:
        return None
    if record.density is not None:
        return record.density(sampler, point)
    return _uniform_density(sampler, point) if record.uniform else None


def _coordinates(point: Any) -> Tuple[int, List[float]]:
    """The scenario index and the unit-box coordinates of a mining-space ``point``."""
    return int(round(float(_first(point.scenario)))), [float(x) for x in point.u]


def _uniform_density(sampler: Any, point: Any) -> Optional[Dict[str, Any]]:
    """The scenario drawn uniformly and the unit box uniformly (density 1)."""
    _, u = _coordinates(point)
    count = _scenario_count(sampler)
    return {"scenario": 1.0 / count, "coords": [1.0] * len(u), "floor": 1.0, "floors": [1.0] * len(u)} if count else None


def _cross_entropy_density(sampler: Any, point: Any) -> Optional[Dict[str, Any]]:
    """The scenario from its discrete distribution, each coordinate from its bucket distribution."""
    scenario, u = _coordinates(point)
    domain = getattr(sampler, "domainSampler", None)
    cont, disc = getattr(domain, "cont_sampler", None), getattr(domain, "disc_sampler", None)
    if cont is None or disc is None:
        return None
    return {"scenario": float(disc.dist[0][scenario]), "coords": _bucket_densities(cont, u),
            "floor": float(min(disc.dist[0])) * len(disc.dist[0]), "floors": _floors(cont, len(u))}


def _novelty_density(sampler: Any, point: Any) -> Optional[Dict[str, Any]]:
    """The scenario from the sampler's last mixture, the parameters uniformly."""
    scenario, u = _coordinates(point)
    row = list(getattr(sampler, "last_probabilities", None) or [])
    if not row or scenario >= len(row):
        return None
    return {"scenario": float(row[scenario]), "coords": [1.0] * len(u), "floor": float(min(row)) * len(row),
            "floors": [1.0] * len(u)}


def _split_density(sampler: Any, point: Any) -> Optional[Dict[str, Any]]:
    """The scenario from the chooser's distribution (a chooser whose draws follow it, no cell avoidance, past the
    warm-up), the parameters from the scenario's own sampler (uniform, or by its buckets)."""
    from dv2s_gym.mining.sampling.split_sampler import BUCKETS, CHOOSER_TABLE, PARAM_TABLE, UNIFORM

    scenario, u = _coordinates(point)
    chooser = CHOOSER_TABLE.get(getattr(sampler, "chooser_kind", None))
    params = PARAM_TABLE.get(getattr(sampler, "params_kind", None))
    if (chooser is None or not chooser.exact or params is None or getattr(sampler, "avoid", 0)
            or sampler.drawn <= len(sampler.warmup_order)):
        return None
    dimension = sampler.dimensions[scenario]
    own = sampler.param_samplers[scenario]
    if params.density == UNIFORM:
        coords, floors = [1.0] * dimension, [1.0] * dimension
    elif params.density == BUCKETS:
        coords, floors = _bucket_densities(own, u[:dimension]), _floors(own, dimension)
    else:
        return None
    dist = sampler.chooser.dist[0]
    return {"scenario": float(dist[scenario]), "coords": coords + [1.0] * (len(u) - dimension),
            "floor": float(min(dist)) * len(dist), "floors": floors + [1.0] * (len(u) - dimension)}


def _first(value):
    return value[0] if isinstance(value, (tuple, list)) else value


def _scenario_count(sampler: Any) -> int:
    try:
        (low, high), = sampler.space.featureNamed["scenario"].domain.intervals
        return int(high) - int(low) + 1
    except (AttributeError, KeyError, TypeError, ValueError):
        return 0


def scene_proposal(proposal: Optional[Dict[str, Any]], used: int) -> Optional[Dict[str, float]]:
    """What an episode record keeps of a draw's :meth:`SceneSampler.proposal` for a scenario with ``used``
    parameters: ``{"scenario", "params" (the density of its own coordinates), "floor" (the smallest share, relative
    to uniform, of any scenario or bucket of its coordinates)}``; ``None`` stays ``None``."""
    if proposal is None:
        return None
    density = 1.0
    for value in proposal["coords"][:used]:
        density *= float(value)
    floor = min([float(proposal.get("floor", 1.0))] + [float(f) for f in proposal.get("floors", [])[:used]])
    return {"scenario": float(proposal["scenario"]), "params": density, "floor": floor}


def _floors(cont: Any, count: int) -> List[float]:
    """Per coordinate: the smallest density any of its buckets has (1 when uniform)."""
    return [float(min(cont.dist[i])) * int(cont.buckets[i]) for i in range(count)]


def _bucket_densities(cont: Any, u: List[float]) -> List[float]:
    densities = []
    for i, x in enumerate(u):
        buckets = int(cont.buckets[i])
        bucket = min(buckets - 1, max(0, int(x * buckets)))
        densities.append(float(cont.dist[i][bucket]) * buckets)
    return densities


def make_sampler(name: str, space: Any, seed: int, options: Optional[Dict[str, Any]] = None) -> SceneSampler:
    """The sampler called ``name`` (one of :func:`registered_samplers`) over ``space``, seeded.

    ``space``: a :class:`~dv2s_gym.mining.sampling.space.SceneSpace`, or its VerifAI ``feature_space``
    (then ``split`` gives every scenario the full width of the unit box). ``options``: VerifAI
    parameters of the adaptive samplers (see the module docstring).
    """
    record = _REGISTRY.get(name)
    params = sampler_params(name, options)
    feature_space = getattr(space, "feature_space", space)
    saved_py, saved_np = random.getstate(), np.random.get_state()
    random.seed(seed)
    np.random.seed(seed % (2**32))
    try:  # some samplers draw while they are built
        inner = record.build(space, feature_space, params)
    finally:
        random.setstate(saved_py)
        np.random.set_state(saved_np)
    _check_protocol(name, inner)
    return SceneSampler(name, inner, seed)


SAMPLER_METHODS = (("getSample", "getSample() -> (point, info)"), ("update", "update(point, info, rho)"))
"""The methods a built sampler must have (:attr:`SamplerRecord.build`), with how the miner calls them."""


def _check_protocol(name: str, sampler: Any) -> None:
    """Refuse a built sampler that lacks a method the miner calls, naming the sampler, the method and the fix."""
    missing = [call for method, call in SAMPLER_METHODS if not callable(getattr(sampler, method, None))]
    if missing:
        raise MiningError(
            f"sampler {name!r} built a {type(sampler).__name__} without {' and '.join(missing)}, which the miner "
            "calls: the object its build returns needs both, getSample() -> (point, info) and update(point, info, "
            "rho), as VerifAI's samplers have them (SamplerRecord.build says what each does)")


def _scenario_dimensions(space: Any, feature_space: Any) -> list:
    """Parameter dimensions per scenario: read from a mining space, or the same width for every scenario of a
    bare feature space."""
    from dv2s_gym.mining.sampling.split_sampler import scenario_dimensions

    if hasattr(space, "scenarios"):
        return scenario_dimensions(space)
    width = len(feature_space.featureNamed["u"].domain.intervals)
    count = feature_space.featureNamed["scenario"].domain.intervals[0][1] + 1
    return [width] * int(count)


def _make_split(space: Any, feature_space: Any, params: Dict[str, Any]):
    from dv2s_gym.mining.sampling.split_sampler import AdaptSettings, ScenarioSplitSampler

    dimensions = _scenario_dimensions(space, feature_space)
    return ScenarioSplitSampler(
        feature_space, dimensions, chooser=params["chooser"], params=params["params"],
        adapt=AdaptSettings(alpha=params["alpha"], thres=params["thres"], buckets=params["buckets"]),
        warmup=params["warmup"], avoid=params["avoid"])


def _make_novelty(space: Any, feature_space: Any, params: Dict[str, float]):
    from dv2s_gym.mining.sampling.novelty_sampler import NoveltyBanditSampler

    return NoveltyBanditSampler(feature_space, _scenario_dimensions(space, feature_space), **params)


_REGISTRY: Registry[SamplerRecord] = Registry("sampler", MiningError, {
    "random": SamplerRecord(_verifai("randomSamplerFor", False), uniform=True),
    "halton": SamplerRecord(_verifai("haltonSamplerFor", False), uniform=True),
    "cross-entropy": SamplerRecord(_verifai("crossEntropySamplerFor", True), _verifai_params("ce"),
                                   ("alpha", "buckets", "thres"), adaptive=True,
                                   density=_cross_entropy_density),
    "bandit": SamplerRecord(_verifai("multiArmedBanditSamplerFor", True), _verifai_params("mab"),
                            ("alpha", "buckets", "thres"), adaptive=True),
    SPLIT: SamplerRecord(_make_split, _split_params, ("alpha", "buckets", "thres", "chooser", "params", "warmup",
                                                      "avoid"),
                         default_feedback="novelty", adaptive=True, density=_split_density),
    NOVELTY: SamplerRecord(_make_novelty, _novelty_params, ("explore", "prior_new", "prior_old", "cover"),
                           default_feedback="state-novelty", adaptive=True, density=_novelty_density),
})

SAMPLERS = tuple(_REGISTRY)
"""The names of the samplers that ship with dv2s-gym, in their documented order (``--sampler`` lists them first).
The names accepted now, plug-in samplers included, are :func:`registered_samplers`: ask it, not this tuple."""

SAMPLER_OPTIONS = {name: record.options for name, record in _REGISTRY.items() if record.options}
"""The options each shipped sampler takes (the others take none)."""
