"""The terrain measurement model: the map's error, the row-sum bound, the information exponent."""

from __future__ import annotations

import numpy as np

from tangraph.maps import BathymetryMap
from tangraph.sensors import (
    MapError,
    NavigationModel,
    information_exponent,
    map_error,
    matern_correlation,
    shared_map_variances,
    sounding_variances,
)
from tangraph.survey import Survey

FLAT = BathymetryMap(np.arange(0.0, 1000, 10), np.arange(0.0, 1000, 10), np.full((100, 100), 30.0))


def scattered_survey(points: np.ndarray) -> Survey:
    """One sounding per ping at ``points (K, 2)`` (the vehicle over each)."""
    k = points.shape[0]
    pose = np.column_stack([points, np.zeros(k)])
    t = np.arange(float(k))
    return Survey(time=t, dr_pose=pose, vehicle_depth=0 * t, beam_forward=np.zeros((k, 1)),
                  beam_starboard=np.zeros((k, 1)), beam_depth=np.full((k, 1), 30.0))


def test_the_row_sum_variances_bound_the_dense_covariance():
    """``diag(v) - (sigma^2 I + S R S)`` is positive semi-definite: the independent-sounding
    likelihood with these variances claims no more information than the exact one."""
    rng = np.random.default_rng(2)
    points = rng.uniform(300, 400, (150, 2))
    model = NavigationModel(sounding_std=0.1, map_std=0.2, map_correlation_length=15.0)
    survey = scattered_survey(points)
    v = sounding_variances(survey, FLAT, model)[:, 0]
    d = np.sqrt(np.sum((points[:, None, :] - points[None, :, :]) ** 2, axis=-1))
    dense = 0.1**2 * np.eye(points.shape[0]) + 0.2**2 * matern_correlation(d, 15.0)
    exact = 0.1**2 + 0.2**2 * matern_correlation(d, 15.0).sum(axis=1)
    np.testing.assert_allclose(v, exact, rtol=0.05)
    assert np.linalg.eigvalsh(np.diag(exact) - dense).min() > -1e-9
    # the shared part is the sum less the sounding's own map error
    shared = shared_map_variances(survey, FLAT, model)[:, 0]
    np.testing.assert_allclose(v, 0.1**2 + 0.2**2 + shared, rtol=1e-12)


def test_a_perfect_map_leaves_the_sounding_noise():
    survey = scattered_survey(np.array([[100.0, 100.0], [100.0, 101.0]]))
    model = NavigationModel(sounding_std=0.3)
    np.testing.assert_allclose(sounding_variances(survey, FLAT, model), 0.09)
    np.testing.assert_allclose(shared_map_variances(survey, FLAT, model), 0.0)


def test_the_map_error_comes_from_the_map_or_the_model():
    error = map_error(FLAT, NavigationModel(map_std=0.4))
    assert error.correlation_length == 10.0  # one cell
    np.testing.assert_allclose(error.std_at(55.0, 55.0), 0.4)
    assert np.isnan(error.std_at(-50.0, 55.0))
    assert map_error(FLAT, NavigationModel()).is_zero
    assert map_error(FLAT, NavigationModel(map_correlation_length=35.0)).correlation_length == 35.0


def test_the_information_exponent():
    w = np.full(5, 0.2)
    tight = np.array([[10.0], [10.01], [9.99], [10.0], [10.02]])
    wide = np.array([[10.0], [12.0], [8.0], [11.0], [9.0]])
    assert information_exponent(tight, w, np.array([0.04]))[0] == 0.0
    assert information_exponent(wide, w, np.array([0.04]))[0] > 0.9
    assert information_exponent(tight, w, np.array([0.0]))[0] == 1.0  # a perfect map
    missing = np.array([[np.nan], [np.nan], [np.nan], [np.nan], [np.nan]])
    assert information_exponent(missing, w, np.array([0.04]))[0] == 0.0


