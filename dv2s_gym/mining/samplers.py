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
  tried less often (``multiArmedBanditSamplerFor``).

The adaptive samplers (``cross-entropy``, ``bandit``) take VerifAI's parameters as
``options`` (:data:`SAMPLER_OPTIONS`): ``alpha`` (how much one failure moves the
distribution: each update multiplies it by ``alpha``, VerifAI's default 0.9), ``buckets``
(buckets per continuous parameter, default 5; 1 leaves the parameters uniform and adapts
only which scenario is drawn) and ``thres`` (robustness below which an outcome counts
as a failure, default 0).
"""

from __future__ import annotations

import io
import random
from typing import Any, Callable, Dict, List, Optional, Tuple

import numpy as np

from dv2s_gym.mining.errors import MiningError

__all__ = ["SAMPLERS", "SAMPLER_OPTIONS", "SceneSampler", "make_sampler", "sampler_params", "is_adaptive"]


def _factories() -> Dict[str, Callable]:
    from verifai.samplers.feature_sampler import FeatureSampler

    return {
        "random": FeatureSampler.randomSamplerFor,
        "halton": FeatureSampler.haltonSamplerFor,
        "cross-entropy": FeatureSampler.crossEntropySamplerFor,
        "bandit": FeatureSampler.multiArmedBanditSamplerFor,
    }


SAMPLERS = ("random", "halton", "cross-entropy", "bandit")
"""Names :func:`make_sampler` accepts."""

SAMPLER_OPTIONS = {"cross-entropy": ("alpha", "buckets", "thres"), "bandit": ("alpha", "buckets", "thres")}
"""The options each sampler takes (the others take none)."""

_VERIFAI_KIND = {"cross-entropy": "ce", "bandit": "mab"}


def is_adaptive(name: str) -> bool:
    """True for samplers whose next draws depend on the outcomes fed back (``cross-entropy``, ``bandit``)."""
    return name in _VERIFAI_KIND


def sampler_params(name: str, options: Optional[Dict[str, Any]] = None):
    """VerifAI's parameter ``DotMap`` for sampler ``name`` with ``options`` applied (``None``: VerifAI's defaults).

    Raises :class:`MiningError` for an option the sampler does not take or a value out of range.
    """
    options = dict(options or {})
    allowed = SAMPLER_OPTIONS.get(name, ())
    unknown = sorted(set(options) - set(allowed))
    if unknown:
        takes = f"it takes {', '.join(allowed)}" if allowed else "it takes none"
        raise MiningError(f"sampler {name!r} has no option {', '.join(map(repr, unknown))}; {takes}")
    if name not in _VERIFAI_KIND:
        return None
    from verifai.samplers.feature_sampler import default_sampler_params

    params = default_sampler_params(_VERIFAI_KIND[name])
    if "alpha" in options:
        alpha = float(options["alpha"])
        if not 0.0 < alpha < 1.0:
            raise MiningError(f"sampler option alpha must be between 0 and 1 (exclusive), not {options['alpha']!r}")
        params.alpha = alpha
    if "buckets" in options:
        buckets = options["buckets"]
        if isinstance(buckets, bool) or not isinstance(buckets, int) or buckets < 1:
            raise MiningError(f"sampler option buckets must be a whole number >= 1, not {buckets!r}")
        params.cont.buckets = int(buckets)
    if "thres" in options:
        params.thres = float(options["thres"])
    return params


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
        return [self._swap(self._sampler.getSample) for _ in range(count)]

    def feed(self, point: Any, info: Any, rho: float) -> None:
        """Tell the sampler the robustness of a drawn point (adaptive samplers learn from it)."""
        self._swap(self._sampler.update, point, info, float(rho))
        self.fed += 1

    def dumps(self) -> bytes:
        """The whole state (sampler and generators) as bytes (:meth:`loads` restores it)."""
        import dill

        buffer = io.BytesIO()
        dill.dump(self, buffer)
        return buffer.getvalue()

    @staticmethod
    def loads(data: bytes) -> "SceneSampler":
        """Inverse of :meth:`dumps`."""
        import dill

        sampler = dill.loads(data)
        if not isinstance(sampler, SceneSampler):
            raise MiningError("the sampler checkpoint holds no sampler; delete sampler.pkl to rebuild it from "
                              "episodes.jsonl")
        return sampler


def make_sampler(name: str, feature_space: Any, seed: int, options: Optional[Dict[str, Any]] = None) -> SceneSampler:
    """The sampler called ``name`` (:data:`SAMPLERS`) over ``feature_space``, seeded.

    ``options``: VerifAI parameters of the adaptive samplers (see the module docstring).
    """
    factories = _factories()
    if name not in factories:
        raise MiningError(f"unknown sampler {name!r}: use one of {', '.join(SAMPLERS)}")
    params = sampler_params(name, options)
    saved_py, saved_np = random.getstate(), np.random.get_state()
    random.seed(seed)
    np.random.seed(seed % (2**32))
    try:  # some samplers draw while they are built
        inner = factories[name](feature_space) if params is None else factories[name](feature_space, params)
    finally:
        random.setstate(saved_py)
        np.random.set_state(saved_np)
    return SceneSampler(name, inner, seed)
