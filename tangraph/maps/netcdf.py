"""NetCDF (COARDS/CF) and GMT grids: read with xarray, written as CF-1.8 that GDAL, GMT and QGIS
place, with the map's error as a CF ancillary variable."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from tangraph.errors import MapFormatError, TangraphError
from tangraph.maps._common import (
    UNCERTAINTY_NAMES,
    Uncertainty,
    _depth_factor,
    _existing,
    _grid_to_map,
    _is_geographic,
    _mask_nodata,
    check_given_crs,
    check_memory,
    checked_std,
    correlation_length_from,
    error_dof_from,
    metric_crs,
    resolve_sign,
    std_factor,
    unit_factor,
)
from tangraph.maps.grid import (
    CORRELATION_ATTRIBUTE,
    DEPTH_STD_ATTRS,
    DOF_ATTRIBUTE,
    DRIFT_ATTRIBUTE,
    BathymetryMap,
)
from tangraph.outputs import write_atomically

__all__ = ["NETCDF_SUFFIXES", "measured_cells", "read_netcdf", "write_netcdf", "write_sounding_grid"]

NETCDF_SUFFIXES = (".nc", ".grd", ".cdf", ".nc4")


def _axis_kind(name: str, attrs: dict) -> tuple[str | None, bool]:
    """('y' | 'x' | None, geographic?) of a coordinate from its CF attributes and name."""
    units = str(attrs.get("units", "")).lower()
    standard = str(attrs.get("standard_name", "")).lower()
    long_name = str(attrs.get("long_name", "")).lower()
    axis = str(attrs.get("axis", "")).upper()
    lname = name.lower()
    geographic = units.startswith("degree") or standard in ("latitude", "longitude") or long_name in (
        "latitude", "longitude") or (not units and lname in ("lat", "latitude", "lon", "long", "longitude"))
    if units == "degrees_north" or "latitude" in (standard, long_name) or axis == "Y" or lname in (
            "lat", "latitude", "y", "northing", "north") or lname.endswith("_y"):
        return "y", geographic
    if units == "degrees_east" or "longitude" in (standard, long_name) or axis == "X" or lname in (
            "lon", "long", "longitude", "x", "easting", "east") or lname.endswith("_x"):
        return "x", geographic
    return None, geographic


def _netcdf_crs(ds, var) -> str | None:
    """The CRS of a grid variable: a ``crs`` attribute (tangraph's), else its CF grid mapping
    (``crs_wkt``/``spatial_ref``/``proj4``, or only the CF grid-mapping parameters)."""
    for source in (var.attrs, ds.attrs):
        if "crs" in source:
            return str(source["crs"])
    mapping = str(var.attrs.get("grid_mapping", "")).split(":")[0].strip()
    if mapping and mapping in ds.variables:
        attrs = ds[mapping].attrs
        for key in ("crs_wkt", "spatial_ref", "proj4", "proj4text"):
            if key in attrs:
                return str(attrs[key])
        if "grid_mapping_name" in attrs:
            import pyproj

            try:
                return pyproj.CRS.from_cf(dict(attrs)).to_wkt()
            except pyproj.exceptions.CRSError as exc:
                raise MapFormatError(f"grid mapping {mapping!r} is not understood by pyproj "
                                     f"({exc})") from None
    return None


def _check_complete_classic(path: Path) -> None:
    """Refuse a classic (CDF-1/2) NetCDF whose variables run past the end of the file.

    The netCDF library reads a cut file as if complete (the missing bytes as zeros or fill);
    scipy's reader reads every variable in full and fails on a short one.
    """
    import scipy.io

    with open(path, "rb") as f:
        magic = f.read(4)
    if magic[:3] != b"CDF" or magic[3:] not in (b"\x01", b"\x02"):
        return
    seen: list[tuple] = []

    class _Probe(scipy.io.netcdf_file):
        def _read_var(self):  # records which variable is being read when a read fails
            info = super()._read_var()
            seen.append(info)
            return info

    try:
        _Probe(path, mmap=False).close()
    except (ValueError, TypeError, OSError, IndexError) as exc:
        size = path.stat().st_size
        if seen:
            var_name, *_, begin, vsize = seen[-1]
            var_name = var_name.decode() if isinstance(var_name, bytes) else var_name
            detail = (f"variable {var_name!r} declares {vsize} bytes from byte {begin} (to {begin + vsize}) "
                      f"but the file has {size} bytes")
        else:
            detail = f"its header does not read ({exc})"
        raise MapFormatError(f"{path}: truncated classic NetCDF: {detail}; the file is incomplete "
                             "(copy or download it again)") from None


def _netcdf_variable(ds, path: Path) -> str:
    """The grid variable of a file that holds several: tangraph's ``depth``, or the one 2-D
    variable left when uncertainty layers (by name or CF ``ancillary_variables``) are set aside."""
    grids = [k for k, v in ds.data_vars.items() if v.ndim == 2]
    if "depth" in grids and (ds["depth"].dims == ("north", "east") or "origin_northing" in ds["depth"].attrs):
        return "depth"  # tangraph's own files (maps and gridded soundings)
    if len(grids) > 1:
        linked = {n for k in grids for n in str(ds[k].attrs.get("ancillary_variables", "")).split()}
        primary = [k for k in grids if k not in linked and k.lower() not in UNCERTAINTY_NAMES]
        grids = primary if len(primary) == 1 else grids
    if len(grids) != 1:
        raise MapFormatError(
            f"{path}: {'no' if not grids else len(grids)} 2-D variables {grids if grids else ''}; "
            "choose one with variable="
        )
    return grids[0]


def _is_uncertainty(name: str, attrs) -> bool:
    words = f"{attrs.get('long_name', '')} {attrs.get('standard_name', '')}".lower()
    return name.lower() in UNCERTAINTY_NAMES or any(
        w in words for w in ("standard_error", "standard deviation", "uncertainty", "std"))


def _netcdf_uncertainty(ds, variable: str, uncertainty: Uncertainty, path: Path) -> str | None:
    """The variable holding the std of ``variable``'s values: ``uncertainty`` if a name, else the
    first of its CF ``ancillary_variables`` that is one, else a 2-D variable named like one
    (``depth_std``, ``uncertainty``, ``stdev``, ``std``, ``error``, ...); None if there is none
    (refused if ``uncertainty`` is True) or ``uncertainty`` is False."""
    if uncertainty is False:
        return None
    if isinstance(uncertainty, str):
        if uncertainty not in ds.variables:
            raise MapFormatError(f"{path}: no uncertainty variable {uncertainty!r}; it has "
                                 f"{list(ds.data_vars)}")
        return uncertainty
    if uncertainty not in (None, True):
        raise TangraphError(f"uncertainty must be a variable name, True, False or None, got {uncertainty!r}")
    linked = [n for n in str(ds[variable].attrs.get("ancillary_variables", "")).split()
              if n in ds.variables and ds[n].ndim == 2 and _is_uncertainty(n, ds[n].attrs)]
    named = [] if "tangraph_depth_statistic" in ds.attrs else [  # there "std" is the soundings' spread
        k for k, v in ds.data_vars.items()
        if k != variable and v.ndim == 2 and k.lower() in UNCERTAINTY_NAMES]
    if not linked and len(named) > 1:
        raise MapFormatError(f"{path}: several uncertainty variables {named}; choose one with "
                             "uncertainty='NAME' or none with uncertainty=False (CLI: --uncertainty)")
    found = (linked or named or [None])[0]
    if found is None and uncertainty is True:
        raise MapFormatError(f"{path}: no uncertainty variable for {variable!r} (no CF ancillary_variables, "
                             f"none named {', '.join(UNCERTAINTY_NAMES[:5])}, ...)")
    return found


def _netcdf_error(ds, var, std_name: str | None, depth: np.ndarray, depth_factor: float, nodata,
                  path: Path) -> tuple[np.ndarray | None, float | None, float | None]:
    """The std layer (metres, laid out as ``var``; None without ``std_name``), the correlation
    length and the Student-t tail (each the attribute of the depths, of the std, or of the file)
    of a NetCDF map."""
    std, sources = None, [var.attrs, ds.attrs]
    if std_name is not None:
        where = f"{path}: uncertainty variable {std_name!r}"
        std_var = ds[std_name]
        if set(std_var.dims) != set(var.dims):
            raise MapFormatError(f"{where} has dims {std_var.dims} (shape {std_var.shape}), not the "
                                 f"depths' {var.dims} (shape {var.shape})")
        std = checked_std(np.asarray(std_var.transpose(*var.dims).values, dtype=float), depth, nodata=nodata,
                          where=where, factor=std_factor(std_var.attrs.get("units"), depth_factor, where))
        sources.insert(1, std_var.attrs)
    keys = (CORRELATION_ATTRIBUTE, "correlation_length_m", "correlation_length")
    where = f"{path}:{std_name or var.name}"
    length = next((v for a in sources if (v := correlation_length_from(a, keys, where)) is not None), None)
    dof = next((v for a in sources if (v := error_dof_from(a, (DOF_ATTRIBUTE,), where)) is not None), None)
    return std, length, dof


def read_netcdf(path, *, variable=None, sign=None, crs=None, cell=None, name=None, nodata=None,
                units=None, uncertainty: Uncertainty = None, max_scale_error=1e-3) -> BathymetryMap:
    """A grid from a NetCDF (COARDS/CF) or GMT ``.grd`` file, with its uncertainty variable if it
    has one; see :func:`read_map`."""
    import xarray as xr

    path = _existing(path)
    _check_complete_classic(path)
    try:
        ds = xr.open_dataset(path, decode_times=False)
    except Exception as exc:  # netCDF4/h5 raise many types for a bad file
        raise MapFormatError(f"{path}: not a readable NetCDF file ({exc})") from None
    with ds:
        variable = variable or _netcdf_variable(ds, path)
        if variable not in ds.variables:
            raise MapFormatError(f"{path}: no variable {variable!r}; it has {list(ds.data_vars)}")
        var = ds[variable]
        if var.ndim != 2:
            raise MapFormatError(f"{path}: variable {variable!r} has dims {var.dims}, not 2-D")
        check_memory(var.shape, f"{path}:{variable}")
        std_name = _netcdf_uncertainty(ds, variable, uncertainty, path)
        if tuple(var.dims) == ("north", "east") and "positive" in var.attrs:  # tangraph's own, older
            depth = var.copy(deep=False)
            error_attributes = (CORRELATION_ATTRIBUTE, DOF_ATTRIBUTE, DRIFT_ATTRIBUTE)
            dropped = ("ancillary_variables",) + (error_attributes if uncertainty is False else ())
            depth.attrs = {k: v for k, v in var.attrs.items() if k not in dropped}
            source = depth if std_name is None else xr.Dataset(
                {"depth": depth.assign_attrs(ancillary_variables=std_name), std_name: ds[std_name]})
            try:
                m = BathymetryMap.from_xarray(source.load(),
                                              name=name or str(var.attrs.get("name") or path.stem))
            except MapFormatError as exc:
                raise MapFormatError(f"{path}: {exc}") from None
            return m.resample(cell) if cell is not None else m
        kinds = [_axis_kind(d, ds[d].attrs if d in ds.variables else {}) for d in var.dims]
        if (kinds[0][0] == "x" and kinds[1][0] in ("y", None)) or kinds[1][0] == "y":
            var = var.transpose()
            kinds = kinds[::-1]
        ydim, xdim = var.dims
        if ydim not in ds.variables or xdim not in ds.variables:
            raise MapFormatError(f"{path}: variable {variable!r} has no coordinate values for {var.dims}")
        where = f"{path}:{variable}"
        try:
            values = _mask_nodata(np.asarray(var.values, dtype=float), nodata)
        except Exception as exc:  # a cut NetCDF-4/HDF5 file fails here, in many types
            raise MapFormatError(f"{where}: the data do not read in full ({exc}); the file is "
                                 "incomplete or damaged") from None
        try:
            file_crs = _netcdf_crs(ds, var)
        except MapFormatError as exc:
            raise MapFormatError(f"{where}: {exc}") from None
        the_crs = check_given_crs(crs, file_crs, where)
        geographic = kinds[0][1] or kinds[1][1] or (the_crs is not None and _is_geographic(the_crs))
        crs_unit = 1.0 if geographic else metric_crs(the_crs, where)[1]
        depth_factor = _depth_factor(var.attrs.get("units"), units, crs_unit, where, variable)
        values = values * depth_factor
        factor = resolve_sign(values, var.attrs, variable, sign, f"{path}")
        std, length, dof = (None, None, None) if uncertainty is False else _netcdf_error(
            ds, var, std_name, values, depth_factor, nodata, path)
        y, x = np.asarray(ds[ydim].values, float), np.asarray(ds[xdim].values, float)
        if not geographic and crs_unit == 1.0:  # axes in feet with no CRS (or a metric one) saying so
            y = y * _axis_factor(ds[ydim].attrs, where, ydim)
            x = x * _axis_factor(ds[xdim].attrs, where, xdim)
        origin = None  # tangraph's own maps keep their origin
        if not geographic and {"origin_northing", "origin_easting"} <= var.attrs.keys():
            origin = (float(var.attrs["origin_northing"]), float(var.attrs["origin_easting"]))
        m = _grid_to_map(
            y, x, factor * values, geographic=geographic, crs=the_crs, cell=cell, origin=origin,
            name=name or str(var.attrs.get("name", "")) or path.stem, where=where, variable=variable,
            max_scale_error=max_scale_error, depth_std=std, correlation_length=length, error_dof=dof,
        )
        drift = None if uncertainty is False else var.attrs.get(DRIFT_ATTRIBUTE)
        try:
            return m if drift is None else m.replace(error_drift=drift)
        except MapFormatError as exc:
            raise MapFormatError(f"{where}: attribute {DRIFT_ATTRIBUTE!r}: {exc}") from None


def _axis_factor(attrs: dict, where: str, axis: str) -> float:
    """Metres per unit of a projected coordinate, from its ``units`` attribute (metres if none)."""
    unit = str(attrs.get("units", "")).strip()
    return unit_factor(unit, where, f"coordinate {axis!r}") if unit else 1.0


def write_netcdf(bathymetry: BathymetryMap, path: Path, extra: dict[str, tuple] | None = None,
                 attrs: dict | None = None) -> None:
    """CF-1.8 NetCDF that GDAL, GMT and QGIS place: dims ``(y, x)`` holding the projected
    coordinates of the cell centres (local + origin), a CF ``grid_mapping`` variable ``crs``
    (``pyproj.CRS.to_cf``: ``crs_wkt`` and the CF parameters), depth positive down; the map's
    own CRS string, origin and name as attributes of ``depth``, so it reads back in its frame.
    The map's error: ``depth_std`` (CF ``long_name``, ``standard_name`` "... standard_error",
    units m) named by depth's CF ``ancillary_variables``, the correlation length and the
    Student-t tail as depth's attributes ``error_correlation_length_m`` and ``error_student_t_dof``,
    the drift along a track as ``error_drift_std_m_time_s``.

    ``extra`` adds per-cell variables: ``{name: (array (ny, nx), attrs)}``; ``attrs`` adds
    global attributes, and its ``"depth"`` entry (a dict) attributes of the depth variable.
    """
    import xarray as xr

    import tangraph

    attrs = dict(attrs or {})
    own = bathymetry.to_dataset()
    depth_attrs = {**own["depth"].attrs, **attrs.pop("depth", {})}
    variables: dict[str, tuple] = {}
    encoding: dict[str, Any] = {"depth": {"zlib": True, "complevel": 4, "_FillValue": np.nan},
                                "x": {"_FillValue": None}, "y": {"_FillValue": None}}
    if bathymetry.crs is not None:
        import pyproj

        crs = pyproj.CRS(bathymetry.crs)
        variables["crs"] = ((), np.int32(0), crs.to_cf())  # crs_wkt and the CF parameters
        depth_attrs["grid_mapping"] = "crs"
    depth_attrs["actual_range"] = np.array([np.nanmin(bathymetry.depth), np.nanmax(bathymetry.depth)])  # GMT
    variables["depth"] = (("y", "x"), np.array(bathymetry.depth), depth_attrs)
    if bathymetry.depth_std is not None:
        extra = {"depth_std": (bathymetry.depth_std, dict(DEPTH_STD_ATTRS)), **(extra or {})}
        encoding["depth_std"] = encoding["depth"]
    for key, (values, var_attrs) in (extra or {}).items():
        variables[key] = (("y", "x"), np.asarray(values),
                          {**var_attrs, **({"grid_mapping": "crs"} if bathymetry.crs else {})})
    where = "projected" if bathymetry.crs else "local"
    coords = {
        "y": ("y", bathymetry.north + bathymetry.origin[0],
              {"standard_name": "projection_y_coordinate", "long_name": f"northing ({where})",
               "units": "m", "axis": "Y"}),
        "x": ("x", bathymetry.east + bathymetry.origin[1],
              {"standard_name": "projection_x_coordinate", "long_name": f"easting ({where})",
               "units": "m", "axis": "X"}),
    }
    ds = xr.Dataset(variables, coords=coords)
    ds.attrs.update({"Conventions": "CF-1.8", "title": bathymetry.name,
                     "source": f"tangraph {tangraph.__version__}", **attrs})
    ds.to_netcdf(path, encoding=encoding)


def write_sounding_grid(grid, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write a `tangraph.maps.gridding.SoundingGrid` as NetCDF.

    ``depth`` is the grid's map (:attr:`~tangraph.maps.SoundingGrid.depth`: its ``statistic``
    per cell, said in the CF ``cell_methods`` attribute, e.g. ``"area: median"``, plus any gap
    fill); ``mean``, ``median`` (if computed), ``count`` and ``std`` are the soundings' per-cell
    statistics, ``filled`` (if a gap fill ran) is 1 where ``depth`` came from the gap fill. The
    grid's ``meta`` is the global attribute ``tangraph_meta`` (JSON). The map's error
    (:func:`tangraph.maps.gridding_error.gridded_error`) is ``depth_std`` with the correlation length
    (:func:`write_netcdf`), and the one-cell semivariance it rests on the global attribute
    ``tangraph_error_semivariance_m2``.
    """
    p = Path(path)
    if p.suffix.lower() not in NETCDF_SUFFIXES:
        raise TangraphError(f"{p}: gridded soundings are written as NetCDF (.nc)")
    extra = {
        "mean": (grid.mean.depth, {"long_name": "mean depth of the soundings in the cell",
                                   "units": "m", "positive": "down"}),
        "count": (grid.count.astype(np.int32), {"long_name": "soundings in the cell"}),
        "std": (grid.std, {"long_name": "std of the soundings in the cell", "units": "m"}),
    }
    if grid.median is not None:
        extra["median"] = (grid.median, {"long_name": "median depth of the soundings in the cell",
                                         "units": "m", "positive": "down"})
    if grid.gap_fill is not None:
        extra["filled"] = (np.isfinite(grid.gap_fill).astype(np.int8),
                           {"long_name": "1 where depth was filled from neighbouring cells"})
    attrs = {"depth": {"cell_methods": f"area: {grid.statistic}"},
             "tangraph_depth_statistic": grid.statistic,
             "tangraph_meta": json.dumps(grid.meta, sort_keys=True)}
    if math.isfinite(grid.error.semivariance):
        attrs["tangraph_error_semivariance_m2"] = grid.error.semivariance
    write_atomically(p, overwrite, lambda tmp: write_netcdf(grid.depth, tmp, extra, attrs))
    return p


def measured_cells(path: str | os.PathLike, bathymetry: BathymetryMap) -> np.ndarray | None:
    """The cells of ``bathymetry`` (read from ``path``) that hold soundings: the ``count`` layer
    :func:`write_sounding_grid` writes, above 0, on the map's grid (bool ``(ny, nx)``); None for
    a file of another format, without that layer, or whose grid is not the map's."""
    import xarray as xr

    if Path(path).suffix.lower() not in NETCDF_SUFFIXES:
        return None
    with xr.open_dataset(path) as ds:
        if "count" not in ds or ds["count"].dims != ("y", "x"):
            return None
        count = ds["count"].sortby("y").sortby("x")
        north = count["y"].values - bathymetry.origin[0]
        east = count["x"].values - bathymetry.origin[1]
        if north.shape != bathymetry.north.shape or east.shape != bathymetry.east.shape \
                or not (np.allclose(north, bathymetry.north) and np.allclose(east, bathymetry.east)):
            return None
        return np.asarray(count.values) > 0