def test_a_map_with_gaps_splits_its_error_by_scale():
    """Well-surveyed cells' error at the cell scale everywhere, the excess of the interpolated
    ones over it correlated over the map's correlation length; the variance is kept."""
    std = np.where(np.arange(100)[None, :] < 50, 0.1, 0.4) * np.ones((100, 1))
    gappy = FLAT.replace(depth_std=std, correlation_length=40.0)
    cell, excess = map_error(gappy, NavigationModel()).components()
    assert (cell.correlation_length, excess.correlation_length) == (10.0, 40.0)
    np.testing.assert_allclose(cell.std, 0.1)
    np.testing.assert_allclose(cell.std**2 + excess.std**2, std**2)
    assert np.all(excess.std[:, :50] == 0.0)
    # a uniform std, or a range of a cell: one field
    uniform = map_error(FLAT, NavigationModel(map_std=0.2, map_correlation_length=30.0)).components()
    assert len(uniform) == 1 and uniform[0].correlation_length == 30.0
    assert len(map_error(gappy.replace(correlation_length=10.0), NavigationModel()).components()) == 1


def test_the_change_since_the_map_is_a_field_of_its_own():
    """The model's change adds to every cell in quadrature, as a uniform field of its own range
    beside the map's own statement, which keeps its split; the offset leaves the change whole."""
    std = np.where(np.arange(100)[None, :] < 50, 0.1, 0.4) * np.ones((100, 1))
    gappy = FLAT.replace(depth_std=std, correlation_length=40.0)
    error = map_error(gappy, NavigationModel(map_change_std=0.2, map_change_length=25.0))
    np.testing.assert_allclose(error.std**2, std**2 + 0.04)
    cell, excess, change = error.components()
    assert [p.correlation_length for p in (cell, excess, change)] == [10.0, 40.0, 25.0]
    np.testing.assert_allclose(cell.std**2 + excess.std**2, std**2)
    np.testing.assert_allclose(change.std, 0.2)
    np.testing.assert_allclose(error.own.std, std)
    # the map's own correlation length when the change states none; none at all on a perfect map
    assert map_error(gappy, NavigationModel(map_change_std=0.2)).change_length == 40.0
    alone = map_error(FLAT, NavigationModel(map_change_std=0.2)).components()
    assert len(alone) == 1 and alone[0].correlation_length == 10.0
    # more error shared: a sounding among others counts for less
    points = np.array([[300.0, 300.0], [300.0, 310.0], [310.0, 300.0]])
    survey = scattered_survey(points)
    told = NavigationModel(sounding_std=0.1, map_std=0.1, map_change_std=0.2, map_change_length=50.0)
    added = sounding_variances(survey, FLAT, told) - sounding_variances(survey, FLAT,
                                                                        told.replace(map_change_std=0))
    d = np.sqrt(np.sum((points[:, None, :] - points[None, :, :]) ** 2, axis=-1))
    np.testing.assert_allclose(added[:, 0], 0.04 * matern_correlation(d, 50.0).sum(axis=1), rtol=0.05)
    plane = BathymetryMap(FLAT.north, FLAT.east, 30.0 + 0.1 * FLAT.north[:, None] + 0 * FLAT.east)
    offset = map_error(plane, NavigationModel(map_std=0.3, map_change_std=0.2)).without_offset(2.0)
    np.testing.assert_allclose(offset.std**2, 0.3**2 - (2.0 * 0.1) ** 2 + 0.2**2, rtol=1e-9)
    assert offset.change_std == 0.2


def test_a_change_larger_than_the_std_it_is_part_of_is_refused():
    import pytest

    from tangraph.errors import TangraphError

    with pytest.raises(TangraphError, match="change since the map .0.3 m. is part of its std"):
        MapError(FLAT, np.full(FLAT.shape, 0.2), 20.0, change_std=0.3)
    with pytest.raises(TangraphError, match="change_std and change_length must be >= 0"):
        MapError(FLAT, np.full(FLAT.shape, 0.2), 20.0, change_std=-0.1)


