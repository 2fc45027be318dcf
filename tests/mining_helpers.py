"""Test helpers for mining runs."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from dv2s_gym.mining import miner as miner_module
from dv2s_gym.mining.miner import mine


def mine_killed_after(policy: str, out: Path, stop_after: int, monkeypatch: Any, **run: Any) -> None:
    """Run ``mine(policy, out=out, **run)`` and kill it (``KeyboardInterrupt``) as it is about to record
    episode number ``stop_after``: the first ``stop_after`` episode records are on disk, others may be in
    flight. The recorder is restored afterwards."""
    original = miner_module._Appender.append
    count = [0]

    def append(self, record):
        if self._path.name == "episodes.jsonl":
            if count[0] == stop_after:
                raise KeyboardInterrupt  # killed with episodes in flight, some finished out of order
            count[0] += 1
        original(self, record)

    monkeypatch.setattr(miner_module._Appender, "append", append)
    with pytest.raises(KeyboardInterrupt):
        mine(policy, out=out, **run)
    monkeypatch.setattr(miner_module._Appender, "append", original)
