"""Plug-in modules: the user's modules that add to dv2s-gym's registries, and how every worker process gets them.

A registration (a failure type, its detector, a policy) holds only in the process that made it, and the worker
processes that run episodes (the local pool's, started by forkserver or spawn; Ray's actors) import the product's
modules, not the user's. So the registries remember the module each plug-in comes from (:func:`remember_plugin`), and
every worker imports those modules (:func:`import_plugins`) before its first episode: a plug-in module registers
at import time, and then registers again in each worker.

A plug-in defined in ``__main__`` (a script, ``python -c``, an interactive session) cannot be imported by another
process; a run in worker processes refuses it (:func:`check_plugins`) and says to move it into an importable
module, named on the command line by the :data:`PLUGINS_VARIABLE` environment variable
(:func:`load_plugins_from_environment`, which ``dv2s`` reads before anything else).

A sampler and a DRA or SG backend run in the parent process only: the workers need nothing of them, so their
registrations are remembered apart (:func:`remember_code`), never imported by the workers, and allowed in
``__main__``. A run's result depends on their code all the same, so :func:`code_modules` (what a run's code identity,
:func:`policies.run_identity.code_identity`, fingerprints) lists both kinds.
"""

from __future__ import annotations

import importlib
import inspect
import os
from types import ModuleType
from typing import Dict, Iterable, List, Optional

from scenario_bank.errors import DV2SError
from scenario_bank.read_files import plugin_label, reading_for, watch

__all__ = ["PluginError", "PLUGINS_VARIABLE", "MAIN", "registering_module", "remember_plugin", "forget_plugin",
           "plugin_modules", "remember_code", "code_modules", "check_plugins", "import_plugins", "load_plugins_from_environment", "module_not_found",
           "import_raised", "missing_attribute"]

PLUGINS_VARIABLE = "DV2S_PLUGINS"
"""The environment variable naming plug-in modules for ``dv2s`` (comma-separated module names)."""

MAIN = "__main__"
"""The name of the module of a script or an interactive session, which no other process can import."""

_ORIGINS: Dict[str, str] = {}
"""What was registered (``"failure type 'hard_brake'"``) -> the module it comes from."""

_PARENT_ORIGINS: Dict[str, str] = {}
"""What was registered that runs in this process only (``"sampler 'upper'"``) -> the module it comes from."""


class PluginError(DV2SError, ValueError):
    """A plug-in module that worker processes cannot import: defined in ``__main__``, or failing to import."""


def remember_plugin(what: str, module: Optional[str]) -> None:
    """Remember that ``what`` (e.g. ``"failure type 'hard_brake'"``) was registered by ``module``, which every
    worker process then imports (:func:`plugin_modules`). The product's own modules need not be remembered (the
    workers import them anyway), nor is a ``None`` module."""
    if module:
        _ORIGINS[what] = module


def remember_code(what: str, module: Optional[str]) -> None:
    """Remember that ``what`` (e.g. ``"sampler 'upper'"``), which runs in this process only, was registered by
    ``module`` (``__main__`` too): part of the code a run depends on (:func:`code_modules`), which the workers do not
    import. The product's own modules and a ``None`` module are not remembered."""
    if module:
        _PARENT_ORIGINS[what] = module


def registering_module() -> Optional[str]:
    """The module of the code that called the registration function calling this (``register_policy`` and the
    like call it to learn which module registers, so that the workers import that module in turn); ``None`` when
    that code is in the registration function's own package (its built-in entries, which every worker has)."""
    frame = inspect.currentframe()
    registration = frame.f_back if frame is not None else None
    caller = registration.f_back if registration is not None else None
    if caller is None:
        return None
    module = caller.f_globals.get("__name__")
    own = str(registration.f_globals.get("__name__", "")).split(".")[0]
    return None if module is None or module.split(".")[0] == own else module


def forget_plugin(what: str) -> None:
    """Undo :func:`remember_plugin` for ``what`` (its registration was undone)."""
    _ORIGINS.pop(what, None)


def plugin_modules() -> List[str]:
    """The modules of every plug-in registered in this process, sorted, each once."""
    return sorted(set(_ORIGINS.values()))


def code_modules() -> List[str]:
    """The modules whose registrations a run's result depends on, sorted, each once: the plug-in modules
    (:func:`plugin_modules`) and those of the registrations that run in this process only (:func:`remember_code`),
    ``__main__`` included."""
    return sorted(set(_ORIGINS.values()) | set(_PARENT_ORIGINS.values()))


