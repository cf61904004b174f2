"""Terrain factors per ping (tangraph.graph.terrain_factors): Jacobians, the information they
carry, and the gate that leaves out misplaced pings."""

import dataclasses

import gtsam
import numpy as np
import pytest

from tangraph.graph.terrain_factors import (
    _evaluate,
    chain_information,
    linear_factors,
    ping_terrain,
    sounding_jacobians,
    terrain_cost,
)
from tangraph.maps import BathymetryMap
from tangraph.sensors import NavigationModel
from tangraph.survey import Survey
from tests.graph.terrain_cases import AXIS, lawnmower, smooth_map


def line_survey(n_pings=9, beams=(-12.0, -4.0, 0.0, 5.0, 13.0)) -> Survey:
    t = np.arange(float(n_pings))
    pose = np.column_stack([150.0 + 2.0 * t, 160.0 + 1.0 * t, np.full(n_pings, 0.4) + 0.01 * t])
    b = len(beams)
    return Survey(time=t, dr_pose=pose, vehicle_depth=np.zeros(n_pings),
                  beam_forward=np.tile([1.0, -2.0, 0.0, 3.0, 0.5][:b], (n_pings, 1)),
                  beam_starboard=np.tile(beams, (n_pings, 1)), beam_depth=np.full((n_pings, b), 50.0),
                  true_pose=pose)


MODEL = NavigationModel(sounding_std=0.2, tide_std=1.0, speed_noise=0.05, heading_noise=0.01)


def terrain_of(survey, bathymetry, keys, calibrated=True, model=MODEL):
    origin = survey.dr_pose[0, :2]
    return ping_terrain(survey, bathymetry, model, keys, model.dead_reckoning, origin, calibrated)


@pytest.mark.parametrize("calibrated", [True, False])
def test_jacobians_match_numerical_derivatives(calibrated):
    bathymetry = smooth_map(slope=(0.02, -0.01))
    survey = line_survey()
    keys = np.array([0, 4])
    terrain = terrain_of(survey, bathymetry, keys, calibrated)
    key_pose = survey.dr_pose[keys] + np.array([[1.3, -0.7, 0.02], [-0.4, 0.9, -0.03]])
    calibration, tide = np.array([0.02, 0.03]), 0.3
    residual, jac, _ = sounding_jacobians(terrain, bathymetry, key_pose, calibration, tide)
    assert np.all(np.isfinite(residual)) and jac.shape == (*residual.shape, 6 if calibrated else 4)
    eps = 1e-5
    for key in range(2):
        for axis in range(3):
            plus, minus = key_pose.copy(), key_pose.copy()
            xi = np.zeros(3)
            xi[axis] = eps
            up, down = gtsam.Pose2(*key_pose[key]).retract(xi), gtsam.Pose2(*key_pose[key]).retract(-xi)
            plus[key] = [up.x(), up.y(), up.theta()]
            minus[key] = [down.x(), down.y(), down.theta()]
            numeric = (sounding_jacobians(terrain, bathymetry, plus, calibration, tide)[0]
                       - sounding_jacobians(terrain, bathymetry, minus, calibration, tide)[0]) / (2 * eps)
            rows = terrain.key_index == key
            np.testing.assert_allclose(jac[rows, :, axis], numeric[rows], atol=2e-6)
            np.testing.assert_allclose(numeric[~rows], 0.0, atol=1e-9)
    column = 3
    if calibrated:
        for axis in range(2):
            step = np.zeros(2)
            step[axis] = eps
            up = sounding_jacobians(terrain, bathymetry, key_pose, calibration + step, tide)[0]
            down = sounding_jacobians(terrain, bathymetry, key_pose, calibration - step, tide)[0]
            numeric = (up - down) / (2 * eps)
            np.testing.assert_allclose(jac[..., column + axis], numeric, atol=2e-6)
        column += 2
    numeric = (sounding_jacobians(terrain, bathymetry, key_pose, calibration, tide + eps)[0]
               - sounding_jacobians(terrain, bathymetry, key_pose, calibration, tide - eps)[0]) / (2 * eps)
    np.testing.assert_allclose(jac[..., column], numeric, atol=1e-9)


