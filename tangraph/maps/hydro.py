"""The hydrographic formats that carry depths with their uncertainty: BAG and S-102.

Both are read by GDAL through rasterio (its BAG and S102 drivers), into a `BathymetryMap`
whose ``depth_std`` is the file's uncertainty layer:

- **BAG** (Bathymetric Attributed Grid, ONS/IHO, HDF5): band 1 ``elevation``, positive *up*
  (metres, whatever the vertical CRS's axis says), band 2 ``uncertainty`` (metres), a projected
  CRS (usually UTM, with a vertical datum: the horizontal part is kept). A variable-resolution
  BAG is read as GDAL presents it by default (its low-resolution grid). GDAL writes BAG.
- **S-102** (IHO bathymetric surface, HDF5): ``depth`` positive *down* (GDAL turns a file
  whose vertical CS is a height into depths) and ``uncertainty``, on a grid in an EPSG CRS,
  geographic (projected once, as every geographic grid) or projected (UTM). GDAL reads S-102
  but does not write it; tangraph writes the layout GDAL's reader expects (IHO S-102 2.2's
  groups and attributes) with netCDF4's HDF5, without the product's ISO metadata and vertical
  datum, which tangraph does not know.

BAG's uncertainty is mandatory: a BAG without one (no band, or a band of no-data where the
elevation has data) is refused in one line unless it is read with ``uncertainty=False``. Neither
format has a place for the correlation length of the map's error; tangraph writes it into the
BAG's abstract and an S-102 root attribute (``tangraph_correlation_length_m``) and reads it
back from there.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import cast

import numpy as np

from tangraph.errors import MapFormatError, TangraphError
from tangraph.maps._common import (
    Uncertainty,
    _existing,
    _grid_to_map,
    _is_geographic,
    check_given_crs,
    checked_std,
    correlation_length_from,
    unit_factor,
)
from tangraph.maps.grid import BathymetryMap
from tangraph.maps.raster import Raster, open_raster, raster_crs

__all__ = ["check_writable", "is_s102", "read_bag", "read_s102", "write_bag", "write_s102"]

#: BAG's and S-102's no-data value
FILL_VALUE = 1.0e6
#: where tangraph keeps the correlation length in a BAG's abstract and an S-102's root attributes
_CORRELATION_KEY = "tangraph_correlation_length_m"
_HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def is_s102(path) -> bool:
    """True if ``path`` is an HDF5 file with S-102's ``BathymetryCoverage`` group (read as GDAL
    identifies one: by the group's name in the file's first bytes)."""
    with open(path, "rb") as f:
        head = f.read(1 << 20)
    return head.startswith(_HDF5_SIGNATURE) and b"BathymetryCoverage" in head


def _uncertainty_layer(raster: Raster, depth: np.ndarray, uncertainty: Uncertainty, label: str,
                       nodata) -> np.ndarray | None:
    """The uncertainty band (metres) of a BAG or S-102, checked; None if ``uncertainty`` is False."""
    path = raster.path
    if uncertainty is False:
        return None
    if isinstance(uncertainty, str) and uncertainty.lower() != "uncertainty":
        raise MapFormatError(f"{path}: {label} has one uncertainty layer, 'uncertainty', not {uncertainty!r}")
    if uncertainty not in (None, True) and not isinstance(uncertainty, str):
        raise TangraphError(f"uncertainty must be a layer name, True, False or None, got {uncertainty!r}")
    where = f"{path}: uncertainty layer 'uncertainty'"
    band = raster.bands[1] if len(raster.bands) > 1 else None
    if band is None or not np.any(np.isfinite(band) & np.isfinite(depth)):
        raise MapFormatError(
            f"{path}: the {label} has no uncertainty (layer 'uncertainty' "
            f"{'missing' if band is None else 'holds no data where the depths do'}); read the depths "
            "alone with uncertainty=False (CLI: --uncertainty none)"
        )
    return checked_std(band, depth, factor=1.0, nodata=nodata, where=where)


def _read_hydro(raster: Raster, *, positive_up: bool, label: str, crs, cell, name, nodata, units,
                uncertainty, max_scale_error, length) -> BathymetryMap:
    path = raster.path
    if crs is None:
        crs = raster_crs(raster.crs, {}, path)
    elif raster.crs is not None:  # a CRS given may not contradict the file's
        crs = check_given_crs(crs, raster_crs(raster.crs, {}, path), str(path))
    geographic = crs is not None and _is_geographic(crs)
    variable = raster.descriptions[0] or "band 1"
    if units and unit_factor(units, str(path), "units=") != 1.0:  # metres, as both formats say
        raise MapFormatError(f"{path}: a {label} holds depths in metres, and units={units!r} (CLI: --units) "
                             "says otherwise; leave units out")
    depth = (-1.0 if positive_up else 1.0) * raster.bands[0] + 0.0  # + 0.0: no -0.0
    std = _uncertainty_layer(raster, depth, uncertainty, label, nodata)
    return _grid_to_map(raster.y, raster.x, depth, geographic=geographic, crs=crs, cell=cell,
                        name=name or path.stem, where=str(path), variable=variable,
                        max_scale_error=max_scale_error, depth_std=std,
                        correlation_length=None if uncertainty is False else length)


def read_bag(path, *, crs=None, cell=None, name=None, nodata=None, units=None,
             uncertainty: Uncertainty = None, max_scale_error=1e-3) -> BathymetryMap:
    """A map from a BAG: depth = -elevation (band 1), ``depth_std`` = its uncertainty (band 2).

    The options are those of :func:`tangraph.maps.read_map` (``crs=`` where the BAG names no
    CRS; ``uncertainty=False`` reads a BAG without uncertainty, depths alone).

    Examples
    --------
    >>> import numpy as np, tempfile, pathlib
    >>> from tangraph.maps import BathymetryMap, read_map, write_map
    >>> m = BathymetryMap(north=[0.0, 10, 20], east=[0.0, 10], depth=[[20.0, 21], [22, 23], [24, 25]],
    ...                   crs="EPSG:32633", origin=(6e6, 5e5), depth_std=np.full((3, 2), 0.3))
    >>> with tempfile.TemporaryDirectory() as folder:
    ...     back = read_map(write_map(m, pathlib.Path(folder) / "m.bag"))
    >>> back.depth[0].tolist(), back.crs, round(float(back.depth_std[0, 0]), 3)
    ([20.0, 21.0], 'EPSG:32633', 0.3)
    """
    raster = open_raster(path, label="BAG", nodata=nodata, driver="BAG", xml_domain="xml:BAG")
    found = re.search(rf"{_CORRELATION_KEY}=([0-9.eE+-]+)", raster.xml, flags=re.IGNORECASE)
    length = correlation_length_from({_CORRELATION_KEY: found[1]} if found else {}, (_CORRELATION_KEY,),
                                     str(raster.path))
    return _read_hydro(raster, positive_up=True, label="BAG", crs=crs, cell=cell, name=name, nodata=nodata,
                       units=units, uncertainty=uncertainty, max_scale_error=max_scale_error, length=length)


def read_s102(path, *, crs=None, cell=None, name=None, nodata=None, units=None,
              uncertainty: Uncertainty = None, max_scale_error=1e-3) -> BathymetryMap:
    """A map from an S-102 file: ``depth`` (positive down) and its ``uncertainty`` as
    ``depth_std`` (a cell whose uncertainty is no-data where the depth is not is refused, as
    in every reader: ``uncertainty=False`` reads the depths alone). A geographic S-102 is
    projected once onto a local transverse Mercator. Options as :func:`tangraph.maps.read_map`.
    """
    path = _existing(path)
    try:
        raster = open_raster(path, label="S-102", nodata=nodata, driver="S102")
    except MapFormatError:
        problem = _s102_problem(path)
        if problem:
            raise MapFormatError(f"{path}: {problem}") from None
        raise
    length = correlation_length_from(raster.tags, (_CORRELATION_KEY,), str(path))
    return _read_hydro(raster, positive_up=False, label="S-102", crs=crs, cell=cell, name=name,
                       nodata=nodata, units=units, uncertainty=uncertainty,
                       max_scale_error=max_scale_error, length=length)


def _s102_problem(path: Path) -> str | None:
    """Why GDAL could not read an S-102 file, where tangraph can tell (None otherwise)."""
    import netCDF4

    try:
        with netCDF4.Dataset(path) as ds:
            values = ds["BathymetryCoverage/BathymetryCoverage.01/Group_001"].variables.get("values")
            if values is None:
                return "not a readable S-102 (no BathymetryCoverage.01/Group_001/values)"
            kind = values.datatype
            fields = list(kind.dtype.names or ()) if isinstance(kind, netCDF4.CompoundType) else []
    except (OSError, KeyError, IndexError, AttributeError, RuntimeError):
        return None
    if "uncertainty" not in fields:
        import rasterio

        return (f"the S-102 values hold {fields or 'no named fields'}, no 'uncertainty'; GDAL "
                f"{rasterio.__gdal_version__} reads S-102 only with it")
    return None


# -- writing --------------------------------------------------------------------------------------
def check_writable(bathymetry: BathymetryMap, path: Path, fmt: str) -> None:
    """Refuse, before writing, a map BAG or S-102 cannot hold (no ``depth_std``, no CRS, or for
    S-102 a CRS without an EPSG code)."""
    label = {"bag": "BAG", "s102": "S-102"}[fmt]
    if bathymetry.depth_std is None:
        raise TangraphError(
            f"{path}: {label} carries the depths with their uncertainty, but map {bathymetry.name!r} has "
            "no depth_std; write NetCDF or GeoTIFF, or give the map one (replace(depth_std=...))"
        )
    if bathymetry.crs is None:
        raise TangraphError(f"{path}: {label} needs a CRS; map {bathymetry.name!r} has none")
    if fmt == "s102" and _epsg(bathymetry.crs) is None:
        raise TangraphError(
            f"{path}: S-102 names its CRS by an EPSG code; the CRS of map {bathymetry.name!r} has none "
            "(a local transverse Mercator?); write BAG, NetCDF or GeoTIFF"
        )


def _epsg(crs: str) -> int | None:
    import pyproj

    return pyproj.CRS(crs).to_epsg(min_confidence=100)


def _filled(layer: np.ndarray) -> np.ndarray:
    return np.where(np.isfinite(layer), layer, FILL_VALUE).astype(np.float32)


def write_bag(bathymetry: BathymetryMap, path: Path) -> None:
    """A BAG written by GDAL: elevation (-depth, positive up) and uncertainty (``depth_std``),
    no-data 1e6, the map's CRS, and its correlation length in the abstract."""
    import pyproj
    import rasterio
    from rasterio.transform import Affine

    import tangraph

    check_writable(bathymetry, path, "bag")
    dn, de = bathymetry.cell_size
    west = bathymetry.east[0] + bathymetry.origin[1] - 0.5 * de
    top = bathymetry.north[-1] + bathymetry.origin[0] + 0.5 * dn
    abstract = f"Bathymetry map {bathymetry.name!r} written by tangraph {tangraph.__version__}."
    if bathymetry.correlation_length is not None:
        abstract += (f" The correlation length of its error is {bathymetry.correlation_length:g} m "
                     f"({_CORRELATION_KEY}={bathymetry.correlation_length!r}).")
    profile = {"driver": "BAG", "height": bathymetry.shape[0], "width": bathymetry.shape[1], "count": 2,
               "dtype": "float32", "nodata": FILL_VALUE, "transform": Affine(de, 0.0, west, 0.0, -dn, top),
               "crs": rasterio.crs.CRS.from_wkt(pyproj.CRS(bathymetry.crs).to_wkt()),
               "VAR_ABSTRACT": abstract}
    with rasterio.Env(GDAL_PAM_ENABLED="NO"), rasterio.open(path, "w", **profile) as dst:
        std = cast(np.ndarray, bathymetry.depth_std)  # check_writable refused a map without it
        dst.write(np.stack([_filled(-bathymetry.depth), _filled(std)])[:, ::-1])


