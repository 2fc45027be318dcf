"""The tests' shorthand for :func:`dv2s_gym.regress.runner.run_regression`: its settings as keywords, as the
``dv2s regress`` options read."""

from __future__ import annotations

from typing import Any

from dv2s_gym.regress import runner
from dv2s_gym.regress.records import RegressReport

_WORKER_OPTIONS = ("backend", "workers", "address", "timeout")
_RUN_OPTIONS = ("out_dir", "progress", "on_result", "clips")


def run_regression(candidate: str, baseline: Any = None, **options: Any) -> RegressReport:
    """:func:`~dv2s_gym.regress.runner.run_regression` with ``baseline_report``, ``baseline_role`` and
    ``accept_failed_baseline`` making its :class:`~dv2s_gym.regress.settings.BaselineReport`, the worker options
    its :class:`~dv2s_gym.workers.settings.WorkerSettings` and the rest its
    :class:`~dv2s_gym.regress.settings.RegressSettings`."""
    report = options.pop("baseline_report", None)
    role = options.pop("baseline_role", "candidate")
    accept = options.pop("accept_failed_baseline", False)
    if report is not None:
        baseline = runner.BaselineReport(report, role=role, accept_failed=accept)
    workers = runner.WorkerSettings(**{key: options.pop(key) for key in _WORKER_OPTIONS if key in options})
    run = {key: options.pop(key) for key in _RUN_OPTIONS if key in options}
    return runner.run_regression(candidate, baseline, runner.RegressSettings(**options), workers=workers, **run)
