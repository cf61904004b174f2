"""`BathymetryMap`: a regular grid of seafloor depths in a local metric frame (the checks its parts
pass are in :mod:`tangraph.maps._grid_checks`)."""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from typing import TYPE_CHECKING, Literal, cast

import numpy as np

from tangraph.errors import MapFormatError, TangraphError
from tangraph.maps._grid_checks import (
    as_query,
    check_axis,
    check_correlation_length,
    check_depth_std,
    check_error_dof,
    check_error_drift,
    check_projected,
)
from tangraph.maps._interp import box_mean, depth_kernel, gradient_kernel

if TYPE_CHECKING:
    import xarray as xr

__all__ = ["BathymetryMap"]

Order = Literal[1, 3]

#: the attribute (of depth, in NetCDF and xarray) that holds the correlation length of the map's error
CORRELATION_ATTRIBUTE = "error_correlation_length_m"
#: the attribute (of depth) that holds the degrees of freedom of the map error's Student-t tail
DOF_ATTRIBUTE = "error_student_t_dof"
#: the attribute (of depth) that holds the error's drift along a track, ``[std m, time s]``
DRIFT_ATTRIBUTE = "error_drift_std_m_time_s"
#: CF attributes of the error layer
DEPTH_STD_ATTRS = {
    "long_name": "standard deviation of the error of depth",
    "standard_name": "sea_floor_depth_below_sea_surface standard_error",
    "units": "m",
}


