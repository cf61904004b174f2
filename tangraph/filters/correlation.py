"""Correlation of many sequences with one: Pearson, Spearman and Kendall's tau-b, per row.

``x (N, L)`` holds one sequence per row (a particle's predicted depths), ``y (L,)`` the
reference (the measured depths); each function returns ``(N,)`` coefficients, NaN where a row or
``y`` is constant or holds a NaN. Each is one compiled pass over the rows: Pearson ``O(L)`` per
row; Spearman, Pearson of average ranks (ties as :func:`scipy.stats.spearmanr`), ``O(L log L)``
(an insertion sort for windows up to 48, fastest there);
Kendall's tau-b ``O(L^2)``, matching :func:`scipy.stats.kendalltau` (variant ``"b"``).
"""

from __future__ import annotations

import enum

import numba
import numpy as np

from tangraph.errors import TangraphError

__all__ = ["Correlation", "correlate_rows", "kendall_rows", "pearson_rows", "spearman_rows"]


class Correlation(enum.StrEnum):
    """Which correlation SJCPF uses (Chen & Che 2022)."""

    PEARSON = "pearson"
    SPEARMAN = "spearman"
    KENDALL = "kendall"


def _checked(x, y) -> tuple[np.ndarray, np.ndarray]:
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    if x.ndim != 2 or y.ndim != 1 or x.shape[1] != y.size:
        raise TangraphError(f"correlation: need x (N, L) and y (L,), got {x.shape} and {y.shape}")
    return x, y


@numba.njit(cache=True, nogil=True)
def _pearson_kernel(x, y, out):
    n, length = x.shape
    y_mean = 0.0
    for i in range(length):
        y_mean += y[i]
    y_mean /= length
    yc = y - y_mean
    syy = 0.0
    for i in range(length):
        syy += yc[i] * yc[i]
    for p in range(n):
        x_mean = 0.0
        for i in range(length):
            x_mean += x[p, i]
        x_mean /= length
        sxy = 0.0
        sxx = 0.0
        for i in range(length):
            d = x[p, i] - x_mean
            sxy += d * yc[i]
            sxx += d * d
        denominator = np.sqrt(sxx * syy)
        if denominator > 0.0:
            out[p] = min(1.0, max(-1.0, sxy / denominator))
        else:
            out[p] = np.nan  # constant, or NaN anywhere (NaN > 0 is False)


_INSERTION_MAX = 48


@numba.njit(cache=True, nogil=True)
def _average_ranks(v, order, out):
    """Ranks 1..L of ``v`` with ties given their average rank (``scipy.stats.rankdata``);
    ``order`` is an (L,) int work array. Insertion sort for short windows, merge sort beyond."""
    length = v.size
    if length > _INSERTION_MAX:
        order[:] = np.argsort(v, kind="mergesort")
    else:
        for i in range(length):
            order[i] = i
    for i in range(1, length if length <= _INSERTION_MAX else 0):
        k = order[i]
        j = i - 1
        while j >= 0 and v[order[j]] > v[k]:
            order[j + 1] = order[j]
            j -= 1
        order[j + 1] = k
    i = 0
    while i < length:
        j = i
        while j + 1 < length and v[order[j + 1]] == v[order[i]]:
            j += 1
        rank = 0.5 * (i + j) + 1.0
        for k in range(i, j + 1):
            out[order[k]] = rank
        i = j + 1


@numba.njit(cache=True, nogil=True)
def _spearman_kernel(x, y, out):
    n, length = x.shape
    order = np.empty(length, dtype=np.int64)
    ry = np.empty(length)
    _average_ranks(y, order, ry)
    rx = np.empty((n, length))
    for p in range(n):
        _average_ranks(x[p], order, rx[p])
    _pearson_kernel(rx, ry, out)


def _has_nan(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    return np.isnan(x).any(axis=1) | bool(np.isnan(y).any())


def pearson_rows(x, y) -> np.ndarray:
    """Pearson's r of each row of ``x (N, L)`` with ``y (L,)``.

    Examples
    --------
    >>> pearson_rows([[1.0, 2.0, 3.0], [3.0, 2.0, 1.0]], [1.0, 2.0, 4.0]).round(4).tolist()
    [0.982, -0.982]
    """
    x, y = _checked(x, y)
    out = np.empty(x.shape[0])
    _pearson_kernel(np.ascontiguousarray(x), np.ascontiguousarray(y), out)
    return out


def spearman_rows(x, y) -> np.ndarray:
    """Spearman's rho (Pearson of average ranks) of each row of ``x (N, L)`` with ``y (L,)``."""
    x, y = _checked(x, y)
    out = np.empty(x.shape[0])
    _spearman_kernel(np.ascontiguousarray(x), np.ascontiguousarray(y), out)
    return np.where(_has_nan(x, y), np.nan, out)


@numba.njit(cache=True, nogil=True)
def _kendall_kernel(x, y, out):
    n, length = x.shape
    for p in range(n):
        concordant = 0.0  # minus discordant
        untied_x = 0.0  # pairs not tied in x
        untied_y = 0.0
        bad = False
        for i in range(length):
            if x[p, i] != x[p, i] or y[i] != y[i]:
                bad = True
                break
            for j in range(i + 1, length):
                dx = x[p, i] - x[p, j]
                dy = y[i] - y[j]
                sx = (dx > 0.0) - (dx < 0.0)
                sy = (dy > 0.0) - (dy < 0.0)
                concordant += sx * sy
                untied_x += sx * sx
                untied_y += sy * sy
        if bad or untied_x == 0.0 or untied_y == 0.0:
            out[p] = np.nan
        else:
            out[p] = concordant / np.sqrt(untied_x * untied_y)


def kendall_rows(x, y) -> np.ndarray:
    """Kendall's tau-b of each row of ``x (N, L)`` with ``y (L,)`` (ties as in scipy's tau-b)."""
    x, y = _checked(x, y)
    out = np.empty(x.shape[0])
    _kendall_kernel(np.ascontiguousarray(x), np.ascontiguousarray(y), out)
    return out


_ROWS = {
    Correlation.PEARSON: pearson_rows,
    Correlation.SPEARMAN: spearman_rows,
    Correlation.KENDALL: kendall_rows,
}


def correlate_rows(x, y, kind: Correlation | str = Correlation.PEARSON) -> np.ndarray:
    """The correlation ``kind`` of each row of ``x (N, L)`` with ``y (L,)``."""
    return _ROWS[Correlation(kind)](x, y)
