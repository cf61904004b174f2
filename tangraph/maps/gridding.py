"""Soundings into a map: a vectorised block reduce into square cells, and gap filling.

:func:`block_reduce` bins ``(north, east, depth)`` points into square cells and gives the count,
(weighted) mean, (weighted) median and spread of depth per cell, by one sort of the points by
cell (no Python loop over cells); :func:`grid_soundings` does it for an array or an Open3D point
cloud. :func:`fill_gaps` gives empty cells near data a depth (linear across gaps). The
result is a :class:`SoundingGrid`, whose :attr:`~SoundingGrid.depth` carries the map's error
(:func:`tangraph.maps.gridding_error.gridded_error`). Surveys are gridded, in one frame, by
:func:`tangraph.gridding_surveys.grid_surveys`.
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import math
import sys
from typing import Any, Literal, cast

import numpy as np

from tangraph.errors import TangraphError
from tangraph.maps._grid_checks import cell_axis, check_cell, check_error_drift
from tangraph.maps.grid import BathymetryMap
from tangraph.maps.gridding_error import bridging_triangles, fill_kernel, gridded_error

__all__ = [
    "SoundingGrid",
    "Statistic",
    "block_reduce",
    "fill_gaps",
    "grid_soundings",
]

log = logging.getLogger(__name__)

#: The most cells a grid of soundings may have (each layer 8 bytes a cell: a few GB for all)
MAX_CELLS = 100_000_000

Statistic = Literal["mean", "median"]


# -- the grid of soundings ---------------------------------------------------------------
@dataclasses.dataclass(frozen=True, eq=False)
class SoundingGrid:
    """Soundings binned on a regular grid.

    ``mean`` is the map of mean depths (NaN in empty cells), ``count (ny, nx)`` the soundings
    per cell, ``std (ny, nx)`` their sample standard deviation (ddof 1; NaN below 2
    soundings), ``n_dropped`` the soundings left out (a NaN coordinate or outside the extent).
    ``median (ny, nx)`` is the (weighted) median depth per cell (NaN in empty cells; None if
    not computed), ``statistic`` which of ``"mean"`` and ``"median"`` is the map's
    :attr:`depth`, ``gap_fill (ny, nx)`` the depth a gap fill gave to empty cells (NaN
    elsewhere; None: no gap fill, see :func:`fill_gaps`), and ``meta``
    JSON-ready provenance (sources, vertical datum), written with the grid. :attr:`error` is
    the map's error told from the soundings (:func:`tangraph.maps.gridding_error.gridded_error`),
    which :attr:`depth` carries as its ``depth_std`` (times ``error_scale``: 1, or the factor
    check lines found, :func:`tangraph.eval.map_check.calibrate_error`) and
    ``correlation_length``; ``error_dof`` is the Student-t tail the check lines found (None:
    Gaussian), the map's ``error_dof``, and ``error_drift`` the drift along a track they found
    (``(std m, time s)``; None: none found), the map's ``error_drift``.
    """

    mean: BathymetryMap
    count: np.ndarray
    std: np.ndarray
    n_dropped: int = 0
    median: np.ndarray | None = None
    statistic: Literal["mean", "median"] = "mean"
    gap_fill: np.ndarray | None = None
    meta: dict[str, Any] = dataclasses.field(default_factory=dict)
    error_scale: float = 1.0
    error_dof: float | None = None
    error_drift: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if not (math.isfinite(self.error_scale) and self.error_scale > 0):
            raise TangraphError(f"error_scale must be a finite number > 0, got {self.error_scale!r}")
        if self.error_dof is not None and not (math.isfinite(self.error_dof) and self.error_dof > 0):
            raise TangraphError(f"error_dof must be a finite number > 0 or None, got {self.error_dof!r}")
        if self.error_drift is not None:
            object.__setattr__(self, "error_drift", check_error_drift(self.error_drift, "error_drift"))
        count = np.array(self.count, dtype=np.int64)
        std = np.array(self.std, dtype=np.float64)
        if count.shape != self.mean.shape or std.shape != self.mean.shape:
            raise TangraphError(
                f"count {count.shape} and std {std.shape} must match the map's {self.mean.shape}"
            )
        if self.statistic not in ("mean", "median"):
            raise TangraphError(f"statistic must be 'mean' or 'median', got {self.statistic!r}")
        if self.statistic == "median" and self.median is None:
            raise TangraphError("statistic 'median' needs the median layer")
        layers = {"count": count, "std": std}
        for name in ("median", "gap_fill"):
            if getattr(self, name) is not None:
                layers[name] = np.array(getattr(self, name), dtype=np.float64)
                if layers[name].shape != self.mean.shape:
                    raise TangraphError(
                        f"{name} {layers[name].shape} must match the map's {self.mean.shape}"
                    )
        if "gap_fill" in layers and np.any(np.isfinite(layers["gap_fill"]) & (count > 0)):
            raise TangraphError("gap_fill gives a depth to a cell that holds soundings")
        for key, a in layers.items():
            a.setflags(write=False)
            object.__setattr__(self, key, a)
        object.__setattr__(self, "n_dropped", int(self.n_dropped))
        object.__setattr__(self, "meta", dict(self.meta))

    @property
    def n_filled(self) -> int:
        """Empty cells given a depth by the gap fill."""
        return 0 if self.gap_fill is None else int(np.isfinite(self.gap_fill).sum())

    @functools.cached_property
    def error(self):
        """The map's error (:class:`tangraph.maps.gridding_error.GriddedError`), computed once."""
        return gridded_error(self)

    @property
    def depth(self) -> BathymetryMap:
        """The map: ``statistic`` per cell, empty cells holding the gap fill's depth (if any),
        with the error layer of :attr:`error` (``depth_std`` times ``error_scale``,
        ``correlation_length``), ``error_dof`` and ``error_drift``."""
        layer = self.mean.depth if self.statistic == "mean" else cast(np.ndarray, self.median)
        if self.gap_fill is not None:
            layer = np.where(self.count > 0, layer, self.gap_fill)
        std = self.error.depth_std
        return self.mean.replace(depth=layer, depth_std=None if std is None else std * self.error_scale,
                                 correlation_length=self.error.correlation_length, error_dof=self.error_dof,
                                 error_drift=self.error_drift)


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


