"""pytest plugin of dv2s-gym: "this policy must not regress on these scenarios" in a user's own test suite.

Installed with dv2s-gym (entry point ``pytest11: dv2s``; or ``-p dv2s_pytest``). A marker runs a regression once for
the test and fails it on a FAIL or ERROR verdict (ERROR: an episode ended in an error; and on INCONCLUSIVE when
``allow_inconclusive=False``)::

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
The statistics and verdicts are those of ``dv2s regress`` (:mod:`dv2s_gym.regress.pytest_plugin` runs them).

Options: ``--dv2s-workers N`` (processes per regression; default every core),
``--dv2s-report-dir DIR`` (reports in ``DIR/<test>/``; default pytest's temporary folder),
``--dv2s-backend local|ray`` (or a backend registered in :mod:`dv2s_gym.workers.backends`) and ``--dv2s-address`` (a Ray cluster).

pytest loads this module in every session of an environment where dv2s-gym is installed, so it imports nothing of
dv2s-gym when loaded (the ``dv2s_gym`` package would load its environments and register ``DV2S-v0``): the regression
runner and the worker backends load when a test uses the marker or a fixture, or pytest checks ``--dv2s-backend``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable, Iterator

import pytest

if TYPE_CHECKING:
    from dv2s_gym.regress.assertions import RegressionReport

__all__ = ["MARKER"]

MARKER = "dv2s_regression"
"""The marker's name (``@pytest.mark.dv2s_regression``)."""
_REPORT = pytest.StashKey["RegressionReport"]()
_ALLOW = pytest.StashKey[bool]()


def _checks():
    """:mod:`dv2s_gym.regress.pytest_plugin`, loaded when a test first needs it."""
    from dv2s_gym.regress import pytest_plugin

    return pytest_plugin


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


@pytest.fixture(autouse=True)
def _dv2s_regression_marker(request: pytest.FixtureRequest, tmp_path_factory: pytest.TempPathFactory) -> None:
    """Run the regression of a test marked ``dv2s_regression`` before it (its verdict is checked in the call)."""
    marker = request.node.get_closest_marker(MARKER)
    if marker is None:
        return
    checks = _checks()
    arguments, allow = checks.marker_arguments(request.node.nodeid, marker.args, marker.kwargs)
    request.node.stash[_REPORT] = checks.run_check(request.config, checks.out_dir(request, tmp_path_factory),
                                                   arguments)
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
    regression and returns its :class:`~dv2s_gym.regress.assertions.RegressionReport` (``.verdict``,
    ``.regressed``, ``.assert_no_regression()``); each call gets its own report folder."""
    calls = [0]

    def run(*args: Any, **kwargs: Any) -> RegressionReport:
        checks = _checks()
        arguments = checks.regression_arguments(*args, **kwargs)
        calls[0] += 1
        out = checks.out_dir(request, tmp_path_factory, suffix="" if calls[0] == 1 else f"-{calls[0]}")
        return checks.run_check(request.config, out, arguments)

    return run
