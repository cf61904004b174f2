"""Readers and writers of bathymetry grids: NetCDF/GMT, GeoTIFF, XYZ, NPZ and TINs.

Everything enters through :func:`read_map` (or :func:`read_soundings` for scattered points)
and leaves a `BathymetryMap` in a local metric frame: geographic grids are projected once
(:mod:`tangraph.maps.projection`), projected grids keep their CRS with the origin at their
first cell centre (tangraph's own files keep the origin they were written with). GeoTIFFs go
through rasterio (GDAL); NetCDF maps are written with projected ``x``/``y`` and a CF
``grid_mapping``, so GDAL, GMT and QGIS place them. Depth is positive down; a file that stores
elevation says so in its metadata, or the caller says so with ``sign=``; a file where neither
tells, or whose data contradict the guess from its names, is refused.

A map is never read wrongly without a word: a truncated classic NetCDF, values beyond 12 000 m
(an unmarked fill value: ``nodata=``), an unknown unit (``units=``) and a geographic grid too
wide for one transverse Mercator (``max_scale_error=``) are refused in one line naming the
file, the variable, the value and the option. Depths in feet (the variable's ``units``) and
coordinates in feet (the CRS's axis unit) are converted to metres.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Literal

import numpy as np

from tangraph.errors import MapFormatError, TangraphError
from tangraph.maps.grid import BathymetryMap
from tangraph.maps.projection import project_geographic_grid

__all__ = ["Soundings", "read_map", "read_soundings", "write_atomically", "write_map", "write_sounding_grid"]

Sign = Literal["depth", "elevation"]

_FORMATS = {
    ".nc": "netcdf", ".grd": "netcdf", ".cdf": "netcdf", ".nc4": "netcdf",
    ".tif": "geotiff", ".tiff": "geotiff",
    ".xyz": "xyz", ".txt": "xyz", ".csv": "xyz",
    ".npz": "npz",
    ".tsh": "tin", ".ply": "tin", ".obj": "tin",
}
_DEPTH_NAMES = ("depth", "depths", "bathy_depth", "sea_floor_depth")
_ELEVATION_NAMES = ("elevation", "elev", "topo", "topography", "height", "altitude", "rose", "bathy")


# -- small shared pieces --------------------------------------------------------------------
def _format_of(path: Path, given: str | None) -> str:
    if given is not None:
        if given not in set(_FORMATS.values()):
            raise TangraphError(f"unknown map format {given!r}; known: {sorted(set(_FORMATS.values()))}")
        return given
    fmt = _FORMATS.get(path.suffix.lower())
    if fmt is None:
        raise MapFormatError(
            f"{path}: cannot tell the format from the suffix {path.suffix!r}; known suffixes: "
            f"{', '.join(sorted(_FORMATS))} (or pass format=)"
        )
    return fmt


def _existing(path: str | os.PathLike) -> Path:
    p = Path(path)
    if not p.exists():
        raise FileNotFoundError(f"map file {p} does not exist")
    if p.is_dir():
        raise MapFormatError(f"{p} is a folder, not a map file")
    return p


#: bytes a grid cell costs while a map is read: the float64 values, their masks and the map's copy
_BYTES_PER_CELL = 32


def available_memory() -> int:
    """Bytes of physical memory free now (the total where the system does not say)."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_AVPHYS_PAGES"))
    except (ValueError, OSError, AttributeError):  # not POSIX: no refusal on memory
        return 1 << 62


def check_memory(shape, where: str) -> None:
    """Refuse, before allocating, a grid of ``shape`` cells that reading would not fit in the
    memory free now (about 32 bytes a cell), naming its size and what to do instead.

    Raises
    ------
    MemoryError
        With that message (the CLI's runtime error, status 1).
    """
    cells = math.prod(int(n) for n in shape)
    need, free = cells * _BYTES_PER_CELL, available_memory()
    if need > free:
        dims = " x ".join(str(int(n)) for n in shape)
        raise MemoryError(
            f"{where}: the grid has {dims} cells; reading it needs about {_gib(need)} of memory, "
            f"{_gib(free)} are free; crop it to the survey area first (gdal_translate -projwin, "
            "gmt grdcut) or read a coarser copy"
        )


