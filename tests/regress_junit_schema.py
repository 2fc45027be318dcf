"""A check of JUnit XML against the structure of the common JUnit schema CI systems read (the
Jenkins / Ant ``junit-10.xsd``): element nesting and order, required attributes and their types,
and counts that agree with the test cases. Returns the problems found (empty: valid)."""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from typing import List

INTEGER = re.compile(r"^[0-9]+$")
DECIMAL = re.compile(r"^[0-9]+(\.[0-9]+)?$")
TIMESTAMP = re.compile(r"^[0-9]{4}-[0-9]{2}-[0-9]{2}T[0-9]{2}:[0-9]{2}:[0-9]{2}$")  # ISO 8601, no zone
TOKEN = re.compile(r"^\S+$")

SUITE_REQUIRED = {"name": None, "tests": INTEGER, "failures": INTEGER, "errors": INTEGER, "time": DECIMAL,
                  "timestamp": TIMESTAMP, "hostname": TOKEN}
SUITE_OPTIONAL = {"skipped": INTEGER, "id": None, "package": None, "disabled": INTEGER, "file": None, "log": None,
                  "url": None, "version": None, "group": None}
CASE_REQUIRED = {"name": None, "classname": None, "time": DECIMAL}
CASE_OPTIONAL = {"assertions": None, "status": None, "file": None, "line": None}
SUITES_OPTIONAL = {"name": None, "time": DECIMAL, "tests": INTEGER, "failures": INTEGER, "errors": INTEGER,
                   "skipped": INTEGER, "disabled": INTEGER}


def _attributes(element: ET.Element, required: dict, optional: dict, where: str) -> List[str]:
    problems = []
    for key, pattern in required.items():
        value = element.get(key)
        if value is None:
            problems.append(f"{where}: missing attribute {key}")
        elif pattern is not None and not pattern.match(value):
            problems.append(f"{where}: attribute {key}={value!r} is not of its type")
    for key, value in element.attrib.items():
        if key not in required and key not in optional:
            problems.append(f"{where}: unknown attribute {key}")
        elif key in optional and optional[key] is not None and not optional[key].match(value):
            problems.append(f"{where}: attribute {key}={value!r} is not of its type")
    return problems


def _ordered(children: List[str], order: List[str], where: str) -> List[str]:
    ranks = []
    for tag in children:
        if tag not in order:
            return [f"{where}: element {tag} is not allowed here"]
        ranks.append(order.index(tag))
    return [] if ranks == sorted(ranks) else [f"{where}: children out of order: {children}"]


def junit_problems(root: ET.Element) -> List[str]:
    """Problems of a ``<testsuites>`` document against the JUnit schema's structure."""
    if root.tag != "testsuites":
        return [f"root element is {root.tag}, not testsuites"]
    problems = _attributes(root, {}, SUITES_OPTIONAL, "testsuites")
    if any(child.tag != "testsuite" for child in root):
        problems.append("testsuites may only hold testsuite elements")
    for suite in root.findall("testsuite"):
        where = f"testsuite {suite.get('name')!r}"
        problems += _attributes(suite, SUITE_REQUIRED, SUITE_OPTIONAL, where)
        problems += _ordered([c.tag for c in suite], ["properties", "testcase", "system-out", "system-err"], where)
        for prop in suite.findall("properties/property"):
            problems += _attributes(prop, {"name": None, "value": None}, {}, f"{where} property")
        cases = suite.findall("testcase")
        outcome_counts = {"failure": 0, "error": 0, "skipped": 0}
        for case in cases:
            at = f"testcase {case.get('name')!r}"
            problems += _attributes(case, CASE_REQUIRED, CASE_OPTIONAL, at)
            tags = [c.tag for c in case]
            problems += _ordered(tags, ["skipped", "error", "failure", "system-out", "system-err"], at)
            outcomes = [t for t in tags if t in outcome_counts]
            if len(outcomes) > 1:
                problems.append(f"{at}: more than one outcome {outcomes}")
            for tag in outcomes:
                outcome_counts[tag] += 1
            for child in case:
                if child.tag in ("failure", "error"):
                    problems += _attributes(child, {}, {"message": None, "type": None}, f"{at} {child.tag}")
                elif child.tag == "skipped":
                    problems += _attributes(child, {}, {"message": None}, f"{at} skipped")
        if suite.get("tests") != str(len(cases)):
            problems.append(f"{where}: tests={suite.get('tests')} but {len(cases)} test cases")
        for tag, attribute in (("failure", "failures"), ("error", "errors"), ("skipped", "skipped")):
            if suite.get(attribute, "0") != str(outcome_counts[tag]):
                problems.append(f"{where}: {attribute}={suite.get(attribute)} but {outcome_counts[tag]} test cases")
    return problems