def check_plugins() -> List[str]:
    """The plug-in modules (:func:`plugin_modules`), checked to be importable by worker processes.

    Raises:
        PluginError: when a plug-in comes from ``__main__``, naming what it registered and the fix.
    """
    in_main = sorted(what for what, module in _ORIGINS.items() if module == MAIN)
    if in_main:
        raise PluginError(
            f"{', '.join(in_main)} {'is' if len(in_main) == 1 else 'are'} registered in __main__ (a script, "
            "python -c or an interactive session), which the worker processes that run episodes cannot import: "
            "put the registration in an importable module (e.g. my_plugins.py on the Python path) and import that "
            f"module, or name it to dv2s with {PLUGINS_VARIABLE}=my_plugins")
    return plugin_modules()


def module_not_found(module: str, error: BaseException) -> bool:
    """Whether ``error``, raised importing ``module``, says that ``module`` (or a package above it) is not found,
    rather than that the module's own code failed (which may be a missing import *inside* it)."""
    missing = getattr(error, "name", None) if isinstance(error, ModuleNotFoundError) else None
    return bool(missing) and (module == missing or module.startswith(f"{missing}."))


def import_raised(module: str, error: BaseException, where: str = "this process") -> str:
    """The words for a module that was found but whose own code raised ``error`` while it was imported in
    ``where`` (a worker process, ``"a worker process"``: the advice says to import it as a worker does, since it may import in the
    process that started the workers and fail only there)."""
    reason = " ".join(f"{type(error).__name__}: {error}".split())
    how = "" if "worker" not in where else (
        f"as {where} does (its working folder, environment and Python path: a module may import here and fail "
        "only there) ")
    return f"importing it raised {reason}; run `python -c 'import {module}'` {how}to see the traceback"


def missing_attribute(module: object, attribute: str) -> str:
    """The words for a module that has no ``attribute``: what it has no, and the public names it defines (not the
    modules, classes and functions it imports)."""
    own = getattr(module, "__name__", None)
    names = sorted(name for name, value in vars(module).items()
                   if not name.startswith("_") and not isinstance(value, ModuleType)
                   and getattr(value, "__module__", own) == own)
    shown = ", ".join(names[:20]) + (f", ... ({len(names)} in all)" if len(names) > 20 else "")
    return f"module {getattr(module, '__name__', module)!r} has no {attribute!r}; it defines: {shown or 'nothing public'}"


def import_plugins(modules: Iterable[str], where: str = "this process") -> None:
    """Import each of ``modules`` (a worker does, before its first episode, so that their registrations hold
    there too).

    Raises:
        PluginError: naming the first module that cannot be imported, where, and why: not found (then it must
            be put on the Python path), or its own code raised (then its traceback shows why).
    """
    modules = list(modules)
    if modules:
        watch()  # what a plug-in reads when imported (a threshold in a file beside it) is part of a run's identity
    for module in modules:
        try:
            with reading_for(plugin_label(module)):
                importlib.import_module(module)
        except BaseException as error:  # a plug-in's own failure at import time, whatever it is, is reported
            if isinstance(error, KeyboardInterrupt):
                raise
            if not module_not_found(module, error):
                raise PluginError(f"plug-in module {module!r} cannot be imported in {where}: "
                                  f"{import_raised(module, error, where)}") from None
            reason = " ".join(f"{type(error).__name__}: {error}".split())
            raise PluginError(f"plug-in module {module!r} cannot be imported in {where} ({reason}); it must be "
                              "importable there: on the Python path of every worker (the same path on every "
                              "node of a cluster)") from None


def load_plugins_from_environment(environ: Optional[Dict[str, str]] = None) -> List[str]:
    """Import the modules :data:`PLUGINS_VARIABLE` names (comma-separated; none when unset) and remember them as
    plug-ins, so the worker processes import them too. Returns their names.

    Raises:
        PluginError: naming a module that cannot be imported.
    """
    value = (os.environ if environ is None else environ).get(PLUGINS_VARIABLE, "")
    modules = [name.strip() for name in value.split(",") if name.strip()]
    import_plugins(modules, where=f"this process (named by {PLUGINS_VARIABLE})")
    for module in modules:
        remember_plugin(f"{PLUGINS_VARIABLE}={module}", module)
    return modules