def _gib(n: float) -> str:
    return f"{n / 2**30:.1f} GiB" if n < 2**40 else f"{n / 2**40:.1f} TiB"


def resolve_sign(values: np.ndarray, attrs: dict, variable: str, given: str | None, where: str) -> float:
    """+1 if ``values`` are depths (positive down), -1 if elevations; raise if it can't be told.

    Order: ``given``; the attribute ``positive``; a guess from ``standard_name`` or the
    variable's name, checked against the data in both directions (a "depth" mostly negative, or
    an "elevation" of a water-named variable mostly positive, is refused naming ``sign=``).
    """
    if given is not None:
        if given not in ("depth", "elevation"):
            raise TangraphError(f"sign must be 'depth' or 'elevation', got {given!r}")
        return 1.0 if given == "depth" else -1.0
    positive = str(attrs.get("positive", "")).lower()
    if positive in ("down", "up"):
        return 1.0 if positive == "down" else -1.0
    standard = str(attrs.get("standard_name", "")).lower()
    name = variable.lower()
    valid = values[np.isfinite(values)]
    negative = float(np.mean(valid < 0)) if valid.size else 0.0
    guess = _guessed_sign(standard, name)
    if guess is not None:
        _check_guess(guess, negative, attrs, variable, where)
        return guess
    raise MapFormatError(
        f"{where}: cannot tell whether variable {variable!r} holds depths or elevations (no "
        "'positive' or 'standard_name' attribute); pass sign='depth' or sign='elevation' (CLI: --sign)"
    )


_WATER_WORDS = ("bathy", "depth", "sounding", "seafloor", "sea_floor", "sea floor", "profondeur", "tiefe")


def _guessed_sign(standard: str, name: str) -> float | None:
    """The sign a ``standard_name`` or a variable's name suggests (None if neither does)."""
    if "depth" in standard:
        return 1.0
    if any(k in standard for k in ("height", "altitude", "elevation")):
        return -1.0
    if name.startswith(_DEPTH_NAMES):
        return 1.0
    if name.startswith(_ELEVATION_NAMES):
        return -1.0
    return None


def _check_guess(guess: float, negative: float, attrs: dict, variable: str, where: str) -> None:
    """Refuse a guessed sign the data contradict: a "depth" mostly above sea level, or an
    "elevation" of a water-named variable (bathy, bathymetrie, ...) mostly below it."""
    basis = (f"standard_name {attrs['standard_name']!r}" if attrs.get("standard_name")
             else f"its name {variable!r}")
    if guess > 0 and negative > 0.5:
        raise MapFormatError(
            f"{where}: variable {variable!r} is named like a depth but {negative:.0%} of its values "
            f"are negative (the guess came from {basis}); say which it is with sign='depth' or "
            "sign='elevation' (CLI: --sign)"
        )
    else:
        words = f"{variable} {attrs.get('long_name', '')}".lower()
        if guess > 0 or not any(w in words for w in _WATER_WORDS) or negative >= 0.5:
            return
    raise MapFormatError(
        f"{where}: variable {variable!r} (long_name {attrs.get('long_name', '')!r}) names water but would "
        f"be read as elevations from {basis}, and {1 - negative:.0%} of its values are positive (above "
        "sea level as elevations); say which it is with sign='depth' or sign='elevation' (CLI: --sign)"
    )


# Deeper than any ocean (Challenger Deep ~10 935 m), higher than any mountain.
_PLAUSIBLE_DEPTH = 12_000.0
_UNITS = {
    "m": 1.0, "meter": 1.0, "meters": 1.0, "metre": 1.0, "metres": 1.0, "metre(s)": 1.0,
    "ft": 0.3048, "feet": 0.3048, "foot": 0.3048, "international foot": 0.3048, "international_foot": 0.3048,
    "us survey foot": 1200.0 / 3937.0, "us_survey_foot": 1200.0 / 3937.0, "ftus": 1200.0 / 3937.0,
    "us-ft": 1200.0 / 3937.0, "survey foot": 1200.0 / 3937.0, "us survey feet": 1200.0 / 3937.0,
    "fathom": 1.8288, "fathoms": 1.8288, "fm": 1.8288, "km": 1000.0, "cm": 0.01,
}


