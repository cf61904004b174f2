"""The pose graph (tangraph.graph.keyposes): key poses at the window ends, every interval and the ends,
the poses nothing ties named, copies with other fixes, a widened start kept and undone."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.graph import PoseGraph, key_indices, smooth_pose_graph, window_ends


def test_key_indices_cover_windows_interval_and_ends():
    t = np.arange(0.0, 100.0, 2.0)  # 50 pings
    ends = window_ends(50, 10, 10)
    np.testing.assert_array_equal(ends, [9, 19, 29, 39, 49])
    keys = key_indices(t, ends, key_interval=7.0)
    assert keys[0] == 0 and keys[-1] == 49 and set(ends) <= set(keys)
    assert np.all(np.diff(t[keys]) < 7.0 + 2.0)  # the first ping at least 7 s after the last key


def test_gap_without_odometry_names_the_unconstrained_poses():
    graph = PoseGraph()
    for k in range(6):
        graph.add_pose(k * 10, float(k), [k * 10.0, 0.0, 0.0])
    graph.add_pose_prior(0, [0.0, 0.0, 0.0], np.diag([1.0, 1.0, 0.01]))
    for i, j in ((0, 10), (10, 20), (30, 40), (40, 50)):  # no odometry from 20 to 30
        graph.add_odometry(i, j, [10.0, 0.0, 0.0], np.diag([0.1, 0.1, 1e-4]))
    graph.add_position_fix(40, [40.0, 0.0], np.eye(2))
    with pytest.raises(TangraphError, match=r"pings 30\.\.50 \(3 key poses\)"):
        smooth_pose_graph(graph)
    graph.add_position_fix(50, [50.0, 0.0], np.eye(2))  # two fixes pin the part after the gap
    solution = smooth_pose_graph(graph)
    np.testing.assert_allclose(solution.pose[-1, :2], [50.0, 0.0], atol=1e-6)


def test_with_fixes_leaves_the_original_graph_alone():
    from tangraph.graph import PoseGraph

    graph = PoseGraph()
    graph.add_pose(0, 0.0, [0.0, 0.0, 0.0])
    graph.add_pose_prior(0, [0.0, 0.0, 0.0], np.eye(3))
    graph.add_position_fix(0, [1.0, 1.0], np.eye(2))
    other = graph.with_fixes([])
    other.add_pose(1, 1.0, [1.0, 0.0, 0.0])
    other.add_odometry(0, 1, [1.0, 0.0, 0.0], np.eye(3) * 0.01)
    assert graph.keys == [0] and len(graph.odometry) == 0 and len(graph.fixes) == 1
    assert graph.factor_graph().size() == 2 and other.factor_graph().size() == 2


def test_a_widened_start_is_kept_and_undone_with_the_breaks():
    from tangraph.graph import PoseGraph

    graph = PoseGraph()
    graph.add_pose(0, 0.0, [0.0, 0.0, 0.0])
    graph.add_start(0, [0.0, 0.0, 0.0], 10.0, 0.01)
    wide = graph.widen_start(200.0)
    assert graph.start_break == pytest.approx(200.0) and graph._factors["start"] == [wide]

    def position_std(g):
        cov = gtsam.Marginals(g.factor_graph(), g.values(None, None)).marginalCovariance(0)
        return float(np.sqrt(cov[0, 0]))

    assert position_std(graph) == pytest.approx(np.hypot(10.0, 200.0), rel=1e-6)
    assert position_std(graph.with_fixes([])) == pytest.approx(np.hypot(10.0, 200.0), rel=1e-6)
    assert position_std(graph.with_fixes([], breaks=False)) == pytest.approx(10.0, rel=1e-6)
    assert graph.start_break == pytest.approx(200.0)  # the original keeps its break
