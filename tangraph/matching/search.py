"""The criterion search of batch terrain matching (TAP): residual sums over a candidate grid.

A patch of ``N`` soundings (``offsets (N, 2)`` = (d_north, d_east) from a reference point and
measured ``depths (N,)``) is placed at every candidate ``X = (north, east)`` of a regular grid,
turned by each heading offset ``dpsi`` (``n' = cos dn - sin de``, ``e' = sin dn + cos de``). With
``h`` the map's bilinear depth at a sounding and ``d = h - z`` its residual, :func:`criterion_sums`
returns per candidate the sums from which every criterion follows (MSD, MAD, tide, Wang et al.'s
sigma^2, correlation, the fixed-tide RSS of Wang's region). Paths (none loops over candidates or
soundings in Python):

- ``"direct"``: numba kernels over candidates x soundings. When the candidate steps are whole map
  cells, a sounding's bilinear weights are the same at every candidate and the kernel runs
  unit-stride (SIMD) loops along candidate rows; otherwise it evaluates every bilinear depth.
- ``"fft"``: exact FFT correlation for whole-cell steps (any headings): ``sum_h`` and ``sum_hz``
  correlate the map with one kernel image each, ``sum_h2`` correlates the map's square and four
  products of neighbouring cells, the count a "cell quad touches NaN" image. ``sum_abs`` has no
  such form: it is NaN, and so is ``mad()``.
- ``"auto"``: ``fft`` where allowed and cheaper by a measured cost model, else ``direct``.

A candidate is valid when every sounding has a depth there (inside the map, no NaN among its 4
cells); elsewhere the sums are NaN and ``count`` (< N) says how many soundings had one. On the
whole-cell paths a sounding exactly on the map's last row or column line counts as off the map
(``depth_at`` clamps it in); this measure-zero case is the only difference between the paths.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from typing import Literal

import numba
import numpy as np
import scipy.fft

from tangraph.errors import TangraphError
from tangraph.geometry import rotate
from tangraph.maps.grid import BathymetryMap

__all__ = ["CandidateGrid", "CriterionSums", "SearchMethod", "criterion_sums"]

_log = logging.getLogger(__name__)

SearchMethod = Literal["auto", "direct", "fft"]

# fastmath without "nnan"/"ninf": NaN marks no-data and must survive.
_FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}
_jit = numba.njit(cache=True, nogil=True, fastmath=_FASTMATH)
_inline = numba.njit(cache=True, nogil=True, fastmath=_FASTMATH, inline="always")
_REGULAR_RTOL = 1e-6  # candidate axes must be this regular
_WHOLE_CELL_TOL = 1e-9  # largest drift (in cells) of a candidate axis from exact whole-cell shifts
_BYTES_PER_CANDIDATE = 12 * 8  # about twelve float64 arrays of the grid's shape at the peak
# Cost model of "auto", fitted on one core (AVX2) to benchmarks/bench_tap_search.py's cases.
_DIRECT_NS = (1e5, 40.0, 0.61)  # fixed, per (candidate row, sounding), per (candidate, sounding)
_FFT_NS = (9e5, 0.45)  # fixed per heading, per point x log2(points) of each of 19 FFTs


def _axis(values, name: str) -> np.ndarray:
    a = np.array(values, dtype=np.float64)
    if a.ndim != 1 or a.size < 1 or not np.all(np.isfinite(a)):
        raise TangraphError(f"CandidateGrid: {name} must be a non-empty 1-D array of finite numbers")
    if a.size > 1 and name != "headings":
        steps, step = np.diff(a), (a[-1] - a[0]) / (a.size - 1)
        if np.any(steps <= 0) or np.max(np.abs(steps - step)) > _REGULAR_RTOL * step:
            raise TangraphError(f"CandidateGrid: {name} must be ascending and regularly spaced")
    a.setflags(write=False)
    return a


@dataclasses.dataclass(frozen=True, eq=False)
class CandidateGrid:
    """Candidate positions ``north (nn,)`` x ``east (ne,)`` (regular, ascending, metres) of the
    patch's reference point and heading offsets ``headings (nh,)`` (radians, clockwise).

    Examples
    --------
    >>> g = CandidateGrid.around((100.0, 200.0), half_width=10.0, step=5.0)
    >>> g.shape, g.north.tolist()
    ((1, 5, 5), [90.0, 95.0, 100.0, 105.0, 110.0])
    """

    north: np.ndarray
    east: np.ndarray
    headings: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(1))

    def __post_init__(self) -> None:
        for name in ("north", "east", "headings"):
            object.__setattr__(self, name, _axis(getattr(self, name), name))

    @classmethod
    def around(cls, centre, half_width: float, step: float, headings=None) -> CandidateGrid:
        """The square grid ``centre + step * k``, ``|step * k| <= half_width``, on both axes."""
        centre = np.asarray(centre, dtype=np.float64)
        if centre.shape != (2,) or not np.all(np.isfinite(centre)):
            raise TangraphError(f"CandidateGrid.around: centre must be (north, east), got {centre!r}")
        if not (np.isfinite(step) and step > 0 and np.isfinite(half_width) and half_width >= 0):
            raise TangraphError(
                f"CandidateGrid.around: need step > 0 and half_width >= 0, got {step!r}, {half_width!r}"
            )
        k = step * np.arange(-(n := math.floor(half_width / step + 1e-9)), n + 1)
        return cls(centre[0] + k, centre[1] + k, np.zeros(1) if headings is None else headings)

    @property
    def shape(self) -> tuple[int, int, int]:
        """``(nh, nn, ne)``: the shape of every sum."""
        return self.headings.size, self.north.size, self.east.size

    @property
    def size(self) -> int:
        """Number of candidates (positions x headings)."""
        return math.prod(self.shape)

    def nbytes_needed(self) -> int:
        """Estimated peak bytes of a search over this grid (the FFT path adds its workspace)."""
        return _BYTES_PER_CANDIDATE * self.size


@dataclasses.dataclass(frozen=True, eq=False)
class CriterionSums:
    """Sums over the soundings of ``d = h - z``, ``d^2``, ``|d|``, ``h``, ``h^2``, ``h z`` per candidate
    ``(nh, nn, ne)``; ``count`` soundings had a map depth. The sums are NaN where ``count <
    n_soundings`` (``valid`` False); ``sum_abs`` is NaN everywhere on the ``fft`` path.
    ``sum_z``, ``sum_z2`` are the sums of the measured depths."""

    grid: CandidateGrid
    n_soundings: int
    count: np.ndarray
    sum_d: np.ndarray
    sum_d2: np.ndarray
    sum_abs: np.ndarray
    sum_h: np.ndarray
    sum_h2: np.ndarray
    sum_hz: np.ndarray
    sum_z: float
    sum_z2: float
    method: str

    def __post_init__(self) -> None:
        for name in ("count", "sum_d", "sum_d2", "sum_abs", "sum_h", "sum_h2", "sum_hz"):
            a = getattr(self, name)
            if a.shape != self.grid.shape:
                raise TangraphError(f"CriterionSums: {name} has shape {a.shape}, not {self.grid.shape}")
            a.setflags(write=False)

    @property
    def valid(self) -> np.ndarray:
        """Candidates where every sounding has a map depth."""
        return self.count == self.n_soundings

    def tide(self) -> np.ndarray:
        """Mean of the search's differences ``mean(h - z)`` (map minus measured: soundings = map +
        tide give ``-tide``; ``TapFix.tide`` turns it into the tide, ``measured - map``)."""
        return self.sum_d / self.n_soundings

    def msd(self) -> np.ndarray:
        """Mean squared difference ``mean(d^2)``."""
        return self.sum_d2 / self.n_soundings

    def mad(self) -> np.ndarray:
        """Mean absolute difference ``mean(|d|)`` (NaN on the ``fft`` path)."""
        return self.sum_abs / self.n_soundings

    def sigma2(self) -> np.ndarray:
        """Residual variance with the tide removed, ``sum((d - t)^2) / (n - 1)`` (Wang et al.
        eq. 4); NaN for a single sounding."""
        n = self.n_soundings
        if n < 2:
            return np.full(self.grid.shape, np.nan)
        return np.maximum((self.sum_d2 - self.sum_d**2 / n) / (n - 1), 0.0)

    def rss_fixed_tide(self, tide) -> np.ndarray:
        """``S = sum((d - tide)^2)`` for a given tide (Wang et al. eq. 10)."""
        return self.sum_d2 - 2.0 * tide * self.sum_d + self.n_soundings * tide**2

    def correlation(self) -> np.ndarray:
        """Normalised cross-correlation of ``h`` and ``z`` (NaN where either is constant)."""
        n = self.n_soundings
        cov = self.sum_hz - self.sum_h * self.sum_z / n
        var_h = np.maximum(self.sum_h2 - self.sum_h**2 / n, 0.0)
        var_z = max(self.sum_z2 - self.sum_z**2 / n, 0.0)
        with np.errstate(divide="ignore", invalid="ignore"):
            r = cov / np.sqrt(var_h * var_z)
        return np.where(np.isfinite(r), np.clip(r, -1.0, 1.0), np.nan)


# -- kernels -------------------------------------------------------------------------------------
# Both kernels walk tiles of candidate rows. For each block of _BLOCK soundings and each row of the
# tile they write the block's residuals along the row (NaN where a sounding has no depth), then add
# the block to the row's accumulators (soundings without a depth, sum d, d^2, d z, |d|) in two
# unit-stride loops that vectorise (split so that each stays within LLVM's limit of runtime alias
# checks). A tile's accumulators stay in cache while the block's map rows are reused.
_BLOCK = 8
_TILE_VALUES = 4096  # candidate rows per tile x candidate columns


@_inline
def _flush(block, zb, k, acc):
    """Add residual rows ``block[:k]`` (measured depths ``zb``) to ``acc (5, ne)``."""
    block[k:] = 0.0
    zb[k:] = 0.0
    bad, s1, s2, s3, s4 = acc[0], acc[1], acc[2], acc[3], acc[4]
    for c in range(acc.shape[1]):
        t1 = t2 = t3 = 0.0
        for q in range(_BLOCK):
            d = block[q, c]
            t1 += d
            t2 += d * d
            t3 += d * zb[q]
        s1[c] += t1
        s2[c] += t2
        s3[c] += t3
    for c in range(acc.shape[1]):
        t0 = t4 = 0.0
        for q in range(_BLOCK):
            d = block[q, c]
            t0 += 0.0 if d == d else 1.0
            t4 += abs(d)
        bad[c] += t0
        s4[c] += t4


@_inline
def _shift_row(depth, i, js, mj, t_y, t_x, zs, row):
    """Residuals along a candidate row of a sounding in cells ``(i, js + c mj)``."""
    ne, (ny, nx) = row.size, depth.shape
    c_lo = min(ne, 0 if js >= 0 else (mj - 1 - js) // mj)
    c_hi = min(ne - 1, (nx - 2 - js) // mj) if 0 <= i <= ny - 2 else -1
    row[:c_lo] = np.nan
    row[max(c_hi + 1, c_lo) :] = np.nan
    if c_hi < c_lo:
        return
    row0, row1 = depth[i], depth[i + 1]
    if mj == 1:  # unit stride, written apart so that it vectorises
        r0, r1, out = row0[js + c_lo : js + c_hi + 2], row1[js + c_lo : js + c_hi + 2], row[c_lo : c_hi + 1]
        for c in range(out.size):
            a = r0[c] + t_x * (r0[c + 1] - r0[c])
            b = r1[c] + t_x * (r1[c + 1] - r1[c])
            out[c] = a + t_y * (b - a) - zs
        return
    for c in range(c_lo, c_hi + 1):
        j = js + c * mj
        a = row0[j] + t_x * (row0[j + 1] - row0[j])
        b = row1[j] + t_x * (row1[j + 1] - row1[j])
        row[c] = a + t_y * (b - a) - zs


@_jit
def _shift_kernel(depth, i0, j0, ty, tx, z, mi, mj, out):
    """Whole-cell shifts: sounding s at candidate (r, c) lies in cell (i0 + r mi, j0 + c mj) with
    fractions (ty, tx). ``out (nn, 5, ne)`` gets count, sum d, d^2, d z, |d|."""
    nn, _, ne = out.shape
    ns = z.size
    block, zb = np.empty((_BLOCK, ne)), np.empty(_BLOCK)
    tile = max(1, _TILE_VALUES // ne)
    for r0 in range(0, nn, tile):
        for s0 in range(0, ns, _BLOCK):
            k = min(_BLOCK, ns - s0)
            for r in range(r0, min(r0 + tile, nn)):
                for q in range(k):
                    s = s0 + q
                    _shift_row(depth, i0[s] + r * mi, j0[s], mj, ty[s], tx[s], z[s], block[q])
                    zb[q] = z[s]
                _flush(block, zb, k, out[r])
    out[:, 0, :] = ns - out[:, 0, :]


@_jit
def _general_kernel(depth, north0, east0, inv_dn, inv_de, cand_n, cand_e, off_n, off_e, z, out):
    """Any grid: bilinear depths per (candidate, sounding) by ``depth_at``'s rules (map rows are
    blended first, then columns). ``off_n, off_e (nh, N)``; ``out (nh, nn, 5, ne)``."""
    ny, nx = depth.shape
    nh, ns = off_n.shape
    nn, ne = cand_n.size, cand_e.size
    block, zb = np.empty((_BLOCK, ne)), np.empty(_BLOCK)
    blend = np.full(nx + 1, np.nan)  # blend[nx] = NaN: the column of points off the map
    cols, fracs = np.empty((_BLOCK, ne), dtype=np.int64), np.empty((_BLOCK, ne))
    span = np.empty((_BLOCK, 2), dtype=np.int64)
    tile = max(1, _TILE_VALUES // ne)
    for h in range(nh):
        for r0 in range(0, nn, tile):
            for s0 in range(0, ns, _BLOCK):
                k = min(_BLOCK, ns - s0)
                for q in range(k):  # column and fraction of each sounding at each candidate column
                    span[q] = nx - 1, 0
                    for c in range(ne):
                        fx = (cand_e[c] + off_e[h, s0 + q] - east0) * inv_de
                        inside = fx >= 0.0 and fx <= nx - 1
                        j = min(int(fx), nx - 2) if inside else nx - 1
                        cols[q, c], fracs[q, c] = j, fx - j if inside else 0.0
                        if inside:
                            span[q] = min(span[q, 0], j), max(span[q, 1], j + 1)
                    zb[q] = z[s0 + q]
                for r in range(r0, min(r0 + tile, nn)):
                    for q in range(k):
                        fy = (cand_n[r] + off_n[h, s0 + q] - north0) * inv_dn
                        if not (fy >= 0.0 and fy <= ny - 1):
                            block[q, :] = np.nan
                            continue
                        i = min(int(fy), ny - 2)
                        t_y = fy - i
                        for c in range(span[q, 0], span[q, 1] + 1):
                            blend[c] = depth[i, c] + t_y * (depth[i + 1, c] - depth[i, c])
                        js, ts, row = cols[q], fracs[q], block[q]
                        for c in range(ne):
                            row[c] = blend[js[c]] + ts[c] * (blend[js[c] + 1] - blend[js[c]]) - zb[q]
                    _flush(block, zb, k, out[h, r])
    out[:, :, 0, :] = ns - out[:, :, 0, :]


# -- whole-cell shifts and the FFT path ----------------------------------------------------------
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


# -- the entry point -----------------------------------------------------------------------------
def _clean_patch(offsets, depths) -> tuple[np.ndarray, np.ndarray]:
    offsets, depths = np.asarray(offsets, dtype=np.float64), np.asarray(depths, dtype=np.float64)
    if offsets.ndim != 2 or offsets.shape[1] != 2 or depths.shape != (offsets.shape[0],):
        raise TangraphError(
            f"criterion_sums: offsets must be (N, 2) and depths (N,), got {offsets.shape} and {depths.shape}"
        )
    if not np.all(np.isfinite(offsets)):
        bad = int(np.sum(~np.all(np.isfinite(offsets), axis=1)))
        raise TangraphError(f"criterion_sums: {bad} sounding offsets are not finite")
    if np.any(np.isinf(depths)):
        raise TangraphError("criterion_sums: depths hold infinite values; mark missing soundings with NaN")
    keep = ~np.isnan(depths)
    if not np.any(keep):
        raise TangraphError(f"criterion_sums: the patch has no soundings ({depths.size} given, all NaN)")
    return np.ascontiguousarray(offsets[keep]), np.ascontiguousarray(depths[keep])


def criterion_sums(
    bathymetry: BathymetryMap,
    offsets,
    depths,
    grid: CandidateGrid,
    *,
    method: SearchMethod = "auto",
    max_bytes: float = 2e9,
) -> CriterionSums:
    """Residual sums of a patch of soundings at every candidate of ``grid``.

    Parameters
    ----------
    bathymetry : BathymetryMap
        The prior map (bilinear depths).
    offsets : array_like, shape (N, 2)
        ``(d_north, d_east)`` of each sounding from the patch's reference point, metres (finite).
    depths : array_like, shape (N,)
        Measured depths, positive down. Soundings with a NaN depth are dropped first, and
        ``n_soundings`` counts the rest.
    grid : CandidateGrid
        Candidate positions of the reference point and heading offsets of the patch.
    method : {"auto", "direct", "fft"}
        See the module docstring; ``"fft"`` needs candidate steps of whole map cells.
    max_bytes : float
        Refuse (TangraphError) a search whose arrays would need more memory than this.

    Returns
    -------
    CriterionSums

    Notes
    -----
    ``direct`` agrees with a per-candidate evaluation by ``depth_at`` to rounding (relative
    1e-12). ``fft`` works on depths centred on the mean measured depth; its absolute error on
    ``sum_d2`` (so on ``sigma2``, ``msd``) is below ``1e-14 N max|depth - mean(z)|^2`` over the
    searched window (measured: up to 3e-15): the relief sets it, not the depth. A perfect match
    leaves a residue of that size instead of an exact 0.

    Examples
    --------
    >>> import numpy as np
    >>> from tangraph.maps import BathymetryMap
    >>> axis = np.arange(50) * 2.0
    >>> m = BathymetryMap(north=axis, east=axis, depth=20 + np.add.outer(np.sin(axis / 7), np.cos(axis / 5)))
    >>> offsets = np.array([[0.0, 0.0], [3.0, 1.0], [-2.5, 4.0], [5.0, -3.5]])
    >>> z = m.depth_at(50.0 + offsets[:, 0], 40.0 + offsets[:, 1]) + 0.7  # truth (50, 40), tide 0.7
    >>> sums = criterion_sums(m, offsets, z, CandidateGrid.around((46.0, 44.0), 10.0, 2.0))
    >>> k = np.unravel_index(np.nanargmin(sums.sigma2()), sums.grid.shape)
    >>> float(sums.grid.north[k[1]]), float(sums.grid.east[k[2]]), round(float(sums.tide()[k]), 9)
    (50.0, 40.0, -0.7)
    """
    if not isinstance(bathymetry, BathymetryMap) or not isinstance(grid, CandidateGrid):
        raise TangraphError("criterion_sums: bathymetry must be a BathymetryMap and grid a CandidateGrid")
    if method not in ("auto", "direct", "fft"):
        raise TangraphError(f"criterion_sums: method must be auto, direct or fft, got {method!r}")
    offsets, z = _clean_patch(offsets, depths)
    n, (nh, nn, ne), (dn, de) = z.size, grid.shape, bathymetry.cell_size
    mi, mj = _cells_per_step(grid.north, dn), _cells_per_step(grid.east, de)
    whole_cell = mi is not None and mj is not None
    if method == "fft" and not whole_cell:
        raise TangraphError(
            f"criterion_sums: method 'fft' needs candidate steps of whole map cells ({dn:g} m x {de:g} m); "
            "use method 'direct' for this grid"
        )
    off_n, off_e = np.moveaxis(rotate(grid.headings[:, None], offsets), -1, 0).copy()  # (nh, N) each
    layouts = [_layout(bathymetry, np.column_stack([a, b]), grid) for a, b in zip(off_n, off_e, strict=True)]
    windows = [_fft_window(lay, nn, ne, mi, mj) for lay in layouts] if whole_cell else []
    if method == "auto":
        fft_ns = sum(_FFT_NS[0] + 19 * _FFT_NS[1] * (p := h * w) * math.log2(p) for h, w in windows)
        direct_ns = _DIRECT_NS[0] + nh * nn * n * (_DIRECT_NS[1] + _DIRECT_NS[2] * ne)
        method = "fft" if whole_cell and fft_ns < direct_ns else "direct"
    need = grid.nbytes_needed()
    if method == "fft":
        need += max(16 * 8 * math.prod(scipy.fft.next_fast_len(k, real=True) for k in w) for w in windows)
    if need > max_bytes:
        raise TangraphError(
            f"criterion_sums: {grid.shape} candidates would need about {need / 1e6:.0f} MB "
            f"(method {method!r}), more than max_bytes = {max_bytes / 1e6:.0f} MB; "
            "search a smaller grid or fewer headings"
        )
    _log.debug("criterion_sums: %s candidates x %d soundings by %s", grid.shape, n, method)
    sum_z, sum_z2 = float(z.sum()), float(z @ z)
    if method == "fft":
        count, sums = _fft_sums(bathymetry.depth, layouts, z, grid.shape, mi, mj)
    else:
        acc = np.zeros((nh, nn, 5, ne))
        if whole_cell:
            for h, (i0, j0, ty, tx) in enumerate(layouts):
                _shift_kernel(bathymetry.depth, i0, j0, ty, tx, z, mi, mj, acc[h])
        else:
            _general_kernel(bathymetry.depth, bathymetry.north[0], bathymetry.east[0], 1.0 / dn, 1.0 / de,
                            grid.north, grid.east, off_n, off_e, z, acc)  # fmt: skip
        count = acc[:, :, 0].astype(np.int64)
        sum_d, sum_d2, sum_dz = acc[:, :, 1], acc[:, :, 2], acc[:, :, 3]
        sums = {"sum_d": sum_d, "sum_d2": sum_d2, "sum_abs": acc[:, :, 4], "sum_h": sum_d + sum_z,
                "sum_h2": sum_d2 + 2.0 * sum_dz + sum_z2, "sum_hz": sum_dz + sum_z2}  # fmt: skip
    for a in sums.values():
        a[count != n] = np.nan
    return CriterionSums(grid, n, count, **sums, sum_z=sum_z, sum_z2=sum_z2, method=method)
