"""What every map reader shares: the file's existence and size, depth or elevation, units, the
one projection step and the local origin, and the error layer's checks."""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Literal

import numpy as np

from tangraph.errors import MapFormatError, TangraphError
from tangraph.maps._grid_checks import check_correlation_length, check_depth_std, check_error_dof
from tangraph.maps.grid import BathymetryMap
from tangraph.maps.projection import project_geographic_grid, same_crs

Sign = Literal["depth", "elevation"]
#: which uncertainty layer to read: None finds it, a name chooses it, True requires one, False reads none
Uncertainty = str | bool | None
#: names of variables (or bands) holding the standard deviation of depth, lower case
UNCERTAINTY_NAMES = (
    "depth_std", "uncertainty", "depth_uncertainty", "std", "stdev", "stddev", "std_dev",
    "standard_deviation", "sigma", "error", "depth_error", "err", "tvu",
)
_DEPTH_NAMES = ("depth", "depths", "bathy_depth", "sea_floor_depth")
_ELEVATION_NAMES = ("elevation", "elev", "topo", "topography", "height", "altitude", "rose", "bathy")


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
    positive = str(attrs.get("positive", "")).lower()
    if given is not None:
        if given not in ("depth", "elevation"):
            raise TangraphError(f"sign must be 'depth' or 'elevation', got {given!r}")
        if positive in ("down", "up") and (positive == "down") != (given == "depth"):
            kind = "depths" if positive == "down" else "elevations"
            raise MapFormatError(
                f"{where}: variable {variable!r} states positive={positive!r} ({kind}), and sign={given!r} "
                "(CLI: --sign) says otherwise; leave sign out (it is for files that do not say) or mend "
                "the file's attribute")
        return 1.0 if given == "depth" else -1.0
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
    """Metres per unit of the depths: the variable's ``units`` attribute, else ``units=`` (which
    may not contradict a unit the file states and tangraph knows); a file whose CRS is not in
    metres and that says nothing about its depths is refused."""
    stated = attr_unit is not None and str(attr_unit).strip()
    if given is not None:
        factor = unit_factor(given, where, "units=")
        if stated and str(attr_unit).strip().lower() in _UNITS \
                and not math.isclose(factor, _UNITS[str(attr_unit).strip().lower()], rel_tol=1e-9):
            raise MapFormatError(
                f"{where}: variable {variable!r} states its units, {str(attr_unit)!r}, and units={given!r} "
                "(CLI: --units) says otherwise; leave units out (it is for files that do not say) or mend "
                "the file's attribute")
        return factor
    if stated:
        return unit_factor(str(attr_unit), where, f"variable {variable!r}")
    if crs_unit != 1.0:
        raise MapFormatError(
            f"{where}: the CRS is in units of {crs_unit:g} m but variable {variable!r} has no units "
            "attribute; pass units='m' (or 'ft', 'US survey foot') (CLI: --units)"
        )
    return 1.0


def check_given_crs(given: str | None, stated: str | None, where: str) -> str | None:
    """The CRS of a map file: ``stated`` (the file's), else ``given`` (``crs=``), which may not
    contradict a CRS the file states."""
    import pyproj

    if given is None or stated is None:
        return given or stated
    if not same_crs(given, stated):
        try:
            pyproj.CRS.from_user_input(given)
        except pyproj.exceptions.CRSError:
            return given  # (the reader's check of crs= names it as not understood)
        file_crs = pyproj.CRS.from_user_input(stated)
        code = file_crs.to_epsg()
        named = f"EPSG:{code}" if code else file_crs.name  # (a WKT named short)
        raise MapFormatError(f"{where}: the file states its CRS, {named}, and crs={given!r} (CLI: --crs) "
                             "says otherwise; leave crs out (it is for files that do not say) or mend it")
    return given


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


def std_factor(attr_unit, depth_factor: float, where: str) -> float:
    """Metres per unit of an uncertainty layer: its own ``units`` if it says, else the depths'."""
    if attr_unit is not None and str(attr_unit).strip():
        return unit_factor(str(attr_unit), where, "the layer")
    return depth_factor


