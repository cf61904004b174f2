"""Rasters through rasterio (GDAL): GeoTIFF maps, and the raster reading BAG and S-102 share.

A GeoTIFF map is one band of depths, or two: the depths and their standard deviation (the
map's error, ``depth_std``), the second band described as such. :func:`open_raster` reads any
north-up raster GDAL opens into plain arrays with their cell-centre coordinates, refusing a
rotated, south-up or ungeoreferenced one in one line naming the file.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from typing import cast

import numpy as np

from tangraph.errors import MapFormatError
from tangraph.maps._common import (
    UNCERTAINTY_NAMES,
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
)
from tangraph.maps.grid import (
    CORRELATION_ATTRIBUTE,
    DEPTH_STD_ATTRS,
    DOF_ATTRIBUTE,
    DRIFT_ATTRIBUTE,
    BathymetryMap,
)

__all__ = ["Raster", "open_raster", "raster_crs", "read_geotiff", "write_geotiff"]

_DEPTH_TAGS = {"positive": "down", "standard_name": "sea_floor_depth_below_sea_surface", "units": "m"}
#: the dataset tag of a tangraph GeoTIFF that holds the correlation length of the map's error
_CORRELATION_TAG = "TANGRAPH_" + CORRELATION_ATTRIBUTE.upper()
_DOF_TAG = "TANGRAPH_" + DOF_ATTRIBUTE.upper()
_DRIFT_TAG = "TANGRAPH_" + DRIFT_ATTRIBUTE.upper()


@dataclasses.dataclass(frozen=True, eq=False)
class Raster:
    """The bands of a north-up raster as float64 arrays (NaN no-data, rows from north to south
    as GDAL gives them), with their descriptions, units and tags, the cell-centre coordinates
    ``y (ny,)`` (descending) and ``x (nx,)`` in the file's CRS units, and that CRS (rasterio's)."""

    path: Path
    driver: str
    bands: tuple[np.ndarray, ...]
    descriptions: tuple[str, ...]
    units: tuple[str | None, ...]
    band_tags: tuple[dict, ...]
    tags: dict
    y: np.ndarray
    x: np.ndarray
    crs: object
    xml: str = ""


def open_raster(path, *, label: str, nodata=None, driver: str | None = None,
                xml_domain: str | None = None) -> Raster:
    """Read every band of a north-up raster (``driver`` restricts GDAL's choice; ``label``
    names the format in errors; ``xml_domain`` a metadata domain to keep, e.g. ``"xml:BAG"``)."""
    import warnings

    import rasterio
    from rasterio.errors import NotGeoreferencedWarning, RasterioError

    path = _existing(path)
    try:
        with warnings.catch_warnings():  # refused below, in one line
            warnings.simplefilter("ignore", NotGeoreferencedWarning)
            src = rasterio.open(path, driver=driver) if driver else rasterio.open(path)
        with src:
            check_memory((src.height, src.width) if src.count == 1 else (src.count, src.height, src.width),
                         str(path))
            bands = tuple(_mask_nodata(np.ma.filled(src.read(k, masked=True).astype(float), np.nan), nodata)
                          for k in range(1, src.count + 1))
            units = tuple((src.units[k] if src.units else None) or src.tags(k + 1).get("units")
                          for k in range(src.count))
            raster = Raster(
                path=path, driver=src.driver, bands=bands,
                descriptions=tuple(d or "" for d in src.descriptions), units=units,
                band_tags=tuple(src.tags(k) for k in range(1, src.count + 1)), tags=src.tags(),
                y=np.empty(0), x=np.empty(0), crs=src.crs,
                xml=next(iter(src.tags(ns=xml_domain).values()), "") if xml_domain else "",
            )
            transform, ny, nx = src.transform, src.height, src.width
    except RasterioError as exc:
        raise MapFormatError(f"{path}: not a readable {label} ({exc})") from None
    a, b, c, d, e, f = (float(v) for v in tuple(transform)[:6])
    if transform.is_identity:
        raise MapFormatError(f"{path}: no georeference (no geotransform); a north-up {label} is expected")
    if b != 0.0 or d != 0.0:
        raise MapFormatError(f"{path}: the raster is rotated (geotransform {tuple(transform)[:6]}); "
                             "warp it north-up first (gdalwarp)")
    if e > 0.0:
        raise MapFormatError(f"{path}: the raster is south-up (pixel height {e} > 0); "
                             "warp it north-up first (gdalwarp)")
    # GDAL's geotransform is PixelIsArea (it shifts PixelIsPoint files, BAG and S-102 included)
    return dataclasses.replace(raster, x=c + (np.arange(nx) + 0.5) * a, y=f + (np.arange(ny) + 0.5) * e)


def raster_crs(file_crs, own: dict, path: Path) -> str | None:
    """The CRS of a raster as a string: tangraph's own (if the file's agrees), an EPSG code the
    file names exactly, or the file's WKT; of a compound CRS (a BAG's, with its vertical datum)
    the horizontal part."""
    import pyproj

    parsed = None
    if file_crs is not None:
        parsed = pyproj.CRS.from_wkt(file_crs.to_wkt())
        if parsed.is_compound:
            parsed = parsed.sub_crs_list[0]
        if parsed.is_bound and _null_towgs84(parsed):  # e.g. GDAL's BAG: TOWGS84[0,0,0,0,0,0,0]
            parsed = cast(pyproj.CRS, parsed.source_crs)
        if parsed.is_engineering:  # LOCAL_CS: a user-defined CRS GDAL could not read
            parsed = None
    if own.get("crs") and (parsed is None or pyproj.CRS(own["crs"]).equals(parsed, ignore_axis_order=True)):
        return str(own["crs"])
    if parsed is None:
        if own:
            return None  # a tangraph map with no place on Earth
        raise MapFormatError(f"{path}: the file names no CRS; pass crs= (CLI: --crs)")
    code = parsed.to_epsg(min_confidence=100)
    return f"EPSG:{code}" if code is not None else parsed.to_wkt()


def _null_towgs84(bound) -> bool:
    """True if a bound CRS's transformation to WGS 84 does nothing (all seven parameters 0)."""
    try:
        return not any(float(v) for v in bound.coordinate_operation.towgs84)
    except (AttributeError, TypeError, ValueError):
        return False


