"""Tests of the map error's Gaussian-Markov field (tangraph.eval.map_field): its marginal variance
and its correlation at the range against the Matérn figures (away from the grid's edges), the
nugget that makes every footprint's variance the model's, and the grid laid over the
footprints; and the Cramér-Rao bound's joint solve with it: a vanishing field tends to the bound
without it; on a planar seabed it equals a dense linear-Gaussian solve with the field's
covariance among all soundings; the field never lowers the bound, and a long-range field shared
by two passes of one line keeps the second pass from halving the first's variance; the filter
bound is never below the smoother's."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.sparse.linalg import splu

import tangraph.eval.map_field as map_field
from tangraph.eval import bound_rmse, posterior_crb
from tangraph.eval.map_field import (
    MARGIN_LENGTHS,
    lattice_correlation,
    map_error_field,
    spde_precision,
)
from tangraph.maps import BathymetryMap
from tangraph.sensors import NavigationModel, map_error, matern_correlation
from tangraph.survey import Survey
from tests.eval.crb_cases import MODEL, SLOPE, _design, _seabed, _soundings, _survey

FIELD = MODEL.replace(map_std=0.3, map_correlation_length=60.0)


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


# -- the Cramér-Rao bound with the field -------------------------------------------------------
@pytest.mark.parametrize("kind", ["smoother", "filter"])
def test_a_vanishing_field_tends_to_the_bound_without_it(kind):
    survey, seabed = _survey(), _seabed()
    old = posterior_crb(survey, seabed, MODEL, kind=kind)
    gaps = []
    for std in (0.3, 0.03, 3e-3, 3e-7):
        got = posterior_crb(survey, seabed, FIELD.replace(map_std=std), kind=kind)
        assert got.map_error and got.field_nodes > 0
        gaps.append(np.max(np.abs(got.position_cov - old.position_cov)) / np.abs(old.position_cov).max())
    assert gaps[0] > 1e-2 and np.all(np.diff(gaps) < 0)
    assert gaps[-1] < 1e-9  # the joint sparse solve holds the same DR model as the Kalman filter
    assert got.tide_std == pytest.approx(old.tide_std, rel=1e-9)
    np.testing.assert_allclose(got.calibration_cov, old.calibration_cov, rtol=1e-8)


def test_a_dead_reckoning_without_speed_noise_is_bounded_through_a_tiny_step_variance():
    # An exact constraint cannot enter the information matrix: the step gets the variance
    # map_field.ZERO_VARIANCE in natural units, about that much times the pings off, relatively.
    model = MODEL.replace(heading_noise=0.0, heading_walk=0.0, speed_noise=0.0)
    survey, seabed = _survey(), _seabed()
    old = posterior_crb(survey, seabed, model)
    got = posterior_crb(survey, seabed, model.replace(map_std=3e-7, map_correlation_length=60.0))
    np.testing.assert_allclose(got.position_cov, old.position_cov, rtol=1e-5)


def test_the_bound_equals_a_dense_solve_with_the_fields_covariance_among_all_soundings():
    # The linear-Gaussian model on a plane: every sounding's row on the DR inputs, and the noise of
    # all soundings together, sounding_std^2 I + diag(nugget) + (W S) Q^-1 (W S)^T, with the field's
    # own nodes, precision Q, node stds S and interpolation weights W. Smoother: the whole survey;
    # filter: the soundings of pings up to k (their noise's marginal is the principal block).
    survey, seabed, model = _survey(), _seabed(), FIELD
    a, e, tide_row, var = _design(survey, model)
    used, turn = _soundings(survey, seabed)
    ping, _ = np.nonzero(used)
    h = -(np.array(SLOPE) @ a)[ping] - turn[used][:, None] * e[ping] + tide_row
    north, east = survey.footprints(survey.true_pose)
    field = map_error_field(north[used], east[used], map_error(seabed, model))
    assert 100 < field.n_nodes < 2000
    node, weight = field.weights(north[used], east[used])
    w = np.zeros((h.shape[0], field.n_nodes))
    np.add.at(w, (np.arange(h.shape[0])[:, None], node), weight * field.std[node])
    noise = (np.diag(model.sounding_std**2 + field.nugget(node, weight))
             + w @ np.linalg.inv(field.precision.toarray()) @ w.T)
    keep = var > 0
    a, h, var = a[:, :, keep], h[:, keep], var[keep]

    def covariance(rows):
        info = np.diag(1 / var) + h[rows].T @ np.linalg.solve(noise[np.ix_(rows, rows)], h[rows])
        return np.linalg.inv(info)

    full = covariance(np.arange(h.shape[0]))
    smoother = np.einsum("kap,pq,kbq->kab", a, full, a)
    filt = np.array([a[k] @ covariance(np.flatnonzero(ping <= k)) @ a[k].T for k in range(survey.n_pings)])
    got_smoother = posterior_crb(survey, seabed, model)
    got_filter = posterior_crb(survey, seabed, model, kind="filter")
    for got, want in ((got_smoother.position_cov, smoother), (got_filter.position_cov, filt)):
        scale = np.abs(want).max(axis=(1, 2), keepdims=True)
        assert np.all(np.abs(got - want) <= 1e-8 * scale)
    np.testing.assert_allclose(got_smoother.calibration_cov, full[2:4, 2:4], rtol=1e-8)
    assert got_smoother.tide_std == pytest.approx(np.sqrt(full[4, 4]), rel=1e-8)
    old = posterior_crb(survey, seabed, MODEL)  # and the field does matter here
    assert bound_rmse(got_smoother) > 1.02 * bound_rmse(old)


@pytest.mark.parametrize("kind", ["smoother", "filter"])
def test_the_map_error_never_lowers_the_bound(kind):
    survey, seabed = _survey(), _seabed()
    without = posterior_crb(survey, seabed, MODEL, kind=kind)
    for length in (10.0, 60.0, 400.0):
        with_field = posterior_crb(survey, seabed, FIELD.replace(map_correlation_length=length), kind=kind)
        gap = np.linalg.eigvalsh(with_field.position_cov - without.position_cov)
        assert np.all(gap >= -1e-9 * np.abs(without.position_cov).max())
        assert bound_rmse(with_field) > bound_rmse(without)


def _two_passes(passes: int) -> Survey:
    """North along a line at 2 m/s, one ping a second (``passes=2``: then back south on it)."""
    t = np.arange(200.0 * passes)
    north = np.where(t < 200, 200 + 2 * t, 200 + 2 * (399 - t))
    psi = np.where(t < 200, 0.0, np.pi)
    truth = np.column_stack([north, 500 + 0 * t, psi])
    offset = np.tile(np.linspace(-20.0, 20.0, 9), (t.size, 1))
    return Survey(time=t, dr_pose=truth, vehicle_depth=0 * t, beam_forward=0 * offset,
                  beam_starboard=offset, beam_depth=25 + 0 * offset, true_pose=truth)


def test_a_long_range_map_error_is_shared_by_a_second_pass_of_the_same_line():
    # A plane sloping north, the tide known, a DR so good that a pass is one rigid offset: with
    # independent map errors a second pass over the same footprints halves the north variance;
    # with a map error of long range the second pass meets the same errors and gains nothing, and
    # the north error cannot drop below what a constant map error hides, about (s / slope)^2.
    axis = np.arange(0.0, 1001.0, 10.0)
    seabed = BathymetryMap(north=axis, east=axis, depth=20 + 0.04 * axis[:, None] + 0 * axis)
    model = NavigationModel(speed_noise=1e-4, heading_noise=0.0, heading_walk=0.0, speed_scale_std=1e-6,
                            heading_bias_std=1e-6, initial_position_std=10.0, sounding_std=0.2,
                            tide_std=0.0, map_std=0.3, map_correlation_length=2000.0)
    white = model.replace(sounding_std=float(np.hypot(0.2, 0.3)), map_std=0.0)
    north = {}
    for name, m in (("shared", model), ("independent", white)):
        one, two = (posterior_crb(_two_passes(p), seabed, m).position_cov[:200, 0, 0] for p in (1, 2))
        north[name] = (one, two)
    one, two = north["independent"]
    assert np.mean(two / one) == pytest.approx(0.5, abs=0.02)
    one, two = north["shared"]
    assert np.mean(two / one) > 0.95
    assert np.min(two) > 0.5 / (1 / 10.0**2 + (0.04 / 0.3) ** 2)  # half the constant error's floor
    assert np.min(two) > 100 * np.max(north["independent"][1])


@pytest.mark.parametrize("exact_pings", [250, 12])
def test_the_filter_bound_is_never_below_the_smoother_bound(monkeypatch, exact_pings):
    # 300 pings on circles (the track turns all the time) over the plane: the survey revisits its
    # own footprints. With 12 exact pings the rest are interpolated.
    monkeypatch.setattr(map_field, "FILTER_PINGS", exact_pings)
    survey, seabed = _survey(300, 7), _seabed(east_end=1000.0)
    model = FIELD.replace(map_correlation_length=40.0)
    smooth = posterior_crb(survey, seabed, model)
    filt = posterior_crb(survey, seabed, model, kind="filter")
    gap = np.linalg.eigvalsh(filt.position_cov - smooth.position_cov)
    assert np.all(gap >= -1e-9 * np.abs(smooth.position_cov).max())
    assert np.max(gap[:-5]) > 1e-2
    np.testing.assert_allclose(filt.position_cov[-1], smooth.position_cov[-1], rtol=1e-8)
    if exact_pings == 12:  # where solved, the same as solving at every ping
        monkeypatch.setattr(map_field, "FILTER_PINGS", survey.n_pings)
        every = posterior_crb(survey, seabed, model, kind="filter").position_cov
        pings = np.unique(np.round(np.linspace(0, survey.n_pings - 1, 12)).astype(int))
        np.testing.assert_allclose(filt.position_cov[pings], every[pings], rtol=1e-8,
                                   atol=1e-10 * np.abs(every).max())


@pytest.mark.parametrize("kind", ["smoother", "filter"])
def test_the_maps_offset_is_an_unknown_the_slope_shows_as_the_vehicles_position(kind):
    # On a plane a rigid offset o of the map is seen exactly as the vehicle's position is
    # (g . o): the bound equals a dense solve with o two more inputs of prior std 1 m, above
    # the bound without it.
    survey, seabed = _survey(), _seabed()
    model = MODEL.replace(map_offset_std=1.0)
    a, e, tide_row, var = _design(survey, model)
    used, turn = _soundings(survey, seabed)
    ping, _ = np.nonzero(used)
    h = -(np.array(SLOPE) @ a)[ping] - turn[used][:, None] * e[ping] + tide_row
    h = np.column_stack([h, np.tile(-np.array(SLOPE), (h.shape[0], 1))])
    var = np.r_[var, 1.0, 1.0]
    a = np.concatenate([a, a[:, :, :2]], axis=2)  # the vehicle's position, the offset apart
    a[:, :, -2:] = 0.0
    keep = var > 0
    a, h, var = a[:, :, keep], h[:, keep], var[keep]

    def covariance(rows):
        return np.linalg.inv(np.diag(1 / var) + h[rows].T @ h[rows] / model.sounding_std**2)

    if kind == "smoother":
        want = np.einsum("kap,pq,kbq->kab", a, covariance(np.arange(h.shape[0])), a)
    else:
        want = np.array([a[k] @ covariance(np.flatnonzero(ping <= k)) @ a[k].T
                         for k in range(survey.n_pings)])
    got = posterior_crb(survey, seabed, model, kind=kind).position_cov
    scale = np.abs(want).max(axis=(1, 2), keepdims=True)
    assert np.all(np.abs(got - want) <= 1e-8 * scale)
    assert bound_rmse(posterior_crb(survey, seabed, MODEL, kind=kind)) < np.sqrt(
        np.mean(np.trace(got, axis1=1, axis2=2)))


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
