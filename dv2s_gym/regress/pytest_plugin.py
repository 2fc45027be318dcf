"""pytest plugin: "this policy must not regress on these scenarios" in a user's own test suite.

Installed with dv2s-gym (entry point ``pytest11: dv2s``; or ``-p dv2s_gym.regress.pytest_plugin``).
A marker runs a regression once for the test and fails it on a FAIL or ERROR verdict (ERROR:
an episode ended in an error; and on INCONCLUSIVE when ``allow_inconclusive=False``)::

    import pytest

    @pytest.mark.dv2s_regression(policy="ppo:models/new.zip", baseline="rule",
                                 scenarios=["tag:highway"], episodes=20, margin=0.05)
    def test_new_policy_does_not_regress(dv2s_report):   # the fixture is optional
        assert dv2s_report["overall"]["candidate"]["collision_rate"]["value"] < 0.2

or, in code, the ``dv2s_regress`` fixture takes the same arguments and returns a
:class:`~dv2s_gym.regress.assertions.RegressionReport`::

    def test_no_regression(dv2s_regress):
        report = dv2s_regress(policy="ppo:models/new.zip", baseline="rule", scenarios=["tag:urban"])
        report.assert_no_regression()          # or: assert report.verdict != "FAIL"

Arguments (both forms): ``policy`` (the candidate spec), ``baseline`` (a spec) or
``baseline_report`` (an earlier ``report.json``), ``scenarios``, ``episodes`` (default: planned
from ``mde`` and ``power``, as ``dv2s regress`` does), ``seed``, ``margin``, ``alpha``, ``mde``,
``power``, ``sequential``, ``env_config``, ``bank_dir``, ``timeout``, ``failure``, ``stall_seconds``; the marker also takes
``allow_inconclusive`` (default ``True``: a significant regression or an error fails).
The statistics and verdicts are those of ``dv2s regress``.

Options: ``--dv2s-workers N`` (processes per regression; default every core),
``--dv2s-report-dir DIR`` (reports in ``DIR/<test>/``; default pytest's temporary folder),
``--dv2s-backend local|ray`` (or a backend registered in :mod:`dv2s_gym.workers.backends`) and ``--dv2s-address`` (a Ray cluster).
"""

from __future__ import annotations

import inspect
import re
import shutil
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, Dict, Iterator, Optional

import pytest

from scenario_bank.errors import WrongTypeError  # loaded with the package anyway (its env registration)

if TYPE_CHECKING:
    from dv2s_gym.regress.assertions import RegressionReport

# pytest loads this module in every session of an environment with dv2s-gym installed, so it adds nothing to what
# its package loads: the regression runner, its errors and the worker backends load when a test uses the plugin.
__all__ = ["MARKER", "regression_arguments"]

MARKER = "dv2s_regression"
_REPORT = pytest.StashKey["RegressionReport"]()
_ALLOW = pytest.StashKey[bool]()


class _BackendChoices:
    """The ``--dv2s-backend`` choices, read from :mod:`dv2s_gym.workers.backends` only when pytest checks a
    given value or prints its help."""

    def _names(self):
        from dv2s_gym.workers.backends import backend_choices

        return backend_choices()

    def __contains__(self, name: object) -> bool:
        return name in self._names()

    def __iter__(self) -> Iterator[str]:
        return iter(self._names())

    def __len__(self) -> int:
        return len(self._names())


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


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("dv2s", "dv2s-gym policy regression tests")
    group.addoption("--dv2s-workers", type=int, default=None, metavar="N",
                    help="worker processes per regression (default: every core)")
    group.addoption("--dv2s-report-dir", default=None, metavar="DIR",
                    help="write each test's regression report to DIR/<test>/ (default: pytest's temporary folder)")
    group.addoption("--dv2s-backend", choices=_BackendChoices(), default="local",
                    help="where regression episodes run (default: local processes)")
    group.addoption("--dv2s-address", default=None, metavar="HOST:PORT",
                    help="with --dv2s-backend ray: the Ray cluster's address")


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers",
        f"{MARKER}(policy, baseline=None, *, baseline_report=None, scenarios=None, episodes=None, seed=0, "
        "margin=0.02, alpha=0.05, mde=None, power=None, sequential=False, env_config=None, bank_dir=None, "
        "timeout=None, allow_inconclusive=True): run a dv2s regression of policy against baseline for this test "
        "and fail it on a FAIL or ERROR verdict (and on INCONCLUSIVE unless allowed)")


