"""JUnit XML of a regression report, in the shape CI systems read (the Jenkins / Ant JUnit schema).

One test case per scenario and one for the overall verdict: FAIL is a ``<failure>``, ERROR an
``<error>``, INCONCLUSIVE ``<skipped>`` with its reason, PASS (and measures only) a passed case. The
suite carries ``hostname``, ``time`` (the run's wall time) and ``timestamp`` (UTC, no zone, as the
schema's ISO 8601 pattern has it); the counts agree with the cases.
"""

from __future__ import annotations

import datetime
import os
import socket
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any, Mapping, Optional, Union

from dv2s_gym.regress.records import RegressReport, ScenarioResult
from dv2s_gym.regress.report import failures_text, headline, power_lines, warnings
from scenario_bank.atomic import atomic_write_text
from scenario_bank.records import recorded

__all__ = ["write_junit", "junit_tree"]


def _seconds(report: RegressReport, scenario: Optional[str] = None) -> float:
    """Wall time the episodes of a scenario (None: of every scenario) took in this run (``report.timing``)."""
    timing = report.timing or {}
    if scenario is not None:
        return float(timing.get(scenario) or 0.0)
    return float(sum(float(v or 0.0) for v in timing.values()))


def _junit_timestamp(created: Any) -> str:
    """``YYYY-MM-DDTHH:MM:SS`` (the JUnit schema's timestamp has no zone; ``created`` is UTC)."""
    try:
        moment = datetime.datetime.fromisoformat(str(created))
    except ValueError:
        moment = datetime.datetime.now(datetime.timezone.utc)
    if moment.tzinfo is not None:
        moment = moment.astimezone(datetime.timezone.utc).replace(tzinfo=None)
    return moment.strftime("%Y-%m-%dT%H:%M:%S")


def _case(name: str, classname: str, seconds: float, verdict: Optional[str], reason: str, detail: str,
          out: str) -> ET.Element:
    """A test case: FAIL a failure, ERROR an error, INCONCLUSIVE skipped with its reason, else passed."""
    case = ET.Element("testcase", {"name": name, "classname": classname, "time": f"{seconds:.3f}"})
    if verdict == "FAIL":
        element = ET.SubElement(case, "failure", {"type": "regression", "message": reason})
        element.text = detail or reason
    elif verdict == "ERROR":
        element = ET.SubElement(case, "error", {"type": "episode error", "message": reason})
        element.text = detail or reason
    elif verdict == "INCONCLUSIVE":
        ET.SubElement(case, "skipped", {"message": f"INCONCLUSIVE: {reason}"})
    ET.SubElement(case, "system-out").text = out
    return case


def _scenario_case(report: RegressReport, name: str, entry: ScenarioResult) -> ET.Element:
    """The test case of one scenario: its verdict, its newly failing episodes and errors."""
    comparison = entry.comparison
    errors = [e for e in report.errors or () if e.scenario == name]
    verdict = comparison.verdict if recorded(comparison) else ("ERROR" if errors else None)
    reason = comparison.reason if recorded(comparison) else (f"{len(errors)} episode(s) ended in an error" if errors
                                                   else "measures only")
    failing = [i for i in report.newly_failing or () if i.rsplit("/", 1)[0] == name]
    detail = reason
    if verdict == "FAIL" and failing:
        detail += "\nnewly failing: " + ", ".join(failing)
    if errors:
        detail += "\n" + "\n".join(f"{e.id} ({e.role}): {e.error}" for e in errors)
    out = (f"candidate failures {failures_text(entry.candidate)}, baseline failures "
           f"{failures_text(entry.baseline)}; {reason}")
    return _case(name, "dv2s.regress.scenario", _seconds(report, name), verdict, reason, detail, out)


def _overall_case(report: RegressReport) -> ET.Element:
    """The test case of the overall verdict."""
    verdict = report.verdict
    comparison = report.overall.comparison if report.overall is not None else None
    reason = report.error_reason or (comparison.reason if recorded(comparison) else None) or \
        "measures only: no baseline, no verdict"
    detail = reason
    if report.regressed:
        detail += "\nregressed: " + ", ".join(report.regressed)
    if report.errors:
        detail += "\n" + "\n".join(f"{e.id} ({e.role}): {e.error}" for e in report.errors[:50])
    out = "\n".join([headline(report), f"verdict: {verdict or 'none (measures only)'}"] + power_lines(report))
    return _case("overall verdict", "dv2s.regress", _seconds(report), verdict, reason, detail, out)


def junit_tree(report: RegressReport) -> ET.ElementTree:
    """The JUnit document of a report (see the module docstring)."""
    cases = [_scenario_case(report, name, entry) for name, entry in report.scenarios.items()]
    cases.append(_overall_case(report))
    counts = {key: str(sum(1 for c in cases if c.find(key) is not None)) for key in ("failure", "error", "skipped")}
    total = f"{float(report.duration or _seconds(report)):.3f}"
    suite = ET.Element("testsuite", {
        "name": "dv2s regress", "tests": str(len(cases)), "failures": counts["failure"], "errors": counts["error"],
        "skipped": counts["skipped"], "time": total, "timestamp": _junit_timestamp(report.created),
        "hostname": str(report.hostname or socket.gethostname()),
    })
    properties = ET.SubElement(suite, "properties")
    for key, value in (("candidate", report.candidate.spec),
                       ("baseline", report.baseline.spec if report.baseline is not None else None),
                       ("verdict", report.verdict), ("bank_version", report.bank.version)):
        ET.SubElement(properties, "property", {"name": key, "value": str(value)})
    found = warnings(report)
    for warning in found:
        ET.SubElement(properties, "property", {"name": "warning", "value": warning})
    suite.extend(cases)
    if found:  # CI systems show a suite's system-err beside its results
        ET.SubElement(suite, "system-err").text = "\n".join(f"warning: {w}" for w in found)
    root = ET.Element("testsuites", {"name": "dv2s regress", "tests": str(len(cases)), "failures": counts["failure"],
                                     "errors": counts["error"], "skipped": counts["skipped"], "time": total})
    root.append(suite)
    ET.indent(root)
    return ET.ElementTree(root)


def write_junit(report: RegressReport, path: Union[str, os.PathLike]) -> Path:
    """Write JUnit XML: one test case per scenario and one for the overall verdict; FAIL is a failure,
    ERROR an error, INCONCLUSIVE skipped with its reason; the suite has hostname, time and timestamp."""
    tree = junit_tree(report)
    text = ET.tostring(tree.getroot(), encoding="unicode", xml_declaration=False)
    return atomic_write_text(path, '<?xml version="1.0" encoding="utf-8"?>\n' + text + "\n")
