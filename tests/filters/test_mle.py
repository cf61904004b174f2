"""The MLE filter (tangraph.filters.mle): plain, it jumps to each fix and dead-reckons between; it fuses
a fix as a Kalman update of position and calibration, and relocalises on two agreeing fixes."""

from __future__ import annotations

import numpy as np

from tangraph.filters import MLEConfig, run_filter
from tangraph.filters.mle import _update
from tangraph.fix_records import FixStatus
from tests.filters.synthetic import gaussian_fix as _fix
from tests.filters.synthetic import multibeam_survey, navigation, rough_map

MAP = rough_map(0)
SURVEY = multibeam_survey(MAP, seed=1, pings=30)
MODEL = navigation(SURVEY, initial_position_std=20.0, sounding_std=0.5)


def test_plain_mle_jumps_to_each_fix_with_its_covariance_and_dead_reckons_between():
    plain = MLEConfig(require_accepted=False, confirm_probability=None, fuse=False)
    track = run_filter("mle", SURVEY, MAP, plain, model=MODEL, rng=np.random.default_rng(0))
    fixes = track.fixes
    assert [f.index for f in fixes] == [4, 9, 14, 19, 24, 29] and all(f.accepted for f in fixes)
    for f in fixes:
        k = f.index
        np.testing.assert_allclose(track.pose[k, :2], f.position)
        np.testing.assert_allclose(track.covariance[k, :2, :2], f.covariance)
        if k + 1 < SURVEY.n_pings:  # then dead reckoning, with a growing covariance
            step = SURVEY.dr_pose[k + 1, :2] - SURVEY.dr_pose[k, :2]
            np.testing.assert_allclose(track.pose[k + 1, :2] - track.pose[k, :2], step)
            assert np.all(np.diag(track.covariance[k + 1, :2, :2]) > np.diag(track.covariance[k, :2, :2]))
    np.testing.assert_allclose(track.pose[:4, :2], SURVEY.dr_pose[:4, :2])  # before the first fix
    assert np.isnan(track.meta["ess"]).all() and track.meta["n_divergences"] == 0


def test_mle_fuses_a_fix_as_a_kalman_update_of_position_and_calibration():
    """The update equals the information-form posterior of ``(north, east, k, b)`` given the fix
    as a measurement of the position."""
    rng = np.random.default_rng(5)
    a = rng.standard_normal((4, 4))
    p = a @ a.T + np.diag([4.0, 4.0, 1e-3, 1e-3])
    x = np.array([10.0, -5.0, 0.01, 0.02])
    fix = _fix([12.0, -3.0], 1.5)
    got_x, got_p = _update(x, p, fix, fuse=True)
    h = np.zeros((2, 4))
    h[:, :2] = np.eye(2)
    info = np.linalg.inv(p) + h.T @ np.linalg.inv(fix.covariance) @ h
    want_p = np.linalg.inv(info)
    want_x = want_p @ (np.linalg.solve(p, x) + h.T @ np.linalg.solve(fix.covariance, fix.position))
    np.testing.assert_allclose(got_p, want_p, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(got_x, want_x, rtol=1e-9)
    jump_x, jump_p = _update(x, p, fix, fuse=False)
    np.testing.assert_allclose(jump_x, [12.0, -3.0, 0.01, 0.02])
    np.testing.assert_allclose(jump_p[:2, :2], fix.covariance)
    assert np.all(jump_p[:2, 2:] == 0) and np.all(jump_p[2:, 2:] == p[2:, 2:])


def test_mle_relocalises_on_two_agreeing_fixes_and_refuses_one_alone():
    """The DR starts 60 m off with a stated 20 m: the first fix is surprising and held, the next
    agrees with it and confirms it, and the estimate jumps there."""
    off = SURVEY.replace(dr_pose=SURVEY.dr_pose + np.array([60.0, 0.0, 0.0]))
    config = MLEConfig(min_half_width=150.0)
    track = run_filter("mle", off, MAP, config, model=MODEL, rng=np.random.default_rng(0))
    held, confirming = track.fixes[:2]
    assert (held.index, held.status, held.detail) == (4, FixStatus.CONFIRMED, "by the fix at ping 9")
    assert confirming.accepted and confirming.detail == "confirms the fix at ping 4"
    np.testing.assert_allclose(track.pose[4, :2], off.dr_pose[4, :2])  # not taken alone
    assert np.hypot(*(track.pose[-1, :2] - SURVEY.true_pose[-1, :2])) < 5.0