def checked_std(values, depth: np.ndarray, *, factor: float, nodata, where: str) -> np.ndarray:
    """An uncertainty layer read from a file: ``nodata`` masked, in metres, no fill value
    beyond 12 000 m, and checked against ``depth`` (:func:`tangraph.maps._grid_checks.check_depth_std`);
    ``where`` names the file and the layer in every refusal."""
    std = _mask_nodata(values, nodata) * factor
    finite = np.isfinite(std)
    bad = finite & (np.where(finite, std, 0.0) > _PLAUSIBLE_DEPTH)
    if np.any(bad):
        k = tuple(int(i) for i in np.unravel_index(int(np.argmax(bad)), std.shape))
        raise MapFormatError(
            f"{where} holds {int(bad.sum())} value(s) beyond {_PLAUSIBLE_DEPTH:.0f} m (e.g. {std[k]:g} m "
            f"at index {k}); an unmarked fill value? pass nodata=VALUE (CLI: --nodata)"
        )
    return check_depth_std(std, depth, where)


def correlation_length_from(attrs, keys, where: str) -> float | None:
    """The first of ``keys`` in ``attrs`` as a checked correlation length (None if none is there)."""
    for key in keys:
        if key in attrs and str(attrs[key]).strip():
            return check_correlation_length(attrs[key], f"{where}: attribute {key!r} (correlation length)")
    return None


def error_dof_from(attrs, keys, where: str) -> float | None:
    """The first of ``keys`` in ``attrs`` as a checked Student-t tail of the map's error (None if
    none is there)."""
    for key in keys:
        if key in attrs and str(attrs[key]).strip():
            return check_error_dof(attrs[key], f"{where}: attribute {key!r} (Student-t degrees of freedom)")
    return None


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
    variable: str = "z", max_scale_error: float = 1e-3, depth_std: np.ndarray | None = None,
    correlation_length: float | None = None, error_dof: float | None = None,
) -> BathymetryMap:
    """Refuse implausible depths (metres), flip descending axes, then project (geographic) or
    shift to a local origin (projected, axes converted to metres): ``origin`` if given, else the
    first cell centre (``(0, 0)`` without a CRS). ``depth_std`` (metres, checked) goes the same
    way: flipped with the depths, projected by the same one step."""
    y = np.asarray(y, float)
    x = np.asarray(x, float)
    depth = np.asarray(depth, float)
    std = None if depth_std is None else np.asarray(depth_std, float)
    _check_plausible(depth, where, variable)
    if not geographic and crs is not None and _is_geographic(crs):
        geographic = True  # a geographic CRS, whatever the axes are called: the one projection step
    if y.size > 1 and y[0] > y[-1]:
        y, depth, std = y[::-1], depth[::-1], None if std is None else std[::-1]
    if x.size > 1 and x[0] > x[-1]:
        x, depth, std = x[::-1], depth[:, ::-1], None if std is None else std[:, ::-1]
    try:
        if geographic:
            m = project_geographic_grid(y, x, depth, cell=cell, name=name, source_crs=crs or "EPSG:4326",
                                        max_scale_error=max_scale_error)
            if std is not None:  # the same grid: the same lat/lon, cell and projection
                std = project_geographic_grid(y, x, std, cell=cell, name=name, source_crs=crs or "EPSG:4326",
                                              max_scale_error=max_scale_error).depth
            return m.replace(depth_std=std, correlation_length=correlation_length, error_dof=error_dof)
        crs, scale = metric_crs(crs, where)
        y, x = y * scale, x * scale
        if origin is None:
            origin = (float(y[0]), float(x[0])) if crs else (0.0, 0.0)
        m = BathymetryMap(north=y - origin[0], east=x - origin[1], depth=depth, crs=crs,
                          origin=origin, name=name, depth_std=std, correlation_length=correlation_length,
                          error_dof=error_dof)
    except MapFormatError as exc:
        raise MapFormatError(f"{where}: {exc}") from None
    return m.resample(cell) if cell is not None else m


def _is_geographic(crs: str) -> bool:
    import pyproj

    return bool(pyproj.CRS(crs).is_geographic)
