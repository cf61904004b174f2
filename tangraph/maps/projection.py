"""The one projection step: geographic grids into a local metric frame, and back to lat/lon.

A map's ``crs`` is a projected CRS and its ``origin`` the ``(northing, easting)`` of the local
point (0, 0) in that CRS. Geographic grids get a transverse Mercator centred on the grid
(conformal, so headings stay true, scale error below 0.1 % within 250 km of the centre).
"""

from __future__ import annotations

import numpy as np
import pyproj

from tangraph.errors import MapFormatError, TangraphError
from tangraph.maps.grid import BathymetryMap

__all__ = ["from_lonlat", "local_crs", "north_in_grid", "project_geographic_grid", "same_crs", "to_lonlat"]

_WGS84 = "EPSG:4326"
_METRES_PER_DEGREE = 111_320.0


def same_crs(a, b) -> bool:
    """Whether two CRSs (strings pyproj reads) are one, axis order aside; two that pyproj cannot
    read are one only when spelt alike."""
    try:
        return a == b or pyproj.CRS.from_user_input(a).equals(pyproj.CRS.from_user_input(b),
                                                             ignore_axis_order=True)
    except pyproj.exceptions.CRSError:
        return False


def local_crs(lat0: float, lon0: float) -> str:
    """A transverse Mercator CRS (WGS84) centred at ``(lat0, lon0)``, as a PROJ string."""
    lon0 = (float(lon0) + 180.0) % 360.0 - 180.0
    return (
        f"+proj=tmerc +lat_0={float(lat0):.8f} +lon_0={lon0:.8f} +k=1 +x_0=0 +y_0=0 "
        "+datum=WGS84 +units=m +no_defs +type=crs"
    )


def mean_degrees(lat, lon, crs, where: str) -> tuple[float, float]:
    """The mean latitude and longitude of points given in the geographic ``crs``; points beyond
    latitude 90 or longitude 360 (projected metres read as degrees) are refused naming ``crs=``."""
    lat, lon = np.asarray(lat, np.float64), np.asarray(lon, np.float64)
    if np.any(np.abs(lat) > 90.0) or np.any(np.abs(lon) > 360.0):
        raise MapFormatError(f"{where}: crs={crs!r} is in degrees, but the points reach latitude "
                             f"{np.max(np.abs(lat)):,.0f} and longitude {np.max(np.abs(lon)):,.0f}: "
                             "projected metres? pass their CRS (CLI: --crs)")
    return float(np.mean(lat)), float(np.mean(lon))


def _transformer(source, target) -> pyproj.Transformer:
    try:
        return pyproj.Transformer.from_crs(source, target, always_xy=True)
    except pyproj.exceptions.CRSError as exc:
        raise TangraphError(f"CRS {source!r} is not understood by pyproj: {exc}") from None


