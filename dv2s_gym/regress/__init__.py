"""``dv2s regress``: compare a candidate driving policy with a baseline on paired episodes.

:func:`run_regression` runs both policies on the same scenario x seed pairs (a local
process pool or Ray), streams results to disk (resumable), and writes a versioned JSON
report, JUnit XML (:mod:`~dv2s_gym.regress.junit`), Markdown and HTML with a PASS / FAIL /
INCONCLUSIVE / ERROR verdict per scenario and overall; :mod:`dv2s_gym.regress.stats` and
:mod:`dv2s_gym.regress.family` hold the statistics, :mod:`dv2s_gym.regress.power` sizes runs. The episodes run in the pools
of :mod:`dv2s_gym.workers` (task kind ``"regress"``, :mod:`dv2s_gym.regress.tasks`).

The names below are re-exported lazily, so a worker process that imports
:mod:`dv2s_gym.regress.tasks` does not load the statistics and reporting modules.
"""

from importlib import import_module
from typing import Any

_EXPORTS = {
    "RegressError": "errors", "ReportMismatchError": "errors", "ResumeMismatchError": "errors",
    "EXIT_CODES": "report", "SCHEMA": "report", "SCHEMA_VERSION": "report", "exit_code": "report",
    "load_report": "report", "write_reports": "outputs",
    "run_regression": "runner", "RegressReport": "records",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    if name in _EXPORTS:
        return getattr(import_module(f"dv2s_gym.regress.{_EXPORTS[name]}"), name)
    raise AttributeError(f"module 'dv2s_gym.regress' has no attribute {name!r}")
