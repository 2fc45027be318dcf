"""``--dra``, ``--sg`` and ``--backend``: one definition of the backend options every command uses.

Their choices are registries (:func:`~dv2s_gym.pipeline.stages.register_dra`,
:func:`~dv2s_gym.pipeline.stages.register_sg`, :func:`~dv2s_gym.workers.backends.register_backend`), read when
the command line is parsed, so a backend a plugin registers before :func:`dv2s_gym.cli.main` runs is accepted
by every command.
"""

from __future__ import annotations

import argparse
from typing import Optional

from dv2s_gym.pipeline.stages import DRA_BACKENDS, registered_dras, registered_sgs, SG_BACKENDS
from dv2s_gym.registered_names import RegisteredNames
from dv2s_gym.workers.backends import backend_choices
from dv2s_gym.workers.settings import WorkerSettings

__all__ = ["dra_option", "sg_option", "worker_backend_option"]


def _help(base: Optional[str], choices: RegisteredNames) -> Optional[str]:
    extras = choices.extras()
    if not extras:
        return base
    added = f"also registered: {', '.join(extras)}"
    return f"{base}; {added}" if base else added


def dra_option(p: argparse.ArgumentParser, help: Optional[str] = None) -> None:
    """``--dra`` (default ``bev``): a Driving Record Analyzer backend by its registered name."""
    choices = RegisteredNames(registered_dras, DRA_BACKENDS)
    p.add_argument("--dra", choices=choices, default="bev", help=_help(help, choices))


def sg_option(p: argparse.ArgumentParser, help: Optional[str] = None) -> None:
    """``--sg`` (default ``rules``): a Scenario Generator backend by its registered name."""
    choices = RegisteredNames(registered_sgs, SG_BACKENDS)
    p.add_argument("--sg", choices=choices, default="rules", help=_help(help, choices))


def worker_backend_option(p: argparse.ArgumentParser, help: Optional[str] = None) -> None:
    """``--backend`` (default ``local``): where episodes run, a worker backend by its registered name."""
    choices = backend_choices()
    p.add_argument("--backend", choices=choices, default=WorkerSettings.backend, help=_help(help, choices))
