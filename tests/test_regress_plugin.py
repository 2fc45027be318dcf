"""The pytest plugin, seen from a user's own suite (run by pytester in a subprocess): a marked
self-comparison passes, a degraded candidate (rule?action_noise=0.3) fails naming the regressed
scenario and the report, the fixture form works, the options are honoured, and misuse is reported."""

from __future__ import annotations

import json
import os
from importlib import metadata
from pathlib import Path

import pytest

from dv2s_gym.regress.assertions import RegressionFailed, RegressionReport
from dv2s_gym.regress.records import RegressReport

pytest_plugins = ["pytester"]

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = "highway_cut_in_from_left"


def _plugin_args() -> list:
    """``-p`` the plugin unless the installed package already registers it (entry point ``dv2s``)."""
    installed = any(ep.name == "dv2s" and ep.value == "dv2s_pytest" for ep in metadata.entry_points(group="pytest11"))
    return [] if installed else ["-p", "dv2s_pytest"]


@pytest.fixture
def user_suite(pytester, monkeypatch):
    monkeypatch.setenv("PYTHONPATH", os.pathsep.join([str(ROOT), str(ROOT / "tests"), os.environ.get("PYTHONPATH", "")]))
    monkeypatch.setenv("OMP_NUM_THREADS", "1")

    def run(source: str, *args: str):
        pytester.makepyfile(test_user=source)
        return pytester.runpytest_subprocess(*_plugin_args(), "-p", "no:cacheprovider", "--dv2s-workers", "2",
                                             *args, timeout=900)

    return run


@pytest.mark.slow
def test_a_self_comparison_passes_and_a_degraded_candidate_fails_naming_the_scenario(user_suite, tmp_path):
    reports = tmp_path / "reports"
    result = user_suite(f'''
import pytest

@pytest.mark.dv2s_regression(policy="rule", baseline="rule", scenarios=["{SCENARIO}"], episodes=6)
def test_same_policy(dv2s_report):
    assert dv2s_report.verdict in ("PASS", "INCONCLUSIVE")
    assert dv2s_report["overall"]["comparison"]["table"]["candidate_only"] == 0

@pytest.mark.dv2s_regression(policy="rule?action_noise=0.3", baseline="rule", scenarios=["{SCENARIO}"],
                             episodes=20, margin=0.05)
def test_noisy_policy():
    raise AssertionError("the body of a test whose regression FAILed does not run")
''', "--dv2s-report-dir", str(reports))
    result.assert_outcomes(passed=1, failed=1)
    out = result.stdout.str()
    assert f"dv2s regression FAIL: 'rule?action_noise=0.3' against 'rule' regressed on {SCENARIO}" in out
    assert "newly failing episodes:" in out and "the body of a test" not in out
    noisy = reports / "test_user.py_test_noisy_policy"
    assert f"report: {noisy / 'report.html'}" in out
    report = json.loads((noisy / "report.json").read_text())
    assert report["verdict"] == "FAIL" and report["regressed"] == [SCENARIO]
    assert report["settings"]["workers"] == 2 and report["settings"]["episodes"] == 20
    assert json.loads((reports / "test_user.py_test_same_policy" / "report.json").read_text())["verdict"] != "FAIL"


@pytest.mark.slow
def test_the_fixture_form_and_inconclusive_when_not_allowed(user_suite):
    result = user_suite(f'''
import pytest

def test_in_code(dv2s_regress):
    report = dv2s_regress(policy="rule", baseline="rule", scenarios="{SCENARIO}", episodes=3)
    assert report.verdict == "INCONCLUSIVE"  # 3 pairs cannot show non-inferiority within 5 points
    report.assert_no_regression()            # INCONCLUSIVE is allowed by default
    again = dv2s_regress("rule", baseline="rule", scenarios=["{SCENARIO}"], episodes=3)
    assert again.out_dir != report.out_dir and again["episodes"] == report["episodes"]
    with pytest.raises(AssertionError, match="INCONCLUSIVE"):
        report.assert_no_regression(allow_inconclusive=False)

@pytest.mark.dv2s_regression("rule", baseline="rule", scenarios=["{SCENARIO}"], episodes=3,
                             allow_inconclusive=False)
def test_strict():
    pass

@pytest.mark.dv2s_regression(policy="rule", scenarios=["{SCENARIO}"])
def test_no_baseline():
    pass

@pytest.mark.dv2s_regression(policy="regress_helpers:BrokenPolicy", baseline="rule", scenarios=["{SCENARIO}"],
                             episodes=2, env_config={{"duration": 2}}, stall_seconds=1)
def test_crashing_candidate():
    pass

@pytest.mark.dv2s_regression(policy="rule", baseline="rule", episode=3)
def test_misspelt():
    pass
''')
    result.assert_outcomes(passed=1, failed=2, errors=2)
    out = result.stdout.str()
    assert "dv2s regression ERROR: 'regress_helpers:BrokenPolicy' against 'rule': 2 episode(s) ended in an error" in out
    assert "RuntimeError: broken policy: no action" in out
    assert "dv2s regression INCONCLUSIVE: 'rule' against 'rule'" in out and "run more episodes" in out
    assert "give baseline= (a policy spec) or baseline_report=" in out
    assert "unexpected keyword argument 'episode'" in out