def unit_factor(unit: str, where: str, what: str) -> float:
    """Metres per ``unit`` (``"m"``, ``"ft"``, ``"US survey foot"``, ``"fathom"``, ...)."""
    key = " ".join(str(unit).strip().lower().split())
    if key in _UNITS:
        return _UNITS[key]
    raise MapFormatError(
        f"{where}: {what} has units {unit!r}, which tangraph does not know; known: m, ft, "
        "US survey foot, fathom, km, cm; pass units='m' (or 'ft', 'US survey foot') (CLI: --units)"
    )


def _depth_factor(attr_unit, given: str | None, crs_unit: float, where: str, variable: str) -> float:
    """Metres per unit of the depths: the variable's ``units`` attribute, else ``units=``; a file
    whose CRS is not in metres and that says nothing about its depths is refused."""
    if given is not None:
        return unit_factor(given, where, "units=")
    if attr_unit is not None and str(attr_unit).strip():
        return unit_factor(str(attr_unit), where, f"variable {variable!r}")
    if crs_unit != 1.0:
        raise MapFormatError(
            f"{where}: the CRS is in units of {crs_unit:g} m but variable {variable!r} has no units "
            "attribute; pass units='m' (or 'ft', 'US survey foot') (CLI: --units)"
        )
    return 1.0


def _mask_nodata(values: np.ndarray, nodata: float | None) -> np.ndarray:
    values = np.array(values, dtype=float)
    if nodata is not None and np.isfinite(nodata):
        values[np.isclose(values, nodata, rtol=1e-6, atol=0)] = np.nan
    return values


def _check_plausible(depth: np.ndarray, where: str, variable: str) -> None:
    """Refuse depths (metres) no ocean or mountain has: an unmarked fill value."""
    finite = np.isfinite(depth)
    bad = finite & (np.abs(np.where(finite, depth, 0.0)) > _PLAUSIBLE_DEPTH)
    if np.any(bad):
        k = np.unravel_index(int(np.argmax(bad)), depth.shape)
        raise MapFormatError(
            f"{where}: variable {variable!r} holds {int(bad.sum())} value(s) beyond "
            f"{_PLAUSIBLE_DEPTH:.0f} m (e.g. {depth[k]:g} m at index {tuple(int(i) for i in k)}), "
            "deeper or higher than any seafloor; an unmarked fill value? pass nodata=VALUE (CLI: --nodata)"
        )


def metric_crs(crs: str | None, where: str) -> tuple[str | None, float]:
    """The CRS with its axes in metres and the metres per unit of the original's axes.

    A projected CRS in feet becomes the same projection in metres (same WKT, axis unit metre);
    coordinates read in the original are multiplied by the factor.
    """
    if crs is None:
        return None, 1.0
    import pyproj

    try:
        parsed = pyproj.CRS(crs)
    except pyproj.exceptions.CRSError as exc:
        raise MapFormatError(f"{where}: CRS {crs!r} is not understood by pyproj ({exc}); "
                             "pass crs= (CLI: --crs)") from None
    if parsed.is_geographic or not parsed.axis_info:
        return crs, 1.0
    factor = float(parsed.axis_info[0].unit_conversion_factor)
    if parsed.axis_info[0].unit_name in ("metre", "meter") or abs(factor - 1.0) < 1e-12:
        return crs, 1.0
    if parsed.is_compound:
        parsed = parsed.sub_crs_list[0]
    spec = parsed.to_json_dict()
    for axis in spec.get("coordinate_system", {}).get("axis", []):
        axis["unit"] = "metre"
    spec["name"] = f"{spec.get('name', 'CRS')} (metre axes)"
    spec.pop("id", None)
    return pyproj.CRS.from_json_dict(spec).to_wkt(), factor


