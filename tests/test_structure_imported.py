"""The structure rules checked on the imported packages, where no spelling of a class can hide what it is.

``tests/test_structure.py`` reads the source, so a class whose bases a metaclass, a computed expression or an
object with ``__mro_entries__`` decides is judged by how it is written. Here every module of the four packages is
imported and every exception class Python knows of is asked what it derives from: a class a product module
defines at import time and that is not under ``DV2SError`` fails, whatever made it.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import List

import pytest

from test_structure import OUTSIDE_THE_BASE, PACKAGES

ROOT = Path(__file__).resolve().parents[1]

_CHECK = textwrap.dedent('''
    import importlib, pkgutil, sys
    from scenario_bank.errors import DV2SError

    packages = sys.argv[1].split(",")
    for top in packages:
        for found in pkgutil.walk_packages(importlib.import_module(top).__path__, top + "."):
            if not found.name.endswith("__main__"):  # running the command line is not importing it
                importlib.import_module(found.name)

    def below(cls):
        for sub in type.__subclasses__(cls):
            yield sub
            yield from below(sub)

    for cls in set(below(BaseException)):
        module = getattr(cls, "__module__", "") or ""
        if module.split(".")[0] in packages and not issubclass(cls, DV2SError) \\
                and not cls.__qualname__.split(".")[-1].startswith("_"):
            print(f"{module}.{cls.__qualname__}")
''')


def imported_errors_outside_the_base(root: Path = ROOT) -> List[str]:
    """The public exception and warning classes the packages under ``root`` define at import time that do not
    derive from ``DV2SError`` (imported in a child process, so this one's modules are not the ones judged)."""
    done = subprocess.run([sys.executable, "-c", _CHECK, ",".join(PACKAGES)], cwd=root, capture_output=True,
                          text=True, timeout=600, env=dict(os.environ, PYTHONPATH=str(root), OMP_NUM_THREADS="1"))
    assert done.returncode == 0, done.stderr[-3000:]
    return sorted(done.stdout.split())


@pytest.mark.slow
def test_every_error_class_the_packages_define_derives_from_the_one_base():
    outside = imported_errors_outside_the_base()
    stray = [name for name in outside if name not in OUTSIDE_THE_BASE]
    assert not stray, f"error classes outside the one base class (seen on the imported packages): {stray}"


def _copy_tree(target: Path) -> None:
    for package in PACKAGES:
        shutil.copytree(ROOT / package, target / package, ignore=shutil.ignore_patterns("__pycache__"))


@pytest.mark.slow
@pytest.mark.parametrize("planted, name", [
    (# a metaclass that swaps the bases in: written as a plain class, it is a RuntimeError
     "class _Swap(type):\n    def __new__(m, name, bases, ns):\n        return super().__new__(m, name, (RuntimeError,), ns)\n"
     "class PlantedMetaError(metaclass=_Swap):\n    pass\n", "PlantedMetaError"),
    (# a base an object's __mro_entries__ decides
     "class _Entry:\n    def __mro_entries__(self, bases):\n        return (ValueError,)\n"
     "class PlantedEntryError(_Entry()):\n    pass\n", "PlantedEntryError"),
])
def test_the_imported_check_sees_a_class_whatever_made_it(tmp_path, planted, name):
    _copy_tree(tmp_path)
    with (tmp_path / "envs" / "trace.py").open("a", encoding="utf-8") as module:
        module.write("\n\n" + planted)
    outside = imported_errors_outside_the_base(tmp_path)
    assert [found for found in outside if found not in OUTSIDE_THE_BASE] == [f"envs.trace.{name}"]
