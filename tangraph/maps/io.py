"""Readers and writers of bathymetry grids: NetCDF/GMT, GeoTIFF, BAG, S-102, XYZ, NPZ and TINs.

Everything enters through :func:`read_map` (or :func:`read_soundings` for scattered points)
and leaves a `BathymetryMap` in a local metric frame: geographic grids are projected once
(:mod:`tangraph.maps.projection`), projected grids keep their CRS with the origin at their
first cell centre (tangraph's own files keep the origin they were written with). GeoTIFFs go
through rasterio (GDAL, :mod:`tangraph.maps.raster`), BAG and S-102 too
(:mod:`tangraph.maps.hydro`); NetCDF maps are written with projected ``x``/``y`` and a CF
``grid_mapping``, so GDAL, GMT and QGIS place them. The map's error (``depth_std``, ``correlation_length``;
``error_dof``, ``error_drift`` in NetCDF, GeoTIFF, NPZ) is written by every writer (XYZ: a fourth
column) and read from every file with one: an uncertainty variable or band, BAG's and S-102's.
Depth is positive down; a file that stores elevation says so in its metadata, or the caller
says so with ``sign=``; a file where neither tells, or whose data contradict the guess from
its names, is refused.

A map is never read wrongly without a word: a truncated classic NetCDF, values beyond 12 000 m
(an unmarked fill value: ``nodata=``), an unknown unit (``units=``), ``units=``, ``sign=`` or
``crs=`` against what the file states, and a geographic grid too wide for one transverse
Mercator (``max_scale_error=``) are refused in one line naming the file, the variable, the
value and the option. Depths and coordinates in feet (the variable's ``units``, the CRS's axis
unit) are converted to metres.
"""

from __future__ import annotations

import dataclasses
import itertools
import os
import re
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from tangraph.errors import MapFormatError, TangraphError
from tangraph.maps._common import (  # noqa: F401 (the shared pieces, imported from here by others)
    UNCERTAINTY_NAMES,
    Sign,
    Uncertainty,
    _check_plausible,
    _depth_factor,
    _existing,
    _grid_to_map,
    _is_geographic,
    _mask_nodata,
    available_memory,
    check_given_crs,
    check_memory,
    checked_std,
    correlation_length_from,
    error_dof_from,
    metric_crs,
    resolve_sign,
    unit_factor,
)
from tangraph.maps.grid import BathymetryMap
from tangraph.maps.netcdf import NETCDF_SUFFIXES, read_netcdf, write_netcdf, write_sounding_grid
from tangraph.outputs import write_atomically

__all__ = ["Soundings", "map_format", "read_map", "read_soundings", "write_map", "write_sounding_grid"]

_FORMATS = {
    **dict.fromkeys(NETCDF_SUFFIXES, "netcdf"),
    ".tif": "geotiff", ".tiff": "geotiff",
    ".xyz": "xyz", ".txt": "xyz", ".csv": "xyz",
    ".npz": "npz",
    ".tsh": "tin", ".ply": "tin", ".obj": "tin",
    ".bag": "bag",
}
#: formats told by content or named, never by suffix alone (``.h5`` is any HDF5 file)
_NAMED_FORMATS = ("s102",)


def map_format(path: str | os.PathLike, format: str | None = None) -> str:
    """The format a map is written in at ``path`` (by its suffix, or ``format``); a one-line
    error naming the formats known otherwise (to check an output before any work)."""
    return _format_of(Path(path), format)


def _format_of(path: Path, given: str | None, *, reading: bool = False) -> str:
    known = set(_FORMATS.values()) | set(_NAMED_FORMATS)
    if given is not None:
        if given not in known:
            raise TangraphError(f"unknown map format {given!r}; known: {sorted(known)}")
        return given
    fmt = _FORMATS.get(path.suffix.lower())
    if fmt is None and path.suffix.lower() in (".h5", ".hdf5") and reading:
        from tangraph.maps.hydro import is_s102

        if is_s102(path):
            return "s102"
        raise MapFormatError(f"{path}: an HDF5 file that is not S-102 (no BathymetryCoverage group); "
                             "tangraph reads HDF5 maps as S-102 only (or pass format=)")
    if fmt is None:
        s102 = " (S-102 .h5: format='s102')" if path.suffix.lower() in (".h5", ".hdf5") else ""
        raise MapFormatError(
            f"{path}: cannot tell the format from the suffix {path.suffix!r}; known suffixes: "
            f"{', '.join(sorted(_FORMATS))} (or pass format=){s102}"
        )
    return fmt


