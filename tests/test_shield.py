"""SarSearch-v1's safety shield (``missions.shield``): commands into a danger zone or across the geofence margin
are cut back, and a drone flying them never enters the zone or leaves the fence."""
from __future__ import annotations

import numpy as np

from missions.shield import FENCE_MARGIN_M, ZONE_MARGIN_M, shield_velocity

FENCE = np.array([[-50.0, 950.0, -500.0, 500.0]])
ZONE = np.array([[[300.0, 0.0, 30.0]]])
VALID = np.array([[True]])


def fly(start, velocity, steps=80, zone=ZONE):
    """Integrate a constant wanted velocity through the shield (1 s steps); returns the path."""
    position, path = np.array([start], dtype=float), []
    for _ in range(steps):
        position = position + shield_velocity(position, np.array([velocity], dtype=float), zone, VALID, FENCE)
        path.append(position[0].copy())
    return np.array(path)


def test_a_command_straight_at_a_zone_slides_round_it_and_never_enters():
    path = fly((0.0, 0.5), (10.0, 0.0))
    distance = np.hypot(path[:, 0] - 300.0, path[:, 1])
    assert distance.min() > 30.0 and path[-1, 0] > 300.0 + 30.0  # round the zone and on beyond it
    assert abs(path[-1, 1]) < 60.0  # slid round it, not sent far away


def test_a_clear_command_is_left_alone():
    velocity = np.array([[10.0, 0.0]])
    clear = shield_velocity(np.array([[0.0, 200.0]]), velocity, ZONE, VALID, FENCE)
    np.testing.assert_array_equal(clear, velocity)
    padding = shield_velocity(np.array([[250.0, 0.0]]), velocity, ZONE, np.array([[False]]), FENCE)
    np.testing.assert_array_equal(padding, velocity)  # a padding slot is no zone


def test_the_fence_margin_stops_the_drone_and_a_drone_beyond_it_comes_back():
    path = fly((900.0, 0.0), (10.0, 5.0), steps=30)
    assert path[:, 0].max() <= 950.0 - FENCE_MARGIN_M + 1e-9 and path[-1, 1] > 100.0  # stopped north, slid east
    back = shield_velocity(np.array([[940.0, 0.0]]), np.array([[3.0, 0.0]]), ZONE, VALID, FENCE)
    assert back[0, 0] < 0.0  # beyond the margin: sent back in
    inside = shield_velocity(np.array([[300.0, 30.0 + ZONE_MARGIN_M / 2]]), np.zeros((1, 2)), ZONE, VALID, FENCE)
    assert inside[0, 1] > 0.0  # within a zone's margin: sent out, away from the centre
