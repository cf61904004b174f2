"""The shared terrain likelihood (tangraph.filters.likelihood) against a numpy reference: the kernel
with NaN and off-map soundings, turned offsets, residual sums, the tide update's checks, MBARI's
information exponents, and no map data as no evidence."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.filters import FilterDivergence, default_config, run_filter
from tangraph.filters.belief import model_belief
from tangraph.filters.likelihood import TerrainLikelihood, log_normalise
from tangraph.filters.model import FilterModel, survey_pings
from tangraph.filters.steps import evaluate, reweight
from tangraph.maps import BathymetryMap
from tangraph.sensors import MisfitScale
from tests.filters.synthetic import multibeam_survey, navigation, rough_map
from tests.maps.reference import interpolate

MAP = rough_map(0)
SURVEY = multibeam_survey(MAP, pings=12)
MODEL = navigation(SURVEY, initial_position_std=10.0, sounding_std=0.5)


def with_missing(per_sounding: np.ndarray) -> np.ndarray:
    """The reference for soundings without a map depth (NaN terms of ``-r^2 / (2 sigma^2)``,
    particles weighted equally): each takes the mean likelihood of the particles that have one."""
    valid = np.isfinite(per_sounding)
    mean = np.log(np.nanmean(np.exp(per_sounding), axis=0))
    return np.sum(np.where(valid, per_sounding, mean), axis=1)


def rough(seed=0):
    rng = np.random.default_rng(seed)
    depth = 50 + rng.normal(size=(80, 90)).cumsum(axis=0) * 0.2
    depth[rng.random(depth.shape) < 0.01] = np.nan
    return BathymetryMap(north=np.arange(80) * 5.0, east=np.arange(90) * 5.0, depth=depth)


def test_kernel_matches_the_numpy_reference_with_nan_and_off_map():
    m = rough()
    rng = np.random.default_rng(1)
    particles = rng.uniform(-20, 420, (500, 2))
    offsets = rng.normal(0, 15, (30, 2))
    depths = rng.uniform(45, 55, 30)
    depths[3] = np.nan  # skipped
    got = TerrainLikelihood(m, sigma=0.5, tide=1.0).log_likelihood(particles, offsets, depths)
    keep = np.isfinite(depths)
    qn = particles[:, 0:1] + offsets[keep, 0]
    qe = particles[:, 1:2] + offsets[keep, 1]
    h, _ = interpolate(m.north, m.east, m.depth, qn.ravel(), qe.ravel())
    r = h.reshape(qn.shape) - (depths[keep] - 1.0)
    want = -0.5 * np.sum(r**2, axis=1) / 0.25  # NaN rows: some sounding off the map or by a NaN cell
    finite = np.isfinite(want)
    assert 0 < finite.sum() < finite.size
    np.testing.assert_allclose(got[finite], want[finite], rtol=1e-10)
    # no map under a sounding is no evidence: it takes the mean likelihood of the particles with one
    np.testing.assert_allclose(got, with_missing(-0.5 * r**2 / 0.25), rtol=1e-9)


def test_the_true_position_is_the_most_likely():
    m = rough(2)
    truth = np.array([200.0, 210.0])
    offsets = np.random.default_rng(3).normal(0, 30, (40, 2))
    depths = m.depth_at(truth[0] + offsets[:, 0], truth[1] + offsets[:, 1])
    grid = np.stack(np.meshgrid(np.arange(180.0, 221), np.arange(190.0, 231), indexing="ij"), -1).reshape(
        -1, 2
    )
    ll = TerrainLikelihood(m, sigma=0.3).log_likelihood(
        grid, offsets[np.isfinite(depths)], depths[np.isfinite(depths)]
    )
    np.testing.assert_array_equal(grid[np.argmax(ll)], truth)


def test_divergence_and_bad_arguments_are_named():
    with pytest.raises(FilterDivergence, match="ping 7"):
        log_normalise(np.full(4, -np.inf), where="ping 7")
    with pytest.raises(TangraphError, match="sigma"):
        TerrainLikelihood(rough(), sigma=0.0)
    with pytest.raises(TangraphError, match="particles"):
        TerrainLikelihood(rough(), sigma=1.0).log_likelihood(np.zeros(3), np.zeros((1, 2)), np.zeros(1))


def test_no_finite_sounding_carries_no_information():
    ll = TerrainLikelihood(rough(), sigma=1.0).log_likelihood(
        np.zeros((3, 2)) + 100, np.zeros((2, 2)), [np.nan] * 2
    )
    assert ll.tolist() == [0.0, 0.0, 0.0]


def test_turned_offsets_match_the_numpy_reference():
    """Each particle's soundings turned about it by its own angle (R(a) o, clockwise from north)."""
    m = rough(4)
    rng = np.random.default_rng(6)
    particles = rng.uniform(60, 340, (300, 2))
    turn = rng.normal(0, 0.3, 300)
    offsets = rng.normal(0, 20, (25, 2))
    depths = rng.uniform(45, 55, 25)
    got = TerrainLikelihood(m, sigma=0.5).log_likelihood(particles, offsets, depths, turn=turn)
    c, s = np.cos(turn)[:, None], np.sin(turn)[:, None]
    qn = particles[:, 0:1] + c * offsets[:, 0] - s * offsets[:, 1]
    qe = particles[:, 1:2] + s * offsets[:, 0] + c * offsets[:, 1]
    h, _ = interpolate(m.north, m.east, m.depth, qn.ravel(), qe.ravel())
    terms = -0.5 * (h.reshape(qn.shape) - depths) ** 2 / 0.25
    want = np.sum(terms, axis=1)
    finite = np.isfinite(want)
    assert 0 < finite.sum() < finite.size
    np.testing.assert_allclose(got[finite], want[finite], rtol=1e-10)
    np.testing.assert_allclose(got, with_missing(terms), rtol=1e-9)
    # a quarter turn clockwise takes a sounding due north of the vehicle to due east of it
    one = TerrainLikelihood(m, sigma=1.0).residual_sums(
        particles[:1], [[10.0, 0.0]], [50.0], turn=[np.pi / 2]
    )
    east = m.depth_at(particles[0, 0], particles[0, 1] + 10.0)
    np.testing.assert_allclose(one[0, 0], 50.0 - east, rtol=1e-10)


