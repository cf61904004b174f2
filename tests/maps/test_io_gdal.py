"""GeoTIFF and NetCDF maps as GDAL (rasterio) writes and reads them."""

from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pyproj
import pytest
import xarray as xr

from tangraph.errors import MapFormatError
from tangraph.maps import BathymetryMap, read_map, write_map
from tangraph.maps.projection import local_crs

rasterio = pytest.importorskip("rasterio")
from rasterio.transform import Affine  # noqa: E402

# a Lambert conformal conic on GRS80 that has no EPSG code: the CRS must travel as WKT
LCC_WKT = pyproj.CRS(
    "+proj=lcc +lat_0=-32 +lon_0=135 +lat_1=-28 +lat_2=-36 +x_0=1000000 +y_0=2000000 +ellps=GRS80 "
    "+units=m +no_defs +type=crs"
).to_wkt()
NY, NX, CELL = 37, 29, 5.0
WEST, TOP = 1_234_500.0, 2_345_600.0


def raster(nodata=-9999.0):
    rng = np.random.default_rng(7)
    depth = (60 + rng.normal(size=(NY, NX)).cumsum(axis=0)).astype(np.float32)
    depth[5, 7] = nodata
    return depth


def write_with_rasterio(path, data, *, crs=LCC_WKT, transform=None, nodata=-9999.0, **options):
    profile = {"driver": "GTiff", "height": data.shape[0], "width": data.shape[1], "count": 1,
               "dtype": data.dtype, "crs": crs, "nodata": nodata,
               "transform": transform or Affine(CELL, 0, WEST, 0, -CELL, TOP), **options}
    with rasterio.open(path, "w", **profile) as dst:
        dst.write(data, 1)
    return path


def assert_placed(m, data, crs_wkt):
    """The map holds ``data`` (north-up rows) on cell centres of the test geotransform."""
    expected = np.where(data == -9999.0, np.nan, data)[::-1].astype(float)
    np.testing.assert_array_equal(m.depth, expected)
    np.testing.assert_allclose(m.east + m.origin[1], WEST + (np.arange(NX) + 0.5) * CELL, rtol=0, atol=1e-9)
    np.testing.assert_allclose(m.north + m.origin[0], TOP - (np.arange(NY)[::-1] + 0.5) * CELL,
                               rtol=0, atol=1e-9)
    assert pyproj.CRS(m.crs).equals(pyproj.CRS(crs_wkt))


# -- GeoTIFFs written by GDAL ------------------------------------------------------------------
@pytest.mark.parametrize("options", [
    {"compress": "lzw"},
    {"compress": "deflate", "predictor": 3},
    {"compress": "zstd"},
    {"compress": "lzw", "predictor": 3, "tiled": True, "blockxsize": 16, "blockysize": 16},
    {"driver": "COG", "compress": "deflate", "blocksize": 16},
], ids=["lzw", "deflate-predictor3", "zstd", "tiled", "cog"])
def test_gdal_geotiffs_read_back_exactly(tmp_path, options):
    data = raster()
    path = write_with_rasterio(tmp_path / "g.tif", data, **options)
    if options.get("driver") == "COG":
        with rasterio.open(path) as src:
            assert src.tags(ns="IMAGE_STRUCTURE")["LAYOUT"] == "COG"
    m = read_map(path, sign="depth")
    assert_placed(m, data, LCC_WKT)
    assert "LOCAL_CS" not in m.crs and m.crs.startswith("PROJCRS")  # WKT, no EPSG code to give


def test_epsg_crs_and_nan_nodata_and_band_metadata(tmp_path):
    data = raster(nodata=np.nan)
    path = write_with_rasterio(tmp_path / "e.tif", -data, crs="EPSG:32755", nodata=np.nan)
    with rasterio.open(path, "r+") as dst:
        dst.update_tags(1, positive="up")  # the band says it holds elevation
    m = read_map(path)
    assert m.crs == "EPSG:32755"
    np.testing.assert_array_equal(m.depth, data[::-1])


