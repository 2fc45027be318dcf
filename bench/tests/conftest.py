"""Pytest setup of the benchmarks' tests, as for the product's (tests/conftest.py): the repository and the
product's test helpers importable, the tests' caches in a throwaway directory, and the shared Scenic fixtures.

The README's test command collects these tests too (``testpaths`` in pyproject.toml)."""

import os
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("DV2S_CACHE_DIR", tempfile.mkdtemp(prefix="dv2s-test-cache-"))

ROOT = Path(__file__).resolve().parents[2]
for folder in (ROOT / "tests", ROOT):
    if str(folder) not in sys.path:
        sys.path.insert(0, str(folder))

from scenic_fixtures import in_process_simulator, scenic_globals_idle  # noqa: E402,F401
