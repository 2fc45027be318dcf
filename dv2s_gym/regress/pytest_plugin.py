"""The regression checks of dv2s-gym's pytest plugin (the top-level module :mod:`dv2s_pytest`, which pytest loads in
every session and which loads this module only when a test uses its marker or fixtures): a check's arguments
(:func:`regression_arguments`, :func:`marker_arguments`), its report folder (:func:`out_dir`) and the regression run
(:func:`run_check`), with the statistics and verdicts of ``dv2s regress``."""

from __future__ import annotations

import inspect
import re
import shutil
from pathlib import Path
from typing import Any, Dict, Mapping, Optional, Sequence, Tuple

import pytest

from dv2s_gym.regress.assertions import RegressionReport
from dv2s_gym.regress.errors import RegressError
from dv2s_gym.regress.runner import BaselineReport, RegressSettings, WorkerSettings, run_regression
from scenario_bank.errors import WrongTypeError

__all__ = ["MARKER", "regression_arguments", "marker_arguments", "out_dir", "run_check"]

MARKER = "dv2s_regression"
"""The plugin's marker (``dv2s_pytest.MARKER``), named in the messages of a misused check."""

_SETTINGS = ("scenarios", "episodes", "seed", "margin", "alpha", "mde", "power", "sequential", "env_config",
             "bank_dir", "failure", "stall_seconds")
"""The :class:`~dv2s_gym.regress.settings.RegressSettings` a check takes by name (its defaults apply)."""


def regression_arguments(policy: str, baseline: Optional[str] = None, *, baseline_report: Optional[str] = None,
                         timeout: Optional[float] = None, **settings: Any) -> Dict[str, Any]:
    """The keyword arguments of :func:`~dv2s_gym.regress.runner.run_regression` for one check: the candidate
    ``policy``, ``baseline`` or ``baseline_report``, the ``timeout`` per episode, and any of ``_SETTINGS``
    (``scenarios`` may be one name); an unknown argument is a ``TypeError``."""
    unknown = sorted(set(settings) - set(_SETTINGS))
    if unknown:
        raise WrongTypeError(f"got an unexpected keyword argument {unknown[0]!r}; pass only the settings: "
                             f"{', '.join(_SETTINGS)}")
    if baseline is None and baseline_report is None:
        raise pytest.UsageError(f"{MARKER}: give baseline= (a policy spec) or baseline_report= (a report.json) "
                                f"to compare {policy!r} against")
    if isinstance(settings.get("scenarios"), str):
        settings["scenarios"] = [settings["scenarios"]]
    elif settings.get("scenarios") is not None:
        settings["scenarios"] = list(settings["scenarios"])
    return dict(candidate=policy, baseline=baseline, baseline_report=baseline_report, timeout=timeout, **settings)


def marker_arguments(nodeid: str, args: Sequence[Any], kwargs: Mapping[str, Any]) -> Tuple[Dict[str, Any], bool]:
    """``(regression arguments, allow_inconclusive)`` of a ``@pytest.mark.dv2s_regression(*args, **kwargs)`` on the
    test ``nodeid``; a wrong argument is a ``pytest.UsageError`` naming the test."""
    kwargs = dict(kwargs)
    allow = bool(kwargs.pop("allow_inconclusive", True))
    try:
        inspect.signature(regression_arguments).bind(*args, **kwargs)
        arguments = regression_arguments(*args, **kwargs)
    except TypeError as error:
        raise pytest.UsageError(f"@pytest.mark.{MARKER} on {nodeid}: {error}") from None
    return arguments, allow


def _folder_name(nodeid: str) -> str:
    name = re.sub(r"[^A-Za-z0-9_.-]+", "_", nodeid).strip("_.")
    return name[-120:] or "test"


def out_dir(request: pytest.FixtureRequest, factory: pytest.TempPathFactory, suffix: str = "") -> Path:
    """A fresh report folder for the test of ``request``: ``--dv2s-report-dir``/<test><suffix>, or a folder of
    pytest's temporary ones."""
    name = _folder_name(request.node.nodeid) + suffix
    root = request.config.getoption("--dv2s-report-dir")
    if root is None:
        return factory.mktemp(f"dv2s-{name[-40:]}", numbered=True)
    out = Path(root) / name
    if out.exists():
        shutil.rmtree(out)  # a fresh run: a policy file may have changed under the same spec
    out.mkdir(parents=True)
    return out


def run_check(config: pytest.Config, out: Path, arguments: Dict[str, Any]) -> RegressionReport:
    """Run the regression of ``arguments`` (:func:`regression_arguments`) into ``out`` on the workers the session's
    ``--dv2s-*`` options give; its :class:`~dv2s_gym.regress.assertions.RegressionReport`."""
    options = dict(arguments)
    candidate, baseline, report = options.pop("candidate"), options.pop("baseline"), options.pop("baseline_report")
    if baseline is not None and report is not None:
        raise RegressError("give --baseline POLICY or --baseline-report REPORT, not both")
    workers = WorkerSettings(backend=config.getoption("--dv2s-backend"), workers=config.getoption("--dv2s-workers"),
                             address=config.getoption("--dv2s-address"), timeout=options.pop("timeout"))
    data = run_regression(candidate, BaselineReport(report) if report is not None else baseline,
                          RegressSettings(**options), workers=workers, out_dir=out, progress=False)
    return RegressionReport(data, out)