def test_pixel_is_point_is_placed_on_the_tie_point(tmp_path):
    tifffile = pytest.importorskip("tifffile")
    data = raster()
    # GeoKeys: model type projected, raster type PixelIsPoint, EPSG:32755; the tie point is the
    # centre of the top-left pixel
    keys = [(1024, 0, 1, 1), (1025, 0, 1, 2), (3072, 0, 1, 32755)]
    geokeys = [1, 1, 0, len(keys), *[v for k in keys for v in k]]
    path = tmp_path / "point.tif"
    tifffile.imwrite(path, data, extratags=[
        (33550, "d", 3, (CELL, CELL, 0.0), True),
        (33922, "d", 6, (0.0, 0.0, 0.0, WEST + CELL / 2, TOP - CELL / 2, 0.0), True),
        (34735, "H", len(geokeys), geokeys, True),
        (42113, "s", 0, "-9999", True),
    ])
    with rasterio.open(path) as src:
        assert src.tags()["AREA_OR_POINT"] == "Point"
    assert_placed(read_map(path, sign="depth"), data, "EPSG:32755")
    area = write_with_rasterio(tmp_path / "area.tif", data, crs="EPSG:32755")
    assert_placed(read_map(area, sign="depth"), data, "EPSG:32755")


@pytest.mark.parametrize(("transform", "message"), [
    (Affine(CELL, 0, WEST, 0, CELL, TOP), r"south-up \(pixel height 5.0 > 0\)"),
    (Affine(CELL, 0, WEST, 0, -CELL, TOP) @ Affine.rotation(10), "rotated"),
])
def test_south_up_and_rotated_rasters_are_refused_in_one_line(tmp_path, transform, message):
    path = write_with_rasterio(tmp_path / "r.tif", raster(), transform=transform)
    with pytest.raises(MapFormatError, match=message) as info:
        read_map(path, sign="depth")
    assert "\n" not in str(info.value) and "r.tif" in str(info.value)


def test_a_geographic_geotiff_is_projected(tmp_path):
    data = raster()
    transform = Affine(0.001, 0, 150.0, 0, -0.001, -37.0)
    path = write_with_rasterio(tmp_path / "geo.tif", data, crs="EPSG:4326", transform=transform)
    m = read_map(path, sign="depth")
    assert m.crs.startswith("+proj=tmerc") and pyproj.CRS(m.crs).is_projected
    assert np.nanmax(m.depth) <= np.max(data) + 1e-4


# -- GeoTIFFs written by tangraph, read by GDAL ------------------------------------------------
def tangraph_map(crs, origin=(5_900_123.5, 750_456.25)):
    rng = np.random.default_rng(3)
    depth = 40 + rng.normal(size=(12, 15)).cumsum(axis=1)
    depth[3, 4] = np.nan
    return BathymetryMap(north=100 + np.arange(12) * 2.5, east=-50 + np.arange(15) * 2.5, depth=depth,
                         crs=crs, origin=origin, name="small")


@pytest.mark.parametrize("crs", ["EPSG:32755", local_crs(-37.0, 150.0), LCC_WKT],
                         ids=["epsg", "geographic-source", "wkt"])
