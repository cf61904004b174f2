"""The point-mass front end: the window's likelihood factor from its posterior, prior removed."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.filters.likelihood import TerrainLikelihood
from tangraph.fix_records import FixStatus
from tangraph.graph import GraphConfig
from tangraph.graph.posterior_fix import posterior_fix
from tangraph.maps.grid import BathymetryMap
from tangraph.matching import MatchingError, Patch
from tangraph.sensors import slope_moment

SLOPE_NORTH = np.array([0.10, 0.05])  # depth gradient (north, east) north of the kink
SLOPE_SOUTH = np.array([-0.08, 0.05])  # and south of it: the same east slope, so it is continuous


def _prior(mean, cov, tide: float = 0.0, tide_std: float = 0.0):
    """A (north, east, tide) prior with the tide independent of the position."""
    p3 = np.zeros((3, 3))
    p3[:2, :2] = cov
    p3[2, 2] = tide_std**2
    return np.append(np.asarray(mean, float), tide), p3


def _kinked_plane() -> BathymetryMap:
    """Two planes meeting along the east axis: every sounding sees one plane (a linear model),
    the two together see both axes."""
    north = np.arange(-400.0, 401.0, 10.0)
    east = np.arange(-400.0, 401.0, 10.0)
    n, e = np.meshgrid(north, east, indexing="ij")
    depth = 50.0 + np.where(n >= 0, SLOPE_NORTH[0], SLOPE_SOUTH[0]) * n + SLOPE_NORTH[1] * e
    return BathymetryMap(north, east, depth)


def _patch(chart: BathymetryMap, truth, rng, noise: float, tide: float = 0.0) -> Patch:
    offsets = np.concatenate([rng.uniform([100, -150], [250, 150], (40, 2)),
                              rng.uniform([-250, -150], [-100, 150], (40, 2))])
    depth = chart.depth_at(truth[0] + offsets[:, 0], truth[1] + offsets[:, 1])
    depths = depth + tide + noise * rng.standard_normal(depth.size)
    return Patch(offsets=offsets, depths=depths, ping=np.zeros(80, np.int64), beam=np.arange(80), reference=9,
                 first=0, reference_position=np.zeros(2), n_dropped=0)


def _exact_factor(patch: Patch, chart: BathymetryMap, variance: float, tide_std: float):
    """The window's exact Gaussian likelihood factor on the position (the tide marginalised from
    its prior ``N(0, tide_std^2)``): linear least squares on the kinked plane."""
    g = np.where(patch.offsets[:, :1] >= 0, SLOPE_NORTH, SLOPE_SOUTH)  # (B, 2)
    base = chart.depth_at(patch.offsets[:, 0], patch.offsets[:, 1])  # map depth with x = 0
    # z = base + g x + t + noise: the joint information of (x, t), then t marginalised
    design = np.column_stack([g, np.ones(g.shape[0])])
    info = design.T @ design / variance
    vector = design.T @ (patch.depths - base) / variance
    if tide_std > 0:
        info[2, 2] += 1.0 / tide_std**2
        schur = info[:2, :2] - np.outer(info[:2, 2], info[2, :2]) / info[2, 2]
        reduced = vector[:2] - info[:2, 2] * vector[2] / info[2, 2]
    else:
        schur, reduced = info[:2, :2], vector[:2]
    cov = np.linalg.inv(schur)
    return cov @ reduced, cov


@pytest.mark.parametrize("tide_std", [0.0, 3.0])
def test_the_prior_removed_is_the_exact_likelihood_factor_on_a_linear_seabed(tide_std):
    chart = _kinked_plane()
    rng = np.random.default_rng(3)
    truth = np.array([4.0, -3.0])
    noise = 0.3
    patch = _patch(chart, truth, rng, noise, tide=1.2 if tide_std else 0.0)
    prior_mean, prior_cov = np.array([1.0, 1.0]), np.array([[25.0, 5.0], [5.0, 16.0]])
    fix = posterior_fix(patch, TerrainLikelihood(chart, noise), np.full(80, noise**2), None,
                        slope_moment(chart), *_prior(prior_mean, prior_cov, 0.0, tide_std))
    mean, cov = _exact_factor(patch, chart, noise**2, tide_std)
    assert fix.accepted and fix.quality.reasons == ()
    std = np.sqrt(np.diag(cov))
    # measured: within 0.5 % of a std and 1 % of the covariance (the grid's quadrature; the
    # resolution term adds about 1e-4 of the soundings' variance on the refined grid)
    assert np.all(np.abs(fix.position - mean) < 0.02 * std)
    np.testing.assert_allclose(fix.covariance, cov, rtol=0.03, atol=0.03 * std.min() ** 2)
    # and the posterior it came from is the exact one
    post_cov = np.linalg.inv(np.linalg.inv(prior_cov) + np.linalg.inv(cov))
    post_mean = post_cov @ (np.linalg.solve(prior_cov, prior_mean) + np.linalg.solve(cov, mean))
    np.testing.assert_allclose(fix.posterior_mean, post_mean, atol=0.02 * std.min())


def test_with_the_tide_in_the_graph_the_factor_is_the_exact_one_on_position_and_tide():
    """A seabed kinked along both axes (four planes): soundings in the four quadrants see four
    gradients, so position and tide are both determined; the prior over (north, east, tide) is
    correlated, as a graph's belief is, and is removed in three dimensions."""
    north = np.arange(-400.0, 401.0, 10.0)
    n, e = np.meshgrid(north, north, indexing="ij")
    slope_n = lambda x: np.where(x >= 0, 0.10, -0.08)  # noqa: E731
    slope_e = lambda x: np.where(x >= 0, 0.05, -0.06)  # noqa: E731
    chart = BathymetryMap(north, north, 50.0 + slope_n(n) * n + slope_e(e) * e)
    rng = np.random.default_rng(8)
    signs = np.repeat([[1, 1], [1, -1], [-1, 1], [-1, -1]], 30, axis=0)
    offsets = signs * rng.uniform(100, 250, (120, 2))
    truth, tide, noise = np.array([2.0, -3.0]), 1.5, 0.3
    depths = chart.depth_at(*(truth + offsets).T) + tide + noise * rng.standard_normal(120)
    patch = Patch(offsets, depths, np.zeros(120, np.int64), np.arange(120), 9, 0, np.zeros(2), 0)
    prior_mean = np.array([1.0, 1.0, 0.5])
    prior_cov = np.array([[25.0, 5.0, 1.0], [5.0, 16.0, -0.5], [1.0, -0.5, 4.0]])
    fix = posterior_fix(patch, TerrainLikelihood(chart, noise), np.full(120, noise**2), None,
                        slope_moment(chart), prior_mean, prior_cov, tide_factor=True)
    design = np.column_stack([slope_n(offsets[:, 0]), slope_e(offsets[:, 1]), np.ones(120)])
    base = chart.depth_at(*offsets.T)
    info = design.T @ design / noise**2
    exact_cov = np.linalg.inv(info)
    exact_mean = exact_cov @ design.T @ (depths - base) / noise**2
    std = np.sqrt(np.diag(exact_cov))
    assert fix.accepted
    # measured: within 1 % of a std and 2 % of the covariance
    assert np.all(np.abs(fix.joint_mean - exact_mean) < 0.03 * std)
    np.testing.assert_allclose(fix.joint_covariance, exact_cov, rtol=0.05, atol=0.05 * std.min() ** 2)
    np.testing.assert_array_equal(fix.position, fix.joint_mean[:2])
    # without the tide in the graph only the position's prior is removed: no joint factor
    plain = posterior_fix(patch, TerrainLikelihood(chart, noise), np.full(120, noise**2), None,
                          slope_moment(chart), prior_mean, prior_cov)
    assert np.all(np.isnan(plain.joint_mean)) and plain.accepted


