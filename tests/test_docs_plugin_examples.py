"""The plug-in examples of docs/mining.md are complete: each code block imports as a module on its own, registers
what the text says, and does what it says (the detector finds a hard brake in a trace, the policy keeps its lane)."""

from __future__ import annotations

import importlib
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from dv2s_gym.mining import monitors
from envs.trace import EpisodeTrace
from policies import registry
from policies.state_driver import IDLE
from scenario_bank.failure_types import unregister_failure_type

MINING = Path(__file__).resolve().parents[1] / "docs" / "mining.md"


def _example(marker: str) -> str:
    blocks = [b for b in re.findall(r"```python\n(.*?)```", MINING.read_text(encoding="utf-8"), re.DOTALL)
              if marker in b]
    assert len(blocks) == 1, f"docs/mining.md should hold one python example with {marker}"
    return blocks[0]


@pytest.fixture
def plugin(tmp_path, monkeypatch):
    """Import a docs example as the module ``name`` from a file of its own (as a user's plug-in is)."""
    monkeypatch.syspath_prepend(str(tmp_path))

    def load(name: str, marker: str):
        (tmp_path / f"{name}.py").write_text(_example(marker), encoding="utf-8")
        monkeypatch.delitem(sys.modules, name, raising=False)
        return importlib.import_module(name)
    yield load
    for name in ("docs_hard_brake", "docs_idle_policy"):
        sys.modules.pop(name, None)


def _trace(ego_speeds):
    return EpisodeTrace(scenario="s", source="", seed=0, scene_seed=0, params={}, config={"policy_frequency": 5},
                        states=[{"ego": [10.0 * i, 0.0, 0.0, v], "car": [50.0, 0.0, 0.0, 5.0]}
                                for i, v in enumerate(ego_speeds)])


def test_the_detector_example_registers_a_type_that_finds_a_hard_brake(plugin):
    try:
        module = plugin("docs_hard_brake", "detect_hard_brake")
        detector = monitors.DETECTORS["hard_brake"]
        assert detector.detect is module.detect_hard_brake
        # 0.2 s steps: 20 -> 19.5 is 2.5 m/s² (not hard), 19.5 -> 18.5 is 5 m/s² (hard), at step 2 = 0.4 s
        failure = detector.detect(None, _trace([20.0, 19.5, 18.5, 18.5]), monitors.DEFAULT_MONITOR)
        assert (failure.type, failure.step, failure.time, failure.speed) == ("hard_brake", 2, pytest.approx(0.4), 18.5)
        assert detector.detect(None, _trace([20.0, 19.5, 19.0, 19.0]), monitors.DEFAULT_MONITOR) is None
    finally:
        monitors.unregister_detector("hard_brake")
        unregister_failure_type("hard_brake")


def test_the_policy_example_registers_a_policy_that_keeps_its_lane(plugin, monkeypatch):
    monkeypatch.setattr(registry, "_REGISTRY", registry._REGISTRY.copy())
    plugin("docs_idle_policy", "register_policy")
    assert "idle" in registry.registered_policies()
    assert registry.load_policy("idle").act(np.zeros((3, 5, 5))).tolist() == [IDLE, IDLE, IDLE]