def test_gdal_places_tangraph_geotiffs(tmp_path, crs):
    m = tangraph_map(crs)
    path = write_map(m, tmp_path / "m.tif")
    with rasterio.open(path) as src:
        assert pyproj.CRS.from_wkt(src.crs.to_wkt()).equals(pyproj.CRS(crs))
        assert "LOCAL_CS" not in src.crs.to_wkt()
        west, south = m.east[0] + m.origin[1] - 1.25, m.north[0] + m.origin[0] - 1.25
        np.testing.assert_allclose(tuple(src.bounds), (west, south, west + 15 * 2.5, south + 12 * 2.5))
        assert np.isnan(src.nodata) and src.tags()["AREA_OR_POINT"] == "Area"
        assert "TIFFTAG_IMAGEDESCRIPTION" not in src.tags()
        assert src.tags(1)["positive"] == "down"
        np.testing.assert_allclose(src.read(1)[::-1], m.depth.astype(np.float32))
    back = read_map(path)
    assert back.crs == crs and back.name == "small"
    np.testing.assert_allclose(back.north + back.origin[0], m.north + m.origin[0], atol=1e-9)
    np.testing.assert_allclose(back.east + back.origin[1], m.east + m.origin[1], atol=1e-9)
    np.testing.assert_allclose(back.depth, m.depth, atol=1e-5)
    assert [p.name for p in tmp_path.iterdir()] == ["m.tif"]  # no .aux.xml beside it


def test_a_map_without_crs_round_trips(tmp_path):
    m = tangraph_map(None, origin=(0.0, 0.0))
    back = read_map(write_map(m, tmp_path / "m.tif"))
    assert back.crs is None
    np.testing.assert_allclose(back.north, m.north)


def test_geotiffs_of_older_tangraph_still_read(tmp_path):
    """tangraph <= 0.1 wrote the CRS, sign and name as JSON in the ImageDescription."""
    import json

    tifffile = pytest.importorskip("tifffile")
    m = tangraph_map(local_crs(-37.0, 150.0))
    x0, y_top = m.east[0] + m.origin[1] - 1.25, m.north[-1] + m.origin[0] + 1.25
    keys = [(1024, 0, 1, 1), (1025, 0, 1, 1), (3072, 0, 1, 32767)]
    geokeys = [1, 1, 0, len(keys), *[v for k in keys for v in k]]
    path = tmp_path / "old.tif"
    tifffile.imwrite(
        path, np.ascontiguousarray(m.depth[::-1], dtype=np.float32),
        description=json.dumps({"tangraph": {"positive": "down", "name": m.name, "crs": m.crs}}),
        extratags=[(33550, "d", 3, (2.5, 2.5, 0.0), True),
                   (33922, "d", 6, (0.0, 0.0, 0.0, x0, y_top, 0.0), True),
                   (34735, "H", len(geokeys), geokeys, True), (42113, "s", 0, "nan", True)])
    back = read_map(path)
    assert back.crs == m.crs and back.name == "small"
    np.testing.assert_allclose(back.east + back.origin[1], m.east + m.origin[1], atol=1e-9)
    np.testing.assert_allclose(back.depth, m.depth, atol=1e-5)


