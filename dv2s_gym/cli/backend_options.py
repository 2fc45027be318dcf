"""``--dra`` and ``--sg``: one definition of the pipeline backend options every command uses.

Their choices are the pipeline's registries (:func:`~dv2s_gym.pipeline.stages.register_dra`,
:func:`~dv2s_gym.pipeline.stages.register_sg`), read when the command line is parsed, so a backend a
plugin registers before :func:`dv2s_gym.cli.main` runs is accepted by every command.
"""

from __future__ import annotations

import argparse
from typing import Callable, Iterator, List, Optional, Sequence

__all__ = ["RegisteredNames", "dra_option", "sg_option"]


class RegisteredNames:
    """The names a registry holds when asked (argparse's ``choices``): checked and listed at parse time,
    not when the parser was built."""

    def __init__(self, names: Callable[[], Sequence[str]], shipped: Sequence[str]):
        self._names = names
        self._shipped = tuple(shipped)

    def _current(self) -> List[str]:
        # the shipped backends first, in their documented order, then the registered ones
        registered = list(self._names())
        return [name for name in self._shipped if name in registered] + \
            [name for name in registered if name not in self._shipped]

    def __iter__(self) -> Iterator[str]:
        return iter(self._current())

    def __contains__(self, name: object) -> bool:
        return name in self._names()

    def __len__(self) -> int:
        return len(self._current())

    def extras(self) -> List[str]:
        """The registered names that do not ship with dv2s-gym."""
        return [name for name in self._current() if name not in self._shipped]


def _help(base: Optional[str], choices: RegisteredNames) -> Optional[str]:
    extras = choices.extras()
    if not extras:
        return base
    added = f"also registered: {', '.join(extras)}"
    return f"{base}; {added}" if base else added


def dra_option(p: argparse.ArgumentParser, help: Optional[str] = None) -> None:
    """``--dra`` (default ``bev``): a Driving Record Analyzer backend by its registered name."""
    from dv2s_gym.pipeline.stages import DRA_BACKENDS, registered_dras

    choices = RegisteredNames(registered_dras, DRA_BACKENDS)
    p.add_argument("--dra", choices=choices, default="bev", help=_help(help, choices))


def sg_option(p: argparse.ArgumentParser, help: Optional[str] = None) -> None:
    """``--sg`` (default ``rules``): a Scenario Generator backend by its registered name."""
    from dv2s_gym.pipeline.stages import SG_BACKENDS, registered_sgs

    choices = RegisteredNames(registered_sgs, SG_BACKENDS)
    p.add_argument("--sg", choices=choices, default="rules", help=_help(help, choices))
