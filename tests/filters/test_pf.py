"""The bootstrap PF and the IPF against an exact Kalman filter on a linear-Gaussian sloped seabed,
with a known tide and with an unknown one (a Kalman state, the filters' Rao-Blackwellised tide),
and with a DVL speed scale in the dead reckoning (the Kalman filter carries ``c = 1 / (1 + k)``,
in which the motion is linear: ``x_k = x_{k-1} + c u_k + w``; the filters carry ``k``); and the
PF's reported spreads against the recursive posterior Cramér-Rao bound of the same model."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.filters import IPFConfig, PFConfig, run_filter
from tangraph.filters.ipf import ipf
from tangraph.filters.pf import bootstrap_pf
from tests.filters.calibrated import MAP, calibrated_survey
from tests.filters.linear_gaussian import (
    kalman,
    kalman_mixture,
    linear_gaussian_run,
    linear_model,
    sloped_seabed,
)
from tests.filters.synthetic import navigation

# Monte Carlo error of a particle estimate. A weighted mean's error is about sqrt(P / ESS), a
# weighted variance's relative error sqrt(2 / ESS), with ESS the effective sample size of the weights
# it is taken from. Over a run what a low-ESS step loses is copied forward by resampling, not
# regained, so the measured ESS used is the smallest of the run (``meta["ess"]``: the PF's before
# resampling, the IPF's after the children's re-weighting). The errors of successive resamplings
# add up, so the actual errors are larger than those by a factor KAPPA, measured in a one-off study
# (not run here) of 30 runs per filter and tide case (seeds 0-29, filters seeded 100 + seed, known
# and unknown tide): the rms error in units of sqrt(P / ESS_min) was at most 1.6 (mean) and 1.8
# (variance) for the PF, 2.7 and 2.5 for the IPF, the largest 5.0 (PF) and 5.2 (IPF); KAPPA rounds
# the larger rms up. The tolerance is 4 KAPPA of those units (4 "sigmas"): 1.6 (PF) and 2.3 (IPF)
# times the largest error of the study.
KAPPA = {"pf": 2.0, "ipf": 3.0}
# With the speed scale a constant state, every resampling moves the k cloud's mean at random and
# nothing but the shrinkage kernel renews it (a static parameter's path degeneracy), so the errors
# in these units are larger: in a one-off study (not run here) of 10 surveys (seeds 10-19, filters
# seeded 100 + seed, kernel bandwidth 0.3) against the exact posterior, the rms errors of the
# position mean, its variance and the mean of k were 5.1, 3.8 and 2.1 units (PF; the largest
# 15.2) and 6.2, 5.8 and 5.8 (IPF; the largest 17.6); five filter seeds on one survey scattered
# as widely about zero (no bias). KAPPA_SCALE rounds the largest rms up; in absolute terms the
# tolerance on the mean is about 0.3 posterior sigma at N = 20000.
KAPPA_SCALE = {"pf": 6.0, "ipf": 7.0}


def run(method, survey, model, n, seed):
    rng = np.random.default_rng(100 + seed)  # independent of the simulation's default_rng(seed)
    if method == "pf":
        return bootstrap_pf(survey, sloped_seabed(), PFConfig(n_particles=n), model=model, rng=rng)
    # the auxiliary resampling at every ping
    return ipf(survey, sloped_seabed(), IPFConfig(n_particles=n, ess_threshold=1.0), model=model, rng=rng)


@pytest.mark.parametrize(
    ("seed", "method", "tide_sd"),
    [(0, "pf", 0.0), (1, "pf", 0.0), (2, "pf", 3.0), (3, "ipf", 0.0), (4, "ipf", 3.0)],
)
def test_filter_matches_the_kalman_filter(seed, method, tide_sd):
    q, sigma, p0, n = 2.0, 1.0, 30.0, 20000
    survey = linear_gaussian_run(seed, q=q, sigma=sigma, p0=p0, tide_sd=tide_sd)
    x_kf, p_kf, _ = kalman(survey, q=q, sigma=sigma, p0=p0, tide_sd=tide_sd)
    track = run(method, survey, linear_model(q=q, sigma=sigma, p0=p0, tide_sd=tide_sd), n, seed)
    x_pf, p_pf = track.pose[-1, :2], track.covariance[-1, :2, :2]
    ess = min(track.meta["ess"])
    assert 0 < ess <= n
    tolerance = 4 * KAPPA[method] * np.sqrt(np.diag(p_kf) / ess)
    assert np.all(np.abs(x_pf - x_kf) < tolerance), (x_pf, x_kf, tolerance)
    rtol = 4 * KAPPA[method] * np.sqrt(2 / ess)
    np.testing.assert_allclose(np.diag(p_pf), np.diag(p_kf), rtol=rtol)


@pytest.mark.parametrize(("seed", "method"), [(5, "pf"), (6, "pf"), (7, "ipf")])
def test_filter_with_a_speed_scale_matches_the_exact_posterior(seed, method):
    """A DVL reading 4 % fast (the prior std of k is 3 %): the filters' position and k against
    the exact posterior, a mixture of Kalman filters over quadrature nodes of k."""
    q, sigma, p0, n, scale_sd = 0.5, 1.0, 30.0, 20000, 0.03
    survey = linear_gaussian_run(seed, k=60, q=q, sigma=sigma, p0=p0, scale=0.04)
    x_kf, p_kf, k_kf, k_sd = kalman_mixture(survey, q=q, sigma=sigma, p0=p0, scale_sd=scale_sd)
    track = run(method, survey, linear_model(q=q, sigma=sigma, p0=p0, scale_sd=scale_sd), n, seed)
    x_pf, p_pf = track.pose[-1, :2], track.covariance[-1, :2, :2]
    ess = min(track.meta["ess"])
    kappa = KAPPA_SCALE[method]
    tolerance = 4 * kappa * np.sqrt(np.diag(p_kf) / ess)
    assert np.all(np.abs(x_pf - x_kf) < tolerance), (x_pf, x_kf, tolerance)
    rtol = 4 * kappa * np.sqrt(2 / ess)
    np.testing.assert_allclose(np.diag(p_pf), np.diag(p_kf), rtol=rtol)
    calibration = track.meta["calibration"]
    assert abs(calibration["speed_scale"] - k_kf) < 4 * kappa * k_sd / np.sqrt(ess)
    np.testing.assert_allclose(calibration["speed_scale_std"], k_sd, rtol=rtol)
    assert k_sd < 0.5 * scale_sd, k_sd  # the soundings did teach the filters the scale


def test_bad_configuration_is_named():
    with pytest.raises(TangraphError, match="n_particles"):
        PFConfig(n_particles=0)
    with pytest.raises(TangraphError, match="tempering_ess"):
        PFConfig(tempering_ess=0.0)


def test_the_reported_spreads_are_those_of_the_cramer_rao_bound():
    """On a linearisable run (the cloud stays in one basin) the PF's reported final position,
    speed-scale and heading-error stds are those of the recursive posterior CRB of the same model.
    Measured (one-off, surveys 1-5, 2000 particles): ratios 0.97-1.07 and 0.97-1.09 (position),
    1.04-1.25 (k), 0.92-1.01 (b); the bounds are 0.8 and 1.4."""
    from tangraph.eval.crb import posterior_crb

    survey = calibrated_survey(1)
    model = navigation(survey)
    config = PFConfig(n_particles=2000)
    track = run_filter("pf", survey, MAP, config, model=model, rng=np.random.default_rng(51))
    bound = posterior_crb(survey, MAP, model, kind="filter")
    c = track.meta["calibration"]
    cal = np.asarray(bound.calibration_cov)
    cal = cal[-1] if cal.ndim == 3 else cal
    ratios = np.concatenate([
        np.sqrt(np.diag(track.covariance[-1, :2, :2]) / np.diag(bound.position_cov[-1])),
        [c["speed_scale_std"] / np.sqrt(cal[0, 0]), c["heading_error_std"] / np.sqrt(cal[1, 1])],
    ])  # fmt: skip
    assert np.all((0.8 < ratios) & (ratios < 1.4)), ratios
