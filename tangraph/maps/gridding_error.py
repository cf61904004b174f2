"""The error of a map gridded from soundings: a standard deviation per cell and one correlation
length (:func:`gridded_error`, which :attr:`SoundingGrid.depth <tangraph.maps.SoundingGrid.depth>`
carries as its ``depth_std`` and ``correlation_length``).

The error is that of the map's depth at a point (the bilinear interpolant of the cells),
the quantity a sounding is compared with.

**A measured cell** errs by the standard error of its value, ``s / sqrt(n)`` from the
spread ``s`` of its ``n`` soundings (times ``sqrt(pi / 2)``, the median's efficiency for
normal data, when the map's statistic is the median of three or more), and at a point of it
by the seafloor's departure from the cell's value there (relief the grid cannot hold, and
its slope: the cell's value is that of where its soundings lie, not of its centre): the
soundings' variance, averaged over the 3 x 3 cells around (one cell's few soundings say
little of it), less their own noise: the smaller of the nugget (half the mean squared
difference of soundings closer than a tenth of a cell,
:func:`~tangraph.maps.gridding.block_reduce`'s ``meta["nugget"]``; pairs from different passes
hold their positioning errors too) and the 10th percentile of the variance over cells of five
or more soundings (the flattest cells show the noise alone)::

    sigma^2 = f^2 s^2 / n + relief^2

A cell with one sounding has no spread of its own, so it takes the mean spread of the cells
with two or more around it (``neighbourhood``), else the median spread of the whole grid,
else (no cell holds two soundings) ``sqrt(gamma_1)`` below: it is never taken as exact.

**A filled cell** (gap fill) is a prediction from measured cells. Predicting the depth at
distance ``d`` from the data by the data there errs with the variance of the terrain's
change over ``d``, twice its semivariogram ``gamma(d)``, measured on the grid itself: half
the mean squared difference of measured cells ``k = 1, 2, ...`` cells apart along north and
along east (the larger of the two, so a seafloor that changes faster across the survey lines
than along them is not under-rated), up to the fill radius. The fill is an average of
measured cells ``i`` with weights ``w_i`` summing to one (a triangle's barycentric weights
across a gap, else inverse squared distance within its radius:
:func:`~tangraph.maps.gridding.fill_gaps`), so a filled cell gets that predictor's error with
the same weights,

    sigma^2 = sum_i w_i (2 gamma(d_i) + sigma_i^2)

(``d_i`` the distance to cell ``i``, ``sigma_i`` its std; ``gamma`` interpolated linearly
in ``d``, never falling with it, and beyond the last lag the data can tell extended along
its last slope; with no two measured cells one lag apart, the linear ``2 gamma_1 d / c`` of
adjacent cells). The exact variance subtracts ``sum_ij w_i w_j gamma(d_ij)``, the spread of
the data among themselves, and the measured semivariogram holds the cells' own errors too
(a nugget): both are left in, on the safe side. A fill leans on its far data as well as its
nearest, which the error of the nearest cell alone, ``2 gamma(d_min)``, under-rates: on the
simulated realistic-map scenarios the filled cells' true error was 1.15-1.26 times that std,
and is 0.75-0.78 times this one (two seeds each of ``demo-map-error`` and
``wang2019-map-error``, the gaps bridged by planes; with the pair term subtracted it would be
1.08-1.13 times, too little: the semivariogram's nugget is not the cells' own error alone).

**Where the soundings were placed.** A sounding's position is known to the gridded
surveys' positioning std ``p`` per axis (``meta["position_std"]``,
:func:`~tangraph.gridding_surveys.grid_surveys`'s ``position_std``: their GPS), and its depth
is binned where it was placed, not where it was measured. On a slope ``g`` (the map's own
gradient; with a gap fill the largest over lags up to its radius, since the fill flattens the
map next to its data) a horizontal error ``dx`` is a depth error ``g . dx``, so every cell's
variance gains ``p^2 |g|^2`` (the horizontal uncertainty propagated through the slope, as a
hydrographic total propagated uncertainty counts it): a steep cell's depth is known less well
than its soundings' spread alone says, and no sounding placed on it can tell a position better
than ``p``. 0 (the default) takes the positions as exact.

**The correlation length**. A measured cell's error is the cell's own (noise averaged in it,
relief within it), independent from cell to cell: its correlation length is the cell. A
filled cell's error is the terrain's change since the measured cells it leans on, shared by
every filled cell leaning on the same data: it is correlated over the gap between the data,
about ``2 d`` for a cell ``d`` from the data (the full gap for a cell midway). One figure for
the map weighs these scales by where the error is::

    L = sum(sigma_i^2 * max(c, 2 d_i)) / sum(sigma_i^2)

over the cells with data: ``c`` for densely measured grids; about two thirds of the gap
for lines far apart with their gaps filled.
"""