# -- GeoTIFF ----------------------------------------------------------------------------------
def _std_band(raster: Raster, uncertainty) -> int | None:
    """Index of the band holding the depths' std (None: read the depths alone)."""
    path, count = raster.path, len(raster.bands)
    if count == 1 and (uncertainty is True or isinstance(uncertainty, str)):
        raise MapFormatError(f"{path}: one band, no uncertainty band to read (uncertainty={uncertainty!r})")
    if count == 1 or uncertainty is False:
        if count > 2:
            raise MapFormatError(f"{path}: {count} bands; one band of depths is expected")
        return None
    description = raster.descriptions[1]
    named = description.lower() in UNCERTAINTY_NAMES or raster.band_tags[1].get("long_name") == \
        DEPTH_STD_ATTRS["long_name"]
    if isinstance(uncertainty, str):
        named = uncertainty.lower() in (description.lower(), "band 2", "2")
        if not named:
            raise MapFormatError(f"{path}: no band {uncertainty!r} (band 2 is {description or 'unnamed'!r})")
    if count > 2 or not named:
        raise MapFormatError(
            f"{path}: {count} bands; one band of depths is expected, and a second only if it holds "
            f"their standard deviation (band 2 is {description or 'unnamed'!r}: name it with "
            "uncertainty='BAND', or read band 1 alone with uncertainty=False; CLI: --uncertainty)"
        )
    return 1


def read_geotiff(path, *, sign=None, crs=None, cell=None, name=None, nodata=None,
                 units=None, uncertainty=None, max_scale_error=1e-3) -> BathymetryMap:
    """A grid from a north-up GeoTIFF (any compression, tiled or COG), read by rasterio.

    The CRS is the file's (an EPSG code where it is one exactly, else its WKT); no-data is the
    file's (or its mask); GDAL resolves PixelIsArea/PixelIsPoint. A rotated or south-up raster is
    refused. A second band is the depths' standard deviation (``depth_std``) if its description
    says so (``depth_std``, ``uncertainty``, ``std``, ...; or ``uncertainty=`` names it;
    ``uncertainty=False`` reads band 1 alone). See :func:`tangraph.maps.read_map`.
    """
    raster = open_raster(path, label="GeoTIFF", nodata=nodata)
    path = raster.path
    std_band = _std_band(raster, uncertainty)
    tags, band_tags = raster.tags, raster.band_tags[0]
    own = _tangraph_description(tags.get("TIFFTAG_IMAGEDESCRIPTION", ""))  # files of tangraph < 0.2
    if tags.get("TANGRAPH_NAME") is not None:
        own = {"name": tags["TANGRAPH_NAME"], "crs": tags.get("TANGRAPH_CRS") or None,
               "positive": band_tags.get("positive")}
    if crs is None:
        crs = raster_crs(raster.crs, own, path)
    elif raster.crs is not None or own.get("crs"):  # a CRS given may not contradict the file's
        crs = check_given_crs(crs, raster_crs(raster.crs, own, path), str(path))
    geographic = crs is not None and _is_geographic(crs)
    crs_unit = 1.0 if geographic else metric_crs(crs, str(path))[1]
    variable = raster.descriptions[0] or "band 1"
    factor = _depth_factor(raster.units[0], units, crs_unit, str(path), variable)
    values = raster.bands[0] * factor
    attrs = band_tags if "positive" in band_tags or "standard_name" in band_tags else {}
    if own and sign is None and own.get("positive") in ("down", "up"):
        attrs = {"positive": own["positive"]}
    depth = resolve_sign(values, attrs, variable, sign, str(path)) * values
    std = length = dof = None
    if std_band is not None:
        band = raster.descriptions[std_band] or f"band {std_band + 1}"
        where = f"{path}: uncertainty band {band!r}"
        std = checked_std(raster.bands[std_band], depth, nodata=None, where=where,
                          factor=std_factor(raster.units[std_band], factor, where))
        length = correlation_length_from(tags, (_CORRELATION_TAG,), str(path))
        dof = error_dof_from(tags, (_DOF_TAG,), str(path))
    m = _grid_to_map(raster.y, raster.x, depth, geographic=geographic, crs=crs, cell=cell,
                     name=name or own.get("name") or path.stem, where=str(path), variable=variable,
                     max_scale_error=max_scale_error, depth_std=std, correlation_length=length,
                     error_dof=dof)
    if uncertainty is False or not tags.get(_DRIFT_TAG, "").strip():
        return m
    try:
        return m.replace(error_drift=tags[_DRIFT_TAG])
    except MapFormatError as exc:
        raise MapFormatError(f"{path}: tag {_DRIFT_TAG!r}: {exc}") from None