# -- XYZ text -------------------------------------------------------------------------------
def _load_xyz(path: Path, columns: int = 3) -> np.ndarray:
    with open(path, encoding="utf-8", errors="replace") as f:
        first = next((line for line in f if line.strip() and not line.startswith("#")), "")
    delimiter = "," if "," in first else None
    skip = 0 if _is_numeric_row(first, delimiter) else 1  # one header row allowed
    try:
        with warnings.catch_warnings(action="ignore", category=UserWarning):  # (empty: said below)
            data = np.loadtxt(path, comments="#", delimiter=delimiter, skiprows=skip, ndmin=2)
    except ValueError as exc:
        raise MapFormatError(f"{path}: not a table of numbers x y z ({exc})") from None
    if data.shape[1] < columns or data.shape[0] == 0:
        raise MapFormatError(f"{path}: expected at least {columns} columns (x/east, y/north, z"
                             f"{', depth_std' if columns > 3 else ''}), got {data.shape}")
    return data[:, :columns]


#: the header line of tangraph's own XYZ maps with the error layer
_XYZ_STD_COLUMNS = "columns: east north depth depth_std"


def _xyz_header(path: Path) -> str:
    """The comment lines at the top of a text file, joined."""
    with open(path, encoding="utf-8", errors="replace") as f:
        return " ".join(line[1:].strip() for line in itertools.takewhile(lambda x: x.startswith("#"), f))


def _is_numeric_row(line: str, delimiter: str | None) -> bool:
    try:
        [float(v) for v in line.split(delimiter)]
    except ValueError:
        return False
    return True


def read_xyz(path, *, sign=None, crs=None, cell=None, name=None, nodata=None,
             units=None, uncertainty: Uncertainty = None, max_scale_error=1e-3) -> BathymetryMap:
    """A regular grid from an ``x y z`` text file (x east/longitude, y north/latitude).

    A fourth column is the depths' std only in tangraph's own files (header ``columns: east north
    depth depth_std``, the correlation length its ``correlation_length_m``); other text files
    carry no error layer. tangraph's own files (header ``tangraph map ...``, depths positive
    down) need no ``sign=`` and state their CRS; any other text grid's is given with ``crs=``.
    """
    path = _existing(path)
    header = _xyz_header(path)
    own = header.startswith("tangraph map ") and "positive down" in header  # written by write_xyz
    stated = re.search(r"; crs (\S+?);", header) if own else None
    crs = check_given_crs(crs, stated[1] if stated and stated[1] != "None" else None, str(path))
    with_std = uncertainty is not False and _XYZ_STD_COLUMNS in header
    data = _load_xyz(path, 4 if with_std else 3)
    x_values, x_index = np.unique(data[:, 0], return_inverse=True)
    y_values, y_index = np.unique(data[:, 1], return_inverse=True)
    flat = y_index * x_values.size + x_index
    if x_values.size * y_values.size != data.shape[0] or np.unique(flat).size != flat.size:
        raise MapFormatError(
            f"{path}: {data.shape[0]} points do not form a full regular grid "
            f"({y_values.size} x {x_values.size}); scattered soundings are gridded with "
            "tangraph.maps.grid_soundings or `tangraph maps grid`"
        )
    geographic = crs is not None and _is_geographic(crs)
    crs_unit = 1.0 if geographic else metric_crs(crs, str(path))[1]
    z = _mask_nodata(data[:, 2], nodata) * _depth_factor(None, units, crs_unit, str(path), "z")
    grid: np.ndarray = np.full(x_values.size * y_values.size, np.nan)
    grid[flat] = z
    grid = grid.reshape(y_values.size, x_values.size)
    factor = resolve_sign(grid, {"positive": "down"} if own else {}, "z", sign, str(path))
    std = length = None
    if with_std:
        std = np.full(grid.size, np.nan)
        std[flat] = data[:, 3]
        std = checked_std(std.reshape(grid.shape), grid, nodata=nodata,
                          factor=_depth_factor(None, units, crs_unit, str(path), "z"),
                          where=f"{path}: uncertainty column 'depth_std'")
        found = re.search(r"correlation_length_m (\S+?);", header + ";")
        length = correlation_length_from({"correlation_length_m": found[1]} if found else {},
                                         ("correlation_length_m",), str(path))
    elif uncertainty is True or isinstance(uncertainty, str):
        raise MapFormatError(f"{path}: an x y z file carries no uncertainty column (only tangraph's own "
                             f"do, with the header '{_XYZ_STD_COLUMNS}')")
    return _grid_to_map(y_values, x_values, factor * grid, geographic=geographic,
                        crs=crs, cell=cell, name=name or path.stem, where=str(path),
                        max_scale_error=max_scale_error, depth_std=std, correlation_length=length)