def test_residual_sums_match_the_numpy_reference():
    m = rough_map(1, shape=(60, 60))
    rng = np.random.default_rng(2)
    particles = rng.uniform(-20, 320, (400, 2))
    offsets = rng.normal(0, 10, (25, 2))
    depths = rng.uniform(70, 90, 25)
    depths[4] = np.nan
    got = TerrainLikelihood(m, 1.0).residual_sums(particles, offsets, depths)
    keep = np.isfinite(depths)
    qn, qe = particles[:, 0:1] + offsets[keep, 0], particles[:, 1:2] + offsets[keep, 1]
    h, _ = interpolate(m.north, m.east, m.depth, qn.ravel(), qe.ravel())
    r = depths[keep] - h.reshape(qn.shape)
    want = np.column_stack([r.sum(axis=1), (r**2).sum(axis=1)])
    finite = np.isfinite(want[:, 0])
    assert 0 < finite.sum() < finite.size
    np.testing.assert_allclose(got[finite], want[finite], rtol=1e-10)
    assert np.isnan(got[~finite]).all()


def test_tide_update_checks_its_inputs_as_log_likelihood_does():
    like = TerrainLikelihood(MAP, 0.5)
    particles, offsets, depths, tide = np.zeros((4, 2)), np.zeros((3, 2)), np.ones(3), np.zeros(4)
    with pytest.raises(TangraphError, match=r"particles must have shape \(N, 2\), got \(4, 3\)"):
        like.tide_update(np.zeros((4, 3)), offsets, depths, tide, 0.0)
    with pytest.raises(TangraphError, match="offsets .* and depths .* do not match"):
        like.tide_update(particles, offsets, np.ones(2), tide, 0.0)
    with pytest.raises(TangraphError, match=r"tide must have shape \(4,\) as particles, got \(3,\)"):
        like.tide_update(particles, offsets, depths, np.zeros(3), 0.0)
    with pytest.raises(TangraphError, match="tide_var must be a finite number >= 0, got -1.0"):
        like.tide_update(particles, offsets, depths, tide, -1.0)
    # NaN depths are skipped, as log_likelihood skips them
    centre = MAP.north[100], MAP.east[100]
    particles = np.array(centre) + np.random.default_rng(0).normal(0, 5, (4, 2))
    depths = MAP.depth_at(centre[0] + offsets[:, 0], centre[1] + offsets[:, 1])
    depths[1] = np.nan
    got = like.tide_update(particles, offsets, depths, tide, 0.0)[0]
    np.testing.assert_allclose(got, like.log_likelihood(particles, offsets[[0, 2]], depths[[0, 2]]))