def test_the_error_a_windows_soundings_share_among_themselves():
    """``shared_among`` of some points is the shared variance of a survey made of them alone."""
    from tangraph.sensors import shared_among

    rng = np.random.default_rng(5)
    points = rng.uniform(300, 360, (80, 2))
    model = NavigationModel(sounding_std=0.1, map_std=0.2, map_correlation_length=25.0)
    error = map_error(FLAT, model)
    np.testing.assert_allclose(shared_among(points[:, 0], points[:, 1], error),
                               shared_map_variances(scattered_survey(points), FLAT, model)[:, 0], rtol=1e-12)
    # fewer soundings share less: the survey's other soundings add to a window's own
    survey = scattered_survey(np.concatenate([points, rng.uniform(300, 360, (200, 2))]))
    own = shared_among(points[:, 0], points[:, 1], error)
    assert np.all(shared_map_variances(survey, FLAT, model)[:80, 0] > own)


def _dense_quadratic(north, east, vectors, error):
    """The reference of ``shared_quadratic``: every pair's covariance, off the diagonal."""
    from tangraph.sensors import matern_correlation

    distance = np.hypot(north[:, None] - north[None], east[:, None] - east[None])
    out = np.zeros((vectors.shape[1], vectors.shape[1]))
    for part in error.components():
        w = part.std_at(north, east)[:, None] * vectors
        correlation = matern_correlation(distance, part.correlation_length)
        np.fill_diagonal(correlation, 0.0)
        out += w.T @ correlation @ w
    return out


def test_the_map_error_a_windows_soundings_share_in_a_fix():
    """``shared_quadratic`` is the dense double sum over pairs (to the grid's 2 %, for vectors of
    either sign and a two-scale error), the sum of ``shared_among`` for unit vectors, and far
    below that row-sum bound for gradients of mixed sign, which cancel."""
    from tangraph.sensors import shared_among, shared_quadratic

    rng = np.random.default_rng(11)
    std = 0.1 + 0.3 * rng.random((100, 100))  # gappy: a cell-scale and a 40 m field
    error = map_error(FLAT.replace(depth_std=std, correlation_length=40.0), NavigationModel())
    assert len(error.components()) == 2
    north, east = rng.uniform(300, 420, (2, 600))
    gradients = rng.normal(size=(600, 2)) + np.array([0.3, -0.2])
    fast = shared_quadratic(north, east, gradients, error)
    dense = _dense_quadratic(north, east, gradients, error)
    assert np.linalg.norm(fast - dense) < 0.02 * np.linalg.norm(dense)
    np.testing.assert_allclose(fast, fast.T)
    ones = shared_quadratic(north, east, np.ones((600, 1)), error)[0, 0]
    np.testing.assert_allclose(ones, shared_among(north, east, error).sum(), rtol=1e-9)
    bound = (gradients * shared_among(north, east, error)[:, None]).T @ gradients
    assert np.trace(fast) < 0.2 * np.trace(bound)
    assert shared_quadratic(north[:1], east[:1], gradients[:1], error).tolist() == [[0.0, 0.0], [0.0, 0.0]]


def test_the_offset_takes_its_part_of_the_stated_error_out_through_the_slope():
    # a plane of slope 0.1 whose cells state 0.3 m and the 2 m positioning error's 0.2 m through
    # the slope: held apart, the offset leaves 0.3 m; where the offset would explain more than
    # three quarters of the stated variance, half the stated std is kept
    axis = np.arange(0.0, 200.0, 10.0)
    plane = BathymetryMap(axis, axis, 30.0 + 0.1 * axis[:, None] + 0 * axis)
    stated = np.hypot(0.3, 2.0 * 0.1)
    error = MapError(plane, np.full(plane.shape, stated), 30.0)
    np.testing.assert_allclose(error.without_offset(2.0).std, 0.3, rtol=1e-9)
    assert error.without_offset(0.0) is error
    np.testing.assert_allclose(error.without_offset(20.0).std, 0.5 * stated, rtol=1e-9)
    assert error.without_offset(2.0).correlation_length == 30.0


