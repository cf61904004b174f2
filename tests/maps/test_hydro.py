"""BAG and S-102 maps (tangraph.maps.hydro): depths with their uncertainty written and read as GDAL
reads them, BAGs written by GDAL, S-102 files laid out as GDAL's own tests lay them out
(geographic ones projected once, heights, no uncertainty), and what they cannot hold refused."""

from __future__ import annotations

import netCDF4
import numpy as np
import pytest

from tangraph.errors import MapFormatError, TangraphError
from tangraph.maps import read_map, write_map
from tests.maps.io_cases import assert_same_error, error_map

rasterio = pytest.importorskip("rasterio")
from rasterio.transform import Affine  # noqa: E402


def test_s102_round_trips_through_gdal(tmp_path):
    m = error_map()
    path = write_map(m, tmp_path / "m.h5", format="s102")
    with rasterio.open(path) as src:  # GDAL's S102 driver reads what tangraph wrote
        assert src.driver == "S102" and src.descriptions == ("depth", "uncertainty")
        assert src.crs.to_epsg() == 32633
        np.testing.assert_allclose(src.read(1, masked=True).filled(np.nan)[::-1], m.depth, atol=1e-5)
    back = read_map(path)  # by its content
    assert_same_error(back, m, atol=1e-5)
    assert back.crs == "EPSG:32633" and back.name == "m"


# -- BAG ---------------------------------------------------------------------------------------
def test_a_bag_holds_elevation_positive_up_and_its_uncertainty(tmp_path):
    m = error_map()
    path = write_map(m, tmp_path / "m.bag")
    with rasterio.open(path) as src:  # as GDAL reads it
        assert src.driver == "BAG" and src.descriptions == ("elevation", "uncertainty")
        elevation = src.read(1, masked=True).filled(np.nan)[::-1]
        np.testing.assert_allclose(elevation, -m.depth, atol=1e-5)  # positive up on disk
        np.testing.assert_allclose(src.read(2, masked=True).filled(np.nan)[::-1], m.depth_std, atol=1e-6)
        assert "tangraph_correlation_length_m=35.5" in src.tags(ns="xml:BAG")["xml:BAG"]
    assert read_map(path).crs == "EPSG:32633"  # the horizontal part of the BAG's compound CRS


def gdal_bag(path, elevation, uncertainty=None, crs="EPSG:32633"):
    """A BAG written by GDAL (CreateCopy from an in-memory raster), one band or two."""
    from rasterio.io import MemoryFile
    from rasterio.shutil import copy

    layers = [elevation] + ([] if uncertainty is None else [uncertainty])
    profile = {"driver": "GTiff", "height": elevation.shape[0], "width": elevation.shape[1],
               "count": len(layers), "dtype": "float32", "nodata": np.nan, "crs": crs,
               "transform": Affine(4, 0, 500_000, 0, -5, 6_000_070)}
    with MemoryFile() as memory:
        with memory.open(**profile) as dst:
            dst.write(np.stack(layers).astype(np.float32))
        with memory.open() as src:
            copy(src, path, driver="BAG")
    return path


def test_a_bag_written_by_gdal_reads_with_the_right_sign_and_place(tmp_path):
    elevation = -(30 + np.arange(12.0).reshape(3, 4))  # north row first, below the datum
    path = gdal_bag(tmp_path / "g.bag", elevation, np.full((3, 4), 0.25))
    m = read_map(path)
    np.testing.assert_allclose(m.depth, -elevation[::-1])
    assert np.all(m.depth > 0) and np.all(m.depth_std == 0.25) and m.correlation_length is None
    assert m.origin == (6_000_070 - 5 * 2.5, 500_002.0) and m.cell_size == (5.0, 4.0)
    # crs= and units= are for files that do not say: agreeing they read the same, contradicting refused
    np.testing.assert_array_equal(read_map(path, crs="EPSG:32633", units="m").depth, m.depth)
    with pytest.raises(MapFormatError, match=r"g\.bag: the file states its CRS, EPSG:32633, and "
                                             r"crs='EPSG:32632' \(CLI: --crs\) says otherwise"):
        read_map(path, crs="EPSG:32632")
    with pytest.raises(MapFormatError, match=r"g\.bag: a BAG holds depths in metres, and units='ft'"):
        read_map(path, units="ft")


