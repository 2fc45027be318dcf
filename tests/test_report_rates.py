"""One rate shape in code: the mining and regression reports write their ``{"value", "low", "high", "count"}``
rates through :meth:`policies.stats.Rate.report_json`, and no report builds its own."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

from policies.stats import Rate, wilson_interval

__all__: list = []

ROOT = Path(__file__).resolve().parents[1]
REPORTS = ("dv2s_gym/mining/report.py", "dv2s_gym/regress/report.py")


@pytest.mark.parametrize("k, n", [(0, 1), (3, 10), (7, 7), (1, 3), (13, 999)])
def test_the_report_shape_is_the_wilson_rate_of_k_in_n(k, n):
    low, high = wilson_interval(k, n, 0.95)
    assert Rate.of(k, n).report_json() == {"value": k / n, "low": low, "high": high, "count": k}
    assert Rate.of(k, n).report_json(scale=100.0, with_n=True) == {
        "value": 100.0 * k / n, "low": 100.0 * low, "high": 100.0 * high, "count": k, "n": n}


def test_a_rate_of_no_episode_has_no_value():
    assert Rate.of(0, 0).report_json() == {"value": None, "low": None, "high": None, "count": 0}
    assert Rate.of(0, 0).report_json(scale=100.0, with_n=True) == {
        "value": None, "low": None, "high": None, "count": 0, "n": 0}


@pytest.mark.parametrize("path", REPORTS)
def test_no_report_computes_a_wilson_interval_itself(path):
    tree = ast.parse((ROOT / path).read_text(encoding="utf-8"))
    calls = [node.lineno for node in ast.walk(tree) if isinstance(node, ast.Call)
             and getattr(node.func, "id", getattr(node.func, "attr", None)) == "wilson_interval"]
    assert not calls, f"{path} computes its own Wilson interval at lines {calls}: use Rate.of(k, n).report_json()"