def test_the_plugin_is_registered_for_pytest():
    """The pytest11 entry point in pyproject.toml names the plugin module (active once installed), a top-level module
    the wheel ships beside the packages."""
    text = (ROOT / "pyproject.toml").read_text()
    assert '[project.entry-points.pytest11]\ndv2s = "dv2s_pytest"' in text
    assert 'py-modules = ["dv2s_pytest"]' in text and (ROOT / "dv2s_pytest.py").is_file()


def test_failure_messages_from_a_report_dict(tmp_path):
    (tmp_path / "report.md").write_text("x")
    comparison = {"table": {"both_fail": 0, "candidate_only": 6, "baseline_only": 0, "neither": 14},
                  "difference": {"value": 0.3, "low": 0.077, "high": 0.519}, "p_value": 0.0156,
                  "p_adjusted": 0.0312, "verdict": "FAIL", "reason": "candidate fails more often"}
    data = {"verdict": "FAIL", "candidate": {"spec": "new"}, "baseline": {"spec": "old"},
            "regressed": ["a"], "newly_failing": [f"a/{i}" for i in range(10)], "errors": [],
            "scenarios": {"a": {"candidate": {"failure_rate": {"value": 0.3}},
                                "baseline": {"failure_rate": {"value": 0.0}}, "comparison": comparison}},
            "overall": {"comparison": dict(comparison, reason="pooled: candidate fails more often")}}
    report = RegressionReport(RegressReport.from_json(data), tmp_path)
    message = report.failure_message()
    assert message.splitlines()[0] == "dv2s regression FAIL: 'new' against 'old' regressed on a"
    assert "a: failure rate 30% vs 0%, difference +30.0 pp [+7.7 pp, +51.9 pp], p = 0.0156 (adjusted 0.0312)" in message
    assert "a/0, a/1" in message and "and 2 more" in message
    assert f"report: {tmp_path / 'report.md'}" in message
    with pytest.raises(RegressionFailed):
        report.assert_no_regression()
    assert RegressionReport(RegressReport.from_json(dict(data, verdict="PASS")), tmp_path).assert_no_regression().verdict == "PASS"
    inconclusive = RegressionReport(RegressReport.from_json(dict(data, verdict="INCONCLUSIVE", regressed=[])),
                                    tmp_path)
    assert inconclusive.failure_message() is None
    assert "INCONCLUSIVE" in inconclusive.failure_message(allow_inconclusive=False)
    assert "without a baseline" in RegressionReport(RegressReport.from_json(dict(data, verdict=None, baseline=None))).failure_message()


def test_the_arguments_of_a_check_are_the_regression_settings():
    from dv2s_gym.regress.pytest_plugin import regression_arguments
    from dv2s_gym.regress.settings import RegressSettings

    arguments = regression_arguments("rule", "rule", scenarios="a", episodes=3, margin=0.05)
    assert arguments == {"candidate": "rule", "baseline": "rule", "baseline_report": None, "timeout": None,
                         "scenarios": ["a"], "episodes": 3, "margin": 0.05}
    settings = RegressSettings(**{k: v for k, v in arguments.items()
                                  if k not in ("candidate", "baseline", "baseline_report", "timeout")})
    assert settings.episodes == 3 and settings.margin == 0.05 and settings.stall_seconds == 5.0
    with pytest.raises(TypeError, match="unexpected keyword argument 'episode'"):
        regression_arguments("rule", "rule", episode=3)
    with pytest.raises(pytest.UsageError, match="give baseline="):
        regression_arguments("rule", episodes=3)


def test_loading_the_plugin_loads_no_module_of_the_project():
    """pytest imports the plugin in every session of an environment with dv2s-gym installed: importing it (in a
    fresh interpreter, pytest already loaded) loads the plugin module alone, so no package of the project, no
    Gymnasium and no registration of DV2S-v0; the checks load when a test uses the marker or a fixture."""
    import subprocess
    import sys

    code = ("import sys, pytest; before = set(sys.modules); import dv2s_pytest; "
            "print(sorted(set(sys.modules) - before))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT)}).stdout.strip()
    assert out == "['dv2s_pytest']"


def test_the_plugin_and_its_checks_name_one_marker():
    import dv2s_pytest
    from dv2s_gym.regress import pytest_plugin

    assert dv2s_pytest.MARKER == pytest_plugin.MARKER == "dv2s_regression"