def write_s102(bathymetry: BathymetryMap, path: Path) -> None:
    """An S-102 file (IHO S-102 2.2 layout, as GDAL reads it): ``BathymetryCoverage.01``'s grid
    of (depth, uncertainty) from the south-west cell centre, no-data 1e6, ``horizontalCRS`` the
    EPSG code of the map's CRS, vertical CS depth in metres; no ISO metadata or vertical datum."""
    import datetime

    import netCDF4

    check_writable(bathymetry, path, "s102")
    values = np.zeros(bathymetry.shape, dtype=[("depth", "<f4"), ("uncertainty", "<f4")])
    values["depth"] = _filled(bathymetry.depth)
    values["uncertainty"] = _filled(cast(np.ndarray, bathymetry.depth_std))
    dn, de = bathymetry.cell_size
    with netCDF4.Dataset(path, "w", format="NETCDF4") as ds:
        ds.setncattr_string("productSpecification", "INT.IHO.S-102.2.2")
        ds.setncattr_string("issueDate", datetime.date.today().strftime("%Y%m%d"))
        ds.setncattr_string("geographicIdentifier", bathymetry.name)
        ds.setncattr("horizontalCRS", np.int32(_epsg(bathymetry.crs)))  # type: ignore[arg-type]
        ds.setncattr("verticalCS", np.int32(6498))  # depth, metres, positive down
        if bathymetry.correlation_length is not None:
            ds.setncattr(_CORRELATION_KEY, np.float64(bathymetry.correlation_length))
        ds.createGroup("Group_F")
        coverage = ds.createGroup("BathymetryCoverage").createGroup("BathymetryCoverage.01")
        for key, value in (("gridOriginLatitude", bathymetry.north[0] + bathymetry.origin[0]),
                           ("gridOriginLongitude", bathymetry.east[0] + bathymetry.origin[1]),
                           ("gridSpacingLatitudinal", dn), ("gridSpacingLongitudinal", de)):
            coverage.setncattr(key, np.float64(value))
        coverage.setncattr("numPointsLatitudinal", np.uint32(bathymetry.shape[0]))
        coverage.setncattr("numPointsLongitudinal", np.uint32(bathymetry.shape[1]))
        group = coverage.createGroup("Group_001")
        group.createDimension("numPointsLatitudinal", bathymetry.shape[0])
        group.createDimension("numPointsLongitudinal", bathymetry.shape[1])
        kind = group.createCompoundType(values.dtype, "BathymetryValues")
        group.createVariable("values", kind, ("numPointsLatitudinal", "numPointsLongitudinal"))[:] = values
        std = cast(np.ndarray, bathymetry.depth_std)  # check_writable refused a map without it
        for key, layer in (("Depth", bathymetry.depth), ("Uncertainty", std)):
            group.setncattr(f"minimum{key}", np.float32(np.nanmin(layer)))
            group.setncattr(f"maximum{key}", np.float32(np.nanmax(layer)))
