"""Tables of named plug-ins (policies, samplers, task kinds, worker and pipeline backends, failure types and their
detectors): one :class:`Registry` type for all.

Each registry is a module-level :class:`Registry` in the module that uses it, and that module's
``register_x(name_or_object, value..., overwrite=False)`` adds to it. A registry is a mutable mapping of name ->
entry too, so code that reads a plain ``dict`` of plug-ins (``name in table``, ``table[name]``, ``sorted(table)``)
reads it unchanged."""

from __future__ import annotations

import warnings
import weakref
from scenario_bank.errors import BuiltInReplacedWarning
from typing import (Callable, Dict, Iterator, List, Mapping, MutableMapping, Optional, Sequence, Type, TypeVar,
                    Union, overload)

__all__ = ["Registry", "replaced_built_ins", "replaced_text"]

V = TypeVar("V")
D = TypeVar("D")
UnknownError = Callable[[str, Sequence[str]], Exception]
"""``unknown(name, known_names) -> error``: the error a registry raises for a name it does not hold."""

_MISSING = object()
_REGISTRIES: "weakref.WeakValueDictionary[int, Registry]" = weakref.WeakValueDictionary()
"""Every registry of this process (:func:`replaced_built_ins` reads them all)."""


def replaced_built_ins() -> List[str]:
    """Every built-in entry a plug-in replaced or removed in this process, in any registry, sorted, one phrase
    each: ``"detector 'collision' (replaced by my_plugins)"``, ``"policy 'rule' (removed)"``."""
    found = set()
    for registry in list(_REGISTRIES.values()):
        for name, module in registry.replaced().items():
            how = "removed" if module == _REMOVED else f"replaced by {module}" if module else "replaced"
            found.add(f"{registry.what} {name!r} ({how})")
    return sorted(found)


def replaced_text(replaced: Sequence[str]) -> str:
    """The sentence a report's banner and a command's summary add when plug-ins replaced built-in entries (a
    detector, the reference driver; :func:`replaced_built_ins`), so that the counts read as the plug-ins'; ``""``
    when none was."""
    if not replaced:
        return ""
    several = len(replaced) > 1
    return (f"Built-in{'s' if several else ''} replaced by plug-ins: {', '.join(replaced)}; what this run counts "
            f"under {'those names' if several else 'that name'} is the plug-ins'")


_REMOVED = "<removed>"


