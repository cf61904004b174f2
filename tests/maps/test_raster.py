"""GeoTIFF maps (tangraph.maps.raster) as GDAL (rasterio) writes and reads them: a real file;
compressions, tiles and COGs, CRSs as EPSG codes and as WKT, pixel-is-point; south-up and
rotated rasters refused, geographic ones projected; tangraph's GeoTIFFs placed by GDAL (older
ones still read, large ones tiled); the map's error as a second band; unreadable files named."""

from __future__ import annotations

import numpy as np
import pyproj
import pytest

from tangraph.errors import MapFormatError
from tangraph.maps import BathymetryMap, catalogue_path, read_map, write_map
from tangraph.maps.projection import local_crs
from tests.maps.io_cases import (
    CELL,
    LCC_WKT,
    NX,
    NY,
    TOP,
    WEST,
    assert_placed,
    error_map,
    raster,
    tangraph_map,
)

rasterio = pytest.importorskip("rasterio")
from rasterio.transform import Affine  # noqa: E402

MAPS = catalogue_path()


def write_with_rasterio(path, data, *, crs=LCC_WKT, transform=None, nodata=-9999.0, **options):
    profile = {"driver": "GTiff", "height": data.shape[0], "width": data.shape[1], "count": 1,
               "dtype": data.dtype, "crs": crs, "nodata": nodata,
               "transform": transform or Affine(CELL, 0, WEST, 0, -CELL, TOP), **options}
    with rasterio.open(path, "w", **profile) as dst:
        dst.write(data, 1)
    return path


# -- a real file -------------------------------------------------------------------------------
def test_geotiff_lidar_dem_georeference():
    path = MAPS / "lidar_dem.tif"
    with pytest.raises(MapFormatError, match="pass sign="):
        read_map(path)
    m = read_map(path, sign="elevation")
    assert m.shape == (400, 400)
    assert m.cell_size == (1.0, 1.0)
    assert m.crs == "EPSG:26915"
    # tie point = top-left corner of the top-left pixel; the map's origin is the centre of the
    # bottom-left cell
    assert m.origin == pytest.approx((5150885.424942633 - 399.5, 429252.313370022 + 0.5))
    assert np.nanmax(m.depth) == pytest.approx(-379.65933, abs=1e-3)


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


def test_large_maps_are_written_tiled(tmp_path):
    rng = np.random.default_rng(1)
    m = BathymetryMap(north=np.arange(600) * 1.0, east=np.arange(520) * 1.0,
                      depth=50 + rng.normal(size=(600, 520)), crs="EPSG:32755", origin=(5.9e6, 7.5e5))
    path = write_map(m, tmp_path / "big.tif")
    with rasterio.open(path) as src:
        assert src.profile["tiled"] and src.block_shapes == [(256, 256)]
        assert src.profile["compress"] == "deflate"
    np.testing.assert_allclose(read_map(path).depth, m.depth, atol=1e-5)


# -- the map's error ---------------------------------------------------------------------------
def test_geotiff_second_band_says_what_it_holds(tmp_path):
    m = error_map()
    path = write_map(m, tmp_path / "m.tif")
    with rasterio.open(path) as src:
        assert src.count == 2 and src.descriptions == ("depth", "depth_std")
        assert src.tags(2)["units"] == "m" and "standard deviation" in src.tags(2)["long_name"]
        assert float(src.tags()["TANGRAPH_ERROR_CORRELATION_LENGTH_M"]) == 35.5
    with rasterio.open(write_map(m.replace(depth_std=None), tmp_path / "one.tif")) as src:
        assert src.count == 1
    with pytest.raises(MapFormatError, match=r"one\.tif: one band, no uncertainty band to read"):
        read_map(tmp_path / "one.tif", uncertainty=True)


def test_bad_geotiff_and_npz_layers_are_named(tmp_path):
    m = error_map()
    bad = m.depth_std.copy()
    bad[4, 4] = -1.0
    profile = {"driver": "GTiff", "height": 14, "width": 11, "count": 2, "dtype": "float32", "nodata": np.nan,
               "crs": "EPSG:32633", "transform": Affine(4, 0, 0, 0, -5, 70)}
    with rasterio.open(tmp_path / "neg.tif", "w", **profile) as dst:
        dst.write(np.stack([m.depth, bad])[:, ::-1].astype(np.float32))
        dst.set_band_description(2, "uncertainty")
        dst.update_tags(1, positive="down")
    with pytest.raises(MapFormatError, match=r"neg\.tif: uncertainty band 'uncertainty' holds 1 negative"):
        read_map(tmp_path / "neg.tif")
    with rasterio.open(tmp_path / "other.tif", "w", **profile) as dst:
        dst.write(np.stack([m.depth, bad])[:, ::-1].astype(np.float32))
        dst.set_band_description(2, "backscatter")
        dst.update_tags(1, positive="down")
    with pytest.raises(MapFormatError, match=r"other\.tif: 2 bands; .*band 2 is 'backscatter'.*=False"):
        read_map(tmp_path / "other.tif")
    assert read_map(tmp_path / "other.tif", uncertainty=False).depth_std is None
    np.savez(tmp_path / "nan.npz", north=m.north, east=m.east, depth=np.nan_to_num(m.depth),
             depth_std=m.depth_std)  # depth everywhere, std NaN where it was not
    with pytest.raises(MapFormatError, match=r"nan\.npz: uncertainty array 'depth_std' is NaN in 2 cell"):
        read_map(tmp_path / "nan.npz")


# -- bad input ---------------------------------------------------------------------------------
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
