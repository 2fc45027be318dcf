"""Packaging facts: declared dependencies are exactly the imported ones (deptry), and an
install that is read-only works and is never written to."""

from __future__ import annotations

import os
import shutil
import stat
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("dv2s_gym", "envs", "policies", "scenario_bank")


def test_declared_dependencies_match_the_imports():
    """deptry (configured in pyproject.toml) finds no missing, unused, transitive or misplaced dependency."""
    pytest.importorskip("deptry")
    out = subprocess.run([sys.executable, "-m", "deptry", "."], cwd=ROOT, capture_output=True, text=True,
                         timeout=300)
    report = out.stdout + out.stderr
    assert out.returncode == 0 and "No dependency issues found" in report, report


def _snapshot(folder: Path):
    return sorted((str(p.relative_to(folder)), p.stat().st_mtime_ns, p.stat().st_size)
                  for p in folder.rglob("*") if "__pycache__" not in p.parts)


def _chmod_tree(folder: Path, writable: bool) -> None:
    for path in [folder, *folder.rglob("*")]:
        mode = path.stat().st_mode
        if writable:
            path.chmod(mode | stat.S_IWUSR)
        else:
            path.chmod(mode & ~(stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH))


@pytest.mark.slow
def test_a_read_only_install_works_and_is_not_written_to(tmp_path):
    """A copy of the packages, made read-only: list the bank, compile and run an episode (parsing
    a map Scenic would cache as .snet), export the bank. Nothing under the copy changes; the index
    and map cache land in DV2S_CACHE_DIR. (As root the mode bits do not stop a write; the before/after
    snapshot of the tree does catch one.)"""
    install = tmp_path / "site"
    install.mkdir()
    for package in PACKAGES:
        shutil.copytree(ROOT / package, install / package,
                        ignore=shutil.ignore_patterns("__pycache__", "*.snet", ".lock"))
    cache = tmp_path / "cache"
    before = _snapshot(install)
    _chmod_tree(install, writable=False)
    code = (
        "import gymnasium as gym, json, sys\n"
        "from scenario_bank.bank import Bank\n"
        "bank = Bank()\n"
        "assert str(bank.root).startswith(sys.argv[1]), bank.root\n"
        "assert len(bank) > 10 and not bank.problems, bank.problems\n"
        "env = gym.make('dv2s_gym:DV2S-v0', scenario='urban_pedestrian_crossing', config={'duration': 1})\n"
        "obs, info = env.reset(seed=0)\n"
        "env.step(env.action_space.sample())\n"
        "env.close()\n"
        "bank.export(sys.argv[2])\n"
        "print('ok', len(bank))\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    env.update(PYTHONPATH=str(install), DV2S_CACHE_DIR=str(cache), PYTHONDONTWRITEBYTECODE="1")
    try:
        out = subprocess.run([sys.executable, "-c", code, str(install), str(tmp_path / "bank.tar.gz")],
                             cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    finally:
        _chmod_tree(install, writable=True)
    assert out.returncode == 0, out.stderr[-3000:]
    assert out.stdout.strip().startswith("ok")
    assert _snapshot(install) == before, "something was written into the installed packages"
    assert list((cache / "banks").glob("scenarios-*/index.json")), "the bank index is not in the cache directory"
    assert list((cache / "maps").glob("urban_two_way-*.snet")), "the parsed map is not in the cache directory"


def test_two_banks_get_separate_cache_folders(tmp_path, monkeypatch):
    from scenario_bank.bank import Bank

    monkeypatch.setenv("DV2S_CACHE_DIR", str(tmp_path / "cache"))
    a, b = Bank(tmp_path / "x" / "bank"), Bank(tmp_path / "y" / "bank")
    assert a._cache_folder() != b._cache_folder()
    assert a._cache_folder().parent == tmp_path / "cache" / "banks"
