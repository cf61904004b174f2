"""The error of a map gridded from soundings (tangraph.maps.gridding_error: ``gridded_error``,
carried by ``SoundingGrid.depth``), with the surveys' positioning std added through the slope."""

from __future__ import annotations

import logging
import math

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.maps import block_reduce, fill_gaps
from tangraph.maps.gridding_error import bridging_triangles, gridded_error
from tests.gridding_cases import _plane_survey


def test_a_measured_cell_gets_the_standard_error_of_its_value():
    z = np.array([10.0, 10.3, 9.8, 10.1, 10.6])
    pts = [[0.1, 0.0, v] for v in z] + [[1.0, 1.0, 12.0], [1.0, 1.1, 12.4]]
    for statistic, factor in (("mean", 1.0), ("median", math.sqrt(math.pi / 2))):
        g = block_reduce(pts, cell=1.0, statistic=statistic)
        std = g.depth.depth_std
        assert std[0, 0] == pytest.approx(factor * np.std(z, ddof=1) / np.sqrt(5), rel=1e-12)
        # two soundings: the median is their mean, no efficiency factor
        assert std[1, 1] == pytest.approx(np.std([12.0, 12.4], ddof=1) / np.sqrt(2), rel=1e-12)


def test_a_single_sounding_borrows_the_spread_around_it():
    rng = np.random.default_rng(2)
    pts = []
    for i in range(8):  # a row of cells with 4 soundings each, spread 0.2 at west, 0.6 at east
        pts += [[0.0, float(i), 20 + s] for s in rng.normal(0, 1, 4)]
    pts = np.array(pts)
    spread = np.where(pts[:, 1] < 4, 0.2, 0.6)
    pts[:, 2] = 20 + (pts[:, 2] - 20) * spread
    pts = np.vstack([pts, [[1.0, 0.0, 20.0], [1.0, 7.0, 20.0], [9.0, 0.0, 20.0]]])  # three singles
    g = block_reduce(pts, cell=1.0)
    std = g.depth.depth_std
    near_west = np.mean(g.std[0, 0:3])  # replicated cells within 2 cells of (1, 0)
    near_east = np.mean(g.std[0, 5:8])
    assert std[1, 0] == pytest.approx(near_west, rel=1e-12)
    assert std[1, 7] == pytest.approx(near_east, rel=1e-12)
    assert std[9, 0] == pytest.approx(np.median(g.std[0]), rel=1e-12)  # nothing near: the grid's median
    assert std[1, 0] > 0 and std[9, 0] > 0


def filled_strip(gap_cells=6, cell=2.0, noise=0.05, seed=0):
    """Two measured lines (rows 0 and gap_cells + 1) of a sloping seafloor, the gap filled."""
    rng = np.random.default_rng(seed)
    pts = []
    for row in (0, gap_cells + 1):
        for col in range(30):
            for _ in range(4):
                north, east = row * cell, col * cell
                pts.append([north, east, 30 + 0.1 * east + 0.3 * np.sin(east / 3) + rng.normal(0, noise)])
    return fill_gaps(block_reduce(pts, cell=cell, statistic="mean"), gap_cells)


def test_a_filled_cell_grows_with_the_distance_to_the_data_as_the_variogram_says():
    g = filled_strip()
    e = gridded_error(g)
    measured = g.count > 0
    layer = np.where(measured, g.mean.depth, np.nan)
    gamma = 0.5 * np.nanmean(np.diff(layer, axis=1) ** 2)  # along the lines: the only pairs
    assert e.semivariance == pytest.approx(gamma, rel=1e-12)
    # twice the semivariogram at k cells, along the lines (the only pairs that close), never
    # falling, linear between lags
    errors = [0.0]
    for k in range(1, 7):
        errors.append(max(errors[-1], np.nanmean((layer[:, k:] - layer[:, :-k]) ** 2)))
    column = e.depth_std[:, 10]
    target, corners, weights = bridging_triangles(measured, 6)  # the gap is bridged by planes
    for row in range(1, 7):  # the fill's own weights over its triangle's corners
        (i,) = np.flatnonzero(target == np.ravel_multi_index((row, 10), measured.shape))
        corner = np.stack(np.unravel_index(corners[i], measured.shape), axis=-1)
        assert measured.flat[corners[i]].all() and weights[i] @ corner == pytest.approx([row, 10])
        r = np.hypot(*(corner - [row, 10]).T)
        own = e.depth_std.flat[corners[i]] ** 2
        expected = np.sqrt(np.sum(weights[i] * (np.interp(r, np.arange(7.0), errors) + own)))
        assert column[row] == pytest.approx(expected, rel=1e-12)
    assert np.all(np.diff(column[0:4]) > 0)  # grows towards the middle of the gap
    assert np.all(np.diff(column[4:8]) < 0)  # and falls towards the northern line
    assert np.all(np.isfinite(column)) and column[3] > 5 * column[0]


