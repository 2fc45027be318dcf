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
"""

from __future__ import annotations

import io
import random
from typing import Any, Callable, Dict, List, Tuple

import numpy as np

from dv2s_gym.mining.errors import MiningError

__all__ = ["SAMPLERS", "SceneSampler", "make_sampler"]


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


def make_sampler(name: str, feature_space: Any, seed: int) -> SceneSampler:
    """The sampler called ``name`` (:data:`SAMPLERS`) over ``feature_space``, seeded."""
    factories = _factories()
    if name not in factories:
        raise MiningError(f"unknown sampler {name!r}: use one of {', '.join(SAMPLERS)}")
    saved_py, saved_np = random.getstate(), np.random.get_state()
    random.seed(seed)
    np.random.seed(seed % (2**32))
    try:  # some samplers draw while they are built
        inner = factories[name](feature_space)
    finally:
        random.setstate(saved_py)
        np.random.set_state(saved_np)
    return SceneSampler(name, inner, seed)