def test_a_bag_without_uncertainty_is_refused_unless_asked(tmp_path):
    path = gdal_bag(tmp_path / "bare.bag", -np.full((3, 4), 12.0))  # GDAL fills band 2 with no-data
    expected = (r"bare\.bag: the BAG has no uncertainty \(layer 'uncertainty' holds no data where the "
                r"depths do\); .*uncertainty=False")
    with pytest.raises(MapFormatError, match=expected) as info:
        read_map(path)
    assert "\n" not in str(info.value)
    m = read_map(path, uncertainty=False)
    assert m.depth_std is None and np.all(m.depth == 12.0)
    holes = np.where(np.eye(3, 4) > 0, np.nan, 0.2)
    partial = gdal_bag(tmp_path / "partial.bag", -np.full((3, 4), 12.0), holes)
    with pytest.raises(MapFormatError, match=r"partial\.bag: uncertainty layer 'uncertainty' is NaN in 3"):
        read_map(partial)
    negative = gdal_bag(tmp_path / "neg.bag", -np.full((3, 4), 12.0), np.where(np.eye(3, 4) > 0, -0.1, 0.2))
    with pytest.raises(MapFormatError, match=r"neg\.bag: uncertainty layer 'uncertainty' holds 3 negative"):
        read_map(negative)


def test_bag_and_s102_refuse_what_they_cannot_hold(tmp_path):
    m = error_map()
    with pytest.raises(TangraphError, match=r"m\.bag: BAG carries the depths with their uncertainty, but map "
                                            r"'prior' has no depth_std"):
        write_map(m.replace(depth_std=None), tmp_path / "m.bag")
    with pytest.raises(TangraphError, match=r"m\.bag: BAG needs a CRS"):
        write_map(error_map(crs=None), tmp_path / "m.bag")
    with pytest.raises(TangraphError, match=r"m\.h5: S-102 names its CRS by an EPSG code"):
        write_map(error_map(crs="+proj=tmerc +lat_0=-37 +lon_0=150 +ellps=WGS84 +units=m +type=crs"),
                  tmp_path / "m.h5", format="s102")
    with pytest.raises(MapFormatError, match=r"m\.h5: cannot tell the format .*format='s102'"):
        write_map(m, tmp_path / "m.h5")
    assert not list(tmp_path.iterdir())  # nothing half written
    with pytest.raises(TangraphError, match="sign= does not apply to BAG"):
        read_map(write_map(m, tmp_path / "ok.bag"), sign="depth")


# -- S-102 as GDAL's own tests lay it out ------------------------------------------------------
def s102_file(path, depth, uncertainty, *, crs, origin, spacing, vertical_cs=6498,
              fields=("depth", "uncertainty")):
    """An S-102 file laid out as GDAL's autotest generator does (h5py there, netCDF4's HDF5
    here): rows from south to north, no-data 1e6, the CRS as an EPSG code."""
    with netCDF4.Dataset(path, "w", format="NETCDF4") as ds:
        ds.setncattr_string("productSpecification", "INT.IHO.S-102.2.2")
        ds.setncattr("horizontalCRS", np.int32(crs))
        ds.setncattr("verticalCS", np.int32(vertical_cs))
        ds.createGroup("Group_F")
        coverage = ds.createGroup("BathymetryCoverage").createGroup("BathymetryCoverage.01")
        for key, value in (("gridOriginLongitude", origin[0]), ("gridOriginLatitude", origin[1]),
                           ("gridSpacingLongitudinal", spacing[0]), ("gridSpacingLatitudinal", spacing[1])):
            coverage.setncattr(key, np.float64(value))
        coverage.setncattr("numPointsLongitudinal", np.uint32(depth.shape[1]))
        coverage.setncattr("numPointsLatitudinal", np.uint32(depth.shape[0]))
        group = coverage.createGroup("Group_001")
        kind = np.dtype([(f, "<f4") for f in fields])
        group.createDimension("dim_0", depth.shape[0])
        group.createDimension("dim_1", depth.shape[1])
        values = np.zeros(depth.shape, kind)
        for f, layer in zip(fields, (depth, uncertainty), strict=False):
            values[f] = layer
        kind_type = group.createCompoundType(kind, "values_t")
        group.createVariable("values", kind_type, ("dim_0", "dim_1"))[:] = values
    return path


