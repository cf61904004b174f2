"""Graduated non-convexity (tangraph.graph.robust) against GTSAM's own GncLMOptimizer, and the
batch smoother's robust solve on fixes and a start prior that are wrong."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from tangraph.graph import GraphConfig, PoseGraph, smooth_survey
from tangraph.graph.robust import gnc
from tangraph.sim.faults import offset_start


def _line_graph(n: int, rate: float, rng: np.random.Generator):
    """A straight chain with a pose prior, odometry, and fixes every other pose, ``rate`` of
    them moved by tens of metres: native GTSAM factors only (GncLMOptimizer clones them)."""
    truth = np.column_stack([np.arange(n) * 10.0, np.zeros(n), np.zeros(n)])
    fixed = [gtsam.PriorFactorPose2(0, gtsam.Pose2(*truth[0]),
                                    gtsam.noiseModel.Diagonal.Sigmas([1, 1, 0.01]))]
    for i in range(1, n):
        fixed.append(gtsam.BetweenFactorPose2(i - 1, i, gtsam.Pose2(10, 0, 0),
                                              gtsam.noiseModel.Diagonal.Sigmas([0.1, 0.1, 0.001])))
    measured, bad = [], []
    for i in range(2, n, 2):
        z = truth[i, :2] + rng.normal(0, 1, 2)
        wrong = rng.random() < rate
        moved = rng.normal(0, 20, 2) + 25.0 * np.sign(rng.normal(size=2)) if wrong else 0.0
        measured.append((i, z + moved))
        bad.append(wrong)
    initial = gtsam.Values()
    for i in range(n):
        initial.insert(i, gtsam.Pose2(*(truth[i] + [rng.normal(0, 3), rng.normal(0, 3), 0.0])))
    return fixed, measured, np.array(bad), initial


def _candidate(measured):
    def make(j, weight):
        key, z = measured[j]
        return gtsam.PoseTranslationPrior2D(key, z, gtsam.noiseModel.Gaussian.Information(weight * np.eye(2)))
    return make


def _lm(graph, values):
    return gtsam.LevenbergMarquardtOptimizer(graph, values, gtsam.LevenbergMarquardtParams()).optimize()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_gnc_gives_gtsams_weights_and_estimate(seed):
    fixed, measured, _, initial = _line_graph(60, 0.3, np.random.default_rng(seed))
    mine = gnc(fixed, _candidate(measured), len(measured), initial, _lm)
    graph = gtsam.NonlinearFactorGraph()
    for factor in fixed:
        graph.add(factor)
    for j in range(len(measured)):
        graph.add(_candidate(measured)(j, 1.0))
    params = gtsam.GncLMParams()
    params.setKnownInliers(list(range(len(fixed))))
    reference = gtsam.GncLMOptimizer(graph, initial, params)
    result = reference.optimize()
    np.testing.assert_allclose(mine.weights, np.asarray(reference.getWeights())[len(fixed):], atol=1e-6)
    for i in range(60):
        assert abs(result.atPose2(i).x() - mine.values.atPose2(i).x()) < 1e-6


def test_gnc_finds_the_moved_fixes():
    fixed, measured, bad, initial = _line_graph(80, 0.3, np.random.default_rng(7))
    result = gnc(fixed, _candidate(measured), len(measured), initial, _lm)
    assert bad.any() and np.array_equal(~result.inliers, bad)


def test_gnc_without_outliers_is_least_squares():
    fixed, measured, _, initial = _line_graph(40, 0.0, np.random.default_rng(3))
    result = gnc(fixed, _candidate(measured), len(measured), initial, _lm, probability=0.999)
    assert result.inliers.all()


def test_the_smoother_drops_a_wrong_start_prior(small_survey, rough_map):
    """The DR starts 80 m off while the model says 10 m: the fixes outvote the start prior."""
    survey = offset_start(small_survey, [60.0, -53.0])
    track = smooth_survey(survey, rough_map, GraphConfig(key_interval=20.0))
    error = np.hypot(*(track.pose[:, :2] - survey.true_pose[:, :2]).T)
    assert track.meta["start_prior"] == "outlier"
    assert np.sqrt(np.mean(error**2)) < 3.0
    plain = smooth_survey(survey, rough_map, GraphConfig().replace(key_interval=20.0, robust_solve="none"))
    assert plain.meta["start_prior"] == "kept"


def test_gnc_keeps_the_start_prior_where_nothing_else_ties_the_graph():
    graph = PoseGraph(np.array([0.02, 0.03]))
    graph.add_pose(0, 0.0, [0.0, 0.0, 0.0])
    graph.add_start(0, [0.0, 0.0, 0.0], 10.0, 0.01)
    graph.add_pose(10, 10.0, [10.0, 0.0, 0.0])
    graph.add_odometry(0, 10, [10.0, 0.0, 0.0], np.diag([0.1, 0.1, 1e-4]))
    graph.add_position_fix(10, [500.0, 0.0], np.eye(2))  # one fix cannot outvote the start
    from tangraph.graph.smoother import _gnc_inliers

    inlier, keep_start = _gnc_inliers(graph, graph.fixes, GraphConfig(), np.asarray(graph.initial),
                                      np.zeros(2))
    assert keep_start and inlier.tolist() == [False]  # the start stays; the wild fix goes


def test_robust_solve_is_validated():
    from tangraph.errors import TangraphError

    with pytest.raises(TangraphError, match="robust_solve"):
        GraphConfig().replace(robust_solve="ransac")
    with pytest.raises(TangraphError, match="gnc_probability"):
        GraphConfig().replace(gnc_probability=1.0)
