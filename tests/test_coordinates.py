"""Property tests of the Scenic <-> highway-env coordinate conventions."""

import math

import numpy as np
from hypothesis import given
from hypothesis import strategies as st

from envs.coordinates import (
    hw_heading_vector,
    hw_to_scenic_heading,
    hw_to_scenic_position,
    hw_to_scenic_velocity,
    scenic_heading_vector,
    scenic_to_hw_heading,
    scenic_to_hw_position,
    scenic_to_hw_velocity,
    wrap_angle,
)

coords = st.floats(min_value=-1e5, max_value=1e5, allow_nan=False)
angles = st.floats(min_value=-20.0, max_value=20.0, allow_nan=False)


def same_angle(a, b, tol=1e-9):
    return abs(wrap_angle(a - b)) < tol


@given(coords, coords)
def test_position_round_trip(x, y):
    hx, hy = scenic_to_hw_position(x, y)
    assert hw_to_scenic_position(hx, hy) == (x, y)


@given(angles)
def test_heading_round_trip(h):
    assert same_angle(hw_to_scenic_heading(scenic_to_hw_heading(h)), h)


@given(angles)
def test_heading_vector_maps_like_positions(h):
    """The direction a heading points to maps exactly as positions do."""
    sx, sy = scenic_heading_vector(h)
    expected = scenic_to_hw_velocity(sx, sy)
    assert np.allclose(hw_heading_vector(scenic_to_hw_heading(h)), expected, atol=1e-9)


@given(angles, angles)
def test_turning_direction_is_preserved_on_screen(h, dh):
    """A counter-clockwise Scenic turn is a decreasing highway-env heading (y drawn down)."""
    dh = abs(dh) % 1.0 + 1e-3
    before, after = scenic_to_hw_heading(h), scenic_to_hw_heading(h + dh)
    assert same_angle(after - before, -dh, 1e-7)


def test_cardinal_directions():
    # Scenic heading 0 points north (+y); on highway-env's screen north is up (-y).
    assert same_angle(scenic_to_hw_heading(0.0), -math.pi / 2)
    # Scenic -pi/2 points east (+x), highway-env heading 0.
    assert same_angle(scenic_to_hw_heading(-math.pi / 2), 0.0)
    assert same_angle(scenic_to_hw_heading(math.pi / 2), math.pi)
    assert np.allclose(scenic_heading_vector(0.0), [0.0, 1.0])


@given(coords, coords)
def test_velocity_round_trip(vx, vy):
    assert hw_to_scenic_velocity(*scenic_to_hw_velocity(vx, vy)) == (vx, vy)


@given(angles)
def test_wrap_angle_range(a):
    w = wrap_angle(a)
    assert -math.pi <= w < math.pi
    assert same_angle(w, a)