def test_gdals_own_s102_example_reads_as_gdal_says(tmp_path):
    """GDAL's autotest file (2 x 3 cells, depth 0..5 with a no-data, uncertainty 100..105 with a
    no-data over depth 4): GDAL presents it north up; tangraph refuses the missing std."""
    depth = np.array([[0, 1, 2], [1e6, 4, 5]], np.float32)
    uncertainty = np.array([[100, 101, 102], [103, 1e6, 105]], np.float32)
    path = s102_file(tmp_path / "gdal.h5", depth, uncertainty, crs=32631, origin=(500_000.0, 5_300_000.0),
                     spacing=(10.0, 20.0))
    with rasterio.open(path) as src:
        assert src.driver == "S102"
        assert tuple(src.read(1).ravel()) == (1e6, 4, 5, 0, 1, 2)  # as test_s102_basic asserts
        assert tuple(src.read(2).ravel()) == (103, 1e6, 105, 100, 101, 102)
    expected = (r"gdal\.h5: uncertainty layer 'uncertainty' is NaN in 1 cell\(s\) where depth holds data "
                r"\(e\.g\. at index \(0, 1\)\)")  # as GDAL presents it, north up
    with pytest.raises(MapFormatError, match=expected):
        read_map(path)
    m = read_map(path, uncertainty=False)
    np.testing.assert_array_equal(m.depth, np.where(depth == 1e6, np.nan, depth))  # south row first
    assert m.crs == "EPSG:32631" and m.origin == (5_300_000.0, 500_000.0) and m.cell_size == (20.0, 10.0)


def test_a_geographic_s102_is_projected_once_with_its_uncertainty(tmp_path):
    ny, nx = 24, 30
    depth = 40 + np.add.outer(np.arange(ny) * 0.5, np.zeros(nx))  # deepens northward
    uncertainty = 0.3 + np.add.outer(np.zeros(ny), np.arange(nx) * 0.02)  # grows eastward
    path = s102_file(tmp_path / "geo.h5", depth, uncertainty, crs=4326, origin=(2.0, 48.0),
                     spacing=(0.0004, 0.0003))
    m = read_map(path)
    assert m.crs.startswith("+proj=tmerc")
    assert 0.3 - 1e-6 <= np.nanmin(m.depth_std) and np.nanmax(m.depth_std) <= 0.3 + 29 * 0.02 + 1e-6
    south, north = np.nanmean(m.depth[:3]), np.nanmean(m.depth[-3:])
    assert north > south + 5  # depth positive down, rows in the right order
    from tangraph.maps.projection import to_lonlat

    lat, lon = to_lonlat(m, m.north[0], m.east[0])
    assert 48.0 - 1e-4 <= lat <= 48.0 + 0.0003 * 2 and 2.0 - 1e-4 <= lon <= 2.0 + 0.0004 * 2


def test_an_s102_of_heights_and_one_without_uncertainty(tmp_path):
    heights = s102_file(tmp_path / "h.h5", -np.full((3, 4), 9.0), np.full((3, 4), 0.5), crs=32633,
                        origin=(500_000.0, 6e6), spacing=(5.0, 5.0), vertical_cs=6499)
    assert np.all(read_map(heights).depth == 9.0)  # GDAL turns heights into depths
    bare = s102_file(tmp_path / "bare.h5", np.full((3, 4), 9.0), None, crs=32633, origin=(500_000.0, 6e6),
                     spacing=(5.0, 5.0), fields=("depth",))
    with pytest.raises(MapFormatError, match=r"bare\.h5: the S-102 values hold \['depth'\], no 'uncert"):
        read_map(bare)
    other = tmp_path / "other.h5"
    with netCDF4.Dataset(other, "w") as ds:
        ds.createDimension("x", 2)
    with pytest.raises(MapFormatError, match=r"other\.h5: an HDF5 file that is not S-102"):
        read_map(other)
