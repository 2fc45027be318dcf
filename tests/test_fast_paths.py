"""The env's fast paths give the answers of the slow code they stand in for.

* collisions: the separating-axis pre-test only drops pairs highway-env's exact
  test finds neither intersecting nor about to; the plain-Python broad phase
  returns the NumPy one's pairs, in the same order, and every pair highway-env's
  spherical pre-check would test;
* Scenic read-back: lazily recomputed ``heading``/``orientation`` equal Scenic's
  eager recomputation, and cached properties are dropped after every step.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from highway_env.vehicle.kinematics import Vehicle
from highway_env.vehicle.objects import Obstacle

import envs.hw_road as hw_road
from envs.coordinates import hw_to_scenic_heading
from envs.hw_road import EventRoad, clearly_apart


def _random_pair(rng, spread: float):
    road = None  # geometry only: no lane look-ups
    objs = []
    for _ in range(2):
        pos = rng.uniform(-spread, spread, 2)
        heading = rng.uniform(-math.pi, math.pi)
        if rng.random() < 0.2:
            obj = Obstacle(road, pos, heading)
        else:
            obj = Vehicle(road, pos, heading, rng.uniform(-5, 35))
        obj.LENGTH, obj.WIDTH = rng.uniform(0.5, 12), rng.uniform(0.5, 3)
        obj.diagonal = math.hypot(obj.LENGTH, obj.WIDTH)
        objs.append(obj)
    return objs


@pytest.mark.slow
@pytest.mark.parametrize("spread", [2.0, 5.0, 10.0])
def test_clearly_apart_never_drops_a_collision(spread):
    rng = np.random.default_rng(int(spread * 10))
    dropped = kept = 0
    for _ in range(3000):
        a, b = _random_pair(rng, spread)
        exact = a._is_colliding(b, 1 / 15)
        shapes = {}
        for _ in range(2):  # computed, then from the per-pass cache: highway-env's answer both times
            mine = hw_road._is_colliding(a, b, 1 / 15, shapes)
            assert mine[:2] == exact[:2]
            assert (mine[2] is None and exact[2] is None) or np.array_equal(mine[2], exact[2])
        if clearly_apart(a, b, 1 / 15):
            dropped += 1
            assert not exact[0] and not exact[1], (a.position, b.position, a.heading, b.heading)
        else:
            kept += 1
    assert dropped > 100 and kept > 100  # both outcomes are exercised at these spreads


def test_clearly_apart_for_distant_boxes_and_not_for_overlapping_ones():
    road = None  # geometry only: no lane look-ups
    a = Vehicle(road, np.array([0.0, 0.0]), 0.0, 20.0)
    far = Vehicle(road, np.array([30.0, 0.0]), 0.0, 20.0)
    beside = Vehicle(road, np.array([0.0, 4.0]), 0.0, 20.0)
    touching = Vehicle(road, np.array([4.0, 0.5]), 0.3, 0.0)
    assert clearly_apart(a, far, 1 / 15)
    assert clearly_apart(a, beside, 1 / 15)
    assert not clearly_apart(a, touching, 1 / 15)
    assert touching._is_colliding(a, 1 / 15)[0]


def test_python_broad_phase_matches_numpy_and_covers_highway_env(monkeypatch):
    rng = np.random.default_rng(3)
    road = None  # geometry only: no lane look-ups
    dt = 1 / 15
    for _ in range(200):
        movers = [Vehicle(road, rng.uniform(0, 40, 2), rng.uniform(-math.pi, math.pi), rng.uniform(0, 30))
                  for _ in range(int(rng.integers(1, 9)))]
        props = [Obstacle(road, rng.uniform(0, 40, 2), 0.0) for _ in range(int(rng.integers(0, 4)))]
        everything = movers + props
        monkeypatch.setattr(hw_road, "_PYTHON_BROAD_PHASE", 10**6)
        python = [tuple(map(int, p)) for p in EventRoad._candidate_pairs(everything, len(movers), dt)]
        monkeypatch.setattr(hw_road, "_PYTHON_BROAD_PHASE", -1)
        numpy = [tuple(map(int, p)) for p in EventRoad._candidate_pairs(everything, len(movers), dt)]
        assert python == numpy
        for i in range(len(movers)):
            for j in range(i + 1, len(everything)):
                a, b = everything[i], everything[j]
                sphere = np.linalg.norm(b.position - a.position) <= (a.diagonal + b.diagonal) / 2 + a.speed * dt
                if sphere:
                    assert (i, j) in python


# --------------------------------------------------------------------------- Scenic read-back

SCENE = """
param map = 'highway_straight'
model scenic.domains.driving.model
ego = new Car on network.lanes[1].centerline, with speed 20
car = new Car ahead of ego by 20, with speed 15, with behavior FollowLaneBehavior(target_speed=18)
other = new Car on network.lanes[2].centerline, with speed 22, with behavior LaneChangeBehavior(laneSectionToSwitch=network.lanes[1].sections[0], target_speed=22)
"""


@pytest.mark.usefixtures("in_process_simulator")  # reads Scenic's objects in the simulating process
def test_lazy_dynamic_finals_equal_scenic_recomputation():
    import gymnasium as gym

    import dv2s_gym  # noqa: F401

    env = gym.make("DV2S-v0", scenario=SCENE, config={"duration": 5}).unwrapped
    env.reset(seed=4)
    sim = env._current_simulation()
    changed = 0
    for step in range(12):
        env.step(0 if step < 3 else 1)  # LANE_LEFT then IDLE: the ego's heading changes
        for obj in sim.objects:
            proxy = object.__getattribute__(obj, "_dynamicProxy")
            state = object.__getattribute__(proxy, "__dict__")
            assert "heading" not in state and "orientation" not in state  # dropped by the read-back
            assert "_cached_corners" not in state
            corners = obj.corners  # cached by Scenic until the next step
            lazy_heading, lazy_orientation = obj.heading, obj.orientation
            assert "_cached_corners" in state and "heading" in state
            proxy._recomputeDynamicFinals()  # Scenic's eager path
            assert obj.heading == lazy_heading
            assert obj.orientation.q.tolist() == lazy_orientation.q.tolist()
            assert corners is obj.corners
            gap = lazy_heading - hw_to_scenic_heading(sim.hw_object(obj).heading)
            assert abs(math.remainder(gap, math.tau)) < 1e-9
            sampled = object.__getattribute__(obj, "__dict__")["heading"]
            changed += abs(math.remainder(lazy_heading - sampled, math.tau)) > 1e-3
    assert changed > 0  # headings moved away from the sampled ones
    env.close()


# --------------------------------------------------------------------------- time-to-collision


def test_time_to_collision_cases():
    from envs.safety_metrics import time_to_collision

    def car(x, y, heading, speed, name):
        v = Vehicle(None, np.array([x, y]), heading, speed)
        v.LENGTH, v.WIDTH, v.name = 4.0, 2.0, name
        return v

    ego = car(0, 0, 0.0, 10.0, "ego")
    ahead = car(30, 0, 0.0, 0.0, "ahead")
    beside = car(0, 4, 0.0, 10.0, "beside")  # same speed, next lane: never meets
    behind = car(-20, 0, 0.0, 20.0, "behind")  # closes 10 m/s from 16 m: 1.6 s
    assert time_to_collision(ego, [ego, ahead, beside]) == pytest.approx((2.6, "ahead"))
    assert time_to_collision(ego, [ego, beside]) == (math.inf, "")
    assert time_to_collision(ego, [ahead, behind]) == pytest.approx((1.6, "behind"))
    assert time_to_collision(ego, [ahead, behind], ahead_only=True) == pytest.approx((2.6, "ahead"))
    assert time_to_collision(ego, [ahead], horizon=2.0) == (math.inf, "")
    overlapping = car(3, 0.5, 0.3, 0.0, "overlapping")
    assert time_to_collision(ego, [ahead, overlapping]) == (0.0, "overlapping")


# --------------------------------------------------------------------------- observation


@pytest.mark.slow
@pytest.mark.parametrize("env_id", ["DV2S-v0", "highway-v0"])
def test_fast_kinematics_equals_highway_env_kinematics(env_id):
    """The NumPy Kinematics gives highway-env's pandas Kinematics array, step by step."""
    import gymnasium as gym
    import highway_env  # noqa: F401
    from highway_env.envs.common.observation import KinematicObservation

    import dv2s_gym  # noqa: F401
    from envs.observations import FastKinematicObservation

    kwargs = {"scenario": "highway_cut_in_from_left"} if env_id == "DV2S-v0" else {}
    config = {"observation": {"type": "Kinematics", "vehicles_count": 6, "see_behind": True,
                              "features": ["presence", "x", "y", "vx", "vy", "cos_h", "sin_h"]}}
    env = gym.make(env_id, config=config, **kwargs).unwrapped
    env.reset(seed=3)
    compared = 0
    for step in range(15):
        obs_type = env.observation_type
        obs_type.__class__ = FastKinematicObservation  # DV2S-v0 already uses it; native gets it here
        fast = obs_type.observe()
        stock = KinematicObservation.observe(obs_type)
        assert fast.dtype == stock.dtype and np.array_equal(fast, stock), step
        compared += int(stock[1:, 0].sum())  # other vehicles present in the observation
        _, _, terminated, truncated, _ = env.step(1)
        if terminated or truncated:
            break
    assert compared > 0
    env.close()
