"""The point-mass filter with its calibration per point (``PMFConfig(calibration="points")``,
:mod:`tangraph.filters.pmf_points`): its lattice kernel's moments, a convolution's conservation,
and the filter against the exact answers the bank is held to (Kalman filter, the exact mixture
posterior of an unknown speed scale, the DR's spread on a flat seabed)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tangraph.filters import PMFConfig
from tangraph.filters import pmf_points as pp
from tangraph.filters.pmf import point_mass_filter, start_run
from tangraph.sensors import DeadReckoningModel
from tangraph.sim.faults import outlier_blocks
from tests.filters.linear_gaussian import (
    kalman,
    kalman_mixture,
    linear_gaussian_run,
    linear_model,
    sloped_seabed,
)
from tests.filters.synthetic import multibeam_survey, navigation, rough_map

POINTS = PMFConfig(calibration="points")


def _moments(table: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    r = (table.shape[0] - 1) // 2
    i, j = np.meshgrid(np.arange(-r, r + 1), np.arange(-r, r + 1), indexing="ij")
    d = np.stack([i.ravel(), j.ravel()], axis=1).astype(float)
    w = table.ravel()
    mean = w @ d
    return mean, (d * w[:, None]).T @ d - np.outer(mean, mean)


@pytest.mark.parametrize("cov", [[[1e-4, 0.0], [0.0, 3e-4]], [[0.3, 0.1], [0.1, 0.2]],
                                 [[25.0, -3.0], [-3.0, 4.0]], [[0.2, -0.19], [-0.19, 0.2]],
                                 [[0.3, 0.2], [0.2, 0.15]]])
def test_the_lattice_kernel_has_the_covariance_it_holds(cov):
    """Mean zero and covariance :func:`held` exactly, however narrow against a step; the last
    case's correlation is beyond a 3 x 3 step's and its smaller variance is raised to it."""
    cov = np.array(cov)
    table = pp._kernel(cov)
    mean, got = _moments(table)
    assert np.all(table >= 0) and table.sum() == pytest.approx(1.0)
    np.testing.assert_allclose(mean, 0.0, atol=1e-12)
    np.testing.assert_allclose(got, pp.held(cov), atol=1e-9)
    assert np.all(pp.held(cov) - cov >= -1e-15) and np.linalg.eigvalsh(pp.held(cov) - cov).min() >= -1e-12


def _state_after(pings: int):
    """The filter's state after ``pings`` pings of the unknown-speed-scale case, before any
    convolution of its shared spread (the grid is laid again when the spread reaches it)."""
    q, sigma, p0, scale_sd = 0.5, 1.0, 30.0, 0.03
    survey = linear_gaussian_run(5, k=60, q=q, sigma=sigma, p0=p0, scale=0.04)
    model = linear_model(q=q, sigma=sigma, p0=p0, scale_sd=scale_sd)
    run, state, pings_ = start_run(survey, sloped_seabed(), model, POINTS)
    for ping in pings_[:pings]:
        state = run.step(state, ping)
    return state


def test_a_convolution_keeps_the_mass_the_mean_and_the_calibrations_spread():
    """Convolving the shared spread in moves no mass off the grid here, keeps the density's mean
    and adds the spread's covariance (to the lattice's exactness), and the calibration's mixture
    (shared covariance plus the spread of the points' means) is unchanged: what the conditioning
    takes from the shared covariance the points' means gain."""
    state = _state_after(25)
    spread = 0.6 * np.linalg.norm(state.axes, axis=0).min() ** 2  # m^2: more than half a step
    joint = state.joint.copy()
    joint[:2, :2] = spread * np.eye(2)
    joint[2, :2] = joint[:2, 2] = [0.8 * np.sqrt(spread * joint[2, 2]), 0.0]  # k with the north offset
    state.joint = joint
    mean, cov = state.moments()
    cal_mean, cal_cov = state.calibration()
    fields = pp.convolve(state, [])
    out = dataclasses.replace(state, **{k: v for k, v in fields.items() if k != "means"})
    new_mean, new_cov = out.moments()
    np.testing.assert_allclose(new_mean, mean, atol=1e-3 * np.sqrt(cov[0, 0]))
    np.testing.assert_allclose(new_cov, cov, rtol=0.02)
    new_cal_mean, new_cal_cov = out.calibration()
    np.testing.assert_allclose(new_cal_mean, cal_mean, atol=0.01 * np.sqrt(cal_cov[0, 0]))
    np.testing.assert_allclose(new_cal_cov, cal_cov, rtol=0.02, atol=1e-12)


@pytest.mark.parametrize(("seed", "tide_sd"), [(0, 0.0), (2, 3.0)])
def test_with_no_calibration_to_learn_it_matches_the_kalman_filter(seed, tide_sd):
    """As the bank's test: a tenth of a posterior std on the mean, 5 % on the variance."""
    q, sigma, p0 = 2.0, 1.0, 30.0
    survey = linear_gaussian_run(seed, q=q, sigma=sigma, p0=p0, tide_sd=tide_sd)
    x_kf, p_kf, _ = kalman(survey, q=q, sigma=sigma, p0=p0, tide_sd=tide_sd)
    track = point_mass_filter(survey, sloped_seabed(), POINTS,
                              model=linear_model(q=q, sigma=sigma, p0=p0, tide_sd=tide_sd))
    x, p = track.pose[-1, :2], track.covariance[-1, :2, :2]
    assert np.all(np.abs(x - x_kf) < 0.1 * np.sqrt(np.diag(p_kf))), (x, x_kf)
    np.testing.assert_allclose(np.diag(p), np.diag(p_kf), rtol=0.05)
    assert track.meta["n_points"] == 31**2


def test_an_unknown_speed_scale_matches_the_exact_posterior():
    """A DVL reading 4 % fast (prior std 3 %), against the exact mixture of Kalman filters. The
    per-point calibration is learnt only where the shared spread is convolved in (a few times a
    minute here) and the lattice rounds it: in seed 5 the position is 0.07 std off with 5-6 %
    more variance, ``k`` 0.37 std off with a std 8 % small."""
    q, sigma, p0, scale_sd = 0.5, 1.0, 30.0, 0.03
    survey = linear_gaussian_run(5, k=60, q=q, sigma=sigma, p0=p0, scale=0.04)
    x_kf, p_kf, k_kf, k_sd = kalman_mixture(survey, q=q, sigma=sigma, p0=p0, scale_sd=scale_sd)
    track = point_mass_filter(survey, sloped_seabed(), POINTS,
                              model=linear_model(q=q, sigma=sigma, p0=p0, scale_sd=scale_sd))
    x, p = track.pose[-1, :2], track.covariance[-1, :2, :2]
    assert np.all(np.abs(x - x_kf) < 0.2 * np.sqrt(np.diag(p_kf))), (x, x_kf)
    np.testing.assert_allclose(np.diag(p), np.diag(p_kf), rtol=0.1)
    calibration = track.meta["calibration"]
    assert abs(calibration["speed_scale"] - k_kf) < 0.5 * k_sd, (calibration, k_kf)
    np.testing.assert_allclose(calibration["speed_scale_std"], k_sd, rtol=0.12)


def test_on_a_flat_seabed_the_density_is_the_dead_reckonings():
    """No terrain information: the mixture over the unknown speed scale of the white-noise
    Gaussians around ``x_0 + S / (1 + k)`` (exact moments from 80 Gauss-Hermite nodes), within
    2 % on the covariance, and the speed scale's prior kept."""
    q, sigma, p0, scale_sd = 0.5, 1.0, 10.0, 0.03
    survey = linear_gaussian_run(3, k=40, q=q, sigma=sigma, p0=p0)
    noise = sigma * np.random.default_rng(3).standard_normal(survey.beam_depth.shape)
    survey = survey.replace(beam_depth=500.0 + noise)
    flat = sloped_seabed()
    flat = dataclasses.replace(flat, depth=np.full(flat.depth.shape, 500.0))
    model = linear_model(q=q, sigma=sigma, p0=p0, scale_sd=scale_sd)
    track = point_mass_filter(survey, flat, POINTS, model=model)
    z, w = np.polynomial.hermite_e.hermegauss(80)
    w = w / w.sum()
    run = survey.dr_pose[-1, :2] - survey.dr_pose[0, :2]
    means = survey.dr_pose[0, :2] + run / (1.0 + scale_sd * z)[:, None]
    mean = w @ means
    d = means - mean
    cov = (p0**2 + (survey.n_pings - 1) * q**2) * np.eye(2) + (d * w[:, None]).T @ d
    np.testing.assert_allclose(track.pose[-1, :2], mean, atol=0.02 * np.sqrt(cov[0, 0]))
    np.testing.assert_allclose(track.covariance[-1, :2, :2], cov, rtol=0.02, atol=0.02 * cov[0, 0])
    assert track.meta["calibration"]["speed_scale_std"] == pytest.approx(scale_sd, rel=0.02)


def test_it_finds_the_vehicle_and_its_heading_error_on_rough_terrain():
    """The bank's rough-terrain case: a DR 3 deg off and 2 % fast ends near the truth, inside
    its covariance, the heading error found."""
    bathymetry = rough_map(1)
    dr = DeadReckoningModel(heading_bias=np.radians(3.0), speed_scale=0.02, speed_noise=0.05)
    survey = multibeam_survey(bathymetry, seed=4, pings=120, dr_model=dr)
    model = navigation(survey)
    track = point_mass_filter(survey, bathymetry, POINTS, model=model)
    error = track.pose[-1, :2] - survey.true_pose[-1, :2]
    dr_error = survey.dr_pose[-1, :2] - survey.true_pose[-1, :2]
    assert np.hypot(*error) < 0.1 * np.hypot(*dr_error), (error, dr_error)
    assert error @ np.linalg.solve(track.covariance[-1, :2, :2], error) < 13.8  # chi2(2) at 0.999
    calibration = track.meta["calibration"]
    truth = survey.dr_pose[-1, 2] - survey.true_pose[-1, 2]
    assert abs(calibration["heading_error"] - truth) < 3 * calibration["heading_error_std"]
    assert calibration["heading_error_std"] < 0.5 * model.calibration_std[1]


def test_the_tails_hold_the_calibrations_mean():
    """Points of negligible mass carry the mixture's mean calibration after a convolution, not
    the conditional means extrapolated to them (which ran away over a long run)."""
    state = _state_after(40)
    fields = pp.convolve(state, [])
    mass = np.exp(fields["log_density"].ravel() - fields["log_density"].max())
    tails = mass < pp.NEGLIGIBLE
    assert tails.any()
    expected = (mass / mass.sum()) @ fields["point_cal"]
    np.testing.assert_allclose(fields["point_cal"][tails], np.broadcast_to(expected, (tails.sum(), 2)),
                               atol=1e-9)


def test_a_start_far_off_is_found_again_on_the_global_grid():
    """The bank's case: a DR 200 m off (10 m stated) is found lost, started afresh on the global
    grid (each point at the calibration's prior) and ends at the truth."""
    bathymetry = rough_map(1)
    survey = multibeam_survey(bathymetry, seed=4, pings=80)
    shifted = survey.replace(dr_pose=survey.dr_pose + np.array([150.0, -130.0, 0.0]))
    track = point_mass_filter(shifted, bathymetry, dataclasses.replace(POINTS, relocalise=True),
                              model=navigation(shifted))
    assert track.meta["relocalisation_steps"], track.meta
    assert np.hypot(*(track.pose[-1, :2] - shifted.true_pose[-1, :2])) < 3.0


def test_the_ping_gate_keeps_a_block_of_biased_depths_out():
    """The bank's case: 20 pings 3-10 m off are gated, exactly them, and the track stays where
    the clean pings put it."""
    bathymetry = rough_map(1)
    survey = multibeam_survey(bathymetry, seed=4, pings=120)
    bad = outlier_blocks(survey, "depth_bias", 20 / 120, rng=np.random.default_rng(2))
    track = point_mass_filter(bad, bathymetry, dataclasses.replace(POINTS, ping_gate=True),
                              model=navigation(survey))
    gated = track.meta["gated_steps"]
    assert len(gated) == 20 and np.ptp(gated) == 19, gated
    assert np.hypot(*(track.pose[-1, :2] - bad.true_pose[-1, :2])) < 2.0