@dataclasses.dataclass(frozen=True, eq=False)
class BathymetryMap:
    """A regular grid of seafloor depths (metres, positive down) in a local NED frame.

    Parameters
    ----------
    north, east : ndarray, shape (ny,), (nx,)
        Ascending, regularly spaced cell-centre coordinates in metres.
    depth : ndarray, shape (ny, nx)
        Depth of the seafloor, positive down; NaN where there is no data.
    crs : str or None
        The projected CRS (anything ``pyproj.CRS`` accepts) in which the local frame lies, or
        None for a synthetic map with no place on Earth.
    origin : (float, float)
        ``(northing, easting)`` in ``crs`` of the local point ``north = east = 0``.
    name : str
        A short name, used in figures and errors.
    depth_std : ndarray, shape (ny, nx), optional
        The map's error as data: per cell, the standard deviation of the error of ``depth``
        (metres; NaN exactly where ``depth`` is NaN: a finite value over a no-data cell is set
        to NaN). None: the map does not say (the navigation model's stated default applies).
    correlation_length : float, optional
        The correlation length of the map's error, metres (> 0). None: not known.
    error_dof : float, optional
        The tail of the map's error (> 0): it errs by ``depth_std`` times a factor that varies
        patch by patch, a Student-t of ``error_dof`` degrees of freedom over the map (its check
        lines measure it: :func:`tangraph.eval.map_check.calibrate_error`); the filters' local
        misfit scale takes its prior from it (:mod:`tangraph.sensors.misfit`). None: a Gaussian
        error, as stated everywhere.
    error_drift : (float, float), optional
        ``(std m, time s)``: the depths a survey measures drift from the map's along its track by a
        Gauss-Markov offset of this std that forgets over this time (the check lines measure it,
        :meth:`tangraph.eval.map_check.MapCheck.drift`); a navigation model that states no drift
        of its own takes this one (:meth:`tangraph.sensors.NavigationModel.with_map`). None: not
        known.

    Notes
    -----
    The arrays are copied and made read-only, so a map never changes and never aliases
    the caller's data. Every map built from this one (:meth:`crop`, :meth:`resample`,
    :meth:`replace`, :meth:`to_dataset`/:meth:`from_xarray`, every writer of
    :func:`tangraph.maps.write_map` but XYZ without the column) carries the error layer.

    Examples
    --------
    >>> import numpy as np
    >>> from tangraph.maps import BathymetryMap
    >>> m = BathymetryMap(north=np.arange(3.0) * 10, east=np.arange(4.0) * 10,
    ...                   depth=np.arange(12.0).reshape(3, 4) + 100)
    >>> float(m.depth_at(5.0, 5.0))
    102.5
    >>> bool(np.isnan(m.depth_at(-1.0, 0.0)))  # off the map
    True
    >>> e = m.replace(depth_std=np.full((3, 4), 0.2), correlation_length=25.0)
    >>> float(e.depth_std_at(5.0, 5.0))
    0.2
    """

    north: np.ndarray
    east: np.ndarray
    depth: np.ndarray
    crs: str | None = None
    origin: tuple[float, float] = (0.0, 0.0)
    name: str = "map"
    depth_std: np.ndarray | None = None
    correlation_length: float | None = None
    error_dof: float | None = None
    error_drift: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        where = f"map {self.name!r}"
        north = np.array(self.north, dtype=np.float64)
        east = np.array(self.east, dtype=np.float64)
        depth = np.array(self.depth, dtype=np.float64)
        n0, dn = check_axis(north, "north", where)
        e0, de = check_axis(east, "east", where)
        if depth.shape != (north.size, east.size):
            raise MapFormatError(
                f"{where}: depth has shape {depth.shape}, expected (len(north), len(east)) = "
                f"{(north.size, east.size)}"
            )
        if np.any(np.isinf(depth)):
            raise MapFormatError(f"{where}: depth holds infinite values; mark no-data with NaN")
        if not np.any(np.isfinite(depth)):
            raise MapFormatError(f"{where}: depth is all NaN (no data at all)")
        if self.crs is not None:
            check_projected(str(self.crs), where)
        origin = tuple(float(v) for v in self.origin)
        if len(origin) != 2 or not all(np.isfinite(origin)):
            raise MapFormatError(f"{where}: origin must be two finite numbers, got {self.origin!r}")
        depth_std = None
        if self.depth_std is not None:
            depth_std = check_depth_std(self.depth_std, depth, f"{where}: depth_std")
            depth_std.setflags(write=False)
        for field, check in (("correlation_length", check_correlation_length), ("error_dof", check_error_dof),
                             ("error_drift", check_error_drift)):  # the error's scalar statements
            if getattr(self, field) is not None:
                object.__setattr__(self, field, check(getattr(self, field), f"{where}: {field}"))
        for a in (north, east, depth):
            a.setflags(write=False)
        object.__setattr__(self, "depth_std", depth_std)
        object.__setattr__(self, "north", north)
        object.__setattr__(self, "east", east)
        object.__setattr__(self, "depth", depth)
        object.__setattr__(self, "origin", origin)
        object.__setattr__(self, "_grid", (n0, e0, dn, de))

    # -- geometry -------------------------------------------------------------------------
    @property
    def shape(self) -> tuple[int, int]:
        """``(ny, nx)``."""
        return self.depth.shape

    @property
    def cell_size(self) -> tuple[float, float]:
        """Cell size ``(d_north, d_east)`` in metres."""
        _, _, dn, de = self._grid  # type: ignore[attr-defined]
        return dn, de

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """``(north_min, north_max, east_min, east_max)`` of the cell centres."""
        return (float(self.north[0]), float(self.north[-1]), float(self.east[0]), float(self.east[-1]))

    @property
    def valid_fraction(self) -> float:
        """Fraction of cells that hold data."""
        return float(np.mean(np.isfinite(self.depth)))

    def __repr__(self) -> str:
        dn, de = self.cell_size
        n_lo, n_hi, e_lo, e_hi = self.extent
        return (
            f"BathymetryMap(name={self.name!r}, shape={self.shape}, cell=({dn:g}, {de:g}) m, "
            f"north=[{n_lo:g}, {n_hi:g}], east=[{e_lo:g}, {e_hi:g}], "
            f"depth=[{np.nanmin(self.depth):g}, {np.nanmax(self.depth):g}] m{self._error_repr()}, "
            f"crs={self.crs!r})"
        )

    def _error_repr(self) -> str:
        text = ""
        if self.depth_std is not None:
            text += f", depth_std=[{np.nanmin(self.depth_std):g}, {np.nanmax(self.depth_std):g}] m"
        if self.correlation_length is not None:
            text += f", correlation_length={self.correlation_length:g} m"
        if self.error_dof is not None:
            text += f", error_dof={self.error_dof:.3g}"
        if self.error_drift is not None:
            text += f", error_drift=({self.error_drift[0]:.3g} m, {self.error_drift[1]:.3g} s)"
        return text

    def error_summary(self) -> dict:
        """The error layer's figures as data: ``depth_std_m`` (median and max over the cells
        with data), ``correlation_length_m``, ``error_dof`` and ``error_drift`` (``std_m``,
        ``time_s``), each only if the map has it
        (``{}`` if none).

        Examples
        --------
        >>> import numpy as np
        >>> m = BathymetryMap(north=[0.0, 1], east=[0.0, 1], depth=np.ones((2, 2)),
        ...                   depth_std=[[0.1, 0.2], [0.3, 0.5]], correlation_length=4.0)
        >>> m.error_summary()
        {'depth_std_m': {'median': 0.25, 'max': 0.5}, 'correlation_length_m': 4.0}
        """
        summary: dict = {}
        if self.depth_std is not None:
            summary["depth_std_m"] = {"median": float(np.nanmedian(self.depth_std)),
                                      "max": float(np.nanmax(self.depth_std))}
        if self.correlation_length is not None:
            summary["correlation_length_m"] = self.correlation_length
        if self.error_dof is not None:
            summary["error_dof"] = self.error_dof
        if self.error_drift is not None:
            summary["error_drift"] = {"std_m": self.error_drift[0], "time_s": self.error_drift[1]}
        return summary

    # -- queries --------------------------------------------------------------------------
    def _query(self, north, east, order: Order, with_grad: bool):
        if order not in (1, 3):
            raise TangraphError(f"order must be 1 (bilinear) or 3 (bicubic), got {order!r}")
        n, e, shape = as_query(north, east)
        out = np.empty(n.size)
        n0, e0, dn, de = self._grid  # type: ignore[attr-defined]
        if not with_grad:
            depth_kernel(self.depth, n0, e0, 1.0 / dn, 1.0 / de, n, e, order, out)
            return out, None, shape
        grad = np.empty((n.size, 2))
        gradient_kernel(self.depth, n0, e0, 1.0 / dn, 1.0 / de, n, e, order, out, grad)
        return out, grad, shape

    def depth_at(self, north, east, *, order: Order = 1):
        """Depth of the seafloor at points ``(north, east)``.

        Parameters
        ----------
        north, east : array_like
            Coordinates in metres, of any broadcastable shapes.
        order : {1, 3}
            1 bilinear, 3 bicubic (Keys, a = -0.5). Bicubic needs the 4 x 4 cells around a
            point; where those leave the grid or hold a NaN it falls back to bilinear.

        Returns
        -------
        ndarray
            Depths with the broadcast shape; NaN off the map (outside the outer cell centres)
            and next to NaN cells. Never clamped to the edge.
        """
        out, _, shape = self._query(north, east, order, with_grad=False)
        return out.reshape(shape)[()]

    def gradient_at(self, north, east, *, order: Order = 1) -> np.ndarray:
        """Gradient of the interpolated depth, ``(d depth / d north, d depth / d east)``.

        Returns an array of shape ``broadcast_shape + (2,)`` (dimensionless, m/m), the exact
        derivative of the interpolant that :meth:`depth_at` evaluates, NaN where it is NaN.
        """
        _, grad, shape = self._query(north, east, order, with_grad=True)
        return grad.reshape(*shape, 2)

    def depth_std_at(self, north, east) -> np.ndarray:
        """Standard deviation of the map's depth error at points ``(north, east)``, bilinear.

        The same compiled kernel as :meth:`depth_at` on the ``depth_std`` layer: NaN off the map
        and next to no-data cells (exactly where bilinear :meth:`depth_at` is NaN).

        Raises
        ------
        TangraphError
            The map has no ``depth_std`` (check ``m.depth_std is not None`` first).
        """
        if self.depth_std is None:
            raise TangraphError(
                f"map {self.name!r} has no depth_std (error layer); read it from a file that carries "
                "one, grid the map with tangraph.maps.grid_surveys, or use the model's default map std"
            )
        n, e, shape = as_query(north, east)
        out = np.empty(n.size)
        n0, e0, dn, de = self._grid  # type: ignore[attr-defined]
        depth_kernel(self.depth_std, n0, e0, 1.0 / dn, 1.0 / de, n, e, 1, out)
        return out.reshape(shape)[()]

    def contains(self, north, east) -> np.ndarray:
        """True where :meth:`depth_at` returns data: inside the grid and not next to a NaN."""
        return np.isfinite(self.depth_at(north, east))

    def nearest_cells(self, north, east) -> tuple[np.ndarray, np.ndarray]:
        """Row and column (int64) of the cell whose centre is nearest to each point; -1 for both
        off the grid or NaN."""
        i = np.rint((np.asarray(north, np.float64) - self.north[0]) / self.cell_size[0])
        j = np.rint((np.asarray(east, np.float64) - self.east[0]) / self.cell_size[1])
        inside = (i >= 0) & (i < self.shape[0]) & (j >= 0) & (j < self.shape[1])  # (False for NaN)
        return np.where(inside, i, -1).astype(np.int64), np.where(inside, j, -1).astype(np.int64)

    def cells_under(self, north, east) -> np.ndarray:
        """The cells ``(ny, nx)`` whose centre is the nearest to any of the points (points off
        the grid or NaN are ignored)."""
        i, j = self.nearest_cells(np.ravel(north), np.ravel(east))
        out = np.zeros(self.shape, dtype=bool)
        out[i[i >= 0], j[i >= 0]] = True
        return out

    # -- new maps from this one -----------------------------------------------------------
    def replace(self, **changes) -> BathymetryMap:
        """A copy with some fields changed (validated again).

        ``depth_std``, ``correlation_length``, ``error_dof`` and ``error_drift`` travel unchanged
        unless given; a new grid shape needs its own ``depth_std`` (or ``depth_std=None``), and new
        depths where the old layer is NaN are refused until one is given.
        """
        if self.depth_std is not None and "depth_std" not in changes and "depth" in changes:
            shape = np.shape(changes["depth"])
            if shape != self.shape:
                raise TangraphError(
                    f"replace of map {self.name!r}: depth changes shape {self.shape} -> {shape} but "
                    "depth_std was not given; pass depth_std= (or depth_std=None)"
                )
        return dataclasses.replace(self, **changes)

    def crop(
        self,
        north: Sequence[float] | None = None,
        east: Sequence[float] | None = None,
    ) -> BathymetryMap:
        """The cells whose centres lie within ``north = (lo, hi)`` and ``east = (lo, hi)``."""
        rows = self._index_range(self.north, north, "north")
        cols = self._index_range(self.east, east, "east")
        std = None if self.depth_std is None else self.depth_std[rows, cols]
        return self.replace(north=self.north[rows], east=self.east[cols], depth=self.depth[rows, cols],
                            depth_std=std)

    def _index_range(self, axis: np.ndarray, bounds, name: str) -> slice:
        if bounds is None:
            return slice(None)
        lo, hi = (float(b) for b in bounds)
        keep = np.flatnonzero((axis >= lo) & (axis <= hi))
        if keep.size < 2:
            raise TangraphError(
                f"crop of map {self.name!r}: {name} range [{lo:g}, {hi:g}] keeps {keep.size} cells "
                f"of [{axis[0]:g}, {axis[-1]:g}]; at least 2 are needed"
            )
        return slice(int(keep[0]), int(keep[-1]) + 1)

    def resample(self, cell: float | tuple[float, float], *, order: Order = 1) -> BathymetryMap:
        """The map on a new regular grid of cell size ``cell`` (metres) over the same extent.

        Finer cells interpolate (``order``); coarser cells average the cells that fall in each
        new cell (so a coarse map is not aliased), then interpolate to the new centres. A
        ``depth_std`` goes the same way, always bilinear (a std never overshoots below 0): a
        coarser cell keeps the mean std of the cells it averages, as if their errors were
        correlated over it (conservative); ``correlation_length`` is unchanged.
        """
        if np.isscalar(cell):
            dn_new = de_new = float(cast(float, cell))
        else:
            dn_new, de_new = map(float, cast(tuple[float, float], cell))
        if not (dn_new > 0 and de_new > 0):
            raise TangraphError(f"resample of map {self.name!r}: cell must be positive, got {cell!r}")
        n_lo, n_hi, e_lo, e_hi = self.extent
        north = n_lo + dn_new * np.arange(int(np.floor((n_hi - n_lo) / dn_new + 1e-9)) + 1)
        east = e_lo + de_new * np.arange(int(np.floor((e_hi - e_lo) / de_new + 1e-9)) + 1)
        if north.size < 2 or east.size < 2:
            raise TangraphError(
                f"resample of map {self.name!r}: cell {cell!r} leaves fewer than 2 x 2 cells"
            )
        source = self._smoothed_for(dn_new, de_new)
        nn, ee = np.meshgrid(north, east, indexing="ij")
        std = None if source.depth_std is None else source.depth_std_at(nn, ee)
        return self.replace(north=north, east=east, depth=source.depth_at(nn, ee, order=order),
                            depth_std=std)

    def _smoothed_for(self, dn_new: float, de_new: float) -> BathymetryMap:
        """A box average over the new cell size where the new grid is coarser (anti-aliasing)."""
        dn, de = self.cell_size
        kn = max(1, round(dn_new / dn))
        ke = max(1, round(de_new / de))
        if kn == 1 and ke == 1:
            return self
        std = None if self.depth_std is None else box_mean(self.depth_std, kn, ke)
        return self.replace(depth=box_mean(self.depth, kn, ke), depth_std=std)

    # -- xarray ---------------------------------------------------------------------------
    def to_xarray(self) -> xr.DataArray:
        """The depths as an ``xarray.DataArray`` with dims ``("north", "east")``; the error layer
        travels with :meth:`to_dataset`."""
        import xarray as xr

        attrs = {
            "long_name": "depth of the seafloor",
            "standard_name": "sea_floor_depth_below_sea_surface",
            "units": "m",
            "positive": "down",
            "name": self.name,
            "origin_northing": self.origin[0],
            "origin_easting": self.origin[1],
        }
        if self.crs is not None:
            attrs["crs"] = self.crs
        return xr.DataArray(
            np.array(self.depth),
            dims=("north", "east"),
            coords={
                "north": ("north", np.array(self.north), {"units": "m", "long_name": "local north"}),
                "east": ("east", np.array(self.east), {"units": "m", "long_name": "local east"}),
            },
            name="depth",
            attrs=attrs,
        )

    def to_dataset(self) -> xr.Dataset:
        """The map with its error layer as an ``xarray.Dataset``: ``depth`` (:meth:`to_xarray`)
        and, if the map has one, ``depth_std`` named by depth's CF ``ancillary_variables``;
        ``correlation_length`` is depth's attribute ``error_correlation_length_m``, ``error_dof``
        its attribute ``error_student_t_dof``.

        Examples
        --------
        >>> import numpy as np
        >>> m = BathymetryMap(north=[0.0, 1], east=[0.0, 1], depth=np.ones((2, 2)),
        ...                   depth_std=np.full((2, 2), 0.3), correlation_length=5.0)
        >>> ds = m.to_dataset()
        >>> ds["depth"].attrs["ancillary_variables"], ds["depth"].attrs["error_correlation_length_m"]
        ('depth_std', 5.0)
        >>> back = BathymetryMap.from_xarray(ds)
        >>> float(back.depth_std[0, 0]), back.correlation_length
        (0.3, 5.0)
        """
        import xarray as xr

        depth = self.to_xarray()
        variables = {"depth": depth}
        if self.correlation_length is not None:
            depth.attrs[CORRELATION_ATTRIBUTE] = self.correlation_length
        if self.error_dof is not None:
            depth.attrs[DOF_ATTRIBUTE] = self.error_dof
        if self.error_drift is not None:
            depth.attrs[DRIFT_ATTRIBUTE] = np.array(self.error_drift)
        if self.depth_std is not None:
            depth.attrs["ancillary_variables"] = "depth_std"
            variables["depth_std"] = depth.copy(data=np.array(self.depth_std)).rename("depth_std")
            variables["depth_std"].attrs = dict(DEPTH_STD_ATTRS)
        return xr.Dataset(variables)

    @classmethod
    def from_xarray(cls, da: xr.DataArray | xr.Dataset, *, name: str | None = None) -> BathymetryMap:
        """Inverse of :meth:`to_xarray` (a DataArray with dims ``("north", "east")`` holding
        depth) and of :meth:`to_dataset` (a Dataset whose ``depth`` names its ``depth_std``
        in ``ancillary_variables``).

        Coordinates may be descending (the grid is flipped). Sign and CRS come from the attrs
        ``positive`` ("down" or "up") and ``crs``; a DataArray without ``positive`` is taken
        as depth only if it was written by :meth:`to_xarray`.
        """
        std_da = None
        if hasattr(da, "data_vars"):  # a Dataset
            if "depth" not in da.data_vars:
                raise MapFormatError(f"Dataset has no variable 'depth' (it has {list(da.data_vars)})")
            linked = str(da["depth"].attrs.get("ancillary_variables", "")).split()
            std_da = da[linked[0]] if linked and linked[0] in da.variables else None
            da = da["depth"]
        if tuple(da.dims) != ("north", "east"):
            raise MapFormatError(
                f"DataArray {da.name!r} has dims {tuple(da.dims)}, expected ('north', 'east')"
            )
        positive = da.attrs.get("positive")
        if positive not in ("down", "up"):
            raise MapFormatError(
                f"DataArray {da.name!r}: attribute 'positive' is {positive!r}; set it to 'down' "
                "(depth) or 'up' (elevation)"
            )
        depth = np.asarray(da.values, dtype=np.float64) * (1.0 if positive == "down" else -1.0)
        std = None
        if std_da is not None:
            if tuple(std_da.dims) != ("north", "east"):
                raise MapFormatError(f"variable {std_da.name!r} has dims {tuple(std_da.dims)}, "
                                     "expected ('north', 'east') like depth")
            std = np.asarray(std_da.values, dtype=np.float64)
        north = np.asarray(da["north"].values, dtype=np.float64)
        east = np.asarray(da["east"].values, dtype=np.float64)
        if north.size > 1 and north[0] > north[-1]:
            north, depth, std = north[::-1], depth[::-1], None if std is None else std[::-1]
        if east.size > 1 and east[0] > east[-1]:
            east, depth, std = east[::-1], depth[:, ::-1], None if std is None else std[:, ::-1]
        return cls(
            north=north,
            east=east,
            depth=depth,
            crs=da.attrs.get("crs"),
            origin=(float(da.attrs.get("origin_northing", 0.0)), float(da.attrs.get("origin_easting", 0.0))),
            name=name or str(da.attrs.get("name", da.name or "map")),
            depth_std=std,
            correlation_length=da.attrs.get(CORRELATION_ATTRIBUTE),
            error_dof=da.attrs.get(DOF_ATTRIBUTE),
            error_drift=da.attrs.get(DRIFT_ATTRIBUTE),
        )