def north_in_grid(transform, x, y, step: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Where the source's north points in the target grid: the projected ``(north, east)`` of
    source points ``(x, y)`` (easting/longitude, northing/latitude) and the angle (rad,
    clockwise from the target's grid north) of the projected step ``step`` north of each (in
    source units: metres, or degrees of latitude). A heading from the source's north plus that
    angle is a heading from the target's grid north (conformal projections keep angles).

    ``transform`` is a ``pyproj.Transformer.transform`` with ``always_xy=True``; NaN where a
    point does not project.
    """
    x, y = np.asarray(x, float), np.asarray(y, float)
    e, n = (np.asarray(v) for v in transform(x, y))
    e1, n1 = (np.asarray(v) for v in transform(x, y + step))
    return n, e, np.arctan2(e1 - e, n1 - n)


def to_lonlat(bathymetry: BathymetryMap, north, east) -> tuple[np.ndarray, np.ndarray]:
    """Latitude and longitude (WGS84 degrees) of local points of a map."""
    if bathymetry.crs is None:
        raise TangraphError(f"map {bathymetry.name!r} has no CRS: it has no place on Earth")
    t = _transformer(bathymetry.crs, _WGS84)
    lon, lat = t.transform(
        np.asarray(east, float) + bathymetry.origin[1], np.asarray(north, float) + bathymetry.origin[0]
    )
    return np.asarray(lat), np.asarray(lon)


def from_lonlat(bathymetry: BathymetryMap, lat, lon) -> tuple[np.ndarray, np.ndarray]:
    """Local ``(north, east)`` of points given in WGS84 degrees."""
    if bathymetry.crs is None:
        raise TangraphError(f"map {bathymetry.name!r} has no CRS: it has no place on Earth")
    t = _transformer(_WGS84, bathymetry.crs)
    x, y = t.transform(np.asarray(lon, float), np.asarray(lat, float))
    return np.asarray(y) - bathymetry.origin[0], np.asarray(x) - bathymetry.origin[1]


def project_geographic_grid(
    lat: np.ndarray,
    lon: np.ndarray,
    depth: np.ndarray,
    *,
    cell: float | None = None,
    name: str = "map",
    source_crs: str = _WGS84,
    max_scale_error: float = 1e-3,
) -> BathymetryMap:
    """Resample a regular latitude/longitude grid of depths onto a local metric grid.

    Parameters
    ----------
    lat, lon : ndarray
        Ascending cell-centre latitudes and longitudes in degrees (longitudes may run
        0..360 or -180..180). They need not be evenly spaced (Mercator-spaced latitudes are
        common in charts): the grid is interpolated in index space.
    depth : ndarray, shape (len(lat), len(lon))
        Depth, positive down, NaN for no data.
    cell : float, optional
        Cell size of the metric grid; by default the finer of the latitude and longitude
        spacings in metres at the grid's centre.
    name : str
        Name of the map.
    source_crs : str
        The geographic CRS of ``lat`` and ``lon``.
    max_scale_error : float
        The largest scale error of the transverse Mercator allowed at the grid's edge (default
        0.1 %, about 285 km from the central meridian); a wider grid is refused with its figure.

    Returns
    -------
    BathymetryMap
        On a transverse Mercator centred on the grid, origin (0, 0); bilinear resampling,
        NaN where the metric grid falls outside the geographic one.
    """
    lat = np.asarray(lat, float)
    lon = np.asarray(lon, float)
    for axis, values in (("latitude", lat), ("longitude", lon)):
        if values.ndim != 1 or values.size < 2 or not np.all(np.diff(values) > 0):
            raise MapFormatError(f"{name}: {axis} must be 1-D, strictly ascending, at least 2 values")
    if lat[0] < -90 or lat[-1] > 90:
        raise MapFormatError(f"{name}: latitudes run from {lat[0]} to {lat[-1]}, outside [-90, 90]")
    # the grid in index space: cell (i, j) at (i, j); coordinates map to fractional indices
    indexed = BathymetryMap(north=np.arange(lat.size, dtype=float), east=np.arange(lon.size, dtype=float),
                            depth=depth, name=f"{name} (geographic)")
    lat0 = 0.5 * (lat[0] + lat[-1])
    if cell is None:  # the finer of the two native spacings, so no detail is lost
        d_lat = (lat[-1] - lat[0]) / (lat.size - 1)
        d_lon = (lon[-1] - lon[0]) / (lon.size - 1) * np.cos(np.radians(lat0))
        cell = min(d_lat, d_lon) * _METRES_PER_DEGREE
    cell = float(cell)
    lon0 = 0.5 * (lon[0] + lon[-1])
    crs = local_crs(lat0, lon0)
    to_local = _transformer(source_crs, crs)
    # the projected outline of the geographic grid bounds the metric grid
    edge_lat = np.concatenate([lat, lat, np.full(lon.size, lat[0]), np.full(lon.size, lat[-1])])
    edge_lon = np.concatenate([np.full(lat.size, lon[0]), np.full(lat.size, lon[-1]), lon, lon])
    x, y = to_local.transform(_wrap(edge_lon), edge_lat)
    _check_scale_error(crs, _wrap(edge_lon), edge_lat, lon, name, max_scale_error)
    north = np.arange(np.ceil(np.min(y) / cell), np.floor(np.max(y) / cell) + 1) * cell
    east = np.arange(np.ceil(np.min(x) / cell), np.floor(np.max(x) / cell) + 1) * cell
    nn, ee = np.meshgrid(north, east, indexing="ij")
    q_lon, q_lat = _transformer(crs, source_crs).transform(ee, nn)
    q_lon = lon[0] + np.mod(q_lon - lon[0], 360.0)  # into the grid's own longitude range
    i = np.interp(q_lat, lat, np.arange(lat.size), left=np.nan, right=np.nan)
    j = np.interp(q_lon, lon, np.arange(lon.size), left=np.nan, right=np.nan)
    return BathymetryMap(
        north=north, east=east, depth=indexed.depth_at(i, j), crs=crs, origin=(0.0, 0.0), name=name
    )


def _check_scale_error(crs: str, edge_lon: np.ndarray, edge_lat: np.ndarray, lon: np.ndarray,
                       name: str, limit: float) -> None:
    """Refuse a grid too wide for one transverse Mercator (scale error beyond 0.1 % at its edge)."""
    factors = pyproj.Proj(crs).get_factors(edge_lon, edge_lat)
    error = float(np.nanmax(np.abs(np.asarray(factors.meridional_scale) - 1.0)))
    if not np.isfinite(error) or error > limit:
        raise MapFormatError(
            f"{name}: the grid spans {lon[-1] - lon[0]:.3g} degrees of longitude; on one transverse "
            f"Mercator centred on it the scale error reaches {error:.2%} at its edge (limit "
            f"{limit:.2%}); crop it (gmt grdcut, gdal_translate -projwin) or accept the error with "
            f"max_scale_error={np.ceil(error * 1e3) / 1e3:g}"
        )


def _wrap(lon: np.ndarray) -> np.ndarray:
    return (np.asarray(lon, float) + 180.0) % 360.0 - 180.0
