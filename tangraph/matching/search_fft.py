"""Whole-cell shifts and the ``fft`` path of the criterion search
(:func:`tangraph.matching.search.criterion_sums`): exact FFT correlation for candidate steps of whole
map cells (any headings). ``sum_h`` and ``sum_hz`` correlate the map with one kernel image each,
``sum_h2`` correlates the map's square and four products of neighbouring cells, the count a "cell
quad touches NaN" image; ``sum_abs`` has no such form and is NaN."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import scipy.fft

if TYPE_CHECKING:
    from tangraph.maps.grid import BathymetryMap
    from tangraph.matching.search import CandidateGrid

_WHOLE_CELL_TOL = 1e-9  # largest drift (in cells) of a candidate axis from exact whole-cell shifts


def _cells_per_step(axis: np.ndarray, cell: float) -> int | None:
    """``m`` if the axis steps by exactly ``m`` whole cells (within _WHOLE_CELL_TOL), else None."""
    if axis.size == 1:
        return 1
    m = round((axis[-1] - axis[0]) / ((axis.size - 1) * cell))
    drift = np.max(np.abs(axis - axis[0] - m * cell * np.arange(axis.size)))
    return m if m >= 1 and drift <= _WHOLE_CELL_TOL * cell else None


def _layout(bathymetry: BathymetryMap, offsets: np.ndarray, grid: CandidateGrid):
    """Cell ``(i0, j0)`` and fractions ``(ty, tx)`` of each sounding at the first candidate."""
    dn, de = bathymetry.cell_size
    fy = (grid.north[0] + offsets[:, 0] - bathymetry.north[0]) * (1.0 / dn)
    fx = (grid.east[0] + offsets[:, 1] - bathymetry.east[0]) * (1.0 / de)
    i0, j0 = np.floor(fy), np.floor(fx)
    return i0.astype(np.int64), j0.astype(np.int64), fy - i0, fx - j0


def _fft_window(layout, nn: int, ne: int, mi: int, mj: int) -> tuple[int, int]:
    """Shape of the map window that every candidate's soundings fall in."""
    return int(np.ptp(layout[0])) + 2 + (nn - 1) * mi, int(np.ptp(layout[1])) + 2 + (ne - 1) * mj


def _fft_heading(depth, layout, zc, centre, nn, ne, mi, mj):
    """``(soundings without a depth, sum h', sum h'^2, sum h'z')`` with ``h' = h - centre``."""
    i0, j0, ty, tx = layout
    u, v = i0 - i0.min(), j0 - j0.min()  # each sounding's cell within the window
    height, width = _fft_window(layout, nn, ne, mi, mj)
    window = np.full((height, width), np.nan)
    r0, c0 = int(i0.min()), int(j0.min())
    rs, re, cs, ce = max(r0, 0), min(r0 + height, depth.shape[0]), max(c0, 0), min(c0 + width, depth.shape[1])
    if rs < re and cs < ce:
        window[rs - r0 : re - r0, cs - c0 : ce - c0] = depth[rs:re, cs:ce] - centre
    nan = np.isnan(window)
    m = np.where(nan, 0.0, window)
    bad = (nan[:-1, :-1] | nan[:-1, 1:] | nan[1:, :-1] | nan[1:, 1:]).astype(np.float64)
    w00, w01, w10, w11 = (1 - ty) * (1 - tx), (1 - ty) * tx, ty * (1 - tx), ty * tx
    ku, kv = int(u.max()) + 2, int(v.max()) + 2
    corners = [(0, 0, w00), (0, 1, w01), (1, 0, w10), (1, 1, w11)]
    size = (scipy.fft.next_fast_len(height, real=True), scipy.fft.next_fast_len(width, real=True))

    def spectrum(image):
        return scipy.fft.rfft2(image, s=size)

    def kernel(shape, entries):  # spectrum of the weights scattered at (u + du, v + dv)
        flat = np.zeros(shape[0] * shape[1])
        for du, dv, values in entries:
            flat += np.bincount((u + du) * shape[1] + v + dv, weights=values, minlength=flat.size)
        return np.conj(spectrum(flat.reshape(shape)))

    def correlation(spectral):  # valid part, candidate steps only; no wrap-around (size >= window)
        return scipy.fft.irfft2(spectral, s=size)[: (nn - 1) * mi + 1 : mi, : (ne - 1) * mj + 1 : mj]

    f_m = spectrum(m)
    sum_h = correlation(f_m * kernel((ku, kv), corners))
    sum_hz = correlation(f_m * kernel((ku, kv), [(a, b, w * zc) for a, b, w in corners]))
    products = [  # sum_h2 = sum_s (sum_q w_q M_q)^2: squares, and pairs of neighbouring corners
        (m * m, (ku, kv), [(a, b, w * w) for a, b, w in corners]),
        (m[:, :-1] * m[:, 1:], (ku, kv - 1), [(0, 0, 2 * w00 * w01), (1, 0, 2 * w10 * w11)]),
        (m[:-1] * m[1:], (ku - 1, kv), [(0, 0, 2 * w00 * w10), (0, 1, 2 * w01 * w11)]),
        (m[:-1, :-1] * m[1:, 1:], (ku - 1, kv - 1), [(0, 0, 2 * w00 * w11)]),
        (m[:-1, 1:] * m[1:, :-1], (ku - 1, kv - 1), [(0, 0, 2 * w01 * w10)]),
    ]
    sum_h2 = correlation(sum(spectrum(image) * kernel(shape, e) for image, shape, e in products))
    n_bad = correlation(spectrum(bad) * kernel((ku - 1, kv - 1), [(0, 0, np.ones(u.size))]))
    return np.rint(n_bad).astype(np.int64), sum_h, sum_h2, sum_hz


def _fft_sums(depth, layouts, z, shape, mi, mj):
    """The sums by FFT: centring on the mean measured depth keeps the cancellation in
    ``sum_d2 = sum h'^2 - 2 sum h'z' + sum z'^2`` at the scale of the relief."""
    n, centre = z.size, float(z.mean())
    zc = z - centre
    parts = [_fft_heading(depth, lay, zc, centre, shape[1], shape[2], mi, mj) for lay in layouts]
    n_bad, sum_hc, sum_h2c, sum_hzc = (np.stack(p) for p in zip(*parts, strict=True))
    szc, szc2 = float(zc.sum()), float(zc @ zc)
    return n - n_bad, {
        "sum_d": sum_hc - szc,
        "sum_d2": np.maximum(sum_h2c - 2.0 * sum_hzc + szc2, 0.0),
        "sum_abs": np.full(shape, np.nan),
        "sum_h": sum_hc + n * centre,
        "sum_h2": sum_h2c + 2.0 * centre * sum_hc + n * centre**2,
        "sum_hz": sum_hzc + centre * (sum_hc + szc) + n * centre**2,
    }
