"""Pools of worker processes that run episodes for ``dv2s regress``, ``dv2s mine`` and ``dv2s loop``.

- :mod:`dv2s_gym.workers.tasks`: the task registry. A task is a plain dict whose ``"kind"`` names
  the function a worker runs on it; regress and mining register their own kinds, so the pools
  import neither of them.
- :mod:`dv2s_gym.workers.pool`: the :class:`~dv2s_gym.workers.pool.Backend` interface, the local
  process pool (:class:`~dv2s_gym.workers.pool.LocalBackend`: per-episode timeout, crashed or hung
  workers replaced, tasks retried).
- :mod:`dv2s_gym.workers.backends`: the backends by name, :func:`~dv2s_gym.workers.backends.get_backend`
  and :func:`~dv2s_gym.workers.backends.register_backend` (``--backend`` of the commands reads them).
- :mod:`dv2s_gym.workers.ray_pool`: the same on a Ray cluster (``--backend ray``).
- :mod:`dv2s_gym.workers.errors`: the errors of the pools.
"""

__all__ = []
