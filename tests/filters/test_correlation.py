"""The row-wise correlations against scipy.stats, with ties, NaN and constant rows."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from tangraph.errors import TangraphError
from tangraph.filters.correlation import (
    Correlation,
    correlate_rows,
    kendall_rows,
    pearson_rows,
    spearman_rows,
)

SCIPY = {
    "pearson": lambda a, b: stats.pearsonr(a, b)[0],
    "spearman": lambda a, b: stats.spearmanr(a, b)[0],
    "kendall": lambda a, b: stats.kendalltau(a, b, variant="b")[0],
}


@pytest.mark.parametrize("kind", list(Correlation))
@pytest.mark.parametrize("ties", [False, True])
@pytest.mark.parametrize("length", [12, 60])  # Spearman ranks by insertion sort, then merge sort
def test_rows_match_scipy(kind, ties, length):
    rng = np.random.default_rng(3)
    x = rng.normal(size=(200, length))
    y = rng.normal(size=length) + 0.5 * x[0]
    if ties:  # few distinct values: many ties in both sequences
        x, y = np.round(x * 1.5), np.round(y * 1.5)
    got = correlate_rows(x, y, kind)
    want = np.array([SCIPY[kind](row, y) for row in x])
    assert np.isfinite(want).all()
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-12)


def test_named_functions_agree_and_undefined_cases_are_nan():
    x = np.array([[1.0, 2.0, 3.0, 4.0], [5.0, 5.0, 5.0, 5.0], [1.0, np.nan, 3.0, 2.0]])
    y = np.array([2.0, 1.0, 4.0, 3.0])
    for fn in (pearson_rows, spearman_rows, kendall_rows):
        r = fn(x, y)
        assert np.isfinite(r[0]) and np.isnan(r[1]) and np.isnan(r[2]), fn.__name__
    assert kendall_rows(x[:1], y)[0] == pytest.approx(stats.kendalltau(x[0], y)[0])
    assert np.isnan(pearson_rows(x[:1], np.full(4, 2.0))[0])  # constant reference


def test_perfect_orderings():
    x = np.array([[1.0, 2.0, 3.0, 4.0, 5.0], [5.0, 4.0, 3.0, 2.0, 1.0]])
    y = np.array([10.0, 20.0, 30.0, 40.0, 80.0])
    np.testing.assert_allclose(spearman_rows(x, y), [1.0, -1.0])
    np.testing.assert_allclose(kendall_rows(x, y), [1.0, -1.0])


def test_shapes_are_checked():
    with pytest.raises(TangraphError, match="correlation"):
        pearson_rows(np.zeros((3, 4)), np.zeros(5))
    with pytest.raises(ValueError):
        correlate_rows(np.zeros((3, 4)), np.zeros(4), "cosine")