def _grid_to_map(
    y: np.ndarray, x: np.ndarray, depth: np.ndarray, *, geographic: bool, crs: str | None,
    cell: float | None, name: str, where: str, origin: tuple[float, float] | None = None,
    variable: str = "z", max_scale_error: float = 1e-3,
) -> BathymetryMap:
    """Refuse implausible depths (metres), flip descending axes, then project (geographic) or
    shift to a local origin (projected, axes converted to metres): ``origin`` if given, else the
    first cell centre (``(0, 0)`` without a CRS)."""
    y = np.asarray(y, float)
    x = np.asarray(x, float)
    depth = np.asarray(depth, float)
    _check_plausible(depth, where, variable)
    if not geographic and crs is not None and _is_geographic(crs):
        geographic = True  # a geographic CRS, whatever the axes are called: the one projection step
    if y.size > 1 and y[0] > y[-1]:
        y, depth = y[::-1], depth[::-1]
    if x.size > 1 and x[0] > x[-1]:
        x, depth = x[::-1], depth[:, ::-1]
    try:
        if geographic:
            return project_geographic_grid(y, x, depth, cell=cell, name=name,
                                           source_crs=crs or "EPSG:4326", max_scale_error=max_scale_error)
        crs, scale = metric_crs(crs, where)
        y, x = y * scale, x * scale
        if origin is None:
            origin = (float(y[0]), float(x[0])) if crs else (0.0, 0.0)
        m = BathymetryMap(north=y - origin[0], east=x - origin[1], depth=depth, crs=crs,
                          origin=origin, name=name)
    except MapFormatError as exc:
        raise MapFormatError(f"{where}: {exc}") from None
    return m.resample(cell) if cell is not None else m


def write_atomically(path: Path, overwrite: bool, write: Callable[[Path], None]) -> None:
    """Write through a temporary file in the same folder, then rename: never a half file."""
    if path.exists() and not overwrite:
        raise FileExistsError(f"{path} exists; pass overwrite=True (CLI: --force) to replace it")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}-", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    try:
        write(Path(tmp))
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)  # mkstemp makes 0600; a written file gets the usual mode
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)


# -- NetCDF / GMT -----------------------------------------------------------------------------
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


def read_netcdf(path, *, variable=None, sign=None, crs=None, cell=None, name=None, nodata=None,
                units=None, max_scale_error=1e-3) -> BathymetryMap:
    """A grid from a NetCDF (COARDS/CF) or GMT ``.grd`` file; see :func:`read_map`."""
    import xarray as xr

    path = _existing(path)
    _check_complete_classic(path)
    try:
        ds = xr.open_dataset(path, decode_times=False)
    except Exception as exc:  # netCDF4/h5 raise many types for a bad file
        raise MapFormatError(f"{path}: not a readable NetCDF file ({exc})") from None
    with ds:
        grids = [k for k, v in ds.data_vars.items() if v.ndim == 2]
        if variable is None and "depth" in grids and (
                ds["depth"].dims == ("north", "east") or "origin_northing" in ds["depth"].attrs):
            variable = "depth"  # tangraph's own files (maps and gridded soundings)
        if variable is None:
            if len(grids) != 1:
                raise MapFormatError(
                    f"{path}: {'no' if not grids else len(grids)} 2-D variables "
                    f"{grids if grids else ''}; choose one with variable="
                )
            variable = grids[0]
        if variable not in ds.variables:
            raise MapFormatError(f"{path}: no variable {variable!r}; it has {list(ds.data_vars)}")
        var = ds[variable]
        if var.ndim != 2:
            raise MapFormatError(f"{path}: variable {variable!r} has dims {var.dims}, not 2-D")
        check_memory(var.shape, f"{path}:{variable}")
        if tuple(var.dims) == ("north", "east") and "positive" in var.attrs:  # tangraph's own
            m = BathymetryMap.from_xarray(var.load(), name=name or str(var.attrs.get("name") or path.stem))
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
        the_crs = crs or file_crs
        geographic = kinds[0][1] or kinds[1][1] or (the_crs is not None and _is_geographic(the_crs))
        crs_unit = 1.0 if geographic else metric_crs(the_crs, where)[1]
        values = values * _depth_factor(var.attrs.get("units"), units, crs_unit, where, variable)
        factor = resolve_sign(values, var.attrs, variable, sign, f"{path}")
        y, x = np.asarray(ds[ydim].values, float), np.asarray(ds[xdim].values, float)
        if not geographic and crs_unit == 1.0:  # axes in feet with no CRS (or a metric one) saying so
            y = y * _axis_factor(ds[ydim].attrs, where, ydim)
            x = x * _axis_factor(ds[xdim].attrs, where, xdim)
        origin = None  # tangraph's own maps keep their origin
        if not geographic and {"origin_northing", "origin_easting"} <= var.attrs.keys():
            origin = (float(var.attrs["origin_northing"]), float(var.attrs["origin_easting"]))
        return _grid_to_map(
            y, x, factor * values, geographic=geographic, crs=the_crs, cell=cell, origin=origin,
            name=name or str(var.attrs.get("name", "")) or path.stem, where=where, variable=variable,
            max_scale_error=max_scale_error,
        )


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

    ``extra`` adds per-cell variables: ``{name: (array (ny, nx), attrs)}``; ``attrs`` adds
    global attributes, and its ``"depth"`` entry (a dict) attributes of the depth variable.
    """
    import xarray as xr

    import tangraph

    attrs = dict(attrs or {})
    depth_attrs = {**bathymetry.to_xarray().attrs, **attrs.pop("depth", {})}
    variables: dict[str, tuple] = {}
    if bathymetry.crs is not None:
        import pyproj

        crs = pyproj.CRS(bathymetry.crs)
        variables["crs"] = ((), np.int32(0), crs.to_cf())  # crs_wkt and the CF parameters
        depth_attrs["grid_mapping"] = "crs"
    depth_attrs["actual_range"] = np.array([np.nanmin(bathymetry.depth), np.nanmax(bathymetry.depth)])  # GMT
    variables["depth"] = (("y", "x"), np.array(bathymetry.depth), depth_attrs)
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
    ds.to_netcdf(path, encoding={"depth": {"zlib": True, "complevel": 4, "_FillValue": np.nan},
                                 "x": {"_FillValue": None}, "y": {"_FillValue": None}})


def write_sounding_grid(grid, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write a `tangraph.maps.mesh.SoundingGrid` as NetCDF.

    ``depth`` is the grid's map (:attr:`~tangraph.maps.SoundingGrid.depth`: its ``statistic``
    per cell, said in the CF ``cell_methods`` attribute, e.g. ``"area: median"``, plus any gap
    fill); ``mean``, ``median`` (if computed), ``count`` and ``std`` are the soundings' per-cell
    statistics, ``filled`` (if a gap fill ran) is 1 where ``depth`` came from the gap fill. The
    grid's ``meta`` is the global attribute ``tangraph_meta`` (JSON).
    """
    p = Path(path)
    if _format_of(p, None) != "netcdf":
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
    write_atomically(p, overwrite, lambda tmp: write_netcdf(grid.depth, tmp, extra, attrs))
    return p