def _cells(pts: np.ndarray, cell: float, extent, where: str):
    """The grid's axes, each point's flat cell index (nearest centre) and whether it is inside."""
    n_lo, n_hi, e_lo, e_hi = _extent(pts, cell, extent, where)
    north = cell_axis(n_lo, n_hi, cell, "north", where)
    east = cell_axis(e_lo, e_hi, cell, "east", where)
    if north.size * east.size > MAX_CELLS:
        raise TangraphError(
            f"{where}: a grid of {north.size:,} x {east.size:,} cells of {cell:g} m over "
            f"{(n_hi - n_lo) / 1e3:,.1f} x {(e_hi - e_lo) / 1e3:,.1f} km is too large (at most {MAX_CELLS:,} "
            "cells): use a larger cell, or soundings of one area (surveys far apart, or in other CRSs?)")
    i = np.rint((pts[:, 0] - n_lo) / cell).astype(np.int64)
    j = np.rint((pts[:, 1] - e_lo) / cell).astype(np.int64)
    inside = (i >= 0) & (i < north.size) & (j >= 0) & (j < east.size)
    return north, east, i * east.size + j, inside


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
    cell = check_cell(cell, where)
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise TangraphError(f"points must have shape (N, 3) [north, east, depth], got {pts.shape}")
    w = _check_weights(weights, pts.shape[0], where)
    finite = np.all(np.isfinite(pts), axis=1)
    pts, w = pts[finite], w[finite]
    if pts.shape[0] == 0:
        raise TangraphError(f"{where}: no finite soundings")
    north, east, flat, inside = _cells(pts, cell, extent, where)
    n_dropped = int(np.sum(~finite) + np.sum(~inside))
    if n_dropped:
        log.info("%s: dropped %d of %d soundings", where, n_dropped, finite.size)
    shape = (north.size, east.size)
    layers = _reduce_cells(flat[inside], pts[inside, 2], w[inside], shape)
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
    """Give empty cells near data a depth: linear across gaps, inverse distance elsewhere.

    An empty cell within ``cells`` cell sizes of a measured cell (a disc) is filled; a cell
    farther from every measured cell stays no-data (NaN). Only measured cells feed the fill (it
    is not iterated), with the grid's chosen statistic as their depth ``d_k``.

    - **Across a gap** (:func:`~tangraph.maps.gridding_error.bridging_triangles`): the cell
      lies in a triangle of the Delaunay triangulation of the measured cells whose sides span at
      most a gap the fill closes from both sides (``2 cells`` empty cells). It gets the plane
      through the three corners, ``sum(w_k d_k)`` with its barycentric weights ``w_k`` (a TIN).
      A plane is reproduced exactly: a seafloor that slopes across a gap is filled with its slope.
    - **Elsewhere** (a bay in the data, beyond the data's hull): ``sum(w_k d_k) / sum(w_k)`` over
      the measured cells within ``cells`` cells, ``w_k = 1 / r_k^2`` (``r_k`` the distance in
      cells), a normalised convolution. This flattens the map towards its data.

    The inverse distance average alone, across a gap between survey lines on a sloping seafloor,
    leans on the nearer line's depth: its error is a sawtooth across the gap, the same all along
    the lines, which a vehicle running along the gap takes for a position offset.

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
    >>> g = block_reduce([[0.0, 0, 10], [0, 3, 16], [1, 0, 10], [1, 3, 16], [0, 7, 20]], cell=1.0)
    >>> f = fill_gaps(g, 1)
    >>> f.depth.depth  # columns 1-2 bridged by the plane; the wider gap is not: its nearest data
    array([[10., 12., 14., 16., 16., nan, 20., 20.],
           [10., 12., 14., 16., 16., nan, nan, 20.]])
    >>> f.n_filled
    8
    """
    from scipy import ndimage

    if isinstance(cells, bool) or not isinstance(cells, int | np.integer) or cells < 0:
        raise TangraphError(f"gap fill: cells must be an integer >= 0, got {cells!r}")
    cells = min(int(cells), int(np.ceil(np.hypot(*grid.mean.shape))))  # (farther: the same cells)
    depth = grid.mean.depth if grid.statistic == "mean" else cast(np.ndarray, grid.median)
    measured = grid.count > 0
    gap_fill = np.full(grid.mean.shape, np.nan)
    if cells > 0:
        kernel, _ = fill_kernel(cells)
        data = np.where(measured, depth, 0.0)
        num = ndimage.correlate(data, kernel, mode="constant", cval=0.0)
        den = ndimage.correlate(measured.astype(np.float64), kernel, mode="constant", cval=0.0)
        near = ~measured & (den > 0)
        gap_fill[near] = num[near] / den[near]
        target, corners, weights = bridging_triangles(measured, cells)
        gap_fill.flat[target] = np.sum(weights * depth.flat[corners], axis=1)
    meta = {**grid.meta, "gap_fill": {"cells": cells, "method": "linear across gaps (Delaunay), "
                                      "inverse distance squared elsewhere"}}
    return SoundingGrid(grid.mean, grid.count, grid.std, grid.n_dropped, median=grid.median,
                        statistic=grid.statistic, gap_fill=gap_fill, meta=meta)


