"""Trajectories (tangraph.sim.trajectories): a straight line's and a route's speed and heading, a
lawnmower's lines and spacing."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.sim import lawnmower, straight_line, waypoint_route


def test_straight_line_and_route_speed_and_heading():
    t, pose = straight_line((10.0, 20.0), np.radians(30), 2.0, 50.0, 2.0)
    assert t.size == 101
    np.testing.assert_allclose(
        pose[-1, :2], [10 + 100 * np.cos(np.radians(30)), 20 + 100 * np.sin(np.radians(30))]
    )
    t, pose = waypoint_route([(0, 0), (0, 100), (100, 100)], 1.0, 1.0, turn_radius=20.0)
    step = np.hypot(*np.diff(pose[:, :2], axis=0).T)
    np.testing.assert_allclose(step, 1.0, atol=2e-3)  # constant speed through the arc
    turn = np.angle(np.exp(1j * np.diff(pose[:, 2])))
    assert np.abs(turn).max() <= 1.0 / 20.0 + 1e-9  # heading rate = speed / radius at most
    assert pose[0, 2] == pytest.approx(np.pi / 2) and pose[-1, 2] == pytest.approx(0.0, abs=1e-9)


def test_lawnmower_lines_and_spacing():
    _, pose = lawnmower((0.0, 0.0), 0.0, 300.0, 50.0, 4, 2.0, 1.0)
    north_legs = pose[np.abs(np.cos(pose[:, 2])) > 0.9999]
    assert set(np.round(north_legs[:, 1]).astype(int)) == {0, 50, 100, 150}