# -- GeoTIFF (rasterio / GDAL) ----------------------------------------------------------------
_DEPTH_TAGS = {"positive": "down", "standard_name": "sea_floor_depth_below_sea_surface", "units": "m"}


def read_geotiff(path, *, sign=None, crs=None, cell=None, name=None, nodata=None,
                 units=None, max_scale_error=1e-3) -> BathymetryMap:
    """A grid from a north-up GeoTIFF (any compression, tiled or COG), read by rasterio.

    The CRS is the file's (an EPSG code where it is one exactly, else its WKT); no-data is the
    file's (or its mask); GDAL resolves PixelIsArea/PixelIsPoint. A rotated or south-up raster is
    refused. See :func:`read_map`.
    """
    import warnings

    import rasterio
    from rasterio.errors import NotGeoreferencedWarning, RasterioError

    path = _existing(path)
    try:
        with warnings.catch_warnings():  # refused below, in one line
            warnings.simplefilter("ignore", NotGeoreferencedWarning)
            src = rasterio.open(path)
        with src:
            if src.count != 1:
                raise MapFormatError(f"{path}: {src.count} bands; one band of depths is expected")
            check_memory((src.height, src.width), str(path))
            band = src.read(1, masked=True)
            transform, file_crs = src.transform, src.crs
            tags, band_tags = src.tags(), src.tags(1)
            variable = src.descriptions[0] or "band 1"
            band_unit = (src.units[0] if src.units else None) or band_tags.get("units")
    except RasterioError as exc:
        raise MapFormatError(f"{path}: not a readable GeoTIFF ({exc})") from None
    values = np.ma.filled(band.astype(float), np.nan)
    a, b, c, d, e, f = (float(v) for v in tuple(transform)[:6])
    if transform.is_identity:
        raise MapFormatError(f"{path}: no georeference (no geotransform); a north-up GeoTIFF is expected")
    if b != 0.0 or d != 0.0:
        raise MapFormatError(f"{path}: the raster is rotated (geotransform {tuple(transform)[:6]}); "
                             "warp it north-up first (gdalwarp)")
    if e > 0.0:
        raise MapFormatError(f"{path}: the raster is south-up (pixel height {e} > 0); "
                             "warp it north-up first (gdalwarp)")
    own = _tangraph_description(tags.get("TIFFTAG_IMAGEDESCRIPTION", ""))  # files of tangraph < 0.2
    if tags.get("TANGRAPH_NAME") is not None:
        own = {"name": tags["TANGRAPH_NAME"], "crs": tags.get("TANGRAPH_CRS") or None,
               "positive": band_tags.get("positive")}
    values = _mask_nodata(values, nodata)
    ny, nx = values.shape
    x = c + (np.arange(nx) + 0.5) * a  # GDAL's geotransform is PixelIsArea (it shifts Point files)
    y = f + (np.arange(ny) + 0.5) * e
    if crs is None:
        crs = _geotiff_crs(file_crs, own, path)
    geographic = crs is not None and _is_geographic(crs)
    crs_unit = 1.0 if geographic else metric_crs(crs, str(path))[1]
    values = values * _depth_factor(band_unit, units, crs_unit, str(path), variable)
    attrs = band_tags if "positive" in band_tags or "standard_name" in band_tags else {}
    if own and sign is None and own.get("positive") in ("down", "up"):
        attrs = {"positive": own["positive"]}
    factor = resolve_sign(values, attrs, variable, sign, str(path))
    return _grid_to_map(y, x, factor * values, geographic=geographic, crs=crs, cell=cell,
                        name=name or own.get("name") or path.stem, where=str(path), variable=variable,
                        max_scale_error=max_scale_error)


