"""The error of a map as the estimators model it (:class:`MapError`, :func:`map_error`): the std the
map states cell by cell, split into independent Matérn fields by scale, and the seafloor's change
since the map was surveyed, a field of its own. How the estimators use it is
:mod:`tangraph.sensors.terrain`'s.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from tangraph.errors import TangraphError
from tangraph.maps.grid import BathymetryMap

__all__ = ["MapError", "map_error"]


@dataclasses.dataclass(frozen=True, eq=False)
class MapError:
    """The error of a map as the estimators model it: the std ``std (ny, nx)`` (m, NaN where the
    map has no data) on the map's grid, and the correlation range ``correlation_length`` (m).
    ``change_std`` (m) of it, in quadrature, is the seafloor's change since the map was surveyed,
    the same everywhere, a field of its own of range ``change_length`` (m; 0: the map's
    ``correlation_length``); the rest is the map's own statement."""

    bathymetry: BathymetryMap
    std: np.ndarray
    correlation_length: float
    change_std: float = 0.0
    change_length: float = 0.0

    def __post_init__(self) -> None:
        std = np.array(self.std, dtype=np.float64)
        if std.shape != self.bathymetry.shape:
            raise TangraphError(f"MapError: std has shape {std.shape}, the map {self.bathymetry.shape}")
        if np.any(std[np.isfinite(std)] < 0):
            raise TangraphError("MapError: std must be >= 0")
        length = float(self.correlation_length)
        if not (np.isfinite(length) and length > 0):
            raise TangraphError(f"MapError: correlation_length must be > 0, got {self.correlation_length!r}")
        change = float(self.change_std)
        if not (np.isfinite(change) and change >= 0 and np.isfinite(self.change_length)
                and self.change_length >= 0):
            raise TangraphError(f"MapError: change_std and change_length must be >= 0, got "
                                f"{self.change_std!r} and {self.change_length!r}")
        if change > 0 and np.any(std[np.isfinite(std)] < change * (1.0 - 1e-9)):
            raise TangraphError(f"MapError: the change since the map ({change:g} m) is part of its std, "
                                "which is smaller in places")
        std.setflags(write=False)
        object.__setattr__(self, "std", std)
        object.__setattr__(self, "correlation_length", length)
        object.__setattr__(self, "change_std", change)
        object.__setattr__(self, "change_length", float(self.change_length) or length)
        object.__setattr__(self, "_field", None)
        object.__setattr__(self, "_parts", None)

    @property
    def is_zero(self) -> bool:
        """The map is taken as the truth (no error anywhere)."""
        return not np.any(np.nan_to_num(self.std) > 0)

    @functools.cached_property
    def typical_std(self) -> float:
        """The median std over the map's data (m), computed once."""
        values = self.std[np.isfinite(self.std)]
        return float(np.median(values)) if values.size else 0.0

    @property
    def cell_length(self) -> float:
        """The range of the cell-scale error: one cell of the map (m)."""
        return float(max(self.bathymetry.cell_size))

    def components(self) -> list[MapError]:
        """The independent fields whose sum is the map error, each a :class:`MapError` of one
        field: of the map's own statement the cell-scale error at the level of its well-surveyed
        cells (the lower quartile of its std), of range one cell, and the excess over it, of range
        ``correlation_length`` (module docstring; one field of range ``correlation_length``
        when that is at most a cell or the std is uniform), then the change since the map, of
        range ``change_length``; none for a perfect map."""
        parts = self._parts  # type: ignore[attr-defined]
        if parts is None:
            parts = self._split()
            object.__setattr__(self, "_parts", parts)
        return list(parts)

    @property
    def own(self) -> MapError:
        """The map's own statement, without the change since it was surveyed."""
        if self.change_std == 0:
            return self
        std = np.sqrt(np.maximum(self.std**2 - self.change_std**2, 0.0))
        return MapError(self.bathymetry, std, self.correlation_length)

    def _split(self) -> tuple[MapError, ...]:
        if self.change_std > 0:
            change = np.where(np.isfinite(self.std), self.change_std, np.nan)
            return (*self.own._split(), MapError(self.bathymetry, change, self.change_length))
        if self.is_zero:
            return ()
        if self.correlation_length <= self.cell_length:
            return (self,)
        floor = float(np.percentile(self.std[np.isfinite(self.std)], 25))
        cell = np.minimum(self.std, floor)
        excess = np.sqrt(np.maximum(self.std**2 - cell**2, 0.0))
        if not np.any(np.nan_to_num(excess) > 0.01 * floor):  # a uniform std: one field of range L
            return (self,)
        return (MapError(self.bathymetry, cell, self.cell_length),
                MapError(self.bathymetry, excess, self.correlation_length))

    def without_offset(self, offset_std: float) -> MapError:
        """The error left once the map's horizontal offset of std ``offset_std`` (m per axis,
        ``NavigationModel.map_offset_std``) is held on its own: each cell's variance less the
        part the offset explains through the map's slope, ``offset_std^2 |g|^2`` (a gridded map
        counts its soundings' positioning error that way, :mod:`tangraph.maps.gridding_error`),
        never below half the stated std (a map whose std leaves its positioning out keeps most
        of what it states)."""
        if not offset_std > 0 or self.own.is_zero:
            return self
        m, own = self.bathymetry, self.own.std
        north, east = np.meshgrid(m.north, m.east, indexing="ij")
        slope = np.nan_to_num(np.sum(m.gradient_at(north, east) ** 2, axis=-1))
        std = np.sqrt(np.maximum(own**2 - offset_std**2 * slope, 0.25 * own**2) + self.change_std**2)
        return dataclasses.replace(self, std=std)

    def std_at(self, north, east) -> np.ndarray:
        """Bilinear std of the map's error at points (NaN where the map has no data)."""
        if self.is_zero:
            out = np.zeros(np.broadcast_shapes(np.shape(north), np.shape(east)))
            return np.where(np.isfinite(self.bathymetry.depth_at(north, east)), out, np.nan)
        field = self._field  # type: ignore[attr-defined]
        if field is None:
            m = self.bathymetry
            field = BathymetryMap(m.north, m.east, np.where(np.isfinite(m.depth), self.std, np.nan),
                                  name=f"{m.name} error std")
            object.__setattr__(self, "_field", field)
        return field.depth_at(north, east)


def map_error(bathymetry: BathymetryMap, model) -> MapError:
    """The map's error: its own ``depth_std`` and ``correlation_length`` where it carries them,
    else the navigation model's ``map_std`` (everywhere the map has data) and
    ``map_correlation_length`` (0: one map cell); and the seafloor's change since the map that
    the model states (``map_change_std``, ``map_change_length``), in quadrature."""
    std = getattr(bathymetry, "depth_std", None)
    if std is None:
        std = np.where(np.isfinite(bathymetry.depth), float(model.map_std), np.nan)
    length = getattr(bathymetry, "correlation_length", None)
    if length is None:
        length = float(model.map_correlation_length) or float(max(bathymetry.cell_size))
    change = float(getattr(model, "map_change_std", 0.0))
    if change > 0:
        std = np.sqrt(np.asarray(std, np.float64) ** 2 + change**2)
    return MapError(bathymetry, std, length, change, float(getattr(model, "map_change_length", 0.0)))
