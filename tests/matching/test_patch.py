"""A window laid with a calibrated dead reckoning, and what its remaining uncertainty adds to a fix."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from tangraph.geometry import to_dr_frame
from tangraph.matching import calibrated_window, shape_covariance
from tangraph.sensors import DeadReckoningModel, increment_covariance, rotation_matrix


def _turning_track(n: int = 9) -> np.ndarray:
    """A curving track, poses (north, east, heading) a second apart."""
    heading = np.linspace(0.2, 1.0, n)
    step = np.column_stack([np.cos(heading), np.sin(heading)]) * 3.0
    return np.column_stack([np.cumsum(step, axis=0), heading])


def test_a_window_laid_with_the_true_calibration_has_the_true_shape():
    truth = _turning_track()
    calibration = (0.04, 0.06)
    dr = to_dr_frame(truth, calibration, [5.0, -3.0])
    poses, _ = calibrated_window(SimpleNamespace(dr_pose=dr), 8, 6, calibration)
    np.testing.assert_allclose(poses[:, :2] - poses[-1, :2], truth[3:, :2] - truth[-1, :2], atol=1e-9)
    np.testing.assert_allclose(poses[:, 2], truth[3:, 2], atol=1e-12)


def test_the_shape_jacobian_is_the_derivative_of_the_middle_pings_offset():
    survey = SimpleNamespace(dr_pose=to_dr_frame(_turning_track(), (0.03, -0.05), [0.0, 0.0]))
    calibration = np.array([0.01, 0.02])
    _, jac = calibrated_window(survey, 8, 7, calibration)

    def offset(c):
        poses, _ = calibrated_window(survey, 8, 7, c)
        return poses[3, :2] - poses[-1, :2]

    h = 1e-6
    numeric = np.column_stack([(offset(calibration + h * e) - offset(calibration - h * e)) / (2 * h)
                               for e in np.eye(2)])
    np.testing.assert_allclose(jac, numeric, rtol=1e-6, atol=1e-9)


def test_the_shape_covariance_counts_the_white_noise_and_the_calibrations_spread():
    """Zero for one ping; the white DR noise from the middle ping to the end, and the calibration's
    covariance as the laid middle ping's offset scatters over drawn calibrations (Monte Carlo,
    within 10 %: 4000 draws give a variance's relative error of about 2 %)."""
    track = _turning_track()
    survey = SimpleNamespace(dr_pose=track, time=np.arange(track.shape[0], dtype=float))
    white = DeadReckoningModel(speed_noise=0.05, heading_walk=1e-3)
    assert not np.any(shape_covariance(survey, white, 8, 8, np.eye(2), np.eye(2)))
    still = DeadReckoningModel(speed_noise=0.0, heading_walk=0.0, heading_noise=0.0)
    white_only = shape_covariance(survey, white, 2, 8, np.zeros((2, 2)), np.zeros((2, 2)))
    rot = rotation_matrix(track[5, 2])
    want = rot @ increment_covariance(white, survey.time[2:9], track[2:9], 3, 6)[:2, :2] @ rot.T
    np.testing.assert_allclose(white_only, want)
    mean, cov = np.array([0.02, 0.01]), np.array([[1e-4, 2e-5], [2e-5, 4e-4]])
    _, jac = calibrated_window(survey, 8, 7, mean)
    drawn = np.random.default_rng(3).multivariate_normal(mean, cov, 4000)
    offsets = np.array([np.subtract(*calibrated_window(survey, 8, 7, c)[0][[3, -1], :2]) for c in drawn])
    got = shape_covariance(survey, still, 2, 8, jac, cov)
    np.testing.assert_allclose(np.cov(offsets.T), got, rtol=0.1, atol=0.02 * np.abs(got).max())
