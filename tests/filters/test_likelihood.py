"""The shared terrain likelihood against a numpy reference, and the resampling schemes."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.filters import FilterDivergence
from tangraph.filters.likelihood import TerrainLikelihood, log_normalise
from tangraph.filters.resampling import Resampler, resample
from tangraph.maps import BathymetryMap
from tests.maps.reference import interpolate


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


@pytest.mark.parametrize("scheme", list(Resampler))
def test_one_particle_with_all_the_weight(scheme):
    w = np.array([0.0, 0.0, 1.0, 0.0])
    idx = resample(w, scheme, rng=np.random.default_rng(0))
    assert idx.tolist() == [2, 2, 2, 2]
    assert w.tolist() == [0.0, 0.0, 1.0, 0.0]  # not modified


@pytest.mark.parametrize("scheme", [Resampler.SYSTEMATIC, Resampler.STRATIFIED, Resampler.RESIDUAL])
def test_equal_weights_keep_every_particle_once(scheme):
    assert sorted(resample(np.full(10, 0.1), scheme, rng=np.random.default_rng(1))) == list(range(10))


@pytest.mark.parametrize("scheme", list(Resampler))
def test_mean_counts_are_n_times_the_weights(scheme):
    w = np.array([0.05, 0.15, 0.3, 0.5])
    n, runs = 40, 400
    rng = np.random.default_rng(5)
    counts = np.array([np.bincount(resample(w, scheme, rng=rng, n=n), minlength=4) for _ in range(runs)])
    if scheme in (Resampler.SYSTEMATIC, Resampler.RESIDUAL):  # each count within floor/ceil of N w
        assert np.all(counts >= np.floor(n * w)) and np.all(counts <= np.ceil(n * w))
    standard_error = np.sqrt(n * w * (1 - w) / runs)  # multinomial bound on the others' scatter
    assert np.all(np.abs(counts.mean(axis=0) - n * w) < 4 * standard_error)


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
