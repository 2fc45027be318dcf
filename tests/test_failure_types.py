"""The failure types are one table (scenario_bank.failure_types): every reader takes them from it, and no other
module lists them again."""

from __future__ import annotations

import ast
from pathlib import Path
from typing import List

from dv2s_gym.mining import monitors
from dv2s_gym.mining import report as mining_report
from dv2s_gym.mining.tasks import reference_avoids
from dv2s_gym.regress import failures
from dv2s_gym.regress import report as regress_report
from scenario_bank.failure_types import FAILURE_TABLE, FAILURE_TYPES, failure_type, severity_order

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("scenario_bank", "envs", "policies", "dv2s_gym")
TABLE = ROOT / "scenario_bank" / "failure_types.py"


def test_the_table_is_in_severity_order_and_its_names_are_unique():
    assert [row.severity for row in FAILURE_TABLE] == list(range(len(FAILURE_TABLE)))
    assert FAILURE_TYPES == ("collision", "off_road", "low_ttc", "stall")
    assert failure_type("stall").result_field == "stalled" and failure_type("nothing") is None
    assert severity_order(["stall", "weird", "collision", "stall", "another"]) == [
        "collision", "stall", "another", "weird"]


def test_the_public_names_are_the_table_read_by_each_part():
    assert monitors.FAILURE_TYPES is FAILURE_TYPES
    assert mining_report.FAILURE_ORDER is FAILURE_TYPES
    assert failures.FAILURE_KINDS == {"collision": "collided", "off_road": "off_road", "stall": "stalled"}
    assert list(failures.FAILURE_KINDS) == [n for n in FAILURE_TYPES if n != "low_ttc"]  # severity order
    assert failures.DEFAULT_FAILURE == ("collision", "off_road", "stall")
    assert failures.FAILURE_BEFORE_CHOICE == ("collision", "off_road")
    assert [key for key, _ in regress_report.RATES] == [
        "collision_rate", "off_road_rate", "stall_rate", "failure_rate", "success_rate"]


def test_the_readers_order_by_the_table():
    assert reference_avoids({"type": "collision"}, {"type": "stall"})  # a stall is less severe
    assert not reference_avoids({"type": "stall"}, {"type": "off_road"})
    result = failures.apply_failure({"collided": False, "off_road": True, "stalled": True}, ["off_road", "stall"])
    assert result["failure_kinds"] == ["off_road", "stall"] and result["failed"]
    assert failures.parse_failure("stall,collision") == ["collision", "stall"]


def _failure_name_lists(source: str, where: str) -> List[str]:
    """Tuples, lists and sets of two or more failure names, and dicts keyed by them only, in a module's source."""
    names = set(FAILURE_TYPES)
    found = []
    for node in ast.walk(ast.parse(source, where)):
        items = node.elts if isinstance(node, (ast.Tuple, ast.List, ast.Set)) else \
            node.keys if isinstance(node, ast.Dict) else None
        if items and len(items) >= 2 and all(isinstance(i, ast.Constant) and i.value in names for i in items):
            found.append(f"{where}:{node.lineno}: {ast.unparse(node)[:80]}")
    return found


def test_no_module_but_the_table_lists_the_failure_types():
    """A second list of the failure types drifts from the table: read the table (its rows, FAILURE_TYPES,
    or regress's FAILURE_KINDS / DEFAULT_FAILURE / FAILURE_BEFORE_CHOICE) instead."""
    planted = 'ORDER = ("collision", "off_road")\nFIELDS = {"stall": "stalled", "low_ttc": None}\n'
    assert len(_failure_name_lists(planted, "planted.py")) == 2  # the check sees such lists
    assert not _failure_name_lists('MEASURES = ("collision", "success")\n', "measures.py")  # other names mixed in
    found = [hit for package in PACKAGES for path in sorted((ROOT / package).rglob("*.py")) if path != TABLE
             for hit in _failure_name_lists(path.read_text(encoding="utf-8"), str(path.relative_to(ROOT)))]
    assert not found, "failure types listed outside scenario_bank/failure_types.py:\n" + "\n".join(found)