def write_xyz(bathymetry: BathymetryMap, path: Path) -> None:
    """``east north depth`` rows (projected coordinates: local plus origin), NaN cells kept; a
    fourth column ``depth_std`` and the header's ``correlation_length_m`` if the map has them."""
    nn, ee = np.meshgrid(bathymetry.north + bathymetry.origin[0],
                         bathymetry.east + bathymetry.origin[1], indexing="ij")
    columns = [ee.ravel(), nn.ravel(), bathymetry.depth.ravel()]
    header = f"tangraph map {bathymetry.name}; crs {bathymetry.crs}; "
    if bathymetry.correlation_length is not None:
        header += f"correlation_length_m {bathymetry.correlation_length!r}; "
    if bathymetry.depth_std is None:
        header += "columns: east north depth (m, positive down)"
    else:
        header += f"{_XYZ_STD_COLUMNS} (m, depth positive down)"
        columns.append(bathymetry.depth_std.ravel())
    np.savetxt(path, np.column_stack(columns), fmt="%.3f", header=header)


@dataclasses.dataclass(frozen=True)
class Soundings:
    """Scattered soundings in a local frame: ``points`` (N, 3) as (north, east, depth)."""

    points: np.ndarray
    crs: str | None
    origin: tuple[float, float]
    source: str


def read_soundings(path, *, sign: Sign | None = None, crs: str | None = None, nodata=None,
                   units: str | None = None) -> Soundings:
    """Scattered soundings from an ``x y z`` text file, in a local frame.

    Geographic points (``crs`` geographic) are projected to a transverse Mercator centred on
    them; projected points keep ``crs`` with the origin at the south-west corner of their
    bounding box (rounded down to whole metres).
    """
    from tangraph.maps.projection import local_crs, mean_degrees

    path = _existing(path)
    data = _load_xyz(path)
    geographic = crs is not None and _is_geographic(crs)
    crs, scale = (crs, 1.0) if geographic else metric_crs(crs, str(path))
    z = _mask_nodata(data[:, 2], nodata) * _depth_factor(None, units, scale, str(path), "z")
    depth = resolve_sign(z, {}, "z", sign, str(path)) * z
    _check_plausible(depth, str(path), "z")
    x, y = data[:, 0] * scale, data[:, 1] * scale
    if geographic:
        import pyproj

        local = local_crs(*mean_degrees(y, x, crs, str(path)))
        east, north = pyproj.Transformer.from_crs(crs, local, always_xy=True).transform(x, y)
        return Soundings(np.column_stack([north, east, depth]), local, (0.0, 0.0), str(path))
    origin = (float(np.floor(np.min(y))), float(np.floor(np.min(x)))) if crs else (0.0, 0.0)
    return Soundings(np.column_stack([y - origin[0], x - origin[1], depth]), crs, origin, str(path))


# -- NPZ ------------------------------------------------------------------------------------
def _npz_error(data: dict, key: str | None, depth: np.ndarray, factor: float, nodata, path: Path,
               uncertainty: Uncertainty):
    """``(depth_std, correlation_length)`` of an ``.npz`` map: the array ``key`` and the scalar
    ``correlation_length`` (None where absent or ``uncertainty`` is False)."""
    if uncertainty is False:
        return None, None
    std = None
    if key is not None:
        std = checked_std(data[key], depth, factor=factor, nodata=nodata,
                          where=f"{path}: uncertainty array {key!r}")
    return std, correlation_length_from(data, ("correlation_length",), str(path))


def _npz_uncertainty_key(data: dict, variable: str | None, uncertainty: Uncertainty,
                         path: Path) -> str | None:
    """The array holding the std: ``uncertainty`` if a name, else the one named like it."""
    if isinstance(uncertainty, str):
        if uncertainty not in data:
            raise MapFormatError(f"{path}: no uncertainty array {uncertainty!r}; it has {sorted(data)}")
        return uncertainty
    named = [k for k, v in data.items()
             if np.ndim(v) == 2 and k != variable and k.lower() in UNCERTAINTY_NAMES]
    if uncertainty is False or not named:
        if uncertainty is True:
            raise MapFormatError(f"{path}: no uncertainty array (none named "
                                 f"{', '.join(UNCERTAINTY_NAMES[:5])}, ...)")
        return None
    if len(named) > 1:
        raise MapFormatError(f"{path}: several uncertainty arrays {named}; choose one with "
                             "uncertainty='NAME'")
    return named[0]


