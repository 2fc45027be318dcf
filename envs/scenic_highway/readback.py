"""Reading the simulator's state back into Scenic objects, cheaply and with Scenic's values.

After every time step Scenic's ``Simulation.updateObjects`` assigns each
object's simulator-provided properties (position, yaw, velocity, ...), then
recomputes its *dynamic final* properties (``orientation``, a SciPy rotation
product, and ``heading``, read back from it) and calls all ~40 cache clearers
of the class one by one. In a highway-env step that is most of the read-back
cost, and most of it is wasted: behaviours rarely read ``orientation`` or
``heading``, and only a few cached values are ever filled.

:func:`update_objects` does the same work with the same results:

* dynamic finals become *lazy*: the stale values are dropped from the object
  and a non-data descriptor on the class recomputes a value with Scenic's own
  expression the first time it is read (then it sits in the object's
  ``__dict__`` again, as before). The inputs (yaw, pitch, roll, parent
  orientation) only change here, so a value computed later equals the one
  Scenic would have computed now, bit for bit;
* cached values stored by ``scenic.core.utils.cached`` are dropped with one
  dictionary pass; other clearers are called as Scenic calls them.

Classes that already define an attribute with a dynamic final's name keep
Scenic's eager recomputation.
"""

from __future__ import annotations

import numbers
import weakref
from typing import FrozenSet, Tuple

from scenic.core.lazy_eval import valueInContext

from envs.errors import SimulatorPropertiesError

__all__ = ["update_objects", "prepare_class"]


class _LazyFinal:
    """Non-data descriptor: a dynamic final property recomputed on first read after a step."""

    def __init__(self, name: str) -> None:
        self.name = name

    def __get__(self, instance, owner=None):
        if instance is None:
            return self
        recomputer = getattr(type(instance), "_dynamicFinalProperties", {}).get(self.name)
        if recomputer is None:
            raise AttributeError(f"{type(instance).__name__} object has no attribute {self.name!r}")
        value = valueInContext(recomputer(instance), instance)
        type(instance)._specify(instance, self.name, value)
        return object.__getattribute__(instance, "__dict__")[self.name]


class _ClassPlan:
    """What a read-back does for one Scenic class (computed once per class)."""

    __slots__ = ("lazy", "final_names", "cached_names", "other_clearers", "plain_sets")

    def __init__(self, cls) -> None:
        finals = tuple(getattr(cls, "_dynamicFinalProperties", {}) or {})
        lazy = True
        for name in finals:
            existing = getattr(cls, name, None)
            if existing is not None and not isinstance(existing, _LazyFinal):
                lazy = False
        if lazy:
            for name in finals:
                if not isinstance(cls.__dict__.get(name), _LazyFinal):
                    setattr(cls, name, _LazyFinal(name))
        self.lazy = lazy
        # Properties without a class-level setter can be written straight into __dict__.
        self.plain_sets = not any(
            hasattr(getattr(cls, prop, None), "__set__") for prop in getattr(cls, "_simulatorProvidedProperties", {})
        )
        self.final_names: Tuple[str, ...] = finals
        cached, others = set(), []
        for clearer in getattr(cls, "_cache_clearers", {}).values():
            name = _cached_storage_name(clearer)
            if name is None:
                others.append(clearer)
            else:
                cached.add(name)
        self.cached_names: FrozenSet[str] = frozenset(cached)
        self.other_clearers = tuple(others)


def _cached_storage_name(clearer):
    """The attribute a ``scenic.core.utils.cached`` clearer deletes, or None for other clearers."""
    code = getattr(clearer, "__code__", None)
    if code is None or code.co_freevars != ("storageName",) or "cached.<locals>" not in clearer.__qualname__:
        return None
    value = clearer.__closure__[0].cell_contents
    return value if isinstance(value, str) else None


_plans: "weakref.WeakKeyDictionary[type, _ClassPlan]" = weakref.WeakKeyDictionary()


def prepare_class(cls) -> _ClassPlan:
    """Plan (and lazy descriptors) for a Scenic object class; idempotent."""
    plan = _plans.get(cls)
    if plan is None:
        plan = _plans[cls] = _ClassPlan(cls)
    return plan


def update_objects(simulation, get_properties) -> None:
    """Scenic's ``updateObjects`` for simulations that neither record nor check replays.

    ``get_properties(obj, properties)`` returns the simulator's values, as
    ``Simulation.getProperties`` does.
    """
    for obj in simulation.objects:
        proxy = object.__getattribute__(obj, "_dynamicProxy")
        cls = type(proxy)
        plan = _plans.get(cls) or prepare_class(cls)
        dyn_types = cls._simulatorProvidedProperties
        values = get_properties(obj, dyn_types.keys())
        if values.keys() != dyn_types.keys():
            raise SimulatorPropertiesError(f"simulator provided properties {sorted(values)} instead of {sorted(dyn_types)}")
        state = object.__getattribute__(proxy, "__dict__")
        for prop, value in values.items():
            ty = dyn_types[prop]
            if ty is float and isinstance(value, numbers.Real):
                value = float(value)
            elif ty is type(None):
                dyn_types[prop] = type(value)
            elif not isinstance(value, ty):
                raise SimulatorPropertiesError(
                    f'simulator provided value for property "{prop}" '
                    f"with type {type(value).__name__} instead of expected {ty.__name__}"
                )
            if plan.plain_sets:
                state[prop] = value
            else:
                object.__setattr__(proxy, prop, value)
        if plan.lazy:
            for name in plan.final_names:
                state.pop(name, None)
        else:
            proxy._recomputeDynamicFinals()
        for name in plan.cached_names.intersection(state):
            del state[name]
        for clearer in plan.other_clearers:
            clearer(proxy)
