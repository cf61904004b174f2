"""Graduated non-convexity (tangraph.graph.robust) against GTSAM's own GncLMOptimizer: its weights and
estimate, the moved fixes found, least squares when there is no outlier."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from tangraph.graph.robust import gnc


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