def _as_points(points) -> np.ndarray:
    o3d = sys.modules.get("open3d")  # an Open3D point cloud exists only once Open3D is loaded
    if o3d is not None and isinstance(points, o3d.geometry.PointCloud):
        return np.asarray(points.points, dtype=np.float64)
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise TangraphError(f"points must have shape (N, 3) [north, east, depth], got {pts.shape}")
    return pts


def grid_soundings(
    points,
    *,
    cell: float,
    name: str = "soundings",
    crs: str | None = None,
    origin: tuple[float, float] = (0.0, 0.0),
    extent: tuple[float, float, float, float] | None = None,
) -> SoundingGrid:
    """Bin scattered soundings into square cells: count, mean, median and spread of depth per cell.

    :func:`block_reduce` of an array or an Open3D point cloud.

    Parameters
    ----------
    points : array_like (N, 3) or open3d.geometry.PointCloud
        Soundings ``(north, east, depth)``; rows with a NaN are dropped and counted.
    cell : float
        Cell size in metres; a sounding goes to the nearest cell centre.
    extent : (north_min, north_max, east_min, east_max), optional
        Cell centres from the minima in steps of ``cell``; soundings outside are dropped.
        By default the centres start at the soundings' smallest north and east.
    name, crs, origin
        As in :class:`BathymetryMap`.

    Examples
    --------
    >>> pts = [[0.0, 0, 10], [0.2, 0, 12], [0, 1, 11], [1, 1, 13]]
    >>> g = grid_soundings(pts, cell=1.0)
    >>> g.count
    array([[2, 1],
           [0, 1]])
    >>> g.mean.depth
    array([[11., 11.],
           [nan, 13.]])
    """
    return block_reduce(_as_points(points), cell=cell, name=name, crs=crs, origin=origin, extent=extent)