def test_the_compiled_exponents_match_the_reference():
    """The likelihood kernel's exponents against :func:`tangraph.sensors.information_exponent` on
    the cloud's predicted depths (a weighted cloud, some particles off the map's data), for a
    ping that carries its map error variances but not the counts that place them."""
    import dataclasses

    from tangraph.sensors import information_exponent

    model = MODEL.replace(map_std=0.3, map_correlation_length=20.0)
    depth = np.array(MAP.depth)
    depth[MAP.north > 240.0, :] = np.nan  # the map's data stop by the survey
    cut = MAP.replace(depth=depth)
    fm = FilterModel.from_model(model, cut)
    ping = dataclasses.replace(survey_pings(SURVEY, cut, model)[5], map_counts=None)
    rng = np.random.default_rng(7)
    belief = model_belief(SURVEY.dr_pose[5, :2], fm, 300, rng=rng, std=40.0)
    belief = reweight(belief, rng.normal(0, 1, 300), where="test")
    got = evaluate(belief, ping, fm).exponent
    residual = fm.terrain.likelihood.residuals(belief.particles, ping.offsets, ping.depths, belief.tide,
                                               turn=-belief.calibration[:, 1])
    predicted = ping.depths[None, :] - residual.T  # (N, B), NaN off the map
    assert np.isnan(predicted).any()
    want = information_exponent(predicted, belief.weights, ping.map_variance)
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)


def test_a_sounding_whose_map_lies_under_negligible_weight_is_left_out():
    """Only particles of tiny weight (1e-200) have the map under some soundings: those soundings
    are left out for all (no NaN from their weighted spread), the others weigh as usual."""
    from tangraph.filters.likelihood import TerrainLikelihood

    depth = np.array(MAP.depth)
    depth[MAP.north > 300.0, :] = np.nan
    cut = MAP.replace(depth=depth)
    like = TerrainLikelihood(cut, 0.5)
    rng = np.random.default_rng(3)
    north = np.concatenate([np.full(3, 350.0), np.full(57, 210.0), np.full(40, 260.0)])
    particles = np.column_stack([north + rng.uniform(-2, 2, 100), rng.uniform(200, 300, 100)])
    # three far north, off the map; 57 whose second sounding (80 m north) has the map; 40 without
    offsets = np.array([[0.0, 0.0], [80.0, 0.0], [-5.0, 10.0]])  # the second: north of most
    depths = np.array([80.0, 80.0, 80.0])
    weights = np.full(100, 1.0)
    weights[3:60] = 1e-200  # the particles whose second sounding has the map: negligible weight
    update = like.ping_update(particles, offsets, depths, np.zeros(100), 0.1, weights=weights,
                              variance=np.full(3, 0.5), map_variance=np.full(3, 0.04))
    assert np.all(np.isfinite(update.log_likelihood))
    assert update.exponent[1] == 0.0
    assert update.exponent[0] > 0.0 and update.exponent[2] > 0.0


