"""A trace is data from anywhere: replaying one never builds an env its config could blow up, nor reads
an unbounded or special file it names."""

from __future__ import annotations

import copy
import os
from types import SimpleNamespace

import pytest

from envs.dv2s_env import DV2SEnv
from envs.replay import replay_trace, trace_config
from envs.trace_bounds import TraceConfigError, check_map


def _trace(config=None, **fields):
    defaults = {"config": DV2SEnv.default_config() if config is None else config, "scenario_path": None,
                "source": "", "params": {}}
    return SimpleNamespace(**{**defaults, **fields})


def test_the_default_config_is_within_bounds():
    config = trace_config(_trace())
    assert config["observation"]["vehicles_count"] == DV2SEnv.default_config()["observation"]["vehicles_count"]


@pytest.mark.parametrize("change, key", [
    (lambda c: c["observation"].update(vehicles_count=50_000_000), "observation.vehicles_count"),
    (lambda c: c["observation"].update(vehicles_count=101), "observation.vehicles_count"),
    (lambda c: c.update(observation={"type": "OccupancyGrid", "features": ["presence"],
                                     "grid_size": [[-2000, 2000], [-2000, 2000]], "grid_step": [1, 1]}),
     "observation.grid_size"),
    (lambda c: c.update(observation={"type": "OccupancyGrid", "grid_size": [[-20000, 20000], [-5, 5]],
                                     "grid_step": [1, 1]}), "observation.grid_size"),
    (lambda c: c["observation"].update(type="MultiAgentObservation"), "observation.type"),
    (lambda c: c["observation"].update(features=["x"] * 100_000), "observation.features"),
    (lambda c: c["action"].update(type="os.system"), "action.type"),
    (lambda c: c["action"].update(target_speeds=list(range(10_000))), "action.target_speeds"),
    (lambda c: c.update(screen_width=100_000), "screen_width"),
    (lambda c: c.update(screen_height=0), "screen_height"),
    (lambda c: c.update(scaling=1e9), "scaling"),
    (lambda c: c.update(max_sample_iterations=10**9), "max_sample_iterations"),
    (lambda c: c.update(other_vehicles_type="subprocess.Popen"), "other_vehicles_type"),
    (lambda c: c.update(manual_control=True), "manual_control"),
    (lambda c: c.update(reward_weights={"collision": float("inf")}), "reward_weights.collision"),
    (lambda c: c.update(map="/etc/passwd"), "map"),
])
def test_a_config_value_outside_its_bounds_is_refused_naming_it(change, key):
    config = copy.deepcopy(DV2SEnv.default_config())
    change(config)
    with pytest.raises(TraceConfigError, match=f"config has {key.replace('.', '[.]')}=.*not written by"):
        trace_config(_trace(config))


def test_a_small_occupancy_grid_is_allowed():
    config = copy.deepcopy(DV2SEnv.default_config())
    config["observation"] = {"type": "OccupancyGrid", "features": ["presence"],
                             "grid_size": [[-27.5, 27.5], [-27.5, 27.5]], "grid_step": [5, 5]}
    assert trace_config(_trace(config))["observation"]["grid_step"] == [5, 5]


def test_a_scenario_path_that_is_big_special_or_not_a_script_is_not_read(tmp_path):
    big = tmp_path / "big.scenic"
    with open(big, "wb") as handle:
        handle.truncate(64 * 1024 * 1024)  # sparse: reading it whole would take 64 MiB
    link = tmp_path / "link.scenic"
    link.symlink_to(big)
    fifo = tmp_path / "pipe.scenic"
    os.mkfifo(fifo)
    for path, why in ((big, "larger than"), (link, "symbolic link|link"), (fifo, "not a regular file"),
                      (tmp_path / "x.txt", "not a .scenic file")):
        with pytest.raises(ValueError, match=why):
            replay_trace(_trace(scenario_path=str(path), source="param x = 1"))


def test_a_map_a_trace_names_must_be_a_regular_small_xodr_file(tmp_path):
    good = tmp_path / "road.xodr"
    good.write_text("<OpenDRIVE/>")
    check_map(str(good))
    check_map("highway_straight")  # a shipped map's name
    link = tmp_path / "link.xodr"
    link.symlink_to(good)
    big = tmp_path / "big.xodr"
    with open(big, "wb") as handle:
        handle.truncate(64 * 1024 * 1024)
    for value, why in ((str(link), "not a regular file"), (str(big), "bytes"), ("/etc/passwd", "not an .xodr"),
                       (str(tmp_path / "none.xodr"), "no such file")):
        with pytest.raises(TraceConfigError, match=why):
            check_map(value)
