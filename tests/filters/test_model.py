"""The shared model: motion, residual sums, and the terrain likelihood with a known or an
estimated (Rao-Blackwellised) tide against direct computations."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import integrate

from tangraph.filters import MotionModel, Ping, TerrainLikelihood, TerrainModel, survey_pings
from tests.filters.synthetic import multibeam_survey, rough_map
from tests.maps.reference import interpolate


def ping(offsets, depths, index=1, increment=(0.0, 0.0)):
    return Ping(index, np.asarray(increment, float), np.asarray(offsets, float), np.asarray(depths, float))


def test_motion_without_noise_is_the_dead_reckoned_increment():
    particles = np.array([[0.0, 0.0], [10.0, -5.0]])
    p = ping(np.zeros((0, 2)), np.zeros(0), increment=(3.0, 4.0))
    moved = MotionModel(0.0, 0.0).predict(particles, p, rng=np.random.default_rng(0))
    np.testing.assert_array_equal(moved, particles + np.array([3.0, 4.0]))
    first = Ping(0, np.zeros(2), np.zeros((0, 2)), np.zeros(0), first=True)
    assert MotionModel(1.0, 0.1).predict(particles, first, rng=np.random.default_rng(0)) is particles
    assert MotionModel(0.5, 0.1).noise_std(np.array([30.0, 40.0])) == pytest.approx(np.hypot(0.5, 5.0))


def test_motion_noise_has_the_stated_std():
    p = ping(np.zeros((0, 2)), np.zeros(0), increment=(60.0, 80.0))
    moved = MotionModel(2.0, 0.1).predict(
        np.zeros((20000, 2)), p, rng=np.random.default_rng(1), extra_std=5.0
    )
    want = np.sqrt(2.0**2 + 10.0**2 + 5.0**2)
    np.testing.assert_allclose(moved.mean(axis=0), [60.0, 80.0], atol=4 * want / np.sqrt(20000))
    np.testing.assert_allclose(moved.std(axis=0), want, rtol=4 * np.sqrt(0.5 / 20000))


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


def test_known_tide_is_the_plain_gaussian_likelihood():
    m = rough_map(2, shape=(60, 60))
    rng = np.random.default_rng(3)
    particles = rng.uniform(50, 250, (100, 2))
    p = ping(rng.normal(0, 15, (20, 2)), rng.uniform(75, 85, 20))
    update = TerrainModel(m, 0.7, tide_std=0.0).evaluate(particles, np.full(100, 1.5), 0.0, p)
    want = TerrainLikelihood(m, 0.7, tide=1.5).log_likelihood(particles, p.offsets, p.depths)
    np.testing.assert_allclose(update.log_likelihood, want, rtol=1e-12)
    assert np.all(update.tide == 1.5) and update.tide_var == 0.0


def test_uncertain_tide_is_marginalised_exactly():
    """The Rao-Blackwellised weight and tide posterior against numerical integration over the tide."""
    m = rough_map(4, shape=(60, 60))
    rng = np.random.default_rng(5)
    particles = rng.uniform(80, 200, (3, 2))
    offsets = rng.normal(0, 15, (8, 2))
    sigma, tide0, tide_sd = 0.6, 1.0, 2.0
    h = m.depth_at(particles[:, 0:1] + offsets[:, 0], particles[:, 1:2] + offsets[:, 1])
    depths = h[0] + 2.2 + sigma * rng.standard_normal(8)
    update = TerrainModel(m, sigma, tide_std=tide_sd).evaluate(
        particles, np.full(3, tide0), tide_sd**2, ping(offsets, depths)
    )

    def log_joint(t, row):  # log p(z | x, t) p(t), up to the constant the model drops
        return -0.5 * np.sum((depths - h[row] - t) ** 2) / sigma**2 - 0.5 * (t - tide0) ** 2 / tide_sd**2

    log_marginal, means = np.empty(3), np.empty(3)
    for r in range(3):
        peak = float(np.mean(depths - h[r]))
        top = log_joint(peak, r)
        f = lambda t, r=r, top=top: np.exp(log_joint(t, r) - top)  # noqa: E731
        mass = integrate.quad(f, peak - 10, peak + 10, points=[peak])[0]
        log_marginal[r] = np.log(mass) + top
        means[r] = integrate.quad(lambda t, f=f: t * f(t), peak - 10, peak + 10, points=[peak])[0] / mass
    marginal = np.exp(log_marginal - log_marginal[0])
    got = update.log_likelihood - update.log_likelihood[0]
    np.testing.assert_allclose(got, np.log(marginal), atol=1e-6)
    np.testing.assert_allclose(update.tide, means, atol=1e-6)
    assert update.tide_var == pytest.approx(1 / (1 / tide_sd**2 + 8 / sigma**2))


def test_survey_pings_drop_nan_soundings_and_keep_empty_pings():
    m = rough_map(0)
    s = multibeam_survey(m, pings=5, beams=4)
    depth = np.array(s.beam_depth)
    depth[1, 2] = np.nan
    depth[3] = np.nan
    pings = survey_pings(s.replace(beam_depth=depth))
    assert [p.n_soundings for p in pings] == [4, 3, 4, 0, 4]
    assert pings[0].first and not pings[1].first
    np.testing.assert_allclose(pings[2].increment, s.dr_pose[2, :2] - s.dr_pose[1, :2])
