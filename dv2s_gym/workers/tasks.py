"""Task kinds, the functions that run them in a worker process, and the results standing for failed tasks.

A *task* is a plain dict, so any pool (local processes, Ray) can ship it. Every task has a
``kind`` (which function runs it), ``role``, ``policy``, ``scenario`` and ``seed``; the other keys
belong to its kind. The packages that make tasks register their kinds when they are imported
(:func:`register`): ``"regress"`` in :mod:`dv2s_gym.regress.tasks`, ``"mine"`` and ``"heldout"`` in
:mod:`dv2s_gym.mining.tasks`. A pool looks the function of each task up in the caller's process
(:func:`function_for`) and ships it with the task by reference (the worker imports the module that
defines it), so the pools import neither regress nor mining and one worker serves every kind.
"""

from __future__ import annotations

import os
import sys
import warnings
from typing import Any, Callable, Dict, List, Mapping, Sequence

from dv2s_gym.workers.errors import WorkerError
from scenario_bank.errors import BuiltInReplacedWarning
from scenario_bank.named_registry import Registry
from scenario_bank.plugins import PluginError, check_plugins, import_plugins
from scenario_bank.records import JsonRecord

if "numpy" not in sys.modules:  # a fresh worker process (e.g. Ray's): one BLAS/OpenMP thread per worker
    os.environ.setdefault("OMP_NUM_THREADS", "1")

__all__ = ["TaskFunction", "register", "mark_built_in", "function_for", "task_modules", "worker_plugins",
           "start_plugins", "run_task", "result_object", "task_id", "error_result", "gave_up_result"]

TaskFunction = Callable[[Dict[str, Any]], Dict[str, Any]]
"""Runs one task in a worker process and returns its result (a JSON-able dict)."""

def _name(function: TaskFunction) -> str:
    return f"{function.__module__}.{function.__qualname__}"


def _unknown_kind(kind: object, known: Sequence[str]) -> WorkerError:
    names = ", ".join(repr(k) for k in sorted(known)) or "none"
    return WorkerError(f"no task function is registered for kind {kind!r} (registered: {names}); import the "
                       "module that registers it before running its tasks")


_KINDS: Registry[TaskFunction] = Registry("task kind", WorkerError, unknown=_unknown_kind)


def register(kind: str, function: TaskFunction, overwrite: bool = False) -> TaskFunction:
    """Make ``function`` run the tasks whose ``"kind"`` is ``kind``; returns ``function``.

    ``function`` must be a module-level function (pools ship it by reference). A kind
    registered with another function is an error unless ``overwrite`` is true; registering the same
    function again (its module imported twice) is not.
    """
    existing = _KINDS.get(kind, None)
    if existing is not None and _name(existing) != _name(function) and not overwrite:
        raise WorkerError(f"task kind {kind!r} is registered twice ({_name(existing)} and {_name(function)}); "
                          "pass overwrite=True to replace it")
    if existing is not None and _name(existing) == _name(function):  # its module imported again: no replacement
        built_in = _KINDS.is_built_in(kind)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", BuiltInReplacedWarning)
            _KINDS.register(kind, function, overwrite=True, module=function.__module__)
        if built_in:
            _KINDS.mark_built_in(kind)
        return function
    return _KINDS.register(kind, function, overwrite=True, module=function.__module__)


def mark_built_in(kind: str) -> None:
    """The task kind ``kind`` is one of the product's own (``"regress"``, ``"mine"``, ``"heldout"``, each marked by
    the module that registers it): a plug-in's ``register(kind, f, overwrite=True)`` then issues a
    :class:`~scenario_bank.errors.BuiltInReplacedWarning` and counts among
    :func:`scenario_bank.named_registry.replaced_built_ins`."""
    _KINDS.mark_built_in(kind)


def function_for(task: Mapping[str, Any]) -> TaskFunction:
    """The registered function that runs ``task``."""
    return _KINDS.get(task.get("kind"))


def task_modules() -> List[str]:
    """The modules defining the registered task functions (a pool may import them before the first task)."""
    return sorted({function.__module__ for function in _KINDS.values()})


def worker_plugins() -> List[str]:
    """The plug-in modules every worker process must import before its first task (a plug-in's failure type and
    detector, :mod:`scenario_bank.plugins`), read when a pool starts its workers.

    Raises:
        WorkerError: when a plug-in was registered in ``__main__``, which no worker can import (the message
            says to move it into an importable module).
    """
    try:
        return check_plugins()
    except PluginError as error:
        raise WorkerError(str(error)) from None


def start_plugins(modules: Sequence[str]) -> None:
    """In a worker process, before its first task: import the plug-in ``modules`` (:func:`worker_plugins` of the
    process that started it), so their registrations hold here too.

    Raises:
        WorkerError: naming the module that cannot be imported here, and why.
    """
    try:
        with warnings.catch_warnings():
            # the process that started the workers has said that a plug-in replaced a built-in; once is enough
            warnings.simplefilter("ignore", BuiltInReplacedWarning)
            import_plugins(modules, where="a worker process")
    except PluginError as error:
        raise WorkerError(str(error)) from None


def run_task(function: TaskFunction, task: Dict[str, Any]) -> Dict[str, Any]:
    """``function(task)`` in a worker; an exception escaping it becomes an error result (the last net).

    Task functions report their episodes' errors themselves; this catches what they do not.
    """
    try:
        return function(task)
    except BaseException as error:
        return error_result(task, f"{type(error).__name__}: {error}")


def result_object(result: Any) -> Dict[str, Any]:
    """A task's result as its JSON object: a record's :meth:`~scenario_bank.records.JsonRecord.to_dict`, an error
    result (a dict) as it is."""
    return result.to_dict() if isinstance(result, JsonRecord) else result


def task_id(scenario: str, seed: int) -> str:
    """The episode id used in results and reports: ``"<scenario>/<seed>"``."""
    return f"{scenario}/{int(seed)}"


def error_result(task: Mapping[str, Any], error: str) -> Dict[str, Any]:
    """The result standing for a task that produced no episode (exception, crash, hang)."""
    return {"id": task_id(task["scenario"], task["seed"]), "role": task["role"], "scenario": task["scenario"],
            "seed": int(task["seed"]), "error": str(error), "trace": None}


def gave_up_result(task: Mapping[str, Any], problems: Sequence[str], attempts: int) -> Dict[str, Any]:
    """The error result of a task whose every attempt crashed or hung its worker (``problems``, in order)."""
    return error_result(task, f"{'; then '.join(problems)} running {task['role']} {task['policy']!r} on "
                              f"{task['scenario']} seed {task['seed']} ({attempts} attempts)")
