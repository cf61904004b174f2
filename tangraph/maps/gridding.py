"""Maps gridded from soundings: a vectorised block reduce, gap filling, and surveys in one frame.

:func:`block_reduce` bins ``(north, east, depth)`` points into square cells and gives the count,
(weighted) mean, (weighted) median and spread of depth per cell, by one sort of the points by
cell (no Python loop over cells). :func:`fill_gaps` gives empty cells near data a depth by
inverse-distance weighting. :func:`grid_surveys` places the soundings of one or more
:class:`~tangraph.survey.Survey` at their reference tracks, in the frame of the first, and grids
them into a map that keeps the first survey's CRS and origin. :func:`gridded_error` gives the
map its error as data (a standard deviation per cell and a correlation length), which
:attr:`SoundingGrid.depth <tangraph.maps.SoundingGrid.depth>` carries.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Sequence
from typing import Literal

import numpy as np

from tangraph.errors import TangraphError
from tangraph.maps.grid import BathymetryMap
from tangraph.maps.mesh import SoundingGrid, _axis, _check_cell
from tangraph.survey import Survey

__all__ = [
    "DEFAULT_VERTICAL_DATUM",
    "GriddedError",
    "Statistic",
    "block_reduce",
    "fill_gaps",
    "grid_surveys",
    "gridded_error",
]

log = logging.getLogger(__name__)

Statistic = Literal["mean", "median"]
DEFAULT_VERTICAL_DATUM = "water surface"  # what a survey without meta["vertical_datum"] means


# -- block reduce -----------------------------------------------------------------------------
def _extent(pts: np.ndarray, cell: float, extent, where: str) -> tuple[float, float, float, float]:
    if extent is None:
        n_lo, e_lo = pts[:, 0].min(), pts[:, 1].min()
        n_hi, e_hi = pts[:, 0].max(), pts[:, 1].max()
        n_hi = n_lo + cell * np.rint((n_hi - n_lo) / cell)
        e_hi = e_lo + cell * np.rint((e_hi - e_lo) / cell)
        return n_lo, n_hi, e_lo, e_hi
    n_lo, n_hi, e_lo, e_hi = (float(x) for x in extent)
    if not (np.isfinite([n_lo, n_hi, e_lo, e_hi]).all() and n_lo < n_hi and e_lo < e_hi):
        raise TangraphError(f"{where}: extent must be finite (lo, hi, lo, hi), got {extent!r}")
    return n_lo, n_hi, e_lo, e_hi


def _check_weights(weights, n: int, where: str) -> np.ndarray:
    if weights is None:
        return np.ones(n)
    w = np.asarray(weights, dtype=np.float64)
    if w.shape != (n,):
        raise TangraphError(f"{where}: weights must have shape ({n},) like the points, got {w.shape}")
    if not np.all(np.isfinite(w) & (w > 0)):
        raise TangraphError(f"{where}: weights must be finite and positive")
    return w


def block_reduce(
    points,
    *,
    cell: float,
    weights=None,
    extent: tuple[float, float, float, float] | None = None,
    statistic: Statistic = "mean",
    name: str = "soundings",
    crs: str | None = None,
    origin: tuple[float, float] = (0.0, 0.0),
) -> SoundingGrid:
    """Count, (weighted) mean, (weighted) median and spread of depth per square cell.

    Parameters
    ----------
    points : array_like, shape (N, 3)
        Soundings ``(north, east, depth)``; rows with a NaN are dropped and counted.
    cell : float
        Cell size in metres; a sounding goes to the nearest cell centre.
    weights : array_like, shape (N,), optional
        Positive weight of each sounding (default: all 1), used by the mean, the median and
        the std.
    extent : (north_min, north_max, east_min, east_max), optional
        Cell centres from the minima in steps of ``cell``; soundings outside are dropped.
        By default the centres start at the soundings' smallest north and east.
    statistic : {"mean", "median"}
        Which statistic is the grid's :attr:`~tangraph.maps.SoundingGrid.depth` map.
    name, crs, origin
        As in :class:`BathymetryMap`.

    Returns
    -------
    SoundingGrid
        ``mean`` (a map), ``median``, ``count``, ``std`` per cell (NaN in empty cells).

    Notes
    -----
    With weights ``w_i`` (all 1 by default) the mean is ``sum(w z) / sum(w)`` and the std is
    ``sqrt(sum(w (z - mean)^2) / sum(w) * n / (n - 1))`` (NaN for ``n < 2``), the sample std
    (ddof 1) for equal weights. The weighted median of a cell is found on its depths sorted
    ascending with cumulative weights ``W_k``: the first ``z_k`` with ``W_k >= W / 2`` (``W``
    the cell's total weight), or the mean of ``z_k`` and ``z_(k+1)`` if ``W_k`` is exactly
    ``W / 2``; with equal weights this is the ordinary median. All cells are reduced at once:
    the points are sorted by (cell, depth) with :func:`numpy.lexsort` and summed per cell
    with :func:`numpy.add.reduceat`.

    Examples
    --------
    >>> pts = [[0.0, 0, 10], [0.2, 0, 12], [0.1, 0, 30], [0, 1, 11], [1, 1, 13]]
    >>> g = block_reduce(pts, cell=1.0, statistic="median")
    >>> g.count
    array([[3, 1],
           [0, 1]])
    >>> g.depth.depth
    array([[12., 11.],
           [nan, 13.]])
    >>> float(block_reduce(pts, cell=1.0, weights=[1, 1, 3, 1, 1]).median[0, 0])
    30.0
    """
    where = f"soundings {name!r}"
    cell = _check_cell(cell, where)
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise TangraphError(f"points must have shape (N, 3) [north, east, depth], got {pts.shape}")
    w = _check_weights(weights, pts.shape[0], where)
    finite = np.all(np.isfinite(pts), axis=1)
    pts, w = pts[finite], w[finite]
    if pts.shape[0] == 0:
        raise TangraphError(f"{where}: no finite soundings")
    n_lo, n_hi, e_lo, e_hi = _extent(pts, cell, extent, where)
    north = _axis(n_lo, n_hi, cell, "north", where)
    east = _axis(e_lo, e_hi, cell, "east", where)
    i = np.rint((pts[:, 0] - n_lo) / cell).astype(np.int64)
    j = np.rint((pts[:, 1] - e_lo) / cell).astype(np.int64)
    inside = (i >= 0) & (i < north.size) & (j >= 0) & (j < east.size)
    n_dropped = int(np.sum(~finite) + np.sum(~inside))
    if n_dropped:
        log.info("%s: dropped %d of %d soundings", where, n_dropped, finite.size)
    shape = (north.size, east.size)
    layers = _reduce_cells(i[inside] * east.size + j[inside], pts[inside, 2], w[inside], shape)
    mean_map = BathymetryMap(north, east, layers["mean"], crs=crs, origin=origin, name=name)
    meta = {"nugget": _nugget(pts[inside], cell)}
    return SoundingGrid(mean_map, layers["count"], layers["std"], n_dropped, median=layers["median"],
                        statistic=statistic, meta=meta)


_NUGGET_PAIRS = 200_000  # soundings sampled for the nugget


def _nugget(points: np.ndarray, cell: float) -> float | None:
    """The soundings' own noise variance: half the mean squared depth difference of pairs of
    soundings closer than a tenth of a cell (at most 1 m), where the seafloor cannot differ
    (the variogram's nugget); None with fewer than 30 such pairs."""
    from scipy.spatial import cKDTree

    if points.shape[0] > _NUGGET_PAIRS:  # a fixed, spread sample (no randomness)
        points = points[:: int(np.ceil(points.shape[0] / _NUGGET_PAIRS))]
    pairs = cKDTree(points[:, :2]).query_pairs(min(0.1 * cell, 1.0), output_type="ndarray")
    if pairs.shape[0] < 30:
        return None
    return float(0.5 * np.mean((points[pairs[:, 0], 2] - points[pairs[:, 1], 2]) ** 2))


def _reduce_cells(flat: np.ndarray, z: np.ndarray, w: np.ndarray, shape: tuple[int, int]) -> dict:
    """Per-cell layers of depths ``z`` with weights ``w`` in flat cell indices ``flat``."""
    size = shape[0] * shape[1]
    layers = {"count": np.zeros(size, np.int64)}
    layers.update({k: np.full(size, np.nan) for k in ("mean", "median", "std")})
    if flat.size:
        order = np.lexsort((z, flat))  # by cell, then by depth within a cell
        cells, zs, ws = flat[order], z[order], w[order]
        starts = np.flatnonzero(np.r_[True, cells[1:] != cells[:-1]])
        counts = np.diff(np.r_[starts, cells.size])
        cell_of = cells[starts]
        total = np.add.reduceat(ws, starts)
        mean = np.add.reduceat(ws * zs, starts) / total
        spread = np.add.reduceat(ws * (zs - np.repeat(mean, counts)) ** 2, starts)
        with np.errstate(divide="ignore", invalid="ignore"):
            var = np.where(counts > 1, spread / total * counts / (counts - 1), np.nan)
        cum = np.cumsum(ws)
        within = cum - np.repeat(cum[starts] - ws[starts], counts)  # cumulative weight in the cell
        half = np.repeat(0.5 * total, counts)
        k = starts + np.add.reduceat((within < half).astype(np.int64), starts)
        k = np.minimum(k, starts + counts - 1)  # guards rounding of real weights
        tie = within[k] == 0.5 * total
        median = np.where(tie, 0.5 * (zs[k] + zs[np.minimum(k + 1, zs.size - 1)]), zs[k])
        layers["count"][cell_of] = counts
        layers["mean"][cell_of] = mean
        layers["median"][cell_of] = median
        layers["std"][cell_of] = np.sqrt(var)
    return {key: value.reshape(shape) for key, value in layers.items()}


# -- gap filling ------------------------------------------------------------------------------
def fill_gaps(grid: SoundingGrid, cells: int) -> SoundingGrid:
    """Give empty cells near data a depth: inverse-distance weighting within ``cells`` cells.

    An empty cell gets ``sum(w_k d_k) / sum(w_k)`` over the cells ``k`` holding soundings
    whose centres lie within ``cells`` cell sizes of its own (a disc), with ``w_k = 1 / r_k^2``
    (``r_k`` the distance in cells) and ``d_k`` the grid's chosen statistic. It is computed for
    all cells at once as a normalised convolution (the data times the kernel over the data
    mask times the kernel). Only measured cells feed the fill (it is not iterated), and a
    cell farther than ``cells`` from every measured cell stays no-data (NaN).

    Parameters
    ----------
    grid : SoundingGrid
    cells : int
        Search radius in cells (``>= 0``; 0 fills nothing).

    Returns
    -------
    SoundingGrid
        ``grid`` with ``gap_fill`` set: its ``depth`` map holds the filled cells, while
        ``mean``, ``median``, ``count`` and ``std`` stay those of the soundings.

    Examples
    --------
    >>> g = block_reduce([[0.0, 0, 10], [0, 2, 14], [1, 0, 10], [1, 2, 14], [0, 6, 20]], cell=1.0)
    >>> f = fill_gaps(g, 1)
    >>> f.depth.depth
    array([[10., 12., 14., 14., nan, 20., 20.],
           [10., 12., 14., 14., nan, nan, 20.]])
    >>> f.n_filled
    6
    """
    from scipy import ndimage

    if isinstance(cells, bool) or not isinstance(cells, int | np.integer) or cells < 0:
        raise TangraphError(f"gap fill: cells must be an integer >= 0, got {cells!r}")
    cells = int(cells)
    depth = grid.mean.depth if grid.statistic == "mean" else grid.median
    measured = grid.count > 0
    gap_fill = np.full(grid.mean.shape, np.nan)
    if cells > 0:
        di, dj = np.mgrid[-cells : cells + 1, -cells : cells + 1]
        r2 = (di**2 + dj**2).astype(np.float64)
        kernel = np.where((r2 > 0) & (r2 <= cells**2), 1.0 / np.where(r2 > 0, r2, 1.0), 0.0)
        data = np.where(measured, depth, 0.0)
        num = ndimage.correlate(data, kernel, mode="constant", cval=0.0)
        den = ndimage.correlate(measured.astype(np.float64), kernel, mode="constant", cval=0.0)
        near = ~measured & (den > 0)
        gap_fill[near] = num[near] / den[near]
    meta = {**grid.meta, "gap_fill": {"cells": cells, "method": "inverse distance squared"}}
    return SoundingGrid(grid.mean, grid.count, grid.std, grid.n_dropped, median=grid.median,
                        statistic=grid.statistic, gap_fill=gap_fill, meta=meta)


# -- the map's error ---------------------------------------------------------------------------
#: the standard error of a median over that of a mean for normal data (many soundings)
_MEDIAN_OVER_MEAN = math.sqrt(math.pi / 2.0)


@dataclasses.dataclass(frozen=True, eq=False)
class GriddedError:
    """The error of a gridded map (:func:`gridded_error`).

    ``depth_std (ny, nx)`` per cell (m, NaN where the map has no depth) and
    ``correlation_length`` (m), both None where they cannot be told; ``semivariance`` the
    terrain's semivariogram at a lag of one cell (m^2, NaN without two adjacent measured
    cells) and ``spread`` the median std of the soundings within cells that hold two or more
    (m, NaN if none does).
    """

    depth_std: np.ndarray | None
    correlation_length: float | None
    semivariance: float
    spread: float


def gridded_error(grid: SoundingGrid, *, neighbourhood: int = 2) -> GriddedError:
    """The error of a map gridded from soundings: a standard deviation per cell and one
    correlation length.

    Parameters
    ----------
    grid : SoundingGrid
        Soundings binned by :func:`block_reduce` (and perhaps gap-filled by :func:`fill_gaps`).
    neighbourhood : int
        A cell with one sounding borrows the spread of the cells with two or more within this
        many cells (default 2: a 5 x 5 window).

    Returns
    -------
    GriddedError

    Notes
    -----
    The error is that of the map's depth at a point (the bilinear interpolant of the cells),
    the quantity a sounding is compared with.

    **A measured cell** errs by the standard error of its value, ``s / sqrt(n)`` from the
    spread ``s`` of its ``n`` soundings (times ``sqrt(pi / 2)``, the median's efficiency for
    normal data, when the map's statistic is the median of three or more), and at a point of it
    by the seafloor's departure from the cell's value there (relief the grid cannot hold, and
    its slope: the cell's value is that of where its soundings lie, not of its centre): the
    soundings' variance, averaged over the 3 x 3 cells around (one cell's few soundings say
    little of it), less their own noise: the smaller of the nugget (half the mean squared
    difference of soundings closer than a tenth of a cell, :func:`block_reduce`'s
    ``meta["nugget"]``; pairs from different passes hold their positioning errors too) and the
    10th percentile of the variance over cells of five or more soundings (the flattest cells
    show the noise alone)::

        sigma^2 = f^2 s^2 / n + relief^2

    A cell with one sounding has no spread of its own, so it takes the mean spread of the cells
    with two or more around it (``neighbourhood``), else the median spread of the whole grid,
    else (no cell holds two soundings) ``sqrt(gamma_1)`` below: it is never taken as exact.

    **A filled cell** (gap fill) is a prediction from measured cells. Predicting the depth at
    distance ``d`` from the data by the data there errs with the variance of the terrain's
    change over ``d``, twice its semivariogram ``gamma(d)``, measured on the grid itself: half
    the mean squared difference of measured cells ``k = 1, 2, ...`` cells apart along north and
    along east (the larger of the two, so a seafloor that changes faster across the survey lines
    than along them is not under-rated), up to the fill radius. The fill is an average of the
    measured cells ``i`` within its radius with weights ``w_i`` (inverse squared distance,
    summing to one), so a filled cell gets that predictor's error with the same weights,

        sigma^2 = sum_i w_i (2 gamma(d_i) + sigma_i^2)

    (``d_i`` the distance to cell ``i``, ``sigma_i`` its std; ``gamma`` interpolated linearly
    in ``d``, never falling with it, and beyond the last lag the data can tell extended along
    its last slope; with no two measured cells one lag apart, the linear ``2 gamma_1 d / c`` of
    adjacent cells). The exact variance subtracts ``sum_ij w_i w_j gamma(d_ij)``, the spread of
    the data among themselves, and the measured semivariogram holds the cells' own errors too
    (a nugget): both are left in, on the safe side. A fill leans on its far data as well as its
    nearest, which the error of the nearest cell alone, ``2 gamma(d_min)``, under-rates: on the
    simulated realistic-map scenarios the filled cells' true error was 1.15-1.26 times that std,
    and is 0.92-1.04 times this one (two seeds each of ``demo-map-error`` and
    ``wang2019-map-error``).

    **Where the soundings were placed.** A sounding's position is known to the gridded
    surveys' positioning std ``p`` per axis (``meta["position_std"]``, :func:`grid_surveys`'s
    ``position_std``: their GPS), and its depth is binned where it was placed, not where it was
    measured. On a slope ``g`` (the map's own gradient; with a gap fill the largest over lags up
    to its radius, since the fill flattens the map next to its data) a horizontal error ``dx``
    is a depth error ``g . dx``, so every cell's variance gains ``p^2 |g|^2`` (the horizontal
    uncertainty propagated through the slope, as a hydrographic total propagated uncertainty
    counts it): a
    steep cell's depth is known less well than its soundings' spread alone says, and no
    sounding placed on it can tell a position better than ``p``. 0 (the default) takes the
    positions as exact.

    **The correlation length**. A measured cell's error is the cell's own (noise averaged in it,
    relief within it), independent from cell to cell: its correlation length is the cell. A
    filled cell's error is the terrain's change since the measured cells it leans on, shared by
    every filled cell leaning on the same data: it is correlated over the gap between the data,
    about ``2 d`` for a cell ``d`` from the data (the full gap for a cell midway). One figure for
    the map weighs these scales by where the error is::

        L = sum(sigma_i^2 * max(c, 2 d_i)) / sum(sigma_i^2)

    over the cells with data: ``c`` for densely measured grids; about two thirds of the gap
    for lines far apart with their gaps filled.

    Where nothing can be told (no cell with two soundings and no two adjacent measured cells,
    or gap-filled cells without ``gamma_1``) ``depth_std`` and ``correlation_length`` are None
    and a warning is logged: the map then gets the navigation model's default map std.

    Examples
    --------
    >>> pts = [[0.0, 0, 10.0], [0, 0, 10.4], [0, 0, 10.2], [0, 0, 10.2],  # cell (0, 0): 4 soundings
    ...        [0, 1, 10.5], [0, 1, 10.7], [1, 0, 10.1], [1, 1, 10.3]]
    >>> e = gridded_error(block_reduce(pts, cell=1.0))
    >>> e.depth_std.round(4)  # (0, 0): std 0.1633 / sqrt(4); (1, x): one sounding, the mean spread
    array([[0.0816, 0.1   ],
           [0.1524, 0.1524]])
    >>> e.correlation_length
    1.0
    """
    from scipy import ndimage

    if isinstance(neighbourhood, bool) or not isinstance(neighbourhood, int | np.integer) \
            or neighbourhood < 0:
        raise TangraphError(f"gridded error: neighbourhood must be an integer >= 0, got {neighbourhood!r}")
    cell = grid.mean.cell_size[0]
    count = grid.count
    measured = count > 0
    layer = np.where(measured, grid.mean.depth if grid.statistic == "mean" else grid.median, np.nan)
    gamma = _semivariance_one_cell(layer)
    replicated = count >= 2
    spread_median = float(np.median(grid.std[replicated])) if replicated.any() else math.nan
    spread = _borrowed_spread(grid.std, replicated, measured, neighbourhood, spread_median, gamma)
    factor = np.where((grid.statistic == "median") & (count >= 3), _MEDIAN_OVER_MEAN, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        std = np.where(measured, factor * spread / np.sqrt(np.maximum(count, 1)), np.nan)
    filled = np.zeros(count.shape, bool) if grid.gap_fill is None else np.isfinite(grid.gap_fill) & ~measured
    if not measured.any() or np.isnan(std[measured]).any() or (filled.any() and math.isnan(gamma)):
        log.warning("map %r: its error cannot be told from these soundings (no cell holds two, no two "
                    "measured cells are adjacent); it is written without depth_std", grid.mean.name)
        return GriddedError(None, None, gamma, spread_median)
    std = np.sqrt(std**2 + _relief_variance(grid))
    distance = ndimage.distance_transform_edt(~measured, sampling=cell)
    if filled.any():
        radius = int(grid.meta.get("gap_fill", {}).get("cells", math.ceil(distance.max() / cell)))
        fill_error = _fill_error(layer, measured, std, radius, gamma)
        std = np.where(filled, np.sqrt(_fill_variance(measured, std, radius, fill_error)), std)
    valid = measured | filled
    position_std = float(grid.meta.get("position_std", 0.0))
    if position_std > 0:  # where its soundings were placed: the slope turns that into depth
        depth = np.where(measured, layer, grid.gap_fill if grid.gap_fill is not None else np.nan)
        lags = int(grid.meta.get("gap_fill", {}).get("cells", 1)) if filled.any() else 1
        std = np.sqrt(std**2 + position_std**2 * _slope_squared(depth, cell, lags))
    weight = std[valid] ** 2
    scale = np.maximum(cell, 2.0 * distance[valid])
    length = float(np.sum(weight * scale) / np.sum(weight)) if np.sum(weight) > 0 else float(cell)
    return GriddedError(std, max(length, float(cell)), gamma, spread_median)


def _slope_squared(depth: np.ndarray, cell: float, lags: int = 1) -> np.ndarray:
    """The squared magnitude of the depth's gradient per cell (dimensionless), the largest over
    central differences ``1 .. lags`` cells either side (a gap fill flattens the map next to its
    data, over about its radius, so the slope the data hold shows at the longer lags; a sharp
    feature at the shortest). A difference falls back to one side where the other has no depth,
    and to 0 along an axis where neither has."""
    out = np.zeros(depth.shape)
    for lag in range(1, max(int(lags), 1) + 1):
        total = np.zeros(depth.shape)
        for axis in (0, 1):
            a = np.moveaxis(depth, axis, 0)
            forward = np.full(a.shape, np.nan)
            backward = np.full(a.shape, np.nan)
            if a.shape[0] > lag:
                forward[:-lag] = (a[lag:] - a[:-lag]) / (lag * cell)
                backward[lag:] = forward[:-lag]
            both = 0.5 * (forward + backward)
            g = np.where(np.isfinite(both), both, np.where(np.isfinite(forward), forward, backward))
            total += np.moveaxis(np.nan_to_num(g) ** 2, 0, axis)
        out = np.maximum(out, total)
    return out


def _relief_variance(grid: SoundingGrid) -> np.ndarray:
    """Per measured cell the variance of the depth at a point of it about the cell's value,
    beyond the soundings' noise: their variance averaged over the 3 x 3 cells around, less the
    smaller of the nugget (:func:`block_reduce`'s ``meta["nugget"]``) and the 10th percentile of
    the cells of five or more soundings; 0 where it cannot be told."""
    from scipy.ndimage import uniform_filter

    variance = grid.std**2
    enough = (grid.count >= 5) & np.isfinite(variance)
    floors = [float(np.percentile(variance[enough], 10))] if enough.sum() >= 10 else []
    if grid.meta.get("nugget") is not None:
        floors.append(float(grid.meta["nugget"]))
    if not floors:
        return np.zeros(variance.shape)
    nugget = min(floors)
    total = uniform_filter(np.where(enough, variance, 0.0), size=3, mode="constant")
    weight = uniform_filter(enough.astype(float), size=3, mode="constant")
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.where(weight > 1e-9, total / weight, nugget)
    return np.where(grid.count > 0, np.maximum(mean - nugget, 0.0), 0.0)


def _fill_variance(measured: np.ndarray, std: np.ndarray, radius: int, fill_error) -> np.ndarray:
    """Per cell the error variance of :func:`fill_gaps`' inverse-distance average of the measured
    cells within ``radius`` cells, with its own weights ``w_i``: ``sum w_i (2 gamma(d_i) +
    sigma_i^2)`` (``fill_error(d) = 2 gamma(d)``, ``sigma_i`` the measured cells' std). The
    predictor's error variance is ``2 sum w_i gamma(d_i) - sum_ij w_i w_j gamma(d_ij)``; the
    second term, the data's own spread, is left out, on the safe side (NaN where no measured
    cell is within reach)."""
    from scipy import ndimage

    di, dj = np.mgrid[-radius : radius + 1, -radius : radius + 1]
    r2 = (di**2 + dj**2).astype(np.float64)
    kernel = np.where((r2 > 0) & (r2 <= radius**2), 1.0 / np.where(r2 > 0, r2, 1.0), 0.0)
    data = measured.astype(np.float64)
    weight = ndimage.correlate(data, kernel, mode="constant", cval=0.0)
    spread = ndimage.correlate(data, kernel * fill_error(np.sqrt(r2)), mode="constant", cval=0.0)
    own = ndimage.correlate(np.where(measured, std**2, 0.0), kernel, mode="constant", cval=0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(weight > 0, (spread + own) / weight, np.nan)


def _fill_error(layer, measured, std, radius: int, gamma: float):
    """The gap fill's error variance as a function of the distance in cells to the data: twice
    the terrain's semivariogram of the measured cells at that lag (see :func:`gridded_error`)."""
    lags, errors = [0.0], [0.0]
    for k in range(1, max(radius, 1) + 1):
        gammas = []
        for axis in (0, 1):
            a = np.moveaxis(layer, axis, 0)
            if a.shape[0] <= k:
                continue
            diffs = a[k:] - a[:-k]
            diffs = diffs[np.isfinite(diffs)]
            if diffs.size >= 10:
                gammas.append(0.5 * float(np.mean(diffs**2)))
        if not gammas:
            break
        lags.append(float(k))
        errors.append(max(2.0 * max(gammas), errors[-1]))  # never less than nearer the data
    if len(lags) > 2:
        slope = (errors[-1] - errors[-2]) / (lags[-1] - lags[-2])
    elif len(lags) == 2:
        slope = errors[-1] / lags[-1]
    else:
        slope = 2.0 * gamma if math.isfinite(gamma) else 0.0
    far_lag, far_error = lags[-1], errors[-1]

    def error(d):
        d = np.asarray(d, dtype=np.float64)
        near = np.interp(d, lags, errors)
        return np.where(d > far_lag, far_error + max(slope, 0.0) * (d - far_lag), near)

    return error


def _semivariance_one_cell(layer: np.ndarray) -> float:
    """Half the mean squared difference of adjacent cells with data, along north and along east;
    the larger of the two (NaN if neither direction has a pair)."""
    gammas = []
    for axis in (0, 1):
        diffs = np.diff(layer, axis=axis)
        diffs = diffs[np.isfinite(diffs)]
        if diffs.size:
            gammas.append(0.5 * float(np.mean(diffs**2)))
    return max(gammas) if gammas else math.nan


def _borrowed_spread(std, replicated, measured, neighbourhood: int, spread_median: float, gamma: float):
    """The soundings' spread per measured cell: its own (two or more soundings), else the mean of
    its neighbours' within ``neighbourhood`` cells, else ``spread_median``, else ``sqrt(gamma)``."""
    from scipy.ndimage import uniform_filter

    spread = np.where(replicated, std, np.nan)
    single = measured & ~replicated
    if single.any() and replicated.any() and neighbourhood > 0:
        size = 2 * neighbourhood + 1
        total = uniform_filter(np.where(replicated, std, 0.0), size=size, mode="constant")
        weight = uniform_filter(replicated.astype(float), size=size, mode="constant")
        near = single & (weight > 1e-9)
        spread[near] = total[near] / weight[near]
    fallback = spread_median if math.isfinite(spread_median) else math.sqrt(gamma)  # NaN stays NaN
    return np.where(single & np.isnan(spread), fallback, spread)


# -- surveys ----------------------------------------------------------------------------------
def _same_crs(a: str, b: str) -> bool:
    import pyproj

    return a == b or pyproj.CRS.from_user_input(a) == pyproj.CRS.from_user_input(b)


def _to_frame(north, east, crs, origin, frame_crs, frame_origin, names: tuple[str, str]):
    """Local ``(north, east)`` of one survey's frame in the frame ``(frame_crs, frame_origin)``."""
    if (crs is None) != (frame_crs is None):
        raise TangraphError(
            f"surveys in different frames: {names[0]} has CRS {frame_crs!r}, {names[1]} has "
            f"{crs!r}; a survey without a CRS can only be gridded with others without one"
        )
    import pyproj

    try:
        if crs is None or _same_crs(crs, frame_crs):
            return north + (origin[0] - frame_origin[0]), east + (origin[1] - frame_origin[1])
        transformer = pyproj.Transformer.from_crs(crs, frame_crs, always_xy=True)
    except pyproj.exceptions.CRSError as exc:
        raise TangraphError(f"{names[0]} ({frame_crs!r}) or {names[1]} ({crs!r}): bad CRS ({exc})") from None
    x, y = transformer.transform(east + origin[1], north + origin[0])
    return np.asarray(y) - frame_origin[0], np.asarray(x) - frame_origin[1]


def _frame_of(survey: Survey, name: str) -> tuple[str | None, tuple[float, float]]:
    crs = survey.meta.get("crs")
    origin = survey.meta.get("origin", (0.0, 0.0))
    try:
        origin = (float(origin[0]), float(origin[1]))
    except (TypeError, ValueError, IndexError):
        raise TangraphError(f"{name}: meta origin must be (northing, easting), got {origin!r}") from None
    return (None if crs is None else str(crs)), origin


def _vertical_datum(surveys: Sequence[Survey], names: Sequence[str]) -> str:
    datums = [str(s.meta.get("vertical_datum", DEFAULT_VERTICAL_DATUM)) for s in surveys]
    for name, datum in zip(names, datums, strict=True):
        if datum != datums[0]:
            raise TangraphError(
                f"surveys with different vertical datums: {names[0]} {datums[0]!r}, {name} "
                f"{datum!r}; reduce them to one datum first"
            )
    return datums[0]


def grid_surveys(
    surveys: Sequence[Survey],
    *,
    cell: float,
    statistic: Statistic = "median",
    fill: int = 0,
    use_dr: bool = False,
    names: Sequence[str] | None = None,
    name: str = "surveys",
    position_std: float = 0.0,
) -> SoundingGrid:
    """Grid the soundings of one or more surveys, placed at their reference tracks, into a map.

    Every sounding (a beam with a return; beams without one are dropped and counted) is placed
    by :meth:`Survey.footprints` seen from the survey's ``true_pose`` (its GPS track, or the
    truth of a simulated run). The surveys are put in the frame of the first: its
    ``meta["crs"]`` and ``meta["origin"]`` (local coordinates + origin = projected
    coordinates). Another survey in the same CRS is shifted by the difference of the origins,
    one in another CRS is reprojected with pyproj. The cell centres lie on multiples of
    ``cell`` in that frame, over the soundings' extent.

    Parameters
    ----------
    surveys : sequence of Survey
    cell : float
        Cell size, metres.
    statistic : {"mean", "median"}
        The depth layer of the map (median: robust to outliers); the other one, the count and
        the std are kept in the result (and written as extra NetCDF variables).
    fill : int
        Fill empty cells from the data within this many cells (:func:`fill_gaps`); 0: none.
    use_dr : bool
        Place the soundings of every survey at its dead reckoning instead (for surveys
        without a reference track).
    names : sequence of str, optional
        Names of the surveys (e.g. their files) in errors and in the result's ``meta``.
    name : str
        Name of the map.
    position_std : float
        The std (m per axis) of the positions the soundings are placed at (the reference
        track's: a GPS's error; the dead reckoning's with ``use_dr``): the map's error gains it
        times the map's slope (:func:`gridded_error`). 0: the positions are exact.

    Returns
    -------
    SoundingGrid
        The map is ``.depth``, in the first survey's CRS and origin; ``meta`` holds the
        sources, the vertical datum, the track used, the position std and the gap fill.

    Raises
    ------
    TangraphError
        No surveys; a survey without ``true_pose`` (unless ``use_dr``); surveys with different
        vertical datums (``meta["vertical_datum"]``, ``"water surface"`` if missing); a survey
        with a CRS mixed with one without.

    Examples
    --------
    >>> import numpy as np
    >>> from tangraph.survey import Survey
    >>> pose = np.column_stack([np.arange(20.0), np.zeros(20), np.zeros(20)])
    >>> s = Survey(time=np.arange(20.0), dr_pose=pose, vehicle_depth=np.zeros(20),
    ...            beam_forward=np.zeros((20, 3)), beam_starboard=np.tile([-2.0, 0, 2], (20, 1)),
    ...            beam_depth=np.full((20, 3), 30.0), true_pose=pose)
    >>> g = grid_surveys([s], cell=2.0)
    >>> g.depth.shape, int(g.count.sum()), g.meta["vertical_datum"]
    ((11, 3), 60, 'water surface')
    """
    surveys = list(surveys)
    if not surveys:
        raise TangraphError("grid_surveys: no surveys")
    if isinstance(position_std, bool) or not isinstance(position_std, int | float | np.floating) \
            or not (math.isfinite(position_std) and position_std >= 0):
        raise TangraphError(f"grid_surveys: position_std must be a number of metres >= 0, "
                            f"got {position_std!r}")
    names = [f"survey {k + 1}" for k in range(len(surveys))] if names is None else [str(n) for n in names]
    if len(names) != len(surveys):
        raise TangraphError(f"grid_surveys: {len(names)} names for {len(surveys)} surveys")
    datum = _vertical_datum(surveys, names)
    frame_crs, frame_origin = _frame_of(surveys[0], names[0])
    blocks = []
    for survey, survey_name in zip(surveys, names, strict=True):
        if not use_dr and survey.true_pose is None:
            raise TangraphError(
                f"{survey_name}: the survey has no reference track (true_pose: GPS or truth); "
                "grid it on its dead reckoning with use_dr (CLI: --use-dr)"
            )
        north, east = survey.footprints(survey.dr_pose if use_dr else survey.true_pose)
        crs, origin = _frame_of(survey, survey_name)
        north, east = _to_frame(north, east, crs, origin, frame_crs, frame_origin, (names[0], survey_name))
        blocks.append(np.column_stack([north.ravel(), east.ravel(), survey.beam_depth.ravel()]))
    points = np.concatenate(blocks)
    cell = _check_cell(cell, f"surveys {name!r}")
    finite = np.all(np.isfinite(points), axis=1)
    if not finite.any():
        raise TangraphError(f"surveys {name!r}: no soundings")
    lo = np.rint(points[finite, :2].min(axis=0) / cell) * cell
    hi = np.maximum(np.rint(points[finite, :2].max(axis=0) / cell) * cell, lo + cell)
    grid = block_reduce(points, cell=cell, extent=(lo[0], hi[0], lo[1], hi[1]), statistic=statistic,
                        name=name, crs=frame_crs, origin=frame_origin)
    meta = {**grid.meta, "sources": names, "vertical_datum": datum,
            "track": "dr_pose" if use_dr else "true_pose", "position_std": float(position_std)}
    grid = SoundingGrid(grid.mean, grid.count, grid.std, grid.n_dropped, median=grid.median,
                        statistic=grid.statistic, meta=meta)
    return fill_gaps(grid, fill) if fill else grid
