"""Terrain statistics: slope, roughness, terrain entropy and the Fisher information of soundings.

Per-cell statistics return an ``ndarray`` of the map's shape ``(ny, nx)``, aligned with
``map.north`` and ``map.east``. Window statistics use the square of ``window x window`` cells
centred on each cell (``window`` odd); a window that holds a NaN cell or leaves the map gives
NaN, so no-data is never silently filled.

Examples
--------
>>> import numpy as np
>>> from tangraph.maps import BathymetryMap
>>> from tangraph.maps.statistics import crlb, fisher_information, slope
>>> x = np.arange(5.0) * 10
>>> plane = BathymetryMap(north=x, east=x, depth=100 + 0.1 * x[:, None] + 0 * x)
>>> round(float(slope(plane)[2, 2]), 4)  # degrees
5.7106
>>> fisher_information(plane, sigma=0.5)[2, 2]  # g g^T / sigma^2, g = (0.1, 0)
array([[0.04, 0.  ],
       [0.  , 0.  ]])
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy import ndimage
from scipy.special import xlogy

from tangraph.errors import TangraphError
from tangraph.maps.grid import BathymetryMap

__all__ = [
    "crlb",
    "describe",
    "fisher_information",
    "region_entropy",
    "roughness",
    "slope",
    "terrain_entropy",
    "terrain_std",
    "window_information",
]

Order = Literal[1, 3]

#: Added to ``h - min(h)`` by the relative terrain entropy, metres (far below any sounding
#: resolution; it only makes an exactly flat window uniform instead of 0 / 0).
RELATIVE_EPSILON = 1e-6

# Information matrices with det <= this * trace^2 are treated as singular by `crlb`.
_SINGULAR_RTOL = 1e-12
# Number of window values held at once by `terrain_entropy` (bounds its memory, ~64 MB).
_ENTROPY_CHUNK = 8_000_000


# -- helpers ---------------------------------------------------------------------------------
def _check_window(bmap: BathymetryMap, window: int, where: str) -> int:
    if not isinstance(window, int | np.integer) or window < 3 or window % 2 == 0:
        raise TangraphError(f"{where}: window must be an odd integer >= 3, got {window!r}")
    if window > min(bmap.shape):
        raise TangraphError(
            f"{where}: window {window} is larger than map {bmap.name!r} of shape {bmap.shape}"
        )
    return int(window)


def _check_sigma(sigma: float, where: str) -> float:
    s = float(sigma)
    if not (np.isfinite(s) and s > 0):
        raise TangraphError(f"{where}: sigma must be finite and positive, got {sigma!r}")
    return s


def _incomplete(depth: np.ndarray, window: int) -> np.ndarray:
    """True where the window holds a NaN cell or leaves the grid."""
    valid = np.isfinite(depth).astype(np.uint8)
    return ndimage.minimum_filter(valid, size=window, mode="constant", cval=0) == 0


def _window_sum(values: np.ndarray, w_north: np.ndarray, w_east: np.ndarray) -> np.ndarray:
    """``sum_{u,v} w_north[u] w_east[v] values[i+u, j+v]`` over the window (separable, direct)."""
    out = ndimage.correlate1d(values, w_north, axis=0, mode="constant", cval=0.0)
    return ndimage.correlate1d(out, w_east, axis=1, mode="constant", cval=0.0)


def _centred(depth: np.ndarray, plane: bool) -> np.ndarray:
    """Depth minus its global mean (or best-fit plane), NaN set to 0.

    Window statistics are invariant to this shift; it keeps the sums of squares small so that
    their differences do not lose precision (a planar map gets a roughness of ~1e-12 m).
    """
    valid = np.isfinite(depth)
    if plane:
        rows, cols = np.nonzero(valid)
        design = np.column_stack([np.ones(rows.size), rows, cols]).astype(np.float64)
        coef = np.linalg.lstsq(design, depth[valid], rcond=None)[0]
        trend = coef[0] + coef[1] * np.arange(depth.shape[0])[:, None] + coef[2] * np.arange(
            depth.shape[1]
        )
    else:
        trend = np.mean(depth[valid])
    return np.where(valid, depth - trend, 0.0)


def _cell_gradient(bmap: BathymetryMap, order: Order) -> np.ndarray:
    """Gradient of the map's interpolant at every cell centre, shape (ny, nx, 2)."""
    nn, ee = np.meshgrid(bmap.north, bmap.east, indexing="ij")
    return bmap.gradient_at(nn, ee, order=order)