# -- NetCDF ------------------------------------------------------------------------------------
@pytest.mark.parametrize("crs", ["EPSG:32755", local_crs(-37.0, 150.0), None], ids=["epsg", "tmerc", "none"])
def test_netcdf_round_trip_keeps_the_frame(tmp_path, crs):
    m = tangraph_map(crs, origin=(5_900_123.5, 750_456.25) if crs else (0.0, 0.0))
    path = write_map(m, tmp_path / "m.nc")
    back = read_map(path)
    assert back.crs == m.crs and back.origin == m.origin and back.name == m.name
    np.testing.assert_allclose(back.north, m.north, rtol=0, atol=1e-9)
    np.testing.assert_allclose(back.east, m.east, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(back.depth, m.depth)
    with xr.open_dataset(path) as ds:
        assert ds["depth"].dims == ("y", "x")
        np.testing.assert_allclose(ds["x"].values, m.east + m.origin[1])
        np.testing.assert_allclose(ds["y"].values, m.north + m.origin[0])
        assert ds["x"].attrs["standard_name"] == "projection_x_coordinate"
        if crs is None:
            assert "crs" not in ds and "grid_mapping" not in ds["depth"].attrs
        else:
            assert ds["depth"].attrs["grid_mapping"] == "crs"
            assert pyproj.CRS.from_cf(ds["crs"].attrs).equals(pyproj.CRS(crs))


def test_netcdf_with_only_cf_grid_mapping_parameters(tmp_path):
    """x/y and a grid mapping as GDAL and GMT write them, the CRS given only by CF parameters."""
    cf = {k: v for k, v in pyproj.CRS(LCC_WKT).to_cf().items() if k not in ("crs_wkt", "spatial_ref")}
    assert cf["grid_mapping_name"] == "lambert_conformal_conic"
    data = raster()
    x = WEST + (np.arange(NX) + 0.5) * CELL
    y = TOP - (np.arange(NY) + 0.5) * CELL  # north-up rows, as GDAL writes them
    ds = xr.Dataset(
        {"elevation": (("y", "x"), -np.where(data == -9999, np.nan, data),
                       {"grid_mapping": "lambert", "units": "m", "positive": "up"}),
         "lambert": ((), 0, cf)},
        coords={"x": ("x", x, {"standard_name": "projection_x_coordinate", "units": "m"}),
                "y": ("y", y, {"standard_name": "projection_y_coordinate", "units": "m"})},
    )
    ds.to_netcdf(tmp_path / "cf.nc")
    m = read_map(tmp_path / "cf.nc")
    assert_placed(m, data, LCC_WKT)
    assert m.origin == (y[-1], x[0])  # a foreign grid: the origin at its first cell centre


@pytest.mark.skipif("netCDF" not in rasterio.drivers.raster_driver_extensions().values(),
                    reason="rasterio's GDAL has no netCDF driver")
@pytest.mark.parametrize("crs", ["EPSG:32755", local_crs(-37.0, 150.0)], ids=["epsg", "tmerc"])
def test_gdal_places_tangraph_netcdf(tmp_path, crs):
    m = tangraph_map(crs)
    path = write_map(m, tmp_path / "m.nc")
    with rasterio.open(f'NETCDF:"{path}":depth') as src:
        assert pyproj.CRS.from_wkt(src.crs.to_wkt()).equals(pyproj.CRS(crs))
        west, south = m.east[0] + m.origin[1] - 1.25, m.north[0] + m.origin[0] - 1.25
        np.testing.assert_allclose(tuple(src.bounds), (west, south, west + 15 * 2.5, south + 12 * 2.5))
        np.testing.assert_allclose(src.read(1)[::-1], m.depth)  # GDAL gives north-up rows


def test_netcdf_maps_of_older_tangraph_still_read(tmp_path):
    """tangraph <= 0.1 wrote dims (north, east) in local metres, CRS and origin as attributes."""
    m = tangraph_map(local_crs(-37.0, 150.0))
    m.to_xarray().to_dataset().to_netcdf(tmp_path / "old.nc")
    back = read_map(tmp_path / "old.nc")
    assert back.crs == m.crs and back.origin == m.origin and back.name == m.name
    np.testing.assert_array_equal(back.north, m.north)
    np.testing.assert_array_equal(back.depth, m.depth)


def test_large_maps_are_written_tiled(tmp_path):
    rng = np.random.default_rng(1)
    m = BathymetryMap(north=np.arange(600) * 1.0, east=np.arange(520) * 1.0,
                      depth=50 + rng.normal(size=(600, 520)), crs="EPSG:32755", origin=(5.9e6, 7.5e5))
    path = write_map(m, tmp_path / "big.tif")
    with rasterio.open(path) as src:
        assert src.profile["tiled"] and src.block_shapes == [(256, 256)]
        assert src.profile["compress"] == "deflate"
    np.testing.assert_allclose(read_map(path).depth, m.depth, atol=1e-5)


def gmt(folder, *args):
    """Run GMT in ``folder`` (it leaves a gmt.history where it runs)."""
    return subprocess.run(["gmt", *args], capture_output=True, text=True, check=True, cwd=folder)


@pytest.mark.skipif(shutil.which("gmt") is None, reason="GMT is not installed")
def test_gmt_places_tangraph_netcdf(tmp_path):
    m = tangraph_map("EPSG:32755")
    path = write_map(m, tmp_path / "m.nc")
    info = gmt(tmp_path, "grdinfo", "-C", str(path))
    fields = [float(v) for v in info.stdout.split()[1:]]
    (west, east, south, north, v_min, v_max, dx, dy, nx, ny), pixel = fields[:10], fields[10]
    half = 0.5 * pixel  # GMT may take the half-cell coordinates as pixel registration: the same cells
    assert (nx, ny, dx, dy) == (15, 12, 2.5, 2.5)
    assert (west + half * dx, east - half * dx) == pytest.approx(
        (m.east[0] + m.origin[1], m.east[-1] + m.origin[1]))
    assert (south + half * dy, north - half * dy) == pytest.approx(
        (m.north[0] + m.origin[0], m.north[-1] + m.origin[0]))
    assert (v_min, v_max) == pytest.approx((np.nanmin(m.depth), np.nanmax(m.depth)))
    xyz = gmt(tmp_path, "grd2xyz", str(path))
    rows = np.loadtxt(xyz.stdout.splitlines())  # cell centres, north row first
    np.testing.assert_allclose(rows[:, 2].reshape(12, 15)[::-1], m.depth)
    np.testing.assert_allclose(rows[:15, 0], m.east + m.origin[1])
    np.testing.assert_allclose(rows[::15, 1][::-1], m.north + m.origin[0])


@pytest.mark.skipif(shutil.which("gmt") is None, reason="GMT is not installed")
@pytest.mark.parametrize("registration", [[], ["-r"]], ids=["gridline", "pixel"])
def test_grids_written_by_gmt(tmp_path, registration):
    path = tmp_path / "g.nc"
    gmt(tmp_path, "grdmath", "-R750000/750100/5900000/5900050", "-I10", *registration,
        "X", "750000", "SUB", "100", "ADD", "=", str(path))
    m = read_map(path, crs="EPSG:32755", sign="depth")
    first = 5.0 if registration else 0.0  # pixel registration: the centre of the first cell
    assert m.origin == (5_900_000.0 + first, 750_000.0 + first) and m.cell_size == (10.0, 10.0)
    np.testing.assert_allclose(m.depth, np.broadcast_to(100 + first + m.east, m.shape))


def test_unreadable_multiband_and_ungeoreferenced_geotiffs_are_named(tmp_path):
    (tmp_path / "junk.tif").write_text("junk")
    with pytest.raises(MapFormatError, match="junk.tif: not a readable GeoTIFF"):
        read_map(tmp_path / "junk.tif")
    data = raster()
    two = tmp_path / "two.tif"
    with rasterio.open(two, "w", driver="GTiff", height=NY, width=NX, count=2, dtype="float32",
                       crs="EPSG:32755", transform=Affine(CELL, 0, WEST, 0, -CELL, TOP)) as dst:
        dst.write(np.stack([data, data]))
    with pytest.raises(MapFormatError, match="two.tif: 2 bands; one band of depths is expected"):
        read_map(two)
    bare = tmp_path / "bare.tif"
    with pytest.warns(rasterio.errors.NotGeoreferencedWarning):
        with rasterio.open(bare, "w", driver="GTiff", height=NY, width=NX, count=1, dtype="float32") as dst:
            dst.write(data, 1)
    with pytest.raises(MapFormatError, match=r"bare.tif: no georeference"):
        read_map(bare, sign="depth")
    no_crs = write_with_rasterio(tmp_path / "nocrs.tif", data, crs=None)
    with pytest.raises(MapFormatError, match="names no CRS; pass crs="):
        read_map(no_crs, sign="depth")
    assert read_map(no_crs, sign="depth", crs="EPSG:32755").crs == "EPSG:32755"
