"""Shared pytest setup: make the repository importable without installing it, and keep
the tests' caches (bank indexes, parsed maps) in a throwaway directory instead of the
user's cache directory. Subprocesses inherit both."""

import os
import sys
import tempfile
from pathlib import Path

# two xdist workers on two cores: one BLAS/OpenMP thread each, or they slow each other down
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("DV2S_CACHE_DIR", tempfile.mkdtemp(prefix="dv2s-test-cache-"))

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