def _folder_name(nodeid: str) -> str:
    name = re.sub(r"[^A-Za-z0-9_.-]+", "_", nodeid).strip("_.")
    return name[-120:] or "test"


def _out_dir(request: pytest.FixtureRequest, factory: pytest.TempPathFactory, suffix: str = "") -> Path:
    name = _folder_name(request.node.nodeid) + suffix
    root = request.config.getoption("--dv2s-report-dir")
    if root is None:
        return factory.mktemp(f"dv2s-{name[-40:]}", numbered=True)
    out = Path(root) / name
    if out.exists():
        shutil.rmtree(out)  # a fresh run: a policy file may have changed under the same spec
    out.mkdir(parents=True)
    return out


def _run(request: pytest.FixtureRequest, out: Path, arguments: Dict[str, Any]) -> RegressionReport:
    from dv2s_gym.regress.assertions import RegressionReport
    from dv2s_gym.regress.errors import RegressError
    from dv2s_gym.regress.runner import BaselineReport, RegressSettings, WorkerSettings, run_regression

    config = request.config
    options = dict(arguments)
    candidate, baseline, report = options.pop("candidate"), options.pop("baseline"), options.pop("baseline_report")
    if baseline is not None and report is not None:
        raise RegressError("give --baseline POLICY or --baseline-report REPORT, not both")
    workers = WorkerSettings(backend=config.getoption("--dv2s-backend"), workers=config.getoption("--dv2s-workers"),
                             address=config.getoption("--dv2s-address"), timeout=options.pop("timeout"))
    data = run_regression(candidate, BaselineReport(report) if report is not None else baseline,
                          RegressSettings(**options), workers=workers, out_dir=out, progress=False)
    return RegressionReport(data, out)


@pytest.fixture(autouse=True)
def _dv2s_regression_marker(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> None:
    """Run the regression of a test marked ``dv2s_regression`` before it (its verdict is checked in the call)."""
    marker = request.node.get_closest_marker(MARKER)
    if marker is None:
        return
    kwargs = dict(marker.kwargs)
    allow = bool(kwargs.pop("allow_inconclusive", True))
    try:
        inspect.signature(regression_arguments).bind(*marker.args, **kwargs)
        arguments = regression_arguments(*marker.args, **kwargs)
    except TypeError as error:
        raise pytest.UsageError(f"@pytest.mark.{MARKER} on {request.node.nodeid}: {error}") from None
    request.node.stash[_REPORT] = _run(request, _out_dir(request, tmp_path_factory), arguments)
    request.node.stash[_ALLOW] = allow


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_call(item: pytest.Item) -> None:
    """Fail a marked test whose regression verdict is not acceptable, before its body runs."""
    report = item.stash.get(_REPORT, None)
    if report is None:
        return
    message = report.failure_message(item.stash.get(_ALLOW, True))
    if message is not None:
        pytest.fail(message, pytrace=False)


@pytest.fixture
def dv2s_report(request: pytest.FixtureRequest, _dv2s_regression_marker: None) -> RegressionReport:
    """The report of this test's ``@pytest.mark.dv2s_regression`` run."""
    report = request.node.stash.get(_REPORT, None)
    if report is None:
        raise pytest.UsageError(f"the dv2s_report fixture needs @pytest.mark.{MARKER}(...) on {request.node.nodeid}; "
                                "for a regression in code use the dv2s_regress fixture")
    return report


@pytest.fixture
def dv2s_regress(request: pytest.FixtureRequest,
                 tmp_path_factory: pytest.TempPathFactory) -> Callable[..., RegressionReport]:
    """``dv2s_regress(policy=..., baseline=..., scenarios=..., episodes=..., margin=...)`` runs a
    regression and returns its :class:`RegressionReport` (``.verdict``, ``.regressed``,
    ``.assert_no_regression()``); each call gets its own report folder."""
    calls = [0]

    def run(*args: Any, **kwargs: Any) -> RegressionReport:
        arguments = regression_arguments(*args, **kwargs)
        calls[0] += 1
        out = _out_dir(request, tmp_path_factory, suffix="" if calls[0] == 1 else f"-{calls[0]}")
        return _run(request, out, arguments)

    return run
