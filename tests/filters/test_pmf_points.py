"""The point-mass filter's calibration per point (``PMFConfig(calibration="points")``,
:mod:`tangraph.filters.pmf_points`): its lattice kernel's moments, a convolution's conservation,
the tails' calibration. The filter itself is held to the bank's exact answers in
``tests/filters/test_pmf.py`` (each case run with both)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tangraph.filters import PMFConfig
from tangraph.filters import pmf_points as pp
from tangraph.filters.pmf import start_run
from tangraph.filters.pmf_grid import _Grid
from tests.filters.linear_gaussian import (
    linear_gaussian_run,
    linear_model,
    sloped_seabed,
)

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


def _with_heading_spread(state, s_bb: float = 4e-3):
    """``state`` with a heading error of variance ``s_bb`` correlated with the speed scale and the
    position's deviation, and the points' heading means spread about zero."""
    joint = state.joint.copy()
    joint[3, 3] = s_bb
    joint[2, 3] = joint[3, 2] = 0.5 * np.sqrt(joint[2, 2] * s_bb)
    joint[0, 3] = joint[3, 0] = 0.02
    joint[:2, :2] += 0.1 * np.eye(2)
    state.joint = joint
    cal = state.point_cal.copy()
    cal[:, 1] = np.linspace(-0.05, 0.05, cal.shape[0])
    state.point_cal = cal
    return state


def test_a_swaths_heading_evidence_is_the_kalman_update():
    """A ping whose log-likelihood is exactly Gaussian in the heading error, ``N(b*; b, r)``,
    conditions every point's Gaussian as a Kalman filter would: its mean by ``S e (b* - b_i) /
    (S_bb + r)`` (position deviation and speed scale by their correlation), the shared
    covariance to ``S - S e e^T S / (S_bb + r)``, and the points' likelihoods become the
    marginal ``N(b*; b_i, S_bb + r)`` up to a constant (a quadratic fit at ``b_i -+ s`` is exact
    here)."""
    state = _with_heading_spread(_state_after(5))
    joint, cal, shift = state.joint.copy(), state.point_cal.copy(), state.shift.copy()
    size = cal.shape[0]
    live = np.arange(size)
    target, r = 0.01, 2e-3
    offsets = np.array([[0.0, -20.0], [0.0, 20.0]])

    def evaluate(sub, heading, move):
        assert move.shape == (len(sub), 2)
        return -0.5 * (heading - target) ** 2 / r + 3.0  # the same for every point but its heading

    base = evaluate(live, cal[:, 1], np.zeros((size, 2)))
    out = pp.swath_heading(state, live, np.zeros(size), base, evaluate, offsets)
    s = joint[:, 3]
    gain = (target - cal[:, 1]) / (joint[3, 3] + r)
    np.testing.assert_allclose(state.point_cal, cal + gain[:, None] * s[None, 2:], atol=1e-12)
    np.testing.assert_allclose(state.shift, shift + gain[:, None] * s[None, :2], atol=1e-12)
    np.testing.assert_allclose(state.joint, joint - np.outer(s, s) / (joint[3, 3] + r), atol=1e-12)
    marginal = -0.5 * (target - cal[:, 1]) ** 2 / (joint[3, 3] + r)
    np.testing.assert_allclose(out - out[0], marginal - marginal[0], atol=1e-9)


def test_a_single_beam_says_nothing_of_the_heading_error():
    """Soundings right under the vehicle are not turned by its heading error: the points'
    likelihoods and calibrations are left as they are, and nothing is evaluated again."""
    state = _with_heading_spread(_state_after(5))
    cal, joint = state.point_cal.copy(), state.joint.copy()
    live = np.arange(cal.shape[0])
    base = np.linspace(-3.0, 0.0, cal.shape[0])

    def evaluate(sub, heading, move):
        raise AssertionError("a single beam is not weighed again")

    out = pp.swath_heading(state, live, np.zeros(cal.shape[0]), base, evaluate, np.zeros((1, 2)))
    np.testing.assert_array_equal(out, base)
    np.testing.assert_array_equal(state.point_cal, cal)
    np.testing.assert_array_equal(state.joint, joint)


@pytest.mark.parametrize("wide", [30.0, 400.0])
def test_a_spread_wider_than_the_lattice_is_not_cut_off(wide):
    """A shared spread of ``wide`` steps^2 (beyond the lattice's half-width at 400) re-gridded:
    the new lattice holds the density with all of it (the mean kept, the covariance the
    density's plus the spread), where convolving it in on the old lattice first would cut it
    off at the edges."""
    state = _state_after(25)
    joint = state.joint.copy()
    joint[:2, :2] = wide * state.axes @ state.axes.T
    state.joint = joint
    mean, cov = state.moments()
    out = pp.regrid(state, _Grid(POINTS, POINTS.min_spacing))
    new_mean, new_cov = out.moments()
    np.testing.assert_allclose(new_mean, mean, atol=0.02 * np.sqrt(cov[0, 0]))
    np.testing.assert_allclose(new_cov, cov, rtol=0.03, atol=0.03 * np.sqrt(cov[0, 0] * cov[1, 1]))
    assert not np.any(out.joint[:2, :2])  # convolved in


def test_a_sharp_heading_evidence_is_found_where_it_peaks():
    """A first ping whose evidence on the heading error is far sharper than the prior and not a
    quadratic across it (here ``-|b - b*| / w``, peaked 3 prior std from the points' means): the
    fit at one std either side would jump by the step's limit; weighed again where they went,
    the points end within a tenth of a prior std of the peak, with a std below a tenth of the
    prior's."""
    state = _with_heading_spread(_state_after(5), s_bb=1e-4)
    cal = state.point_cal.copy()
    cal[:, 1] = 0.0
    state.point_cal = cal
    size = cal.shape[0]
    live = np.arange(size)
    target, width = 0.03, 2e-4

    def evaluate(sub, heading, move):
        return -np.abs(heading - target) / width - 0.5 * ((heading - target) / width) ** 2

    pp.swath_heading(state, live, np.zeros(size), evaluate(live, cal[:, 1], None),
                     evaluate, np.array([[0.0, 30.0]]))
    np.testing.assert_allclose(state.point_cal[:, 1], target, atol=0.1 * 1e-2)
    assert np.sqrt(state.joint[3, 3]) < 0.1 * 1e-2