@pytest.mark.parametrize("method", ["pf", "ipf"])
@pytest.mark.parametrize("misfit_dof", [0.0, 2.0])
def test_a_filter_started_at_the_edge_of_the_maps_data_does_not_collapse(method, misfit_dof):
    """Half the cloud's soundings fall where the map has no data: no data is no evidence, so the
    cloud keeps its particles there instead of collapsing onto the few with the map under every
    sounding (with the old rule one ping took the spread to zero). With the misfit scale too: a
    Gaussian imputation beside its Student-t gave the cloud to the particles with no map under
    any sounding (35-38 m off at the first ping)."""
    depth = np.array(MAP.depth)
    edge = 215.0  # north of the start: the map's data stop here
    depth[MAP.north > edge, :] = np.nan
    cut = MAP.replace(depth=depth)
    survey = multibeam_survey(MAP, pings=8, start=(200.0, 150.0), heading_deg=90.0, rate=0.5)
    model = navigation(survey, initial_position_std=15.0, sounding_std=0.5, misfit_dof=misfit_dof)
    config = dataclasses.replace(default_config(method), n_particles=800)
    track = run_filter(method, survey, cut, config, model=model, rng=np.random.default_rng(0))
    spread = np.sqrt(np.trace(track.covariance[:, :2, :2], axis1=1, axis2=2))
    error = np.hypot(*(track.pose[:, :2] - survey.true_pose[:, :2]).T)
    # the old rule: 37-45 m off with a spread of 0.2-0.6 m; now within its spread at every ping
    assert np.all(error < 3 * spread + 0.5), (error.round(2), spread.round(2))
    assert track.meta["n_divergences"] == 0


def _misfit_case(seed=4):
    holes = rough(seed)
    m = holes.replace(depth=np.where(np.isfinite(holes.depth), holes.depth, 50.0))
    rng = np.random.default_rng(seed)
    particles = rng.uniform(150, 250, (300, 2))
    offsets = rng.normal(0, 20, (25, 2))
    depths = m.depth_at(200 + offsets[:, 0], 200 + offsets[:, 1]) + rng.normal(0, 1.0, 25)
    keep = np.isfinite(depths)
    return m, particles, offsets[keep], depths[keep], rng.uniform(0.2, 0.5, keep.sum())


@pytest.mark.parametrize("tide_var", [0.0, 4.0])
def test_the_misfit_scale_gives_the_student_t_of_its_formula(tide_var):
    """The compiled Student-t (the scale integrated out, the tide at its estimate) against its
    formula in numpy, per particle, with each sounding's own variance and count."""
    from math import lgamma

    m, particles, offsets, depths, variance = _misfit_case()
    scale = MisfitScale(3.0, 7.5, 4.0, 100.0)  # a factor of 2.5 learnt
    counts = np.linspace(0.5, 1.0, depths.size)
    tide = np.full(len(particles), 0.3)
    likelihood = TerrainLikelihood(m, sigma=0.5)
    update = likelihood.ping_update(particles, offsets, depths, tide, tide_var, variance=variance,
                                    exponent=np.ones(depths.size), scale=scale, counts=counts)
    r = likelihood.residuals(particles, offsets, depths, tide)
    ok = np.all(np.isfinite(r), axis=0)
    assert ok.all()
    lam = (1.0 / variance)[:, None]
    s1, s2, big_l = np.sum(lam * r, 0), np.sum(lam * r**2, 0), np.sum(lam)
    k = scale.factor
    q, log_det = s2, 0.0
    if tide_var:
        gain = 1.0 / (1.0 / tide_var + big_l / k)
        q = s2 - gain * s1**2 / k
        log_det = -0.5 * np.log1p(tide_var * big_l / k)
    half = 0.5 * counts.sum()
    want = lgamma(3.0 + half) - lgamma(3.0) + 3.0 * np.log(7.5) - (3.0 + half) * np.log(7.5 + 0.5 * q)
    want = want + log_det
    np.testing.assert_allclose(update.log_likelihood[ok], want[ok], rtol=1e-9)
    np.testing.assert_allclose(update.quadratic[ok], q[ok], rtol=1e-9)
    np.testing.assert_allclose(update.count[ok], counts.sum(), rtol=1e-12)


