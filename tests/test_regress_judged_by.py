"""A regression report records the code that judged its episodes (``code_identity``), and ``--baseline-report``
refuses a baseline whose detector for a ``--failure`` kind differs from the run's."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from dv2s_gym.regress.errors import ReportMismatchError
from dv2s_gym.regress.report import (check_baseline_code, load_report, warnings, write_json,
                                     write_markdown)
from policies.run_identity import BUILT_IN, report_code_identity
from regress_report_data import report_from_json
from scenario_bank.atomic import file_sha256
from tests import test_one_detector_path as plug_in
from tests.test_one_detector_path import finds_no_collision, noop_collision  # noqa: F401 (a fixture)

__all__: list = []

KINDS = ["collision", "off_road"]


def _report(kinds=KINDS, bank=None, scenario="s"):
    bank = bank or {"path": "bank", "version": "v", "scenarios": [scenario], "hashes": {scenario: "h"}}
    result = {"id": f"{scenario}/0", "scenario": scenario, "seed": 0, "collided": False, "off_road": False, "stalled": False,
              "failed": False, "min_ttc": None, "mean_speed": 10.0, "episode_return": 1.0, "success": True,
              "error": None}
    episode = {"id": f"{scenario}/0", "scenario": scenario, "seed": 0, "candidate": {**result, "role": "candidate"},
               "baseline": {**result, "role": "baseline"}}
    return report_from_json(bank=bank, settings={"episodes": 1, "seed": 0, "margin": 0.02, "alpha": 0.05,
                                             "failure": list(kinds)},
                            candidate={"spec": "a"}, baseline={"spec": "b"}, episodes=[episode])


def test_a_report_records_who_judged_each_kind():
    identity = _report().code_identity
    assert identity["detectors"] == {kind: {"failure type": BUILT_IN, "detector": BUILT_IN, "sources (SHA-256)": {}}
                                     for kind in KINDS}
    assert identity["replaced built-ins"] == [] and len(identity["dv2s sources (SHA-256)"]) == 64
    assert list(_report().to_json())[:5] == ["schema", "schema_version", "created", "dv2s_version", "code_identity"]


def test_a_replaced_detector_is_recorded_and_named_in_report_md(noop_collision, tmp_path):
    report = _report()
    entry = report.code_identity["detectors"]["collision"]
    module = finds_no_collision.__module__
    assert entry["detector"] == module and entry["failure type"] == BUILT_IN
    assert entry["sources (SHA-256)"] == {module: file_sha256(Path(plug_in.__file__))}
    assert report.code_identity["detectors"]["off_road"]["detector"] == BUILT_IN
    write_json(report, tmp_path / "report.json")
    assert load_report(tmp_path / "report.json").code_identity == json.loads(json.dumps(report.code_identity))
    write_markdown(report, tmp_path / "report.md")
    assert (f"warning: Built-in replaced by plug-ins: detector 'collision' (replaced by {module}); what this run "
            "counts under that name is the plug-ins'") in (tmp_path / "report.md").read_text(encoding="utf-8")


def test_a_baseline_judged_by_another_detector_is_refused(noop_collision, tmp_path):
    baseline = _report()  # judged with the plug-in's collision detector
    here = {**report_code_identity(KINDS)}
    here["detectors"] = {kind: {"failure type": BUILT_IN, "detector": BUILT_IN, "sources (SHA-256)": {}}
                         for kind in KINDS}  # as a run without the plug-in records it
    here["replaced built-ins"] = []
    with pytest.raises(ReportMismatchError) as refused:
        check_baseline_code(baseline, path="old/report.json", kinds=["collision"], code_identity=here)
    message = str(refused.value)
    assert "failure kind 'collision'" in message and "rerun the baseline with the same plug-ins" in message
    assert f"detector {finds_no_collision.__module__} (source {file_sha256(Path(plug_in.__file__))[:12]}) there" in message
    assert f"detector {BUILT_IN} here" in message and "\n" not in message
    # a kind the run does not judge is not refused; the other code differences are flagged
    flagged = check_baseline_code(baseline, path="old/report.json", kinds=["off_road"], code_identity=here)
    assert flagged and "other code (replaced built-ins differ)" in flagged and "rerun the baseline" in flagged


def test_a_baseline_judged_alike_passes_and_other_sources_are_flagged():
    baseline, here = _report(), report_code_identity(KINDS)
    assert check_baseline_code(baseline, path="old/report.json", kinds=KINDS, code_identity=here) is None
    other = {**here, "dv2s sources (SHA-256)": "0" * 64}
    flagged = check_baseline_code(baseline, path="old/report.json", kinds=KINDS, code_identity=other)
    assert "other code (dv2s sources differ)" in flagged


def test_the_run_refuses_a_baseline_report_judged_by_another_detector(tmp_path):
    """Through the runner: the report's recorded detector differs from this process's for a --failure kind."""
    from tests.regress_call import run_regression

    from dv2s_gym.regress.report import bank_info

    name = "highway_lead_vehicle_brakes"
    old = _report(bank=bank_info([name]), scenario=name).to_json()
    old["code_identity"]["detectors"]["collision"] = {"failure type": BUILT_IN, "detector": "my_plugins",
                                                      "sources (SHA-256)": {"my_plugins": "ab" * 32}}
    path = tmp_path / "old" / "report.json"
    path.parent.mkdir()
    path.write_text(json.dumps(old), encoding="utf-8")
    with pytest.raises(ReportMismatchError, match="judged failure kind 'collision' with another detector"):
        run_regression("rule", baseline_report=path, scenarios=[name], episodes=1, failure=KINDS,
                       out_dir=tmp_path / "new", progress=False)
    assert not (tmp_path / "new" / "report.json").exists()


def test_no_replacement_is_left_over():
    assert warnings(_report()) == []


def test_a_baseline_judged_on_other_kinds_is_refused_as_such_and_its_kinds_are_the_default(tmp_path):
    """A run against a report judged on ``off_road`` only, asked to judge ``collision`` too, is told which kinds the
    report was judged on and how to match them; left out, ``--failure`` is the report's."""
    from dv2s_gym.regress.report import baseline_defaults

    baseline = _report(kinds=["off_road"])
    with pytest.raises(ReportMismatchError) as refused:
        check_baseline_code(baseline, path="base/report.json", kinds=KINDS, code_identity=report_code_identity(KINDS))
    message = str(refused.value)
    assert "was judged on off_road only, not on collision" in message and "--failure off_road" in message
    assert "another detector" not in message
    write_json(baseline, tmp_path / "report.json")
    assert baseline_defaults(tmp_path / "report.json", None, None, None) == (0, None, ["off_road"])
    assert baseline_defaults(tmp_path / "report.json", None, None, "collision")[2] == "collision"