def _tangraph_description(text: str) -> dict:
    try:
        data = json.loads(text)
    except (json.JSONDecodeError, TypeError):
        return {}
    return data.get("tangraph", {}) if isinstance(data, dict) else {}


def _geotiff_crs(file_crs, own: dict, path: Path) -> str | None:
    """The CRS of a GeoTIFF as a string: tangraph's own (if the file's agrees), an EPSG code the
    file names exactly, or the file's WKT."""
    import pyproj

    parsed = None
    if file_crs is not None:
        parsed = pyproj.CRS.from_wkt(file_crs.to_wkt())
        if parsed.is_engineering:  # LOCAL_CS: a user-defined CRS GDAL could not read
            parsed = None
    if own.get("crs") and (parsed is None or pyproj.CRS(own["crs"]).equals(parsed, ignore_axis_order=True)):
        return str(own["crs"])
    if parsed is None:
        if own:
            return None  # a tangraph map with no place on Earth
        raise MapFormatError(f"{path}: the GeoTIFF names no CRS; pass crs= (CLI: --crs)")
    code = parsed.to_epsg(min_confidence=100)
    return f"EPSG:{code}" if code is not None else parsed.to_wkt()


def write_geotiff(bathymetry: BathymetryMap, path: Path) -> None:
    """A float32 GeoTIFF (DEFLATE, floating-point predictor), north up, NaN no-data, the map's CRS
    and bounds as GDAL reads them; depth positive down in the band's metadata."""
    import pyproj
    import rasterio
    from rasterio.transform import Affine

    dn, de = bathymetry.cell_size
    west = bathymetry.east[0] + bathymetry.origin[1] - 0.5 * de
    top = bathymetry.north[-1] + bathymetry.origin[0] + 0.5 * dn
    ny, nx = bathymetry.shape
    profile = {
        "driver": "GTiff", "height": ny, "width": nx, "count": 1, "dtype": "float32", "nodata": np.nan,
        "transform": Affine(de, 0.0, west, 0.0, -dn, top), "compress": "deflate", "predictor": 3,
        "crs": (rasterio.crs.CRS.from_wkt(pyproj.CRS(bathymetry.crs).to_wkt())
                if bathymetry.crs else None),
    }
    if ny >= 512 and nx >= 512:
        profile.update(tiled=True, blockxsize=256, blockysize=256)
    with rasterio.Env(GDAL_PAM_ENABLED="NO"), rasterio.open(path, "w", **profile) as dst:
        dst.write(np.ascontiguousarray(bathymetry.depth[::-1], dtype=np.float32), 1)
        dst.set_band_description(1, "depth")
        dst.update_tags(1, **_DEPTH_TAGS)
        dst.update_tags(TANGRAPH_NAME=bathymetry.name, TANGRAPH_CRS=bathymetry.crs or "")