def _entropy(h: np.ndarray, relative: bool) -> np.ndarray:
    """Entropy (nats) of ``p = h / sum(h)`` along the last axis; NaN in, NaN out."""
    with np.errstate(invalid="ignore", divide="ignore"):
        if relative:
            h = h - np.min(h, axis=-1, keepdims=True) + RELATIVE_EPSILON
        p = h / np.sum(h, axis=-1, keepdims=True)
        return -np.sum(xlogy(p, p), axis=-1)


def _check_positive_depth(depth: np.ndarray, where: str) -> None:
    finite = depth[np.isfinite(depth)]
    if finite.size and finite.min() <= 0:
        raise TangraphError(
            f"{where}: the absolute terrain entropy needs positive depths, "
            f"found {finite.min():g} m; use relative=True"
        )


# -- slope, roughness, spread ----------------------------------------------------------------
def slope(bmap: BathymetryMap, *, order: Order = 1) -> np.ndarray:
    """Seafloor slope in degrees, ``atan(|grad depth|)``, at every cell centre.

    The gradient is that of the map's interpolant (:meth:`BathymetryMap.gradient_at`):
    ``order=1`` (bilinear) takes the forward difference towards the next cell, ``order=3``
    (bicubic) the central difference inside the grid. NaN next to NaN cells.
    """
    g = _cell_gradient(bmap, order)
    return np.degrees(np.arctan(np.hypot(g[..., 0], g[..., 1])))


def roughness(bmap: BathymetryMap, window: int) -> np.ndarray:
    """Standard deviation (metres) of the depth about the best-fit plane of each window.

    The plane ``a + b u + c v`` is fitted by least squares to the ``N = window^2`` cells; the
    residual sum of squares is divided by ``N - 3`` (its degrees of freedom), so the figure is
    an unbiased estimate of the variance of white noise on a plane. Vectorised with separable
    ``scipy.ndimage`` correlations; a planar map gives 0 to rounding (~1e-12 m).

    Examples
    --------
    >>> import numpy as np
    >>> from tangraph.maps import BathymetryMap
    >>> x = np.arange(7.0)
    >>> m = BathymetryMap(north=x, east=x, depth=50 + 0.3 * x[:, None] - 0.2 * x)
    >>> bool(np.nanmax(roughness(m, 3)) < 1e-9)
    True
    """
    w = _check_window(bmap, window, "roughness")
    z = _centred(bmap.depth, plane=True)
    ones, u = np.ones(w), np.arange(w, dtype=np.float64) - w // 2
    n, s_uu = float(w * w), float(w * np.sum(u * u))
    s_z = _window_sum(z, ones, ones)
    rss = (
        _window_sum(z * z, ones, ones)
        - s_z**2 / n
        - _window_sum(z, u, ones) ** 2 / s_uu
        - _window_sum(z, ones, u) ** 2 / s_uu
    )
    out = np.sqrt(np.maximum(rss, 0.0) / (n - 3.0))
    out[_incomplete(bmap.depth, w)] = np.nan
    return out


def terrain_std(bmap: BathymetryMap, window: int) -> np.ndarray:
    """Standard deviation (metres, ``N - 1`` in the denominator) of the depths of each window.

    Examples
    --------
    >>> import numpy as np
    >>> from tangraph.maps import BathymetryMap
    >>> m = BathymetryMap(north=np.arange(3.0), east=np.arange(3.0),
    ...                   depth=np.array([[1.0, 2, 3], [4, 5, 6], [7, 8, 9]]))
    >>> round(float(terrain_std(m, 3)[1, 1]), 6) == round(float(np.std(m.depth, ddof=1)), 6)
    True
    """
    w = _check_window(bmap, window, "terrain_std")
    z = _centred(bmap.depth, plane=False)
    ones, n = np.ones(w), float(w * w)
    ss = _window_sum(z * z, ones, ones) - _window_sum(z, ones, ones) ** 2 / n
    out = np.sqrt(np.maximum(ss, 0.0) / (n - 1.0))
    out[_incomplete(bmap.depth, w)] = np.nan
    return out


