"""The Matérn correlation of the map's error: the seeded field, and its gridded row sums and
quadratic form against direct sums."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.sensors import matern_correlation, matern_field
from tangraph.sensors.matern import _correlation_quadratic, _correlation_sums, _weighted_correlation_sums


def test_matern_field_has_its_std_and_correlation():
    axis = np.arange(0.0, 2000.0, 5.0)
    length, std = 60.0, 0.3
    fields = [matern_field(axis, axis, std, length, rng=np.random.default_rng(s)) for s in range(4)]
    f = np.stack(fields)
    # thousands of correlated samples: the variance within 10 %
    assert abs(f.var() / std**2 - 1) < 0.1, f.var()
    lag = int(length / 5.0)
    corr = np.mean(f[:, :, lag:] * f[:, :, :-lag]) / f.var()
    assert abs(corr - matern_correlation(length, length)) < 0.05, corr
    with pytest.raises(TangraphError, match="length > 0"):
        matern_field(axis, axis, 0.3, 0.0, rng=np.random.default_rng(0))


def test_correlation_sums_match_the_direct_sum():
    """The gridded sums against the direct sum of the Matérn correlation."""
    rng = np.random.default_rng(1)
    length = 20.0
    points = np.concatenate([rng.uniform(200, 260, (300, 2)), rng.uniform(500, 800, (200, 2))])
    weight = rng.uniform(0.1, 0.3, points.shape[0])
    got = _weighted_correlation_sums(points[:, 0], points[:, 1], weight, length)
    d = np.sqrt(np.sum((points[:, None, :] - points[None, :, :]) ** 2, axis=-1))
    want = matern_correlation(d, length) @ weight
    np.testing.assert_allclose(got, want, rtol=0.05)


def test_the_spectral_quadratic_is_the_read_back_one():
    """``_correlation_quadratic`` (Parseval on the splatted spectra) is ``w^T (sums - w)`` of the
    read-back sums to rounding, for weights of either sign on grids of odd and even FFT width."""
    rng = np.random.default_rng(12)
    for width, length in ((60.0, 10.0), (173.0, 23.0), (20.0, 10.0)):  # FFT widths 100, 108, 75
        north, east = rng.uniform(0, width, (2, 300))
        w = rng.normal(size=(300, 3))
        want = w.T @ (_correlation_sums(north, east, w, length) - w)
        np.testing.assert_allclose(_correlation_quadratic(north, east, w, length), want,
                                   rtol=1e-9, atol=1e-9 * np.abs(want).max())