# -- XYZ text -------------------------------------------------------------------------------
def _load_xyz(path: Path) -> np.ndarray:
    with open(path, encoding="utf-8", errors="replace") as f:
        first = next((line for line in f if line.strip() and not line.startswith("#")), "")
    delimiter = "," if "," in first else None
    skip = 0 if _is_numeric_row(first, delimiter) else 1  # one header row allowed
    try:
        data = np.loadtxt(path, comments="#", delimiter=delimiter, skiprows=skip, ndmin=2)
    except ValueError as exc:
        raise MapFormatError(f"{path}: not a table of numbers x y z ({exc})") from None
    if data.shape[1] < 3 or data.shape[0] == 0:
        raise MapFormatError(f"{path}: expected at least 3 columns (x/east, y/north, z), got {data.shape}")
    return data[:, :3]


def _is_numeric_row(line: str, delimiter: str | None) -> bool:
    try:
        [float(v) for v in line.split(delimiter)]
    except ValueError:
        return False
    return True


def read_xyz(path, *, sign=None, crs=None, cell=None, name=None, nodata=None,
             units=None, max_scale_error=1e-3) -> BathymetryMap:
    """A regular grid from an ``x y z`` text file (x east/longitude, y north/latitude)."""
    path = _existing(path)
    data = _load_xyz(path)
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
    grid = np.full(x_values.size * y_values.size, np.nan)
    grid[flat] = z
    grid = grid.reshape(y_values.size, x_values.size)
    factor = resolve_sign(grid, {}, "z", sign, str(path))
    return _grid_to_map(y_values, x_values, factor * grid, geographic=geographic,
                        crs=crs, cell=cell, name=name or path.stem, where=str(path),
                        max_scale_error=max_scale_error)


def _is_geographic(crs: str) -> bool:
    import pyproj

    return bool(pyproj.CRS(crs).is_geographic)


def write_xyz(bathymetry: BathymetryMap, path: Path) -> None:
    """``east north depth`` rows (projected coordinates: local plus origin), NaN cells kept."""
    nn, ee = np.meshgrid(bathymetry.north + bathymetry.origin[0],
                         bathymetry.east + bathymetry.origin[1], indexing="ij")
    header = (f"tangraph map {bathymetry.name}; crs {bathymetry.crs}; "
              "columns: east north depth (m, positive down)")
    np.savetxt(path, np.column_stack([ee.ravel(), nn.ravel(), bathymetry.depth.ravel()]),
               fmt="%.3f", header=header)


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
    from tangraph.maps.projection import local_crs

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

        local = local_crs(float(np.mean(y)), float(np.mean(x)))
        east, north = pyproj.Transformer.from_crs(crs, local, always_xy=True).transform(x, y)
        return Soundings(np.column_stack([north, east, depth]), local, (0.0, 0.0), str(path))
    origin = (float(np.floor(np.min(y))), float(np.floor(np.min(x)))) if crs else (0.0, 0.0)
    return Soundings(np.column_stack([y - origin[0], x - origin[1], depth]), crs, origin, str(path))


