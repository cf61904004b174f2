"""Tests of the map error's Gaussian-Markov field: its marginal variance and its correlation at the
range against the Matérn figures (away from the grid's edges), the nugget that makes every
footprint's variance the model's, and the grid laid over the footprints."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse.linalg import splu

from tangraph.eval.map_field import (
    MARGIN_LENGTHS,
    lattice_correlation,
    map_error_field,
    spde_precision,
)
from tangraph.maps import BathymetryMap
from tangraph.sensors import NavigationModel, map_error, matern_correlation


def _covariance_column(shape, c, node):
    """Column ``node`` of the field's covariance (the inverse of its precision)."""
    e = np.zeros(shape[0] * shape[1])
    e[node] = 1.0
    return splu(spde_precision(shape, c).tocsc()).solve(e).reshape(shape)


@pytest.mark.parametrize("per_length", [3, 6])
def test_the_field_has_unit_variance_and_the_matern_correlation_away_from_the_edges(per_length):
    # A grid 12 ranges a side, h = L / per_length. At the centre (6 ranges from every edge) the
    # variance is 1 within 1e-6 (the wrap-free lattice sum is exact; the edges are far); the
    # correlation at the range L is Matérn's 0.140 within 0.015 (the lattice gives 0.126 at h = L/3,
    # 0.130 at L/6) and at 2 L its 0.011 within 0.002; it is isotropic along both axes.
    n = 12 * per_length + 1
    centre = n // 2
    column = _covariance_column((n, n), np.sqrt(8.0) / per_length, centre * n + centre)
    assert column[centre, centre] == pytest.approx(1.0, abs=1e-6)
    for distance, tolerance in ((1, 0.015), (2, 0.002)):
        k = distance * per_length
        want = float(matern_correlation(float(distance), 1.0))
        assert column[centre, centre + k] == pytest.approx(want, abs=tolerance)
        assert column[centre + k, centre] == pytest.approx(column[centre, centre + k], rel=1e-9)
    _, lattice = lattice_correlation(np.sqrt(8.0) / per_length)
    assert column[centre, centre + 1] == pytest.approx(lattice[1], rel=1e-6)
    assert column[centre + 1, centre + 1] == pytest.approx(lattice[2], rel=1e-6)


def test_the_edges_inflate_the_variance_and_the_margin_keeps_it_off_the_footprints():
    per_length = 3
    n = 12 * per_length + 1
    middle = n // 2
    variance = {name: _covariance_column((n, n), np.sqrt(8.0) / per_length, middle * n + j)[middle, j]
                for name, j in (("edge", 0), ("margin", int(MARGIN_LENGTHS * per_length)))}
    assert variance["edge"] > 1.5
    assert variance["margin"] == pytest.approx(1.0, abs=1e-3)


def _flat(std=None, length=None) -> BathymetryMap:
    axis = np.arange(0.0, 1000.0, 10.0)
    depth = np.full((100, 100), 20.0)
    depth[:10, :10] = np.nan
    flat = BathymetryMap(axis, axis, depth)
    return flat if std is None else flat.replace(depth_std=std, correlation_length=length)


def test_the_grid_covers_the_footprints_with_a_margin_of_two_ranges():
    north, east = np.array([300.0, 420.0, 510.0]), np.array([400.0, 470.0, 455.0])
    error = map_error(_flat(), NavigationModel(map_std=0.2, map_correlation_length=45.0))
    field = map_error_field(north, east, error)
    assert field.spacing == pytest.approx(15.0)  # L / 3 (the map's cell is 10 m)
    node_n, node_e = field.nodes()
    assert node_n.min() <= north.min() - 90.0 and node_n.max() >= north.max() + 90.0
    assert node_e.min() <= east.min() - 90.0 and node_e.max() >= east.max() + 90.0
    np.testing.assert_allclose(field.std, 0.2)
    one_cell = map_error(_flat(), NavigationModel(map_std=0.2))
    coarse = map_error_field(north, east, one_cell)
    assert coarse.spacing == pytest.approx(10.0)  # a range of one cell: nodes a cell apart
    fine = map_error_field(north, east, one_cell, finer_than_cell=True)
    assert fine.spacing == pytest.approx(10.0 / 3)  # the bound's: a third of the range all the same
    capped = map_error_field(north, east, error, max_nodes=100)
    assert capped.n_nodes <= 100 and capped.spacing > field.spacing


def test_node_stds_come_from_the_maps_error_and_its_median_off_the_data():
    """One grid per independent field of the error (a varying std with a range over a cell:
    the cell-scale error and the excess), each node's std its field's, the median off the data."""
    std = np.where(np.arange(100)[None, :] < 50, 0.1, 0.5) * np.ones((100, 1))
    error = map_error(_flat(std, 30.0), NavigationModel())
    field = map_error_field(np.array([500.0]), np.array([480.0]), error)
    parts = error.components()
    assert len(field.fields) == len(parts) == 2
    assert field.n_nodes == sum(f.n_nodes for f in field.fields)
    for grid, part in zip(field.fields, parts, strict=True):
        node_n, node_e = grid.nodes()
        want = part.std_at(node_n, node_e)
        assert np.all(np.isfinite(want[(node_e < 480) | (node_e > 520)]))
        np.testing.assert_allclose(grid.std, np.where(np.isfinite(want), want, part.typical_std))
    assert [f.correlation_length for f in field.fields] == [10.0, 30.0]
    corner = map_error_field(np.array([60.0]), np.array([60.0]), error)
    for grid, part in zip(corner.fields, parts, strict=True):
        cn, ce = grid.nodes()
        off_data = ~np.isfinite(part.std_at(cn, ce))
        assert off_data.any()
        np.testing.assert_allclose(grid.std[off_data], part.typical_std)


def test_the_nugget_gives_every_footprint_the_models_variance():
    error = map_error(_flat(), NavigationModel(map_std=0.3, map_correlation_length=40.0))
    field = map_error_field(np.array([500.0]), np.array([500.0]), error)
    node_n, node_e = field.nodes()
    h = field.spacing
    points_n = node_n[80] + np.array([0.0, 0.0, 0.5, 0.25, 0.7]) * h
    points_e = node_e[80] + np.array([0.0, 0.5, 0.5, 0.9, 0.1]) * h
    index, weight = field.weights(points_n, points_e)
    np.testing.assert_allclose(weight.sum(axis=1), 1.0)
    np.testing.assert_allclose((weight[:, :, None] * field.nodes()[0][index][..., None]).sum(axis=1)[:, 0],
                               points_n)
    # the interpolated field's variance from the stationary correlation of the lattice's nodes
    _, r = lattice_correlation(np.sqrt(8.0) * h / 40.0)
    row, col = np.array([0, 0, 1, 1]), np.array([0, 1, 0, 1])  # the corners' offsets
    steps = np.abs(row[:, None] - row) + np.abs(col[:, None] - col)
    interpolated = np.einsum("pa,ab,pb->p", weight, r[steps], weight) * 0.3**2
    nugget = field.nugget(index, weight)
    np.testing.assert_allclose(interpolated + nugget, 0.3**2, rtol=1e-12)
    assert nugget[0] == pytest.approx(0.0, abs=1e-15)  # on a node: all in the field
    assert nugget[2] > nugget[1] > 0  # a cell's centre misses most