def test_the_gridded_std_matches_a_simulated_prior_maps_true_error():
    """Recovery of a known map error's statistics: a prior map gridded from a simulated earlier
    survey of a seafloor that is the map plus a random field (the realistic-map scenarios); its
    true error normalised by the std it carries has an RMS near one where measured and in the
    filled gaps (within 25 %; 0.90 and 0.92 with this seed)."""
    from tangraph.sim.scenario import load_scenario, simulate_run

    run = simulate_run(load_scenario("wang2019-map-error"), rng=np.random.default_rng(3))
    prior, world = run.bathymetry, run.world
    z = world.map_error() / prior.depth_std
    from tangraph.gridding_surveys import grid_surveys

    counts = grid_surveys([world.prior_survey], cell=10.0, statistic="median").count
    assert counts.shape == prior.shape
    measured = (counts > 0) & np.isfinite(z)
    filled = (counts == 0) & np.isfinite(z)
    assert measured.sum() > 1000 and filled.sum() > 1000
    assert 0.75 < np.sqrt(np.mean(z[measured] ** 2)) < 1.25
    assert 0.75 < np.sqrt(np.mean(z[filled] ** 2)) < 1.25


def test_the_correlation_length_is_the_cell_under_dense_coverage():
    rng = np.random.default_rng(3)
    pts = rng.uniform(0, 200, (40000, 3))
    pts[:, 2] = 40 + 0.05 * pts[:, 0] + np.sin(pts[:, 1] / 20) + rng.normal(0, 0.1, len(pts))
    g = fill_gaps(block_reduce(pts, cell=5.0), 3)
    assert g.n_filled == 0  # nothing to fill: every cell measured
    assert gridded_error(g).correlation_length == 5.0
    assert g.depth.correlation_length == 5.0


@pytest.mark.parametrize("spacing", [60.0, 120.0])
def test_the_correlation_length_follows_the_line_spacing_when_gaps_are_filled(spacing):
    rng = np.random.default_rng(4)
    east = rng.uniform(0, 600, 60000)
    north = rng.choice(np.arange(0, 601, spacing), east.size) + rng.uniform(-4, 4, east.size)
    depth = 50 + 3 * np.sin(north / 40) + 2 * np.cos(east / 55) + rng.normal(0, 0.1, east.size)
    grid = block_reduce(np.column_stack([north, east, depth]), cell=5.0)
    unfilled = gridded_error(grid).correlation_length
    filled = gridded_error(fill_gaps(grid, int(spacing / 5))).correlation_length
    assert unfilled == pytest.approx(5.0)  # gaps left empty: the map's data are the lines, cell by cell
    assert 0.3 * spacing < filled < spacing


def test_the_grid_carries_its_error_and_a_grid_that_cannot_tell_says_so(caplog):
    g = filled_strip()
    m = g.depth
    np.testing.assert_array_equal(m.depth_std, g.error.depth_std)
    assert m.correlation_length == g.error.correlation_length > 2.0
    assert g.error is g.error  # computed once
    # every cell one sounding, no two measured cells adjacent, a gap filled between them
    sparse = fill_gaps(block_reduce([[0.0, 0, 10], [0, 4, 11], [4, 0, 12], [4, 4, 13]], cell=1.0), 2)
    with caplog.at_level(logging.WARNING, logger="tangraph.maps.gridding"):
        assert sparse.depth.depth_std is None and sparse.depth.correlation_length is None
    assert "cannot be told" in caplog.text