def test_a_window_whose_depths_are_off_the_held_tide_is_a_depth_fault():
    """With the tide held by the graph (0.05 m), a window whose depths are all 5 m off is a depth
    fault, judged MISFIT (no evidence of a wrong position); the same window at the held tide,
    or 0.1 m off it, is an ordinary fix."""
    from tangraph.graph.fixes import judge_fix

    chart = _kinked_plane()
    prior_mean, prior_cov = _prior([1.0, 1.0], np.array([[25.0, 5.0], [5.0, 16.0]]), 1.5, 0.05)
    for offset, fault in ((0.0, False), (0.1, False), (5.0, True), (-5.0, True)):
        patch = _patch(chart, np.array([4.0, -3.0]), np.random.default_rng(3), 0.3, tide=1.5 + offset)
        fix = posterior_fix(patch, TerrainLikelihood(chart, 0.3), np.full(80, 0.09), None,
                            slope_moment(chart), prior_mean, prior_cov, tide_factor=True)
        assert fix.quality.depth_fault is fault, (offset, fix.quality.reasons)
        outcome = judge_fix(fix, prior_mean[:2], prior_cov[:2, :2], GraphConfig(), 50.0, strict=True)
        assert (outcome.record.status is FixStatus.MISFIT) is fault, (offset, outcome.record.status)
        if fault:  # the offset it reports: the free offset's posterior mean, the position free too
            said = float(outcome.record.detail.split("sit ")[1].split(" m")[0])
            assert abs(said - offset) < 0.5, outcome.record.detail


