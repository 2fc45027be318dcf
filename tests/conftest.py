"""Shared pytest setup: make the repository importable without installing it."""

import os
import sys
from pathlib import Path

# two xdist workers on two cores: one BLAS/OpenMP thread each, or they slow each other down
os.environ.setdefault("OMP_NUM_THREADS", "1")

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))