def read_npz(path, *, variable=None, sign=None, crs=None, cell=None, name=None, nodata=None,
             units=None, uncertainty: Uncertainty = None, max_scale_error=1e-3) -> BathymetryMap:
    """A grid from ``.npz``: tangraph's own (north, east, depth, ..., and ``depth_std``,
    ``correlation_length`` if the map has them) or (lat, lon, values, and an array named like an
    uncertainty: ``depth_std``, ``uncertainty``, ``std``, ...)."""
    path = _existing(path)
    try:
        data = dict(np.load(path, allow_pickle=False))
    except (OSError, ValueError) as exc:
        raise MapFormatError(f"{path}: not a readable .npz file ({exc})") from None
    if {"north", "east", "depth"} <= data.keys() and variable is None:
        scale = unit_factor(units, str(path), "units=") if units else 1.0
        depth = _mask_nodata(data["depth"], nodata) * scale
        _check_plausible(depth, f"{path}:depth", "depth")
        key = _npz_uncertainty_key(data, "depth", uncertainty, path)
        std, length = _npz_error(data, key, depth, scale, nodata, path, uncertainty)
        dof, drift = (None, None) if uncertainty is False else (
            error_dof_from(data, ("error_dof",), str(path)), data.get("error_drift"))
        try:
            m = BathymetryMap(
                north=data["north"], east=data["east"], depth=depth,
                crs=str(data["crs"]) if "crs" in data and str(data["crs"]) else None,
                origin=tuple(data.get("origin", (0.0, 0.0))), name=name or str(data.get("name", path.stem)),
                depth_std=std, correlation_length=length, error_dof=dof, error_drift=drift)
        except MapFormatError as exc:
            raise MapFormatError(f"{path}: {exc}") from None
        return m.resample(cell) if cell is not None else m
    y_key = next((k for k in ("lat", "latitude", "y") if k in data), None)
    x_key = next((k for k in ("lon", "longitude", "x") if k in data), None)
    grids = [k for k, v in data.items() if np.ndim(v) == 2 and k.lower() not in UNCERTAINTY_NAMES]
    variable = variable or (grids[0] if len(grids) == 1 else None)
    if y_key is None or x_key is None or variable not in data:
        raise MapFormatError(
            f"{path}: keys {sorted(data)}; expected north/east/depth, or lat/lon (or x/y) with one "
            "2-D variable (choose it with variable=)"
        )
    geographic = (y_key.startswith("lat") and crs is None) or (crs is not None and _is_geographic(crs))
    crs_unit = 1.0 if geographic else metric_crs(crs, str(path))[1]
    depth_factor = _depth_factor(None, units, crs_unit, str(path), variable)
    values = _mask_nodata(data[variable], nodata) * depth_factor
    factor = resolve_sign(values, {}, variable, sign, str(path))
    key = _npz_uncertainty_key(data, variable, uncertainty, path)
    std, length = _npz_error(data, key, values, depth_factor, nodata, path, uncertainty)
    return _grid_to_map(data[y_key], data[x_key], factor * values, geographic=geographic, crs=crs,
                        cell=cell, name=name or path.stem, where=f"{path}:{variable}", variable=variable,
                        max_scale_error=max_scale_error, depth_std=std, correlation_length=length)


def write_npz(bathymetry: BathymetryMap, path: Path) -> None:
    """tangraph's own ``.npz``: ``north``, ``east``, ``depth``, ``crs``, ``origin``, ``name``, and
    ``depth_std``, ``correlation_length``, ``error_dof``, ``error_drift`` where the map has them."""
    error: dict[str, Any] = {k: np.asarray(v, np.float64) for k in ("depth_std", "correlation_length",
                             "error_dof", "error_drift") if (v := getattr(bathymetry, k)) is not None}
    with open(path, "wb") as f:
        np.savez_compressed(f, north=bathymetry.north, east=bathymetry.east, depth=bathymetry.depth,
                            crs=np.str_(bathymetry.crs or ""), origin=np.asarray(bathymetry.origin),
                            name=np.str_(bathymetry.name), **error)


