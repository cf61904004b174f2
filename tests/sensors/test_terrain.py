"""The terrain measurement model: the map's error, the row-sum bound, the information exponent."""

from __future__ import annotations

import numpy as np

from tangraph.maps import BathymetryMap
from tangraph.sensors import (
    NavigationModel,
    information_exponent,
    map_error,
    matern_correlation,
    shared_map_variances,
    sounding_variances,
)
from tests.sensors.terrain_cases import FLAT, scattered_survey


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


def test_the_information_exponent():
    w = np.full(5, 0.2)
    tight = np.array([[10.0], [10.01], [9.99], [10.0], [10.02]])
    wide = np.array([[10.0], [12.0], [8.0], [11.0], [9.0]])
    assert information_exponent(tight, w, np.array([0.04]))[0] == 0.0
    assert information_exponent(wide, w, np.array([0.04]))[0] > 0.9
    assert information_exponent(tight, w, np.array([0.0]))[0] == 1.0  # a perfect map
    missing = np.array([[np.nan], [np.nan], [np.nan], [np.nan], [np.nan]])
    assert information_exponent(missing, w, np.array([0.04]))[0] == 0.0


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