from __future__ import annotations

import dataclasses
import hashlib
import logging
import math
from typing import TYPE_CHECKING, cast

import numpy as np

from tangraph.errors import TangraphError

if TYPE_CHECKING:
    from tangraph.maps.gridding import SoundingGrid

__all__ = ["GriddedError", "bridging_triangles", "fill_kernel", "gridded_error"]

#: the logger of gridding (the one the map's error has always been reported under)
log = logging.getLogger("tangraph.maps.gridding")


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
        Soundings binned by :func:`~tangraph.maps.gridding.block_reduce` (and perhaps gap-filled by
        :func:`~tangraph.maps.gridding.fill_gaps`).
    neighbourhood : int
        A cell with one sounding borrows the spread of the cells with two or more within this
        many cells (default 2: a 5 x 5 window).

    Returns
    -------
    GriddedError

    Notes
    -----
    The model (a measured cell, a filled cell, where the soundings were placed, the correlation
    length) is set out in :mod:`tangraph.maps.gridding_error`.

    Where nothing can be told (no cell with two soundings and no two adjacent measured cells,
    or gap-filled cells without ``gamma_1``) ``depth_std`` and ``correlation_length`` are None
    and a warning is logged: the map then gets the navigation model's default map std.

    Examples
    --------
    >>> from tangraph.maps.gridding import block_reduce
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
    mean_or_median = grid.mean.depth if grid.statistic == "mean" else cast(np.ndarray, grid.median)
    layer = np.where(measured, mean_or_median, np.nan)
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
        variance = _fill_variance(measured, std, radius, fill_error)
        variance = _bridged_variance(variance.ravel(), measured, std, radius, fill_error).reshape(std.shape)
        std = np.where(filled, np.sqrt(variance), std)
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
    smaller of the nugget (:func:`~tangraph.maps.gridding.block_reduce`'s ``meta["nugget"]``) and
    the 10th percentile of the cells of five or more soundings; 0 where it cannot be told."""
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
    """Per cell the error variance of :func:`~tangraph.maps.gridding.fill_gaps`' inverse-distance
    average of the measured cells within ``radius`` cells, with its own weights ``w_i``:
    ``sum w_i (2 gamma(d_i) + sigma_i^2)`` (``fill_error(d) = 2 gamma(d)``, ``sigma_i`` the
    measured cells' std). The predictor's error variance is
    ``2 sum w_i gamma(d_i) - sum_ij w_i w_j gamma(d_ij)``; the second term, the data's own
    spread, is left out, on the safe side (NaN where no measured cell is within reach)."""
    from scipy import ndimage

    kernel, distance = fill_kernel(radius)
    data = measured.astype(np.float64)
    weight = ndimage.correlate(data, kernel, mode="constant", cval=0.0)
    spread = ndimage.correlate(data, kernel * fill_error(distance), mode="constant", cval=0.0)
    own = ndimage.correlate(np.where(measured, std**2, 0.0), kernel, mode="constant", cval=0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(weight > 0, (spread + own) / weight, np.nan)


def fill_kernel(cells: int) -> tuple[np.ndarray, np.ndarray]:
    """The inverse-distance fill's weights ``1 / r^2`` over the cells within ``cells`` of the
    centre (0 at the centre and beyond), and the distances ``r`` (in cells) of that window."""
    di, dj = np.mgrid[-cells : cells + 1, -cells : cells + 1]
    r2 = (di**2 + dj**2).astype(np.float64)
    return np.where((r2 > 0) & (r2 <= cells**2), 1.0 / np.where(r2 > 0, r2, 1.0), 0.0), np.sqrt(r2)


def bridging_triangles(measured: np.ndarray, cells: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The empty cells :func:`fill_gaps` fills across a gap, as flat indices ``target (m,)``, with
    the flat indices of their triangle's corners ``corners (m, 3)`` and its barycentric weights
    ``weights (m, 3)`` (non-negative, summing to one).

    A cell qualifies when it is within ``cells`` of a measured cell and lies in a triangle of the
    Delaunay triangulation of the measured cells near a gap (those within ``2 cells + 2`` of an
    empty cell) whose sides are at most ``2 cells + 2`` cells long: a gap the fill closes from
    both sides (``2 cells`` empty cells between data), a diagonal's slack included."""
    measured = np.asarray(measured, bool)
    key = (int(cells), measured.shape, hashlib.blake2b(np.packbits(measured).tobytes()).digest())
    if _BRIDGED[0] != key:  # a gap fill and the map's error ask for the same grid's in turn
        answer = _bridging_triangles(measured, int(cells))
        for array in answer:
            array.flags.writeable = False
        _BRIDGED[:] = [key, answer]
    return _BRIDGED[1]


#: the latest :func:`bridging_triangles` asked for: its key and its (read-only) answer
_BRIDGED: list = [None, None]


def _bridging_triangles(measured: np.ndarray, cells: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    from scipy import ndimage
    from scipy.spatial import Delaunay, QhullError

    empty = (np.zeros((0,), np.intp), np.zeros((0, 3), np.intp), np.zeros((0, 3)))
    if cells <= 0 or measured.all() or not measured.any():
        return empty
    reach = 2 * cells + 2  # the widest gap the fill closes from both sides, and a cell's slack
    to_data = ndimage.distance_transform_edt(~measured)
    to_gap = ndimage.distance_transform_edt(measured)
    nodes = np.argwhere(measured & (to_gap <= reach))
    target = np.argwhere(~measured & (to_data <= cells))
    if len(nodes) < 3 or not len(target):
        return empty
    try:
        tri = Delaunay(nodes.astype(np.float64))
    except QhullError:  # the data in a line: nothing to bridge
        return empty
    simplex = tri.find_simplex(target.astype(np.float64))
    inside = simplex >= 0
    target, simplex = target[inside], simplex[inside]
    transform = tri.transform[simplex]
    b = np.einsum("mij,mj->mi", transform[:, :2], target - transform[:, 2])
    weights = np.clip(np.column_stack([b, 1.0 - b.sum(axis=1)]), 0.0, 1.0)
    weights /= weights.sum(axis=1, keepdims=True)
    corner_cells = nodes[tri.simplices[simplex]]  # (m, 3, 2)
    edges = corner_cells - np.roll(corner_cells, 1, axis=1)
    near = np.all(np.hypot(edges[..., 0], edges[..., 1]) <= reach, axis=1)
    near &= np.all(np.isfinite(weights), axis=1)  # (a sliver's barycentric transform may be NaN)
    shape = measured.shape
    flat = np.ravel_multi_index(tuple(target[near].T), shape)
    corners = np.ravel_multi_index(tuple(np.moveaxis(corner_cells[near], -1, 0)), shape)
    return flat, corners, weights[near]


def _bridged_variance(variance: np.ndarray, measured: np.ndarray, std: np.ndarray, radius: int,
                      fill_error) -> np.ndarray:
    """``variance`` (flat) with the cells :func:`~tangraph.maps.gridding.fill_gaps` fills across a
    gap by a plane given that predictor's error with its barycentric weights ``w_k``:
    ``sum w_k (2 gamma(d_k) + sigma_k^2)``, ``d_k`` the distance to corner ``k``."""
    target, corners, weights = bridging_triangles(measured, radius)
    if not target.size:
        return variance
    shape = measured.shape
    at = np.stack(np.unravel_index(target, shape), axis=-1)[:, None, :]
    corner = np.stack(np.unravel_index(corners, shape), axis=-1)
    d = np.sqrt(np.sum((corner - at) ** 2, axis=-1))
    out = variance.copy()
    out[target] = np.sum(weights * (fill_error(d) + std.flat[corners] ** 2), axis=1)
    return out


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


