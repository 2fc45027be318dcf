"""The wheel holds the documents the shipped bank's scenarios and the docs point to: ``pyproject.toml``'s
package-data covers them."""

from __future__ import annotations

import fnmatch
import tomllib
from pathlib import Path

__all__: list = []

ROOT = Path(__file__).resolve().parents[1]


def _packaged(path: str) -> bool:
    data = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    patterns = data["tool"]["setuptools"]["package-data"]
    for package, globs in patterns.items():
        folder = package.replace(".", "/") + "/"
        if path.startswith(folder) and any(fnmatch.fnmatch(path[len(folder):], glob) for glob in globs):
            return True
    return False


def test_the_scenario_bank_readme_is_packaged():
    assert (ROOT / "scenario_bank" / "README.md").is_file()
    assert _packaged("scenario_bank/README.md"), "scenario_bank/README.md is not in pyproject.toml's package-data"
    assert _packaged("scenario_bank/shipped_scenarios.sha256")  # the reading of the patterns itself
