"""The regression report is a typed record (dv2s_gym.regress.records.RegressReport): a report written to disk reads
back as records that write the very same JSON (keys, order, nulls), its consumers read its parts by attribute, and a
field of the wrong kind is named."""

from __future__ import annotations

import argparse

import json
import re
from pathlib import Path

import pytest

import dv2s_gym.regress.report as report_module
from dv2s_gym.regress.errors import ReportMismatchError
from dv2s_gym.regress.records import (BankInfo, EpisodeError, PairedComparison, PairedEpisode, PolicyInfo,
                                      RegressReport, ReportSettings, ScenarioResult, SequentialOutcome, Summary)
from dv2s_gym.regress.report import format_summary, load_report, write_json
from regress_report_data import report_from_json
from scenario_bank.records import RecordError, RegressEpisode

RESULTS = Path(__file__).resolve().parent / "data" / "regress" / "results.jsonl"
TOP_KEYS = ["schema", "schema_version", "created", "dv2s_version", "code_identity", "bank", "settings", "candidate", "baseline",
            "episodes", "scenarios", "overall", "verdict", "regressed", "newly_failing", "errors", "stopped_early",
            "sequential", "power", "aggregates"]
"""A built report's keys, in the order the report has always had them (``dv2s regress --json`` prints them so)."""


def _results():
    return [RegressEpisode.from_dict(json.loads(line)) for line in RESULTS.read_text().splitlines() if line]


def _report(*, baseline: bool = True, sequential=None) -> RegressReport:
    """A report of the real episodes in tests/data/regress (one of them an error, one a stall)."""
    pairs = {}
    for result in _results():
        pairs.setdefault(result.id, {})[result.role] = result
    names = sorted({result.scenario for result in _results()})
    episodes = [{"id": episode_id, "scenario": sides["candidate"].scenario, "seed": sides["candidate"].seed,
                 "candidate": sides["candidate"], "baseline": sides.get("baseline") if baseline else None}
                for episode_id, sides in pairs.items() if "candidate" in sides]
    settings = {"episodes": 2, "seed": 0, "margin": 0.05, "alpha": 0.05, "sequential": sequential is not None,
                "env_config": {}, "backend": "local", "workers": 1, "timeout": None,
                "failure": ["collision", "off_road", "stall"], "stall_seconds": 5.0, "mde": 0.3, "power": 0.8}
    return report_from_json(bank={"path": "bank", "version": "v", "scenarios": names, "hashes": {n: "h" for n in names}},
                            settings=settings, candidate={"spec": "new", "card": None},
                            baseline={"spec": "old", "card": None} if baseline else None, episodes=episodes,
                            stopped_early=False, sequential=sequential)


@pytest.mark.parametrize("baseline", [True, False], ids=["compared", "measures only"])
def test_a_written_report_reads_back_as_records_that_write_the_same_bytes(tmp_path, baseline):
    report = _report(baseline=baseline).replace(hostname="here", timing={"a": 1.5}, duration=2.0)
    path = write_json(report, tmp_path / "report.json")
    written = path.read_bytes()
    read = load_report(path)
    assert type(read) is RegressReport
    assert json.dumps(read.to_json(), indent=1, sort_keys=True).encode() + b"\n" == written
    assert read.to_json() == report.to_json() == json.loads(written)
    assert RegressReport.from_json(report.to_json()).to_json() == report.to_json()
    # unsorted, as --json prints it: the order the report has always had, the run's facts last
    extra = ["error_reason"] if not baseline else []  # measures only with an errored episode
    assert list(report.to_json()) == TOP_KEYS + extra + ["hostname", "timing", "duration"]


def test_the_parts_are_records_read_by_attribute_as_the_consumers_do():
    report = _report()
    assert isinstance(report.bank, BankInfo) and report.bank.scenarios[0] == "highway_cut_in_from_left"
    assert isinstance(report.settings, ReportSettings) and report.settings.margin == 0.05
    assert report.settings.failure == ("collision", "off_road", "stall") and report.settings.timeout is None
    assert isinstance(report.candidate, PolicyInfo) and report.candidate.spec == "new" and report.baseline.spec == "old"
    assert all(isinstance(e, PairedEpisode) and type(e.candidate) is RegressEpisode for e in report.episodes)
    entry = report.scenario("highway_lead_vehicle_brakes")
    assert isinstance(entry, ScenarioResult) and isinstance(entry.candidate, Summary)
    assert isinstance(entry.comparison, PairedComparison) and entry.verdict == entry.comparison.verdict == "ERROR"
    assert entry.candidate.failure_rate == entry.candidate.to_dict()["failure_rate"] == entry.candidate.rates["failure_rate"]
    assert entry.candidate.episode_return == entry.candidate.to_dict()["return"]  # "return" is a keyword: its attribute
    assert entry.candidate.rate("stall")["count"] == 1  # the stalled episode of the data
    assert report.errors and all(isinstance(e, EpisodeError) for e in report.errors)
    error = report.errors[0]
    assert error.role == "candidate" and error.first_line.startswith("RuntimeError") and error.scenario in report.scenarios
    assert report.verdict == "ERROR" and report.overall.comparison.reason.startswith("1 episode ended in an error")
    assert report.episode(error.id).errored("candidate") and not report.episode(error.id).errored("baseline")
    # the report's JSON object
    assert report.to_dict()["scenarios"]["highway_lead_vehicle_brakes"]["comparison"]["verdict"] == "ERROR"
    assert report.to_dict()["errors"] == [{"id": error.id, "role": "candidate", "error": error.error}]
    with pytest.raises(TypeError):
        report["verdict"] = "PASS"  # noqa - a frozen record


