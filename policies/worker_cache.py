"""Envs and loaded policies kept by a worker process between episodes.

Making an env and compiling a scenario is the slow part of an episode, so the worker
processes of ``dv2s regress`` and ``dv2s mine`` keep one env per (bank, env config) and
one loaded policy per spec and env, for every task they run.
"""

from __future__ import annotations

import json
from typing import Any, Dict, Optional, Tuple
from policies.evaluation import make_eval_env
from policies.registry import load_policy

__all__ = ["env_for", "policy_for", "drop_env"]

_ENVS: Dict[Tuple[Optional[str], str], Any] = {}
_POLICIES: Dict[Tuple[str, str, Optional[str], str], Any] = {}


def _config_key(config: Optional[Dict[str, Any]]) -> str:
    return json.dumps(config or {}, sort_keys=True, default=str)


def env_for(bank_dir: Optional[str], config: Optional[Dict[str, Any]]):
    """This process's cached env for a bank and env config: ``(cache key, env)``."""
    key = (bank_dir, _config_key(config))
    env = _ENVS.get(key)
    if env is None:
        # the whole bank: reset(options={"scenario": name}) picks the episode's scenario,
        # and each scenario is compiled once, the first time it runs here
        env = make_eval_env(None, config=dict(config or {}), bank_dir=bank_dir)
        _ENVS[key] = env
    return key, env


def policy_for(spec: str, env_key: Tuple[Optional[str], str], env, owner: str = ""):
    """This process's cached policy ``spec``, bound to the env cached under ``env_key``.

    ``owner`` keeps instances apart: ``dv2s regress`` gives each role its own, so a stateful policy
    run as both candidate and baseline sees the same sequence of episodes in both roles.
    """
    key = (spec, owner, *env_key)
    policy = _POLICIES.get(key)
    if policy is None:
        policy = load_policy(spec)
        policy.bind([env])
        _POLICIES[key] = policy
    return policy


def drop_env(env_key: Tuple[Optional[str], str]) -> None:
    """Forget an env (and the policies bound to it) after an exception left it in an unknown state."""
    env = _ENVS.pop(env_key, None)
    for key in [k for k in _POLICIES if k[2:] == env_key]:
        del _POLICIES[key]
    if env is not None:
        try:
            env.close()
        except Exception:  # closing a broken env must not hide the episode's error
            pass