def test_the_count_form_bounds_the_dense_covariance_of_a_varying_error():
    """``diag(sigma^2 + sum_f a_f(p_b)^2 n_fb) - C`` is positive semi-definite for a map whose
    error varies across it (two fields: cell-scale and excess, :meth:`MapError.components`),
    though each sounding's variance needs the error's std at its own footprint only; and it is
    what the filters' variance grids times the counts give."""
    from tangraph.sensors import map_error_grids, sounding_map_counts

    rng = np.random.default_rng(4)
    north, east = np.meshgrid(FLAT.north, FLAT.east, indexing="ij")
    varying = FLAT.replace(depth_std=0.05 + 0.6 * (east > 350.0) + 0.2 * np.sin(north / 40.0) ** 2,
                           correlation_length=40.0)
    model = NavigationModel(sounding_std=0.1)
    points = rng.uniform(300, 420, (200, 2))
    survey = scattered_survey(points)
    counts = sounding_map_counts(survey, varying, model)[:, 0, :]
    grids = map_error_grids(varying, model)
    parts = map_error(varying, model).components()
    assert len(parts) == 2 and counts.shape == (200, 2) and grids.shape == (*FLAT.shape, 2)
    d = np.sqrt(np.sum((points[:, None, :] - points[None, :, :]) ** 2, axis=-1))
    dense = 0.1**2 * np.eye(points.shape[0])
    bound = np.full(points.shape[0], 0.1**2)
    for f, part in enumerate(parts):
        a = part.std_at(points[:, 0], points[:, 1])
        dense = dense + np.outer(a, a) * matern_correlation(d, part.correlation_length)
        np.testing.assert_allclose(counts[:, f], matern_correlation(d, part.correlation_length).sum(1),
                                   rtol=0.05)  # (the sums are made on a grid)
        bound = bound + a**2 * counts[:, f]
        inside = (points[:, 0] > 10) & (points[:, 1] > 10)
        grid_field = BathymetryMap(FLAT.north, FLAT.east, grids[:, :, f])
        # bilinear in the variance, not in the std: never below the square of the std's (Jensen)
        read = grid_field.depth_at(points[inside, 0], points[inside, 1])
        assert np.all(read >= a[inside] ** 2 - 1e-12)
        assert np.mean(read - a[inside] ** 2) < 0.05 * np.mean(a[inside] ** 2)
    assert np.linalg.eigvalsh(np.diag(bound) - dense).min() > -1e-9


def test_placed_variances_are_the_count_form_read_where_the_soundings_are_put():
    """With one error field of uniform std the count form is the row sum: placed at their own
    footprints the soundings get :func:`sounding_variances`. Placed 300 m east, in a stretch
    known ten times worse, each reads that stretch's error with the counts of its own
    geometry (a dead reckoning's footprints are placed well relative to each other)."""
    from tangraph.sensors import placed_map_variances, sounding_map_counts

    rng = np.random.default_rng(5)
    points = rng.uniform(300, 400, (120, 2))
    survey = scattered_survey(points)
    model = NavigationModel(sounding_std=0.1, map_std=0.2, map_correlation_length=15.0)
    even = FLAT.replace(depth_std=np.full(FLAT.shape, 0.2), correlation_length=15.0)
    counts = sounding_map_counts(survey, even, model)
    shared, own = placed_map_variances(map_error(even, model), counts, points[:, None, 0], points[:, None, 1])
    np.testing.assert_allclose(0.1**2 + shared, sounding_variances(survey, even, model), rtol=1e-12)
    np.testing.assert_allclose(own, 0.2**2)

    east = np.broadcast_to(FLAT.east, FLAT.shape)
    two = FLAT.replace(depth_std=np.where(east >= 600.0, 2.0, 0.2), correlation_length=15.0)
    error = map_error(two, model)
    counts = sounding_map_counts(survey, two, model)
    here = placed_map_variances(error, counts, points[:, None, 0], points[:, None, 1])
    there = placed_map_variances(error, counts, points[:, None, 0], points[:, None, 1] + 300.0)
    np.testing.assert_allclose(here[1], 0.2**2, rtol=1e-12)
    np.testing.assert_allclose(there[1], 2.0**2, rtol=1e-12)  # every field's variance, summed
    fields = [part.std_at(points[:, 0], points[:, 1] + 300.0) ** 2 for part in error.components()]
    expected = sum(f * counts[:, 0, i] for i, f in enumerate(fields))
    np.testing.assert_allclose(there[0][:, 0], expected, rtol=1e-12)
    assert np.all(there[0] > 50 * here[0])
