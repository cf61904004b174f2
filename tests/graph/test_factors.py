"""Factors and frames (tangraph.graph.factors): Jacobians against numerical derivatives, propagation
against its own derivatives and Monte Carlo, a bad fix covariance refused naming the fix."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.graph import (
    between_noise,
    check_fix_covariance,
    compose,
    propagate,
    tangent_to_world,
    world_to_tangent,
)
from tangraph.graph.factors import position_fix_factor
from tangraph.sensors import odometry


def numerical_jacobian(factor, pose: gtsam.Pose2, key: int = 0, h: float = 1e-6) -> np.ndarray:
    """d unwhitened error / d local perturbation of the pose (central differences)."""
    columns = []
    for axis in range(3):
        delta = np.zeros(3)
        delta[axis] = h
        errors = []
        for sign in (1.0, -1.0):
            values = gtsam.Values()
            values.insert(key, pose.retract(sign * delta))
            errors.append(factor.unwhitenedError(values))
        columns.append((errors[0] - errors[1]) / (2 * h))
    return np.column_stack(columns)


def analytic_jacobian(factor, pose: gtsam.Pose2, key: int = 0) -> np.ndarray:
    values = gtsam.Values()
    values.insert(key, pose)
    a, _ = factor.linearize(values).jacobian()
    return a


def test_translation_prior_jacobian_matches_numerical_and_is_world_frame():
    pose = gtsam.Pose2(120.0, -40.0, 0.7)
    factor = position_fix_factor(0, [121.0, -38.0], np.eye(2), "none", 1.0)
    values = gtsam.Values()
    values.insert(0, pose)
    np.testing.assert_allclose(factor.unwhitenedError(values), [-1.0, -2.0], atol=1e-12)
    numeric = numerical_jacobian(factor, pose)
    np.testing.assert_allclose(analytic_jacobian(factor, pose), numeric, atol=1e-6)
    c, s = np.cos(0.7), np.sin(0.7)
    np.testing.assert_allclose(numeric, [[c, -s, 0.0], [s, c, 0.0]], atol=1e-6)  # [R(psi), 0]


def test_robust_translation_prior_whitened_jacobian_is_scaled_copy():
    pose = gtsam.Pose2(0.0, 0.0, 0.3)
    cov = np.array([[4.0, 1.0], [1.0, 2.0]])
    factor = position_fix_factor(0, [30.0, 0.0], cov, "huber", 2.45)  # far: downweighted
    plain = position_fix_factor(0, [30.0, 0.0], cov, "none", 2.45)
    robust, gaussian = analytic_jacobian(factor, pose), analytic_jacobian(plain, pose)
    finite = np.abs(gaussian) > 1e-9
    ratio = np.divide(robust, gaussian, out=np.zeros_like(robust), where=finite)
    assert np.allclose(ratio[finite], ratio[finite][0]) and 0 < ratio[finite][0] < 1


def test_between_factor_jacobians_and_noise_frame():
    z = np.array([10.0, 2.0, 0.4])
    noise = gtsam.noiseModel.Unit.Create(3)
    factor = gtsam.BetweenFactorPose2(0, 1, gtsam.Pose2(*z), noise)
    x0 = gtsam.Pose2(5.0, 3.0, 0.2)
    x1 = gtsam.Pose2(*compose([5.0, 3.0, 0.2], z + np.array([0.1, -0.2, 0.01])))
    values = gtsam.Values()
    values.insert(0, x0)
    values.insert(1, x1)
    a, _ = factor.linearize(values).jacobian()
    h = 1e-6
    for col, key in enumerate((0, 1)):
        for axis in range(3):
            delta = np.zeros(3)
            delta[axis] = h
            errs = []
            for sign in (1.0, -1.0):
                v = gtsam.Values(values)
                v.update(key, values.atPose2(key).retract(sign * delta))
                errs.append(factor.unwhitenedError(v))
            np.testing.assert_allclose(a[:, 3 * col + axis], (errs[0] - errs[1]) / (2 * h), atol=1e-5)
    # An increment error delta (frame of pose i) appears as blkdiag(R(-dpsi), 1) delta in the factor.
    delta = np.array([1e-4, -2e-4, 3e-5])
    v = gtsam.Values()
    v.insert(0, gtsam.Pose2())
    v.insert(1, gtsam.Pose2(*(z + delta)))
    c, s = np.cos(z[2]), np.sin(z[2])
    expected = np.array([c * delta[0] + s * delta[1], -s * delta[0] + c * delta[1], delta[2]])
    np.testing.assert_allclose(factor.unwhitenedError(v), expected, rtol=1e-3, atol=1e-9)
    cov = np.diag([1.0, 4.0, 0.01])
    rot = np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]])
    np.testing.assert_allclose(between_noise(z, cov, 1e-9, 1e-9), rot @ cov @ rot.T, atol=1e-12)


def test_frames_round_trip_and_propagation_matches_numerical():
    cov = np.array([[2.0, 0.3, 0.01], [0.3, 1.0, -0.02], [0.01, -0.02, 0.004]])
    np.testing.assert_allclose(world_to_tangent(0.9, tangent_to_world(0.9, cov)), cov, atol=1e-12)
    pose, inc = np.array([1.0, 2.0, 0.5]), np.array([30.0, -4.0, 0.1])
    jac = np.zeros((3, 3))
    for axis in range(3):
        d = np.zeros(3)
        d[axis] = 1e-6
        jac[:, axis] = (compose(pose + d, inc) - compose(pose - d, inc)) / 2e-6
    np.testing.assert_allclose(propagate(pose, cov, inc, np.zeros((3, 3))), jac @ cov @ jac.T, rtol=1e-6)
    np.testing.assert_allclose(compose(pose, odometry(np.array([pose, compose(pose, inc)]), 0, 1)),
                               compose(pose, inc), atol=1e-12)


@pytest.mark.parametrize("cov", [np.zeros((2, 2)), -np.eye(2), np.array([[1.0, np.nan], [np.nan, 1.0]]),
                                 np.array([[1.0, 2.0], [2.0, 1.0]]), np.array([[1.0, 0.5], [0.0, 1.0]]),
                                 np.full((2, 2), np.inf)])
def test_bad_fix_covariance_is_refused_naming_the_fix(cov):
    with pytest.raises(TangraphError, match="fix at ping 17"):
        check_fix_covariance(cov, "fix at ping 17")


def test_inverse_increment_covariance_matches_monte_carlo():
    """The covariance of d^-1 against 200 000 sampled increments: within 3 % (Monte Carlo error of
    a variance over n samples is sqrt(2 / n) = 0.3 %)."""
    from tangraph.graph.factors import compose, inverse_increment_covariance

    rng = np.random.default_rng(4)
    d = np.array([100.0, -20.0, 0.4])
    cov = np.diag([0.5, 0.2, 0.01**2])
    cov[0, 2] = cov[2, 0] = 0.0005
    samples = rng.multivariate_normal(d, cov, size=200_000)
    c, s = np.cos(samples[:, 2]), np.sin(samples[:, 2])
    north, east = samples[:, 0], samples[:, 1]
    inverse = np.column_stack([-(c * north + s * east), s * north - c * east, -samples[:, 2]])
    np.testing.assert_allclose(compose(samples[:3], inverse[:3]), 0.0, atol=1e-9)  # they are inverses
    c0, s0 = np.cos(d[2]), np.sin(d[2])
    mean_inverse = np.array([-(c0 * d[0] + s0 * d[1]), s0 * d[0] - c0 * d[1], -d[2]])
    got = inverse_increment_covariance(mean_inverse, cov)
    np.testing.assert_allclose(got, np.cov(inverse.T), rtol=0.03, atol=1e-6)
    # a pure rotation of the position block (the old code) misses the heading's lever arm
    assert got[1, 1] > 1.5 * np.diag(cov)[:2].max()
