"""What a grid's parts must be: a regular ascending axis, a metric CRS, an error layer (std and
correlation length), query points that broadcast, a cell size and the axis of a new grid.

Each check raises a one-line error naming the map or file (``where``) and the field.
"""

from __future__ import annotations

import functools
import math

import numpy as np

from tangraph.errors import MapFormatError, TangraphError

__all__ = [
    "as_query",
    "cell_axis",
    "check_axis",
    "check_cell",
    "check_correlation_length",
    "check_depth_std",
    "check_projected",
]

# Relative tolerance on the spacing of "regular" coordinates (float32 files round them).
_SPACING_RTOL = 1e-4


def check_axis(values: np.ndarray, name: str, where: str) -> tuple[float, float]:
    """Return (first, spacing) of a regular ascending axis, or raise naming the problem."""
    if values.ndim != 1 or values.size < 2:
        raise MapFormatError(f"{where}: {name} must be 1-D with at least 2 cells, got shape {values.shape}")
    if not np.all(np.isfinite(values)):
        raise MapFormatError(f"{where}: {name} holds non-finite coordinates")
    steps = np.diff(values)
    if np.any(steps <= 0):
        k = int(np.argmax(steps <= 0))
        raise MapFormatError(
            f"{where}: {name} is not strictly ascending "
            f"({name}[{k}] = {values[k]!r}, {name}[{k + 1}] = {values[k + 1]!r})"
        )
    spacing = (values[-1] - values[0]) / (values.size - 1)
    worst = float(np.max(np.abs(steps - spacing)))
    if worst > _SPACING_RTOL * spacing:
        raise MapFormatError(
            f"{where}: {name} is not regularly spaced (mean step {spacing!r}, "
            f"a step deviates by {worst!r}); resample the grid first"
        )
    return float(values[0]), float(spacing)


@functools.lru_cache(maxsize=64)
def _crs_problem(crs: str) -> str | None:
    """Why ``crs`` cannot hold a metric local frame (None if it can)."""
    import pyproj

    try:
        parsed = pyproj.CRS(crs)
    except pyproj.exceptions.CRSError:
        return None  # named where the CRS is used (to_lonlat, the survey's frame)
    if parsed.is_geographic:
        return (f"its CRS {parsed.name!r} is geographic (degrees), but north/east are metres; "
                "read geographic grids with tangraph.maps.read_map (crs=) or "
                "tangraph.maps.project_geographic_grid")
    axes = [a for a in parsed.axis_info if a.direction in ("north", "east", "south", "west")]
    if axes and any(abs(a.unit_conversion_factor - 1.0) > 1e-12 for a in axes):
        return (f"its CRS {parsed.name!r} has axes in {axes[0].unit_name} "
                "(north/east/origin must be metres); read it with tangraph.maps.read_map")
    return None


def check_projected(crs: str, where: str) -> None:
    """Refuse a CRS that cannot hold a metric local frame (geographic, or axes not in metres)."""
    problem = _crs_problem(crs)
    if problem is not None:
        raise MapFormatError(f"{where}: {problem}")


def check_depth_std(std, depth: np.ndarray, where: str) -> np.ndarray:
    """The error layer ``std`` as a new float64 array, NaN wherever ``depth`` is NaN; or a
    one-line `MapFormatError` beginning with ``where`` (which names the file or map and the field).

    Refused: another shape than ``depth``; infinite or negative values; NaN where ``depth``
    holds data. A finite std over a no-data cell is set to NaN without a word.
    """
    std = np.array(std, dtype=np.float64)
    if std.shape != depth.shape:
        raise MapFormatError(f"{where} has shape {std.shape}, expected the depth's {depth.shape}")
    nodata = np.isnan(depth)
    std[nodata] = np.nan
    for problem, bad in (("infinite", np.isinf(std)), ("negative", std < 0),
                         ("NaN", np.isnan(std) & ~nodata)):
        if np.any(bad):
            k = tuple(int(i) for i in np.unravel_index(int(np.argmax(bad)), std.shape))
            if problem == "NaN":
                raise MapFormatError(
                    f"{where} is NaN in {int(bad.sum())} cell(s) where depth holds data (e.g. at index "
                    f"{k}); every cell with a depth needs its standard deviation"
                )
            raise MapFormatError(
                f"{where} holds {int(bad.sum())} {problem} value(s) (e.g. {std[k]:g} m at index {k}); "
                "a standard deviation is finite and >= 0"
            )
    return std


def _positive(value, where: str, what: str) -> float:
    """``value`` as a float if it is finite and > 0, else a one-line `MapFormatError` beginning
    with ``where`` and saying ``what`` it must be."""
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = math.nan
    if isinstance(value, bool) or not (math.isfinite(number) and number > 0):
        shown = value.item() if isinstance(value, np.generic) else value
        raise MapFormatError(f"{where} must be {what}, got {shown!r}")
    return number


def check_correlation_length(value, where: str) -> float:
    """``value`` as a float if it is a finite length > 0 (metres), else a one-line
    `MapFormatError` beginning with ``where``."""
    return _positive(value, where, "a finite length > 0 m")


def check_error_drift(value, where: str) -> tuple[float, float]:
    """``value`` as ``(std m, time s)`` if it is two finite numbers > 0, else a one-line
    `MapFormatError` beginning with ``where``."""
    parts = np.ravel(np.asarray(value if not isinstance(value, str) else value.split(), dtype=object))
    if parts.size != 2:
        raise MapFormatError(f"{where} must be two numbers (std in m, time in s), got {value!r}")
    return (_positive(parts[0], f"{where} std", "a finite std > 0 m"),
            _positive(parts[1], f"{where} time", "a finite time > 0 s"))


def check_error_dof(value, where: str) -> float:
    """``value`` as a float if it is a finite number of degrees of freedom > 0, else a one-line
    `MapFormatError` beginning with ``where``."""
    return _positive(value, where, "a finite number of degrees of freedom > 0")


def as_query(north, east) -> tuple[np.ndarray, np.ndarray, tuple[int, ...]]:
    """Query points as flat contiguous float64 ``north``, ``east`` and their broadcast shape."""
    n = np.asarray(north, dtype=np.float64)
    e = np.asarray(east, dtype=np.float64)
    try:
        shape = np.broadcast_shapes(n.shape, e.shape)
    except ValueError:
        raise TangraphError(
            f"north and east have shapes {n.shape} and {e.shape}, which do not broadcast"
        ) from None
    n = np.ascontiguousarray(np.broadcast_to(n, shape)).ravel()
    e = np.ascontiguousarray(np.broadcast_to(e, shape)).ravel()
    return n, e, shape


def check_cell(cell, where: str) -> float:
    """A cell size as a float if it is a positive number of metres, else a `TangraphError`."""
    value = float(cell)
    if not (np.isfinite(value) and value > 0):
        raise TangraphError(f"{where}: cell must be a positive number of metres, got {cell!r}")
    return value


def cell_axis(lo: float, hi: float, cell: float, name: str, where: str) -> np.ndarray:
    """Cell centres from ``lo`` in steps of ``cell`` up to ``hi``; at least two, else an error."""
    axis = lo + cell * np.arange(int(np.floor((hi - lo) / cell + 1e-9)) + 1)
    if axis.size < 2:
        raise TangraphError(
            f"{where}: {name} spans {hi - lo:g} m, less than 2 cells of {cell:g} m; "
            "use a smaller cell"
        )
    return axis