@pytest.mark.parametrize("q", [3, 4])
def test_the_chain_information_is_that_of_the_dense_covariance(q):
    """Pings hung in a row from a key, their soundings sharing the DR noise of each ping's
    increment (a walk; ``q = 4``: with the tide's drift since the key as a fourth noise): the
    backward information filter gives ``A^T C^-1 A`` and ``A^T C^-1 r`` of the soundings' dense
    covariance ``C = W^-1 + N cov(u) N^T``, with some soundings unused, whether the first ping
    is the key's own (no noise) or one after it."""
    rng = np.random.default_rng(3)
    k, b, p = 6, 5, 6
    a = rng.normal(size=(k, b, p))
    a_noise = rng.normal(size=(k, b, q))
    residual = rng.normal(size=(k, b))
    weight = rng.uniform(0.5, 4.0, size=(k, b))
    weight[2, [1, 3]] = 0.0
    for own in (True, False):
        steps = np.stack([(lambda m: m @ m.T)(rng.normal(scale=0.3, size=(q, q))) for _ in range(k)])
        if own:
            steps[0] = 0.0
        cumulative = np.cumsum(steps, axis=0)
        info, grad = chain_information(a, a_noise, residual, weight, cumulative)
        used = weight.ravel() > 0
        big_n = np.zeros((k * b, q * k))
        for j in range(k):
            big_n[j * b:(j + 1) * b, q * j:q * j + q] = a_noise[j]
        cov_u = np.block([[cumulative[min(i, j)] for j in range(k)] for i in range(k)])
        dense = np.diag(1.0 / np.where(used, weight.ravel(), 1.0)) + big_n @ cov_u @ big_n.T
        dense = dense[np.ix_(used, used)]
        rows, r = a.reshape(-1, p)[used], residual.ravel()[used]
        np.testing.assert_allclose(info, rows.T @ np.linalg.solve(dense, rows), rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(grad, rows.T @ np.linalg.solve(dense, r), rtol=1e-9, atol=1e-9)
    # no DR noise: the soundings' own normal equations
    info, grad = chain_information(a, a_noise, residual, weight, np.zeros((k, q, q)))
    rows, w = a.reshape(-1, p), weight.ravel()
    np.testing.assert_allclose(info, rows.T @ (w[:, None] * rows), rtol=1e-12)
    np.testing.assert_allclose(grad, rows.T @ (w * residual.ravel()), rtol=1e-12)


def test_the_residuals_derivatives_in_the_dr_noise():
    """The derivatives of the residuals in each ping's increment from its key (the DR noise the
    chain integrates out) against numerical ones."""
    bathymetry = smooth_map(slope=(0.02, -0.01))
    survey = line_survey()
    terrain = terrain_of(survey, bathymetry, np.array([0, 4]))
    key_pose = survey.dr_pose[[0, 4]] + np.array([[1.3, -0.7, 0.02], [-0.4, 0.9, -0.03]])
    calibration, tide = np.array([0.02, 0.03]), 0.3
    derivative = _evaluate(terrain, bathymetry, key_pose, calibration, tide, noise=True)[-1]
    eps = 1e-5
    for axis in range(3):
        step = np.zeros(3)
        step[axis] = eps
        moved = [dataclasses.replace(terrain, increment=terrain.increment + sign * step) for sign in (1, -1)]
        up, down = (sounding_jacobians(m, bathymetry, key_pose, calibration, tide)[0] for m in moved)
        np.testing.assert_allclose(derivative[..., axis], (up - down) / (2 * eps), atol=2e-6)


def test_linear_factors_carry_the_soundings_normal_equations():
    bathymetry = smooth_map(slope=(0.02, -0.01))
    survey = line_survey()
    keys = np.array([0, 4])
    terrain = terrain_of(survey, bathymetry, keys)
    key_pose = survey.dr_pose[keys] + np.array([[1.3, -0.7, 0.02], [-0.4, 0.9, -0.03]])
    calibration, tide = np.array([0.02, 0.03]), 0.3
    used = np.isfinite(survey.beam_depth)
    factors = linear_factors(terrain, bathymetry, key_pose, calibration, tide, used)
    assert len(factors) == 2
    residual, jac, dr_var = sounding_jacobians(terrain, bathymetry, key_pose, calibration, tide)
    w = 1.0 / (terrain.variance + dr_var)
    for n_key, factor in enumerate(factors):
        rows = terrain.key_index == n_key
        j, r, wk = jac[rows].reshape(-1, 6), residual[rows].ravel(), w[rows].ravel()
        info = j.T @ (wk[:, None] * j)
        a, b = factor.jacobian()
        np.testing.assert_allclose(a.T @ a, info, rtol=1e-8, atol=1e-8 * np.abs(info).max())
        np.testing.assert_allclose(a.T @ b, -j.T @ (wk * r), rtol=1e-6, atol=1e-8)
    assert terrain_cost(terrain, bathymetry, key_pose, calibration, tide, used) == \
        pytest.approx(0.5 * np.sum(w * residual**2))


def test_a_flat_map_informs_the_tide_only():
    flat = BathymetryMap(AXIS, AXIS, np.full((AXIS.size, AXIS.size), 50.0))
    survey = line_survey()
    terrain = terrain_of(survey, flat, np.array([0, 4]))
    used = np.isfinite(survey.beam_depth)
    factors = linear_factors(terrain, flat, survey.dr_pose[[0, 4]], np.zeros(2), 0.0, used)
    for factor in factors:
        a, _ = factor.jacobian()
        np.testing.assert_allclose(a[:, :5], 0.0, atol=1e-12)  # pose and calibration: nothing
        assert np.linalg.norm(a[:, 5]) > 0  # the tide: the soundings' level


def test_the_gate_leaves_out_misplaced_pings_not_an_uncertain_track():
    # pings 20-29 measured 30 m further east than their footprints (a position fault): the
    # ping test leaves them out at the true track; the same soundings with the whole track
    # 6 m off are kept when the track's prior says it may be that far off, and not otherwise
    from tangraph.graph.terrain_factors import gate

    bathymetry = smooth_map(wavy=1.0)
    _, survey = lawnmower(start_error=(0.0, 0.0))
    north, east = survey.footprints(survey.true_pose)
    depth = bathymetry.depth_at(north, east)
    depth[20:30] = bathymetry.depth_at(north[20:30], east[20:30] + 30.0)
    survey = survey.replace(beam_depth=depth + 0.05 * np.random.default_rng(3).standard_normal(depth.shape))
    model = NavigationModel(sounding_std=0.1, tide_std=0.0)
    keys = np.arange(survey.n_pings)
    terrain = terrain_of(survey, bathymetry, keys, calibrated=False, model=model)
    tight = np.tile(np.eye(2), (survey.n_pings, 1, 1))
    used = gate(terrain, bathymetry, survey.true_pose, np.zeros(2), 0.0, 3.29, tight)
    assert not used[20:30].any()
    assert used[np.r_[0:20, 30:survey.n_pings]].mean() > 0.99
    off = survey.true_pose + np.array([6.0, 0.0, 0.0])
    clean = survey.replace(beam_depth=bathymetry.depth_at(north, east))
    terrain = terrain_of(clean, bathymetry, keys, calibrated=False, model=model)
    assert gate(terrain, bathymetry, off, np.zeros(2), 0.0, 3.29, 100.0 * tight).mean() > 0.95
    assert gate(terrain, bathymetry, off, np.zeros(2), 0.0, 3.29, 0.01 * tight).mean() < 0.5
