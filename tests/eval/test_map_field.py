"""Tests of the map error's Gaussian-Markov field (tangraph.eval.map_field): its marginal variance
and its correlation at the range against the Matérn figures (away from the grid's edges), the
nugget that makes every footprint's variance the model's, the grid laid over the footprints
(trimmed to the nodes near them: free edges), and a field of the map's offset seen through the
slope. The bound's joint solve with the field is tested in test_field_bound.py."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse.linalg import splu

import tangraph.eval.map_field as map_field
from tangraph.errors import TangraphError
from tangraph.eval import bound_rmse, posterior_crb
from tangraph.eval.map_field import (
    MARGIN_LENGTHS,
    lattice_correlation,
    map_error_field,
    spde_precision,
)
from tangraph.maps import BathymetryMap
from tangraph.sensors import NavigationModel, map_error, matern_correlation
from tests.eval.crb_cases import FIELD, MODEL, SLOPE, _seabed, _soundings, _survey


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


def test_a_trimmed_grid_keeps_the_nodes_near_the_footprints_with_free_edges_between_them():
    # Two short lines far apart in one box: the trimmed grid keeps the nodes within the margin of
    # a footprint (every node within 2 L of one, none beyond 2 L plus 2.5 spacings) and each
    # footprint's four nodes; its Laplacian has free edges (M 1 = c^2 1); kept all, it is the
    # whole grid's precision.
    north = np.r_[np.linspace(200.0, 260.0, 7), np.linspace(700.0, 760.0, 7)]
    east = np.r_[np.full(7, 200.0), np.full(7, 800.0)]
    error = map_error(_flat(), NavigationModel(map_std=0.2, map_correlation_length=30.0))
    whole, trimmed = map_error_field(north, east, error), map_error_field(north, east, error, trim=True)
    assert trimmed.spacing == whole.spacing and trimmed.shape == whole.shape
    assert trimmed.n_nodes < 0.5 * whole.n_nodes
    node_n, node_e = whole.nodes()
    distance = np.min(np.hypot(node_n[:, None] - north, node_e[:, None] - east), axis=1)
    kept = np.isin(np.arange(whole.n_nodes), trimmed.kept)
    assert np.all(kept[distance <= MARGIN_LENGTHS * 30.0])
    assert np.all(distance[kept] <= MARGIN_LENGTHS * 30.0 + 2.5 * whole.spacing)
    np.testing.assert_allclose(np.column_stack(trimmed.nodes()), np.column_stack([node_n, node_e])[kept])
    index, weight = trimmed.weights(north, east)
    whole_index, whole_weight = whole.weights(north, east)
    np.testing.assert_array_equal(trimmed.kept[index], whole_index)
    np.testing.assert_allclose(weight, whole_weight)
    np.testing.assert_allclose(trimmed.std, whole.std[kept])
    c = np.sqrt(8.0) * trimmed.spacing / 30.0
    variance, _ = lattice_correlation(c)
    m = splu(trimmed.precision.tocsc() / variance)  # M^2: M 1 = c^2 1, so M^2 1 = c^4 1
    np.testing.assert_allclose(m.solve(np.full(trimmed.n_nodes, c**4)), 1.0, rtol=1e-8)
    everything = spde_precision(whole.shape, c, np.arange(whole.n_nodes))
    assert abs(everything - whole.precision).max() == 0.0
    with pytest.raises(TangraphError, match="beyond the nodes"):
        trimmed.weights(np.array([480.0]), np.array([500.0]))


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


# -- the Cramér-Rao bound with the field -------------------------------------------------------
def test_a_field_of_offsets_is_seen_through_the_slope_and_tends_to_one_offset_at_long_range():
    survey, seabed = _survey(), _seabed()
    north, east = survey.footprints(survey.true_pose)
    used, _ = _soundings(survey, seabed)
    field = map_error_field(north[used], east[used], map_error(seabed, FIELD), offset=(1.0, 200.0))
    offsets = field.fields[-2:]
    assert [f.through[1] for f in offsets] == [0, 1] and all(f.correlation_length == 200.0 for f in offsets)
    for n, slope in zip((-2, -1), SLOPE, strict=True):  # the bilinear weights times the slope
        plain = offsets[n].weights(north[used], east[used])
        _, bilinear = map_field.MapErrorField.weights(
            map_field.dataclasses.replace(offsets[n], through=None), north[used], east[used])
        np.testing.assert_allclose(plain[1], slope * bilinear, rtol=1e-9)
    # with a map whose depth is exact (nothing for the offset to take out of its error), a field
    # of offsets of a range far beyond the survey is the one offset, and any offset raises the bound
    rigid = bound_rmse(posterior_crb(survey, seabed, MODEL.replace(map_offset_std=5.0)))
    for length in (1e5, 60.0, 20.0):
        model = MODEL.replace(map_offset_std=5.0, map_offset_length=length)
        got = bound_rmse(posterior_crb(survey, seabed, model))
        assert got > bound_rmse(posterior_crb(survey, seabed, MODEL))
        if length == 1e5:
            assert got == pytest.approx(rigid, rel=1e-3)
