"""The map of a trace: one the loader cannot read leaves the map-based rules without a map, with a warning;
any other fault in loading it surfaces. (Each test's map is a new path: map views are cached by path.)"""

from __future__ import annotations

from types import SimpleNamespace

import pytest

import envs.road_network as road_network
from dv2s_gym.pipeline.semantics import trace as semantics


def test_an_unreadable_map_warns_and_judges_without_it(tmp_path):
    broken = tmp_path / "broken_map.xodr"
    broken.write_text("<OpenDRIVE><not a map")
    with pytest.warns(UserWarning, match="broken_map.xodr of a trace cannot be loaded.*judged without it"):
        assert semantics.map_view(SimpleNamespace(params={"map": str(broken)})) is None


def test_another_fault_loading_the_map_surfaces(tmp_path, monkeypatch):
    a_map = tmp_path / "some_map.xodr"
    a_map.write_text("<OpenDRIVE/>")

    def faulty(path):
        raise KeyError("a fault of the loader, not of the map")

    monkeypatch.setattr(road_network, "load_road_network", faulty)
    with pytest.raises(KeyError, match="a fault of the loader"):
        semantics.map_view(SimpleNamespace(params={"map": str(a_map)}))