def _tangraph_description(text: str) -> dict:
    try:
        data = json.loads(text)
    except (json.JSONDecodeError, TypeError):
        return {}
    return data.get("tangraph", {}) if isinstance(data, dict) else {}


def write_geotiff(bathymetry: BathymetryMap, path: Path) -> None:
    """A float32 GeoTIFF (DEFLATE, floating-point predictor), north up, NaN no-data, the map's CRS
    and bounds as GDAL reads them; depth positive down in the band's metadata. A map with a
    ``depth_std`` gets a second band holding it (description ``depth_std``, ``long_name``
    "standard deviation of the error of depth", units m), its ``correlation_length`` and
    ``error_dof`` the dataset tags ``TANGRAPH_ERROR_CORRELATION_LENGTH_M`` and
    ``TANGRAPH_ERROR_STUDENT_T_DOF``, its ``error_drift`` ``TANGRAPH_ERROR_DRIFT_STD_M_TIME_S``
    (``"std time"``)."""
    import pyproj
    import rasterio
    from rasterio.transform import Affine

    dn, de = bathymetry.cell_size
    west = bathymetry.east[0] + bathymetry.origin[1] - 0.5 * de
    top = bathymetry.north[-1] + bathymetry.origin[0] + 0.5 * dn
    ny, nx = bathymetry.shape
    layers = [bathymetry.depth] + ([] if bathymetry.depth_std is None else [bathymetry.depth_std])
    profile = {
        "driver": "GTiff", "height": ny, "width": nx, "count": len(layers), "dtype": "float32",
        "nodata": np.nan, "transform": Affine(de, 0.0, west, 0.0, -dn, top), "compress": "deflate",
        "predictor": 3, "crs": (rasterio.crs.CRS.from_wkt(pyproj.CRS(bathymetry.crs).to_wkt())
                                if bathymetry.crs else None),
    }
    if ny >= 512 and nx >= 512:
        profile.update(tiled=True, blockxsize=256, blockysize=256)
    tags = {"TANGRAPH_NAME": bathymetry.name, "TANGRAPH_CRS": bathymetry.crs or ""}
    if bathymetry.correlation_length is not None:
        tags[_CORRELATION_TAG] = repr(bathymetry.correlation_length)
    if bathymetry.error_dof is not None:
        tags[_DOF_TAG] = repr(bathymetry.error_dof)
    if bathymetry.error_drift is not None:
        tags[_DRIFT_TAG] = " ".join(repr(v) for v in bathymetry.error_drift)
    with rasterio.Env(GDAL_PAM_ENABLED="NO"), rasterio.open(path, "w", **profile) as dst:
        dst.write(np.ascontiguousarray(np.stack(layers)[:, ::-1], dtype=np.float32))
        dst.set_band_description(1, "depth")
        dst.update_tags(1, **_DEPTH_TAGS)
        if bathymetry.depth_std is not None:
            dst.set_band_description(2, "depth_std")
            dst.update_tags(2, **DEPTH_STD_ATTRS)
        dst.update_tags(**tags)