class Registry(MutableMapping[str, V]):
    """Name -> entry, in the order registered, with the module that registered each entry when one is given.

    ``what`` names the kind in messages (``"sampler"``, ``"worker backend"``); ``error`` is the project error a
    clash or an unknown name raises; ``unknown`` (optional) makes the unknown-name error instead, for a registry
    whose callers word it their own way. ``entries`` are registered first, in their order, and are built in
    (:meth:`mark_built_in`): replacing or removing one issues a
    :class:`~scenario_bank.errors.BuiltInReplacedWarning`, so a plug-in cannot swap the product's own entry
    (the collision detector, the reference driver) without a word."""

    def __init__(self, what: str, error: Type[Exception], entries: Optional[Mapping[str, V]] = None, *,
                 unknown: Optional[UnknownError] = None) -> None:
        self.what = what
        self.error = error
        self._unknown = unknown
        self._entries: Dict[str, V] = {}
        self._modules: Dict[str, str] = {}
        self._built_in: set = set()
        self._replaced: Dict[str, Optional[str]] = {}
        _REGISTRIES[id(self)] = self
        for name, value in (entries or {}).items():
            self.register(name, value)
        self.mark_built_in()

    def mark_built_in(self, *names: str) -> None:
        """Every entry held now is one of the product's own (a module that registers its entries by calls
        marks them once it has); none of them counts as replaced. With ``names``: those entries only (a
        registry that product modules fill one entry each, as they are imported)."""
        if names:
            self._built_in.update(name for name in names if name in self._entries)
            for name in names:
                self._replaced.pop(name, None)
            return
        self._built_in = set(self._entries)
        self._replaced = {}

    def replaced(self) -> Dict[str, Optional[str]]:
        """The built-in entries replaced since they were marked, name -> the module that replaced it (``None``:
        not known; ``"<removed>"``: removed)."""
        return dict(self._replaced)

    def is_built_in(self, name: str) -> bool:
        """Whether ``name`` is one of the product's own entries (:meth:`mark_built_in`)."""
        return name in self._built_in

    def register(self, name: str, value: V, *, overwrite: bool = False, module: Optional[str] = None) -> V:
        """Hold ``value`` under ``name`` (registered by ``module``, when given); returns ``value``.

        Raises ``error`` for a name that is not a non-empty string, or one already held without ``overwrite``
        (saying to pass ``overwrite=True`` to replace it). A replaced entry keeps its place in the order."""
        if not isinstance(name, str) or not name:
            raise self.error(f"{self.what} name {name!r} must be a non-empty string")
        if name in self._entries and not overwrite:
            raise self.error(f"a {self.what} named {name!r} is already registered; pass overwrite=True to replace it")
        if name in self._built_in:
            warnings.warn(BuiltInReplacedWarning(self.what, name, module), stacklevel=3)
            self._built_in.discard(name)
            self._replaced[name] = module
        self._entries[name] = value
        if module:
            self._modules[name] = module
        else:
            self._modules.pop(name, None)
        return value

    @overload
    def get(self, name: str) -> V: ...

    @overload
    def get(self, name: str, default: D) -> Union[V, D]: ...

    def get(self, name: str, default: object = _MISSING) -> object:
        """The entry called ``name``; for a name not held, ``default`` when one is given, else ``error`` naming
        the known names."""
        if isinstance(name, str) and name in self._entries:
            return self._entries[name]
        if default is not _MISSING:
            return default
        raise self.unknown_error(name)

    def unknown_error(self, name: object) -> Exception:
        """The error for ``name``, which this registry does not hold: it lists the names it does."""
        if self._unknown is not None:
            return self._unknown(name, self.names())  # type: ignore[arg-type]
        known = ", ".join(self._entries) or "none is registered"
        return self.error(f"unknown {self.what} {name!r}: use one of {known}")

    def names(self) -> List[str]:
        """The names held, in the order registered."""
        return list(self._entries)

    def module(self, name: str) -> Optional[str]:
        """The module that registered ``name`` (``None``: not held, or registered without one)."""
        return self._modules.get(name)

    def unregister(self, name: str) -> V:
        """Remove the entry called ``name`` and return it; a name not held raises as :meth:`get` does."""
        value = self.get(name)
        del self[name]
        return value

    def copy(self) -> "Registry[V]":
        """A new registry holding the same entries and modules (a test can register into it and drop it)."""
        other: Registry[V] = Registry(self.what, self.error, unknown=self._unknown)
        other._entries = dict(self._entries)
        other._modules = dict(self._modules)
        other._built_in = set(self._built_in)
        other._replaced = dict(self._replaced)
        return other

    # the mapping protocol: ``[]`` and ``del`` raise KeyError as a dict does; ``[] =`` replaces
    def __getitem__(self, name: str) -> V:
        return self._entries[name]

    def __setitem__(self, name: str, value: V) -> None:
        self.register(name, value, overwrite=True)

    def __delitem__(self, name: str) -> None:
        del self._entries[name]
        self._modules.pop(name, None)
        if name in self._built_in:
            warnings.warn(BuiltInReplacedWarning(self.what, name, None, removed=True), stacklevel=3)
            self._built_in.discard(name)
            self._replaced[name] = _REMOVED

    def __contains__(self, name: object) -> bool:
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        return iter(self._entries)

    def __len__(self) -> int:
        return len(self._entries)

    def __repr__(self) -> str:
        return f"Registry({self.what!r}, {self.names()!r})"