@pytest.mark.parametrize("tide_var", [0.0, 4.0])
def test_a_sure_misfit_scale_of_one_is_the_gaussian_likelihood(tide_var):
    m, particles, offsets, depths, variance = _misfit_case(5)
    tide = np.zeros(len(particles))
    likelihood = TerrainLikelihood(m, sigma=0.5)
    sure = MisfitScale(1e9, 1e9, 2.0, 1.0)
    args = (particles, offsets, depths, tide, tide_var)
    gaussian = likelihood.ping_update(*args, variance=variance)
    student = likelihood.ping_update(*args, variance=variance, scale=sure)
    ok = np.isfinite(gaussian.log_likelihood)
    assert ok.all()
    a, b = gaussian.log_likelihood[ok], student.log_likelihood[ok]
    np.testing.assert_allclose(b - b.max(), a - a.max(), atol=1e-4)
    np.testing.assert_allclose(student.tide, gaussian.tide, rtol=1e-7)


def test_where_the_map_errs_beyond_its_statement_the_likelihood_flattens():
    """Residuals three times their stated std at the truth: once the scale has learnt them
    (a factor near 9), a rival position's log-ratio is about a ninth of the Gaussian's."""
    m, _, offsets, _, _ = _misfit_case(6)
    rng = np.random.default_rng(6)
    truth, rival = np.array([200.0, 200.0]), np.array([203.0, 201.0])
    depths = m.depth_at(truth[0] + offsets[:, 0], truth[1] + offsets[:, 1]) + 3 * 0.5 * rng.standard_normal(
        offsets.shape[0])
    likelihood = TerrainLikelihood(m, sigma=0.5)
    args = (np.stack([truth, rival]), offsets, depths, np.zeros(2), 0.0)
    gaussian = likelihood.ping_update(*args).log_likelihood
    learnt = MisfitScale(500.0, 4500.0, 4.0, 100.0)
    student = likelihood.ping_update(*args, scale=learnt).log_likelihood
    ratio = (student[0] - student[1]) / (gaussian[0] - gaussian[1])
    assert gaussian[0] - gaussian[1] > 5
    assert 0.08 < ratio < 0.14, ratio


@pytest.mark.parametrize("method", ["pf", "pmf"])
def test_the_misfit_scale_keeps_a_filter_honest_where_the_soundings_err_beyond_their_statement(method):
    """Soundings five times as noisy as the model states: with the stated errors trusted the
    filter's final NEES over ten runs is in the hundreds; with the misfit scale (8 degrees of
    freedom) its mean is inside the chi-square(20)/10 band's upper 99.9 % point (4.5)."""
    nees = {0.0: [], 8.0: []}
    for dof in nees:
        for seed in range(10):
            survey = multibeam_survey(MAP, seed=seed, pings=30, noise=1.5)
            model = navigation(survey, initial_position_std=10.0, sounding_std=0.3, misfit_dof=dof)
            config = default_config(method)
            if method == "pf":
                config = dataclasses.replace(config, n_particles=1000)
            track = run_filter(method, survey, MAP, config, model=model, rng=np.random.default_rng(seed))
            e = track.pose[-1, :2] - survey.true_pose[-1, :2]
            nees[dof].append(float(e @ np.linalg.solve(track.covariance[-1, :2, :2], e)))
    assert np.mean(nees[0.0]) > 20
    assert np.mean(nees[8.0]) < 4.5, np.round(nees[8.0], 2)