# -- NPZ ------------------------------------------------------------------------------------
def read_npz(path, *, variable=None, sign=None, crs=None, cell=None, name=None, nodata=None,
             units=None, max_scale_error=1e-3) -> BathymetryMap:
    """A grid from ``.npz``: tangraph's own (north, east, depth, ...) or (lat, lon, values)."""
    path = _existing(path)
    try:
        data = dict(np.load(path, allow_pickle=False))
    except (OSError, ValueError) as exc:
        raise MapFormatError(f"{path}: not a readable .npz file ({exc})") from None
    if {"north", "east", "depth"} <= data.keys() and variable is None:
        scale = unit_factor(units, str(path), "units=") if units else 1.0
        depth = _mask_nodata(data["depth"], nodata) * scale
        _check_plausible(depth, f"{path}:depth", "depth")
        m = BathymetryMap(
            north=data["north"], east=data["east"], depth=depth,
            crs=str(data["crs"]) if "crs" in data and str(data["crs"]) else None,
            origin=tuple(data.get("origin", (0.0, 0.0))), name=name or str(data.get("name", path.stem)),
        )
        return m.resample(cell) if cell is not None else m
    y_key = next((k for k in ("lat", "latitude", "y") if k in data), None)
    x_key = next((k for k in ("lon", "longitude", "x") if k in data), None)
    grids = [k for k, v in data.items() if np.ndim(v) == 2]
    variable = variable or (grids[0] if len(grids) == 1 else None)
    if y_key is None or x_key is None or variable not in data:
        raise MapFormatError(
            f"{path}: keys {sorted(data)}; expected north/east/depth, or lat/lon (or x/y) with one "
            "2-D variable (choose it with variable=)"
        )
    geographic = (y_key.startswith("lat") and crs is None) or (crs is not None and _is_geographic(crs))
    crs_unit = 1.0 if geographic else metric_crs(crs, str(path))[1]
    values = _mask_nodata(data[variable], nodata) * _depth_factor(None, units, crs_unit, str(path), variable)
    factor = resolve_sign(values, {}, variable, sign, str(path))
    return _grid_to_map(data[y_key], data[x_key], factor * values, geographic=geographic, crs=crs,
                        cell=cell, name=name or path.stem, where=f"{path}:{variable}", variable=variable,
                        max_scale_error=max_scale_error)


def write_npz(bathymetry: BathymetryMap, path: Path) -> None:
    with open(path, "wb") as f:
        np.savez_compressed(f, north=bathymetry.north, east=bathymetry.east, depth=bathymetry.depth,
                            crs=np.str_(bathymetry.crs or ""), origin=np.asarray(bathymetry.origin),
                            name=np.str_(bathymetry.name))


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
    max_scale_error: float = 1e-3,
) -> BathymetryMap:
    """Read a bathymetry grid from a file into a local metric `BathymetryMap`.

    Parameters
    ----------
    path : path-like
        ``.nc/.grd/.cdf`` NetCDF (COARDS/CF or GMT), ``.tif`` GeoTIFF, ``.xyz/.txt/.csv`` text
        grid, ``.npz``, ``.tsh/.ply/.obj`` triangulated surface.
    format : {"netcdf", "geotiff", "xyz", "npz", "tin"}, optional
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
    fmt = _format_of(p, format)
    if fmt == "netcdf":
        return read_netcdf(p, variable=variable, sign=sign, crs=crs, cell=cell, name=name,
                           nodata=nodata, units=units, max_scale_error=max_scale_error)
    if fmt == "geotiff":
        return read_geotiff(p, sign=sign, crs=crs, cell=cell, name=name, nodata=nodata, units=units,
                            max_scale_error=max_scale_error)
    if fmt == "xyz":
        return read_xyz(p, sign=sign, crs=crs, cell=cell, name=name, nodata=nodata, units=units,
                        max_scale_error=max_scale_error)
    if fmt == "npz":
        return read_npz(p, variable=variable, sign=sign, crs=crs, cell=cell, name=name,
                        nodata=nodata, units=units, max_scale_error=max_scale_error)
    return read_tin(p, sign=sign, crs=crs, cell=cell, name=name)


def write_map(bathymetry: BathymetryMap, path: str | os.PathLike, *, format: str | None = None,
              overwrite: bool = False) -> Path:
    """Write a map as NetCDF, GeoTIFF, XYZ, NPZ or a PLY/OBJ mesh (by suffix or ``format``).

    The file is written next to its final name and renamed into place, so an interrupted write
    leaves nothing half-written; an existing file is only replaced with ``overwrite=True``.
    """
    from tangraph.maps import mesh

    p = Path(path)
    fmt = _format_of(p, format)
    writers: dict[str, Callable[[BathymetryMap, Path], None]] = {
        "netcdf": write_netcdf, "geotiff": write_geotiff, "xyz": write_xyz, "npz": write_npz,
        "tin": mesh.write_mesh,
    }
    if fmt == "tin" and p.suffix.lower() == ".tsh":
        raise TangraphError(f"{p}: writing .tsh is not supported; write .ply or .obj")
    write_atomically(p, overwrite, lambda tmp: writers[fmt](bathymetry, tmp))
    return p
