"""The likelihood's compiled kernels (tangraph.filters.likelihood_kernels) against slow references:
the map error's variance read where a cloud puts each sounding, and the likelihood it gives."""

from __future__ import annotations

import numpy as np

from tangraph.filters.likelihood import TerrainLikelihood
from tangraph.geometry import rotate
from tangraph.maps import BathymetryMap
from tangraph.sensors import NavigationModel, map_error_grids
from tests.filters.synthetic import rough_map

MAP = rough_map(3)


def varying_map() -> BathymetryMap:
    """The rough map with an error that grows eastwards and a hole in its data."""
    north, east = np.meshgrid(MAP.north, MAP.east, indexing="ij")
    depth = np.array(MAP.depth)
    depth[(north > 300) & (north < 330) & (east > 200) & (east < 240)] = np.nan
    std = 0.05 + 0.5 * (east - east.min()) / np.ptp(east) + 0.1 * (north > 260)
    return MAP.replace(depth=depth, depth_std=std, correlation_length=30.0)


def cloud(rng, n=60):
    centre = np.array([np.mean(MAP.north), np.mean(MAP.east)])
    particles = centre + rng.normal(0, 25.0, (n, 2))
    turn = rng.normal(0, 0.05, n)
    weights = rng.random(n)
    return particles, turn, weights / weights.sum()


def test_the_variance_kernel_reads_each_field_where_the_cloud_puts_the_sounding():
    """Per sounding and field the weighted mean of the field's variance at the particles'
    (turned) footprints, over the particles with the map under the sounding; 0 where none has;
    a cloud larger than ``JUDGED`` is averaged over a systematic draw of it, to a few per cent."""
    from tangraph.filters.likelihood import JUDGED

    rng = np.random.default_rng(1)
    chart = varying_map()
    model = NavigationModel(sounding_std=0.1)
    grids = map_error_grids(chart, model)
    like = TerrainLikelihood(chart, 0.1, error_grids=grids)
    particles, turn, weights = cloud(rng)
    offsets = rng.uniform(-40, 40, (25, 2))
    offsets[0] = [5000.0, 0.0]  # off the map under every particle
    depths = rng.normal(30, 1, 25)
    tide = rng.normal(0, 0.2, particles.shape[0])
    residual = like.residuals(particles, offsets, depths, tide, turn=turn)
    shared, own = like._judged(particles, offsets, turn, weights, np.ones((25, grids.shape[2])))
    want = reference(chart, grids, particles, turn, weights, offsets, residual)
    assert np.all(want[0] == 0) and np.isnan(residual[0]).all()
    assert np.isnan(residual).any() and not np.isnan(residual[1:]).all(axis=1).any()
    np.testing.assert_allclose(own, want.sum(axis=1), rtol=1e-9, atol=1e-15)
    np.testing.assert_allclose(shared, want.sum(axis=1), rtol=1e-9, atol=1e-15)  # (counts of 1)
    # a large cloud: a systematic draw of JUDGED particles
    particles, turn, weights = cloud(rng, 20 * JUDGED)
    residual = like.residuals(particles, offsets, depths, np.zeros(particles.shape[0]), turn=turn)
    counts = rng.uniform(1, 50, (25, grids.shape[2]))
    shared, own = like._judged(particles, offsets, turn, weights, counts)
    want = reference(chart, grids, particles, turn, weights, offsets, residual)
    np.testing.assert_allclose(own[1:], want[1:].sum(axis=1), rtol=0.05)
    np.testing.assert_allclose(shared[1:], np.sum(counts * want, axis=1)[1:], rtol=0.05)


def reference(chart, grids, particles, turn, weights, offsets, residual) -> np.ndarray:
    """The weighted mean of each field's variance under each sounding, ``(B, F)``, slowly."""
    want = np.zeros((offsets.shape[0], grids.shape[2]))
    for b in range(offsets.shape[0]):
        feet = particles + rotate(turn, np.broadcast_to(offsets[b], particles.shape))
        has = np.isfinite(residual[b])
        if not has.any():
            continue
        for f in range(grids.shape[2]):
            g = BathymetryMap(chart.north, chart.east, grids[:, :, f]).depth_at(feet[has, 0], feet[has, 1])
            want[b, f] = weights[has] @ g / weights[has].sum()
    return want


def test_a_placed_map_error_is_a_likelihood_of_the_judged_variances():
    """A ping weighed with its map error placed by the cloud is the same likelihood as one given
    those variances (``noise^2 + sum_f n_f E_w[g_f]``) and map error variances (``sum_f
    E_w[g_f]``, which the exponents are judged against), and it returns them."""
    rng = np.random.default_rng(2)
    chart = varying_map()
    grids = map_error_grids(chart, NavigationModel(sounding_std=0.1))
    like = TerrainLikelihood(chart, 0.1, error_grids=grids)
    particles, turn, weights = cloud(rng)
    offsets = rng.uniform(-40, 40, (25, 2))
    depths = chart.depth_at(np.mean(MAP.north) + offsets[:, 0], np.mean(MAP.east) + offsets[:, 1]) + 0.1
    counts = rng.uniform(1, 300, (25, grids.shape[2]))
    tide = np.zeros(particles.shape[0])
    placed = like.ping_update(particles, offsets, depths, tide, 0.5, turn=turn, weights=weights,
                              variance=np.full(25, 0.01), map_counts=counts)
    shared, own = like._judged(particles, offsets, turn, weights, counts)
    given = like.ping_update(particles, offsets, depths, tide, 0.5, turn=turn, weights=weights,
                             variance=0.01 + shared, map_variance=own)
    np.testing.assert_allclose(placed.variance, 0.01 + shared, rtol=1e-12)
    np.testing.assert_allclose(placed.log_likelihood, given.log_likelihood, rtol=1e-10)
    np.testing.assert_allclose(placed.tide, given.tide, rtol=1e-10)
    np.testing.assert_allclose(placed.exponent, given.exponent, rtol=1e-12)
    # the same ping whose soundings the cloud puts on the better-known west weighs more sharply
    west = particles - [0.0, 150.0]
    sharp = like.ping_update(west, offsets, depths, tide, 0.5, turn=turn, weights=weights,
                             variance=np.full(25, 0.01), map_counts=counts)
    assert np.all(sharp.variance < placed.variance)