# -- TIN ------------------------------------------------------------------------------------
def read_tsh(path: Path) -> tuple[np.ndarray, np.ndarray, str]:
    """Vertices (N, 3) as (x, y, attribute), triangles (M, 3) and the attribute's title from an
    ANUGA ``.tsh`` triangulation."""
    path = _existing(path)
    try:
        with open(path, encoding="utf-8") as f:
            lines = f.read().splitlines()
        n_vert, n_attr = (int(v) for v in lines[0].split("#")[0].split()[:2])
        if n_attr < 1:
            raise MapFormatError(f"{path}: the vertices carry no attribute (no elevation)")
        verts = np.array([line.split()[1:4] for line in lines[1:1 + n_vert]], dtype=float)
        pos = 1 + n_vert
        title = lines[pos + 1].strip() if lines[pos].startswith("#") else "elevation"
        pos += 1 + n_attr
        n_tri = int(lines[pos].split("#")[0].split()[0])
        tris = np.array([line.split()[1:4] for line in lines[pos + 1:pos + 1 + n_tri]], dtype=np.int64)
    except (IndexError, ValueError) as exc:
        raise MapFormatError(f"{path}: not an ANUGA .tsh triangulation ({exc})") from None
    if verts.shape != (n_vert, 3) or tris.shape != (n_tri, 3):
        raise MapFormatError(f"{path}: truncated .tsh (expected {n_vert} vertices, {n_tri} triangles)")
    return verts, tris, title


def read_tin(path, *, sign=None, crs=None, cell=None, name=None) -> BathymetryMap:
    """A triangulated surface (ANUGA ``.tsh``, PLY, OBJ) gridded at ``cell`` metres by ray casting."""
    from tangraph.maps import mesh

    path = _existing(path)
    if cell is None:
        raise TangraphError(f"{path}: a triangulated surface needs a grid cell size (cell=)")
    if path.suffix.lower() != ".tsh":
        return mesh.read_mesh(path, cell=cell, name=name or path.stem, crs=crs)
    verts, tris, title = read_tsh(path)
    factor = resolve_sign(verts[:, 2], {}, title, sign, str(path))
    origin = (float(np.floor(verts[:, 1].min())), float(np.floor(verts[:, 0].min()))) if crs else (0.0, 0.0)
    vertices = np.column_stack([verts[:, 1] - origin[0], verts[:, 0] - origin[1], factor * verts[:, 2]])
    return mesh.triangles_to_map(vertices, tris, cell=cell, name=name or path.stem, crs=crs, origin=origin)


# -- dispatch -------------------------------------------------------------------------------
def read_map(
    path: str | os.PathLike,
    *,
    format: str | None = None,
    variable: str | None = None,
    sign: Sign | None = None,
    crs: str | None = None,
    cell: float | None = None,
    name: str | None = None,
    nodata: float | None = None,
    units: str | None = None,
    uncertainty: Uncertainty = None,
    max_scale_error: float = 1e-3,
) -> BathymetryMap:
    """Read a bathymetry grid from a file into a local metric `BathymetryMap`.

    Parameters
    ----------
    path : path-like
        ``.nc/.grd/.cdf`` NetCDF (COARDS/CF or GMT), ``.tif`` GeoTIFF, ``.bag`` BAG, ``.h5``
        S-102 (told by its content), ``.xyz/.txt/.csv`` text grid, ``.npz``,
        ``.tsh/.ply/.obj`` triangulated surface.
    format : {"netcdf", "geotiff", "bag", "s102", "xyz", "npz", "tin"}, optional
        Overrides the suffix.
    variable : str, optional
        The grid variable of a NetCDF/NPZ file holding several.
    sign : {"depth", "elevation"}, optional
        What the values are, where the file's metadata does not say.
    crs : str, optional
        The file's CRS where it does not say (e.g. ``"EPSG:32755"``, ``"EPSG:4326"``).
    cell : float, optional
        Resample to this cell size in metres (required for triangulated surfaces).
    name : str, optional
        Name of the map (default: the file's stem).
    nodata : float, optional
        A value that marks missing data, besides NaN and the file's own fill value (every
        format). Values beyond 12 000 m (deeper than any ocean) are refused as an unmarked
        fill value until it is named here.
    units : str, optional
        Unit of the depths where the file does not say (``"m"``, ``"ft"``, ``"US survey
        foot"``, ``"fathom"``); a ``units`` attribute of the variable wins. Coordinates are
        converted to metres from the CRS's axis unit (or the coordinates' ``units``).
    uncertainty : str, bool or None, optional
        The map's error layer (its ``depth_std``), read with the same unit handling as the depths
        (an uncertainty in feet is converted). None (default): the file's, if it has one: a
        NetCDF variable named by depth's CF ``ancillary_variables``, else one named
        ``depth_std``, ``uncertainty``, ``stdev``, ``std``, ``error``, ...; a GeoTIFF's second
        band described so; BAG's and S-102's uncertainty (required there); tangraph's own NPZ
        and XYZ. A name chooses the variable (band, array); True requires one; False reads the
        depths alone (no ``depth_std``, no ``correlation_length``). An uncertainty that is
        negative, of another shape or NaN where the depth is not is refused in one line naming
        the file and the layer.
    max_scale_error : float, optional
        Geographic grids: the largest scale error of the one transverse Mercator allowed at the
        grid's edge (default 0.1 %); a wider grid is refused with its figure.

    Returns
    -------
    BathymetryMap

    Examples
    --------
    >>> from tangraph.maps import catalogue_path, read_map
    >>> m = read_map(catalogue_path() / "topobathy_vancouver.npz")
    >>> m.crs.startswith("+proj=tmerc")
    True
    """
    p = Path(path)
    fmt = _format_of(p, format, reading=True)
    common: dict[str, Any] = {"crs": crs, "cell": cell, "name": name}
    grid: dict[str, Any] = {**common, "nodata": nodata, "units": units, "uncertainty": uncertainty,
                            "max_scale_error": max_scale_error}
    return _read_as(fmt, p, variable, sign, common, grid)