def test_a_sequential_run_records_its_test():
    sequential = {"looks": 2, "episodes": 4, "max_episodes": 8, "batch": 1, "spending": "obrien-fleming",
                  "verdict": None}
    report = _report(sequential=sequential)
    assert isinstance(report.sequential, SequentialOutcome) and report.sequential.looks == 2
    assert report.to_json()["sequential"] == sequential  # the null verdict written, as before


def test_a_summary_keeps_every_rate_in_its_order_with_a_registered_failure_kind():
    rate = {"value": 0.5, "low": 0.1, "high": 0.9, "count": 1}
    mean = {"value": 1.0, "low": 0.5, "high": 1.5, "n": 2}
    data = {"episodes": 2, "errors": 0, "collision_rate": rate, "off_road_rate": rate, "stall_rate": rate,
            "hard_brake_rate": rate, "failure_rate": rate, "success_rate": rate, "min_ttc": mean, "mean_speed": mean,
            "return": mean}
    summary = Summary.from_json(data)
    assert list(summary.to_json()) == list(data) and summary.to_json() == data
    assert summary.rate("hard_brake") == rate and summary.extra == {}


def test_a_field_of_the_wrong_kind_is_named_and_a_damaged_report_is_refused(tmp_path):
    data = _report().to_json()
    data["scenarios"]["highway_cut_in_from_left"]["candidate"]["episodes"] = "3"
    with pytest.raises(RecordError, match=r"'scenarios\.highway_cut_in_from_left'.*'candidate\.episodes' must be an "
                                          r"integer, not str"):
        RegressReport.from_json(data)
    data = _report().to_json()
    data["episodes"][1]["seed"] = "1"
    with pytest.raises(RecordError, match=r"field 'episodes\[1\]'.*'seed' must be an integer"):
        RegressReport.from_json(data)
    (tmp_path / "report.json").write_text(json.dumps(data))
    with pytest.raises(ReportMismatchError, match=r"is damaged: .*episodes\[1\]"):
        load_report(tmp_path / "report.json")


def test_the_consumers_read_a_record_and_its_json_alike():
    from dv2s_gym.loop import comparisons as loop

    report = _report()
    read_back = RegressReport.from_json(json.loads(json.dumps(report.to_json())))
    assert format_summary(report) == format_summary(read_back)
    assert loop._regress_summary(report, Path("r.json"), ["urban_pull_back_in"]) == \
        loop._regress_summary(read_back, Path("r.json"), ["urban_pull_back_in"])
    summary = loop._regress_summary(report, Path("r.json"), ["urban_pull_back_in"])
    assert summary.to_dict()["verdict"] == "ERROR" and summary.to_dict()["regressed"] == list(report.regressed)
    assert summary.to_dict()["new_failure_rate"] == report.overall.candidate.failure_rate
    roles = {"baseline": "start", "candidate": "fine_tuned"}
    assert loop._regress_errored(report, roles) == loop._regress_errored(read_back, roles)


def test_the_report_format_documented_in_the_module_is_the_version_written():
    """The module docstring is the format's specification: its version is the one the code writes."""
    doc = report_module.__doc__
    assert f"version {report_module.SCHEMA_VERSION} (:data:`SCHEMA_VERSION`" in doc
    assert f'"schema_version": {report_module.SCHEMA_VERSION},' in doc
    page = (Path(__file__).resolve().parents[1] / "docs" / "regress.md").read_text()
    assert re.findall(r"schema `dv2s-regress` version (\d+)", page) == [str(report_module.SCHEMA_VERSION)]


def test_the_command_help_names_no_other_report_version():
    """``dv2s regress --help`` points to the format's page and names no version the code does not write."""
    from dv2s_gym.cli import build_parser

    commands = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    text = " ".join(commands.choices["regress"].format_help().split())
    assert "schema dv2s-regress" in text and "docs/regress.md" in text
    named = re.findall(r"dv2s-regress,? v(?:ersion )?(\d+)", text)
    assert all(version == str(report_module.SCHEMA_VERSION) for version in named), named