# -- entropy ---------------------------------------------------------------------------------
def terrain_entropy(bmap: BathymetryMap, window: int, *, relative: bool = False) -> np.ndarray:
    """Terrain entropy (Wang et al. 2007, as used by Han et al. 2020) of each window, in nats.

    With ``h`` the depths of the window's ``N`` cells, ``p_ij = h_ij / sum(h)`` and
    ``H = -sum p_ij ln p_ij`` (natural log; divide by ``ln 2`` for bits). ``H <= ln N``, with
    equality for a flat window; lower entropy means more distinctive terrain.

    Parameters
    ----------
    bmap : BathymetryMap
    window : int
        Odd side of the window, in cells.
    relative : bool
        False: the literal definition on absolute depths (which must be positive). With depths
        of ~1000 m and relief of a few metres every ``p_ij`` is close to ``1/N`` and ``H`` is
        ``ln N`` to within ~1e-5 everywhere, so the figure mostly measures the mean depth. True:
        use ``h - min(h) + RELATIVE_EPSILON`` of each window instead, which reacts to the shape
        of the relief and not to the depth it lies at (it is unchanged by a shift of depth, and
        by scaling the relief). It is not symmetric in up and down: a pit in a flat window
        concentrates ``p`` on a few cells (low entropy), a knoll leaves it nearly uniform.

    Returns
    -------
    ndarray, shape (ny, nx)
        NaN where the window holds NaN or leaves the map.

    Examples
    --------
    >>> import numpy as np
    >>> from tangraph.maps import BathymetryMap
    >>> flat = BathymetryMap(north=np.arange(5.0), east=np.arange(5.0), depth=np.full((5, 5), 80.0))
    >>> bool(np.isclose(terrain_entropy(flat, 3)[2, 2], np.log(9)))
    True
    """
    where = "terrain_entropy"
    w = _check_window(bmap, window, where)
    if not relative:
        _check_positive_depth(bmap.depth, where)
    r = w // 2
    padded = np.pad(bmap.depth, r, constant_values=np.nan)
    ny, nx = bmap.shape
    rows = max(1, _ENTROPY_CHUNK // (nx * w * w))
    out = np.empty((ny, nx))
    for start in range(0, ny, rows):  # blocks of rows bound the memory of the window views
        stop = min(ny, start + rows)
        views = sliding_window_view(padded[start : stop + 2 * r], (w, w))
        out[start:stop] = _entropy(views.reshape(stop - start, nx, w * w), relative)
    return out


def region_entropy(
    bmap: BathymetryMap,
    north: Sequence[float] | None = None,
    east: Sequence[float] | None = None,
    *,
    relative: bool = False,
) -> float:
    """Terrain entropy (nats) of the cells whose centres lie in ``north = (lo, hi)``,
    ``east = (lo, hi)`` (the whole map where omitted); see :func:`terrain_entropy`.

    NaN if the region holds a NaN cell.

    Examples
    --------
    >>> import numpy as np
    >>> from tangraph.maps import BathymetryMap
    >>> flat = BathymetryMap(north=np.arange(4.0), east=np.arange(4.0), depth=np.full((4, 4), 9.0))
    >>> bool(np.isclose(region_entropy(flat, north=(0, 1), east=(0, 2)), np.log(6)))  # 6 cells
    True
    """
    area = bmap.crop(north=north, east=east)
    if not relative:
        _check_positive_depth(area.depth, "region_entropy")
    return float(_entropy(area.depth.ravel(), relative))


# -- Fisher information ----------------------------------------------------------------------
def fisher_information(bmap: BathymetryMap, *, sigma: float, order: Order = 1) -> np.ndarray:
    """Fisher information on ``(north, east)`` of one sounding at each cell centre.

    A sounding ``y = depth(x) + e``, ``e ~ N(0, sigma^2)``, carries ``J = g g^T / sigma^2`` with
    ``g`` the gradient of the depth (:func:`slope` explains ``order``). Units 1/m^2.

    Returns
    -------
    ndarray, shape (ny, nx, 2, 2)
        NaN where the gradient is NaN.
    """
    sigma = _check_sigma(sigma, "fisher_information")
    g = _cell_gradient(bmap, order)
    return g[..., :, None] * g[..., None, :] / sigma**2


def window_information(
    bmap: BathymetryMap, north, east, *, sigma: float, order: Order = 1
) -> np.ndarray:
    """Fisher information (2 x 2, 1/m^2) of independent soundings at the points ``(north, east)``.

    The sum of ``g g^T / sigma^2`` over the points. A point off the map or next to a NaN cell
    makes the result NaN: drop such soundings first (``bmap.contains``).

    Examples
    --------
    >>> import numpy as np
    >>> from tangraph.maps import BathymetryMap
    >>> x = np.arange(5.0)
    >>> m = BathymetryMap(north=x, east=x, depth=10 + 0.5 * x[:, None] + 0.5 * x)
    >>> window_information(m, [1.0, 2.0], [1.0, 2.0], sigma=1.0)
    array([[0.5, 0.5],
           [0.5, 0.5]])
    """
    sigma = _check_sigma(sigma, "window_information")
    g = bmap.gradient_at(north, east, order=order).reshape(-1, 2)
    return g.T @ g / sigma**2


def crlb(information) -> np.ndarray:
    """Cramér-Rao lower bound (m^2) on the position covariance: the inverse of ``information``.

    Parameters
    ----------
    information : array_like, shape (..., 2, 2)
        Symmetric positive semi-definite Fisher information matrices.

    Returns
    -------
    ndarray, shape (..., 2, 2)
        The inverses. Where the information is singular (``det <= 1e-12 trace^2``: flat
        terrain, or soundings that all share one gradient direction) the position is
        unobservable and every entry is ``inf``; NaN information gives NaN.

    Examples
    --------
    >>> crlb([[4.0, 0.0], [0.0, 1.0]])
    array([[0.25, 0.  ],
           [0.  , 1.  ]])
    >>> crlb([[1.0, 1.0], [1.0, 1.0]])
    array([[inf, inf],
           [inf, inf]])
    """
    info = np.asarray(information, dtype=np.float64)
    if info.ndim < 2 or info.shape[-2:] != (2, 2):
        raise TangraphError(f"crlb: information must have shape (..., 2, 2), got {info.shape}")
    a, b, c, d = info[..., 0, 0], info[..., 0, 1], info[..., 1, 0], info[..., 1, 1]
    trace, det = a + d, a * d - b * c
    scale = np.abs(a) + np.abs(d)
    with np.errstate(invalid="ignore"):
        bad = (np.abs(b - c) > 1e-9 * scale) | (trace < 0) | (det < -_SINGULAR_RTOL * trace**2)
        singular = det <= _SINGULAR_RTOL * trace**2
    if np.any(bad):
        raise TangraphError(
            "crlb: information is not symmetric positive semi-definite "
            f"(first offending matrix: {info.reshape(-1, 2, 2)[np.argmax(bad.ravel())].tolist()})"
        )
    with np.errstate(divide="ignore", invalid="ignore"):
        adjugate = np.stack([np.stack([d, -b], -1), np.stack([-c, a], -1)], -2)
        inverse = adjugate / det[..., None, None] + 0.0  # + 0.0 turns -0.0 into 0.0
    inverse[singular] = np.inf
    return inverse


def _median(values: np.ndarray) -> float:
    """The median of the finite values (NaN when there is none, without numpy's warning)."""
    finite = values[np.isfinite(values)]
    return float(np.median(finite)) if finite.size else float("nan")


def describe(bathymetry: BathymetryMap, *, window: int = 5) -> dict:
    """A map's figures, as data (``tangraph maps info``, ``--json``): shape, cell, extent, depth
    range, valid fraction, CRS, origin, centre in latitude/longitude (with a CRS), median slope
    (deg) and median roughness (plane-fit residual std over ``window`` x ``window`` cells, m)."""
    m = bathymetry
    dn, de = m.cell_size
    n_lo, n_hi, e_lo, e_hi = m.extent
    report = {
        "name": m.name, "shape": [int(m.shape[0]), int(m.shape[1])], "cell_m": [float(dn), float(de)],
        "extent_m": {"north": [float(n_lo), float(n_hi)], "east": [float(e_lo), float(e_hi)]},
        "depth_m": {"min": float(np.nanmin(m.depth)), "max": float(np.nanmax(m.depth)),
                    "mean": float(np.nanmean(m.depth))},
        "valid_fraction": float(m.valid_fraction), "crs": m.crs,
        "origin": {"northing": float(m.origin[0]), "easting": float(m.origin[1])},
        "slope_median_deg": _median(slope(m)),
        # (NaN: no window of the map holds data, or the map is smaller than a window)
        "roughness_median_m": _median(roughness(m, window)) if min(m.shape) >= window else float("nan"),
        "roughness_window": window,
    }
    if m.crs is not None:
        from tangraph.maps.projection import to_lonlat

        lat, lon = to_lonlat(m, 0.5 * (n_lo + n_hi), 0.5 * (e_lo + e_hi))
        report["centre"] = {"lat": float(lat), "lon": float(lon)}
    return report