def test_neighbourhood_must_be_a_count():
    with pytest.raises(TangraphError, match="neighbourhood must be an integer >= 0"):
        gridded_error(filled_strip(), neighbourhood=-1)


def test_the_positioning_std_adds_its_depth_error_through_the_slope():
    """On a plane of slope ``g`` every cell's variance gains exactly ``p^2 |g|^2`` away from
    the map's edges (where a cell's value is the plane at its soundings' centroid, not at its
    centre, so the map's own slope differs); ``p = 0`` changes nothing."""
    from tangraph.maps import grid_surveys

    surveys = _plane_survey(0.0)
    plain = grid_surveys(surveys, cell=10.0, statistic="mean", fill=2)
    none = grid_surveys(surveys, cell=10.0, statistic="mean", fill=2, position_std=0.0)
    placed = grid_surveys(surveys, cell=10.0, statistic="mean", fill=2, position_std=3.0)
    s0, s1 = plain.depth.depth_std, placed.depth.depth_std
    np.testing.assert_array_equal(none.depth.depth_std, s0)
    assert np.array_equal(np.isfinite(s0), np.isfinite(s1))
    inner = np.zeros(s0.shape, bool)
    inner[2:-2, 2:-2] = True
    ok = inner & np.isfinite(s0)
    assert ok.sum() > 100
    np.testing.assert_allclose(s1[ok] ** 2 - s0[ok] ** 2, 9.0 * (0.1**2 + 0.05**2), rtol=1e-9)
    assert np.all(s1[np.isfinite(s0)] >= s0[np.isfinite(s0)])
    assert placed.meta["position_std"] == 3.0


def test_a_gap_fill_does_not_hide_the_slope_next_to_the_data():
    """Lines 40 m apart, the gaps filled from 2 cells: the slope the positioning error meets is
    the seafloor's (0.112 here), wherever the fill is flatter next to the data."""
    from tangraph.maps import grid_surveys

    surveys = _plane_survey(0.0, n_lines=40)[::4]
    plain = grid_surveys(surveys, cell=10.0, statistic="mean", fill=2)
    placed = grid_surveys(surveys, cell=10.0, statistic="mean", fill=2, position_std=3.0)
    measured = (plain.count > 0) & np.isfinite(plain.depth.depth_std)
    measured[:, :2] = measured[:, -2:] = False
    gained = placed.depth.depth_std[measured] ** 2 - plain.depth.depth_std[measured] ** 2
    np.testing.assert_allclose(np.sqrt(gained / 9.0), np.hypot(0.1, 0.05), rtol=0.02)


def test_a_map_placed_by_an_erring_track_states_the_error_it_has():
    """Recovery of a known error: lines each placed 10 m off per axis (a slowly varying GPS
    error, larger than a cell) on a seafloor sloping 0.05 along them; a cell's true error is
    then ``0.05`` times its line's offset along the slope. Told the positioning std, the map's
    stated std covers it (z RMS 0.76-0.89 over eight seeds: a little cautious, as the cells'
    relief counts the plane's slope within a cell too; 80 independent offsets); without it the
    map claims several times too little."""
    from tangraph.maps import grid_surveys

    surveys = _plane_survey(10.0, seed=5, n_lines=80, north_slope=0.0)

    def z_rms(position_std):
        gridded = grid_surveys(surveys, cell=10.0, statistic="mean", position_std=position_std)
        grid = gridded.depth
        _, e = np.meshgrid(grid.north, grid.east, indexing="ij")
        error = grid.depth - (30.0 + 0.05 * e)
        measured = np.isfinite(error) & (gridded.count > 0) & (grid.depth_std > 0)  # (a few 0 without)
        return float(np.sqrt(np.mean((error[measured] / grid.depth_std[measured]) ** 2)))

    told, untold = z_rms(10.0), z_rms(0.0)
    assert 0.7 < told < 1.25, told
    assert untold > 2.0 * told, (told, untold)
