"""Every module of ``bench/`` and ``scripts/`` imports: they use the product's API, and a refactor of the product
that keeps ``tests/`` green must not leave a benchmark or a calibration that cannot start."""

from __future__ import annotations

import importlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
MODULES = sorted(
    ".".join(path.relative_to(ROOT).with_suffix("").parts)
    for folder in ("bench", "scripts") for path in (ROOT / folder).rglob("*.py")
    if "tests" not in path.relative_to(ROOT).parts and path.name != "__init__.py"
)


def test_the_modules_are_found():
    assert "bench.calibrate_regress" in MODULES and "bench.research.regress_montecarlo" in MODULES


@pytest.mark.parametrize("module", MODULES)
def test_module_imports(module):
    importlib.import_module(module)