def _read_as(fmt: str, p: Path, variable: str | None, sign: Sign | None, common: dict[str, Any],
             grid: dict[str, Any]) -> BathymetryMap:
    """The map of ``p`` read by format ``fmt``'s reader: ``grid`` the settings of a gridded
    format, ``common`` those a triangulated surface takes (:func:`read_map`'s)."""
    from tangraph.maps import hydro, raster

    if fmt == "netcdf":
        return read_netcdf(p, variable=variable, sign=sign, **grid)
    if fmt == "geotiff":
        return raster.read_geotiff(p, sign=sign, **grid)
    if fmt in ("bag", "s102"):
        if sign is not None:
            raise TangraphError(f"{p}: sign= does not apply to {fmt.upper()}, whose layers say what they "
                                "hold (BAG elevation positive up, S-102 depth positive down)")
        return (hydro.read_bag if fmt == "bag" else hydro.read_s102)(p, **grid)
    if fmt == "xyz":
        return read_xyz(p, sign=sign, **grid)
    if fmt == "npz":
        return read_npz(p, variable=variable, sign=sign, **grid)
    return read_tin(p, sign=sign, **common)


def write_map(bathymetry: BathymetryMap, path: str | os.PathLike, *, format: str | None = None,
              overwrite: bool = False) -> Path:
    """Write a map as NetCDF, GeoTIFF, BAG, S-102, XYZ, NPZ or a PLY/OBJ mesh (by suffix or
    ``format``; S-102, an ``.h5`` file, only with ``format="s102"``).

    Every format but the meshes keeps the map's error (``depth_std``, ``correlation_length``;
    XYZ as a fourth column). BAG and S-102 carry the depths with their uncertainty, so a map
    without ``depth_std`` is refused there. The file is written next to its final name and
    renamed into place, so an interrupted write leaves nothing half-written; an existing file is
    only replaced with ``overwrite=True``.
    """
    from tangraph.maps import hydro, mesh, raster

    p = Path(path)
    fmt = _format_of(p, format)
    writers: dict[str, Callable[[BathymetryMap, Path], object]] = {
        "netcdf": write_netcdf, "geotiff": raster.write_geotiff, "xyz": write_xyz, "npz": write_npz,
        "tin": mesh.write_mesh, "bag": hydro.write_bag, "s102": hydro.write_s102,
    }
    if fmt in ("bag", "s102"):
        hydro.check_writable(bathymetry, p, fmt)
    if fmt == "tin" and p.suffix.lower() == ".tsh":
        raise TangraphError(f"{p}: writing .tsh is not supported; write .ply or .obj")
    write_atomically(p, overwrite, lambda tmp: writers[fmt](bathymetry, tmp))
    return p
