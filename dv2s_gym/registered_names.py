"""The names a registry holds, as argparse ``choices`` that are read when a command line is parsed."""

from __future__ import annotations

from typing import Callable, Iterator, List, Sequence

__all__ = ["RegisteredNames"]


class RegisteredNames:
    """The names a registry holds when asked (argparse's ``choices``): checked and listed at parse time,
    not when the parser was built."""

    def __init__(self, names: Callable[[], Sequence[str]], shipped: Sequence[str]):
        self._names = names
        self._shipped = tuple(shipped)

    def _current(self) -> List[str]:
        # the shipped names first, in their documented order, then the ones registered since
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
