"""``dv2s regress``: compare a candidate driving policy with a baseline on paired episodes.

:func:`run_regression` runs both policies on the same scenario x seed pairs (a local
process pool or Ray), streams results to disk (resumable), and writes a versioned JSON
report, JUnit XML and Markdown with a PASS / FAIL / INCONCLUSIVE verdict per scenario
and overall; :mod:`dv2s_gym.regress.stats` holds the statistics.
"""

from dv2s_gym.regress.backends import Backend, LocalBackend, get_backend
from dv2s_gym.regress.errors import RegressError, ReportMismatchError, ResumeMismatchError
from dv2s_gym.regress.report import EXIT_CODES, SCHEMA, SCHEMA_VERSION, exit_code, load_report, write_reports
from dv2s_gym.regress.runner import run_regression
from dv2s_gym.regress.worker import run_task

__all__ = ["Backend", "EXIT_CODES", "LocalBackend", "RegressError", "ReportMismatchError", "ResumeMismatchError",
           "SCHEMA", "SCHEMA_VERSION", "exit_code", "get_backend", "load_report", "run_regression", "run_task",
           "write_reports"]