def test_a_window_that_sees_one_axis_keeps_the_prior_along_the_other():
    north = np.arange(-300.0, 301.0, 10.0)
    n, _ = np.meshgrid(north, north, indexing="ij")
    chart = BathymetryMap(north, north, 50.0 + 0.1 * n)  # slopes north only: east is unseen
    rng = np.random.default_rng(4)
    offsets = rng.uniform(-100, 100, (60, 2))
    truth = np.array([3.0, 7.0])
    depths = chart.depth_at(*(truth + offsets).T) + 0.2 * rng.standard_normal(60)
    patch = Patch(offsets, depths, np.zeros(60, np.int64), np.arange(60), 5, 0, np.zeros(2), 0)
    prior_cov = np.diag([16.0, 16.0])
    fix = posterior_fix(patch, TerrainLikelihood(chart, 0.2), np.full(60, 0.04), None, slope_moment(chart),
                        *_prior(np.zeros(2), prior_cov))
    assert fix.accepted
    # north: the soundings' information 60 * 0.1^2 / 0.04 = 15 per m^2
    assert fix.covariance[0, 0] == pytest.approx(1 / 15.0, rel=0.03)
    assert abs(fix.position[0] - truth[0]) < 4 * np.sqrt(1 / 15.0)
    # east: the prior's mean, with almost no information (1e-4 of the prior's)
    assert fix.position[1] == pytest.approx(0.0, abs=1e-6)
    assert fix.covariance[1, 1] > 1e3 * prior_cov[1, 1]


def test_a_bimodal_window_is_refused_not_given_as_one_gaussian():
    north = np.arange(-200.0, 201.0, 2.0)
    n, e = np.meshgrid(north, north, indexing="ij")
    # two identical hills 60 m apart east, a patch over one: it fits the other as well
    hill = lambda c: 10.0 * np.exp(-((n - 0.0) ** 2 + (e - c) ** 2) / (2 * 15.0**2))  # noqa: E731
    chart = BathymetryMap(north, north, 80.0 - hill(-30.0) - hill(30.0))
    rng = np.random.default_rng(5)
    offsets = rng.uniform(-10, 10, (20, 2))
    truth = np.array([0.0, -30.0])
    depths = chart.depth_at(*(truth + offsets).T) + 0.5 * rng.standard_normal(20)
    patch = Patch(offsets, depths, np.zeros(20, np.int64), np.arange(20), 5, 0, np.zeros(2), 0)
    args = (patch, TerrainLikelihood(chart, 0.5), np.full(20, 0.25), None, slope_moment(chart))
    fix = posterior_fix(*args, *_prior(np.zeros(2), np.diag([100.0, 900.0])))
    assert fix.quality.multimodal and not fix.accepted
    assert fix.quality.n_basins == 2
    # a prior that holds one hill only makes it unimodal
    near = posterior_fix(*args, *_prior([0.0, -27.0], np.diag([16.0, 16.0])))
    assert near.accepted and np.hypot(*(near.position - truth)) < 2.0


@pytest.mark.parametrize("seed", range(3))
def test_a_likelihood_sharper_than_the_grid_does_not_hide_the_second_hill(seed):
    """10 cm soundings on hills of 8 m: the likelihood is a few centimetres wide where the
    prior-wide grid's spacing is 3-7 m. A shift within a cell is shared by every sounding (the
    row-sum resolution term), so neither hill is lost between the points."""
    north = np.arange(-200.0, 201.0, 2.0)
    n, e = np.meshgrid(north, north, indexing="ij")
    hill = lambda c: 10.0 * np.exp(-(n**2 + (e - c) ** 2) / (2 * 8.0**2))  # noqa: E731
    chart = BathymetryMap(north, north, 80.0 - hill(-15.0) - hill(15.0))
    rng = np.random.default_rng(seed)
    offsets = rng.uniform(-12, 12, (80, 2))
    depths = chart.depth_at(*(np.array([0.0, -15.0]) + offsets).T) + 0.1 * rng.standard_normal(80)
    patch = Patch(offsets, depths, np.zeros(80, np.int64), np.arange(80), 5, 0, np.zeros(2), 0)
    fix = posterior_fix(patch, TerrainLikelihood(chart, 0.1), np.full(80, 0.01), None, slope_moment(chart),
                        *_prior(np.zeros(2), np.diag([100.0, 400.0])))
    assert fix.quality.multimodal and fix.quality.n_basins == 2


def test_a_prior_without_a_covariance_is_refused():
    chart = _kinked_plane()
    patch = _patch(chart, np.zeros(2), np.random.default_rng(1), 0.3)
    with pytest.raises(MatchingError, match="prior covariance is not finite and positive definite"):
        posterior_fix(patch, TerrainLikelihood(chart, 0.3), np.full(80, 0.09), None, slope_moment(chart),
                      *_prior(np.zeros(2), np.zeros((2, 2))))
