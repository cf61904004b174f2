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
from typing import Literal, cast

import numpy as np
import scipy.fft

from tangraph.errors import TangraphError
from tangraph.geometry import rotate
from tangraph.maps.grid import BathymetryMap
from tangraph.matching.search_direct import _direct_sums
from tangraph.matching.search_fft import _cells_per_step, _fft_sums, _fft_window, _layout

__all__ = ["CandidateGrid", "CriterionSums", "SearchMethod", "criterion_sums"]

_log = logging.getLogger(__name__)

SearchMethod = Literal["auto", "direct", "fft"]

_REGULAR_RTOL = 1e-6  # candidate axes must be this regular
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


_Method = Literal["auto", "direct", "fft"]


def _choose_method(
    method: _Method, whole_cell: bool, windows, grid: CandidateGrid, n: int, max_bytes
) -> _Method:
    """``method``, ``"auto"`` resolved by the cost model; refuses a search needing over ``max_bytes``."""
    nh, nn, ne = grid.shape
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
    return method


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
    n, (_, nn, ne), (dn, de) = z.size, grid.shape, bathymetry.cell_size
    mi, mj = _cells_per_step(grid.north, dn), _cells_per_step(grid.east, de)
    whole_cell = mi is not None and mj is not None
    if method == "fft" and not whole_cell:
        raise TangraphError(
            f"criterion_sums: method 'fft' needs candidate steps of whole map cells ({dn:g} m x {de:g} m); "
            "use method 'direct' for this grid"
        )
    off_n, off_e = np.moveaxis(rotate(grid.headings[:, None], offsets), -1, 0).copy()  # (nh, N) each
    layouts = [_layout(bathymetry, np.column_stack([a, b]), grid) for a, b in zip(off_n, off_e, strict=True)]
    windows = [_fft_window(lay, nn, ne, cast(int, mi), cast(int, mj))
               for lay in layouts] if whole_cell else []
    method = _choose_method(method, whole_cell, windows, grid, n, max_bytes)
    _log.debug("criterion_sums: %s candidates x %d soundings by %s", grid.shape, n, method)
    sum_z, sum_z2 = float(z.sum()), float(z @ z)
    if method == "fft":
        count, sums = _fft_sums(bathymetry.depth, layouts, z, grid.shape, mi, mj)
    else:
        count, sums = _direct_sums(bathymetry, grid, layouts, off_n, off_e, z, mi, mj, whole_cell,
                                   sum_z, sum_z2)
    for a in sums.values():
        a[count != n] = np.nan
    return CriterionSums(grid, n, count, **sums, sum_z=sum_z, sum_z2=sum_z2, method=method)
