"""The map's error through every reader and writer: NetCDF, GeoTIFF, NPZ, XYZ, BAG and S-102."""

from __future__ import annotations

import netCDF4
import numpy as np
import pyproj
import pytest
import xarray as xr

from tangraph.errors import MapFormatError, TangraphError
from tangraph.maps import BathymetryMap, block_reduce, fill_gaps, read_map, write_map
from tangraph.maps.io import write_sounding_grid

rasterio = pytest.importorskip("rasterio")
from rasterio.transform import Affine  # noqa: E402

ORIGIN = (6_543_210.0, 456_780.0)


def error_map(crs="EPSG:32633", shape=(14, 11), correlation_length=35.5, name="prior"):
    """A map with NaN holes, a varying std and a correlation length, on whole-metre cells."""
    rng = np.random.default_rng(11)
    depth = 30 + rng.normal(size=shape).cumsum(axis=1)
    depth[2, 3] = depth[7, 0] = np.nan
    std = 0.05 + rng.random(shape)
    return BathymetryMap(north=np.arange(shape[0]) * 5.0, east=np.arange(shape[1]) * 4.0, depth=depth,
                         crs=crs, origin=ORIGIN if crs else (0.0, 0.0), name=name, depth_std=std,
                         correlation_length=correlation_length)


def assert_same_error(back, m, atol=0.0):
    np.testing.assert_allclose(back.depth, m.depth, atol=atol, rtol=0)
    np.testing.assert_allclose(back.depth_std, m.depth_std, atol=atol, rtol=0)
    np.testing.assert_array_equal(np.isnan(back.depth_std), np.isnan(m.depth))
    assert back.correlation_length == pytest.approx(m.correlation_length, rel=1e-12)
    np.testing.assert_allclose(back.north + back.origin[0], m.north + m.origin[0], atol=1e-6, rtol=0)
    np.testing.assert_allclose(back.east + back.origin[1], m.east + m.origin[1], atol=1e-6, rtol=0)


# -- round trips ---------------------------------------------------------------------------------
@pytest.mark.parametrize("suffix", [".nc", ".tif", ".npz", ".xyz", ".bag"])
def test_the_error_layer_round_trips(tmp_path, suffix):
    m = error_map()
    back = read_map(write_map(m, tmp_path / f"m{suffix}"), **({"crs": m.crs} if suffix == ".xyz" else {}))
    exact = suffix in (".nc", ".npz")
    assert_same_error(back, m, atol=0.0 if exact else 1e-3 if suffix == ".xyz" else 1e-5)
    assert pyproj.CRS(back.crs).equals(pyproj.CRS(m.crs))
    assert read_map(tmp_path / f"m{suffix}", uncertainty=False,
                    **({"crs": m.crs} if suffix == ".xyz" else {})).depth_std is None


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


def test_netcdf_links_the_std_as_cf_says(tmp_path):
    m = error_map()
    path = write_map(m, tmp_path / "m.nc")
    with xr.open_dataset(path) as ds:
        assert ds["depth"].attrs["ancillary_variables"] == "depth_std"
        assert ds["depth"].attrs["error_correlation_length_m"] == 35.5
        std = ds["depth_std"]
        assert std.attrs["units"] == "m" and "standard deviation" in std.attrs["long_name"]
        assert std.attrs["standard_name"].endswith("standard_error") and std.attrs["grid_mapping"] == "crs"
        assert std.dims == ("y", "x")
    plain = write_map(m.replace(depth_std=None, correlation_length=None), tmp_path / "plain.nc")
    with xr.open_dataset(plain) as ds:
        assert "depth_std" not in ds and "ancillary_variables" not in ds["depth"].attrs


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


def test_xyz_carries_the_std_as_a_fourth_column(tmp_path):
    m = error_map()
    path = write_map(m, tmp_path / "m.xyz")
    header = path.read_text().splitlines()[0]
    assert "columns: east north depth depth_std" in header and "correlation_length_m 35.5;" in header
    assert np.loadtxt(path).shape == (m.depth.size, 4)
    data = np.loadtxt(path)[:, :3]  # a foreign file's fourth column is not read as a std
    np.savetxt(tmp_path / "foreign.xyz", np.column_stack([data, np.ones(len(data))]))
    assert read_map(tmp_path / "foreign.xyz", sign="depth", crs=m.crs).depth_std is None


def test_an_own_xarray_dataset_file_reads_with_its_std(tmp_path):
    m = error_map()
    m.to_dataset().to_netcdf(tmp_path / "own.nc")  # dims (north, east): the older own layout
    back = read_map(tmp_path / "own.nc")
    assert_same_error(back, m)
    assert back.origin == m.origin and back.crs == m.crs


def test_a_geographic_grid_projects_its_std_with_its_depths(tmp_path):
    lat = -36.90 + 0.0005 * np.arange(30)
    lon = 149.90 + 0.0006 * np.arange(25)
    depth = 20 + np.add.outer(np.arange(30.0), np.arange(25.0)) * 0.1
    std = 0.2 + np.add.outer(np.zeros(30), np.arange(25.0)) * 0.01  # grows eastward
    ds = xr.Dataset({"depth": (("lat", "lon"), depth, {"positive": "down", "units": "m",
                                                       "ancillary_variables": "depth_uncertainty"}),
                     "depth_uncertainty": (("lat", "lon"), std, {"units": "m"})},
                    coords={"lat": ("lat", lat, {"units": "degrees_north"}),
                            "lon": ("lon", lon, {"units": "degrees_east"})})
    ds.to_netcdf(tmp_path / "geo.nc")
    m = read_map(tmp_path / "geo.nc")
    assert m.crs.startswith("+proj=tmerc")
    np.testing.assert_array_equal(np.isnan(m.depth_std), np.isnan(m.depth))
    assert 0.2 <= np.nanmin(m.depth_std) and np.nanmax(m.depth_std) <= 0.44 + 1e-12
    west, east = np.nanmean(m.depth_std[:, :3]), np.nanmean(m.depth_std[:, -3:])
    assert east > west + 0.15  # the std went east with its cells


# -- finding the uncertainty ---------------------------------------------------------------------
def netcdf_grid(path, layers, depth_units="m", depth_attrs=None):
    y, x = 1000.0 + 5 * np.arange(4), 2000.0 + 5 * np.arange(5)
    depth = 10 + np.arange(20.0).reshape(4, 5)
    attrs = {"positive": "down", "units": depth_units, **(depth_attrs or {})}
    variables = {"depth": (("y", "x"), depth, attrs)}
    variables.update({k: (("y", "x"), v, a) for k, (v, a) in layers.items()})
    xr.Dataset(variables, coords={"y": y, "x": x}).to_netcdf(path)
    return path


def test_an_uncertainty_is_found_by_ancillary_variables_then_by_name(tmp_path):
    both = netcdf_grid(tmp_path / "both.nc", {"q": (np.full((4, 5), 0.4), {"long_name": "uncertainty"}),
                                              "stdev": (np.full((4, 5), 0.7), {})},
                       depth_attrs={"ancillary_variables": "q"})
    assert np.all(read_map(both).depth_std == 0.4)  # the CF link wins over the name
    named = netcdf_grid(tmp_path / "named.nc", {"stdev": (np.full((4, 5), 0.7), {})})
    assert np.all(read_map(named).depth_std == 0.7)
    two = netcdf_grid(tmp_path / "two.nc", {"stdev": (np.full((4, 5), 0.7), {}),
                                            "error": (np.full((4, 5), 0.9), {})})
    with pytest.raises(MapFormatError, match=r"two\.nc: several uncertainty variables \['stdev', 'error'\]"):
        read_map(two)
    assert np.all(read_map(two, uncertainty="error").depth_std == 0.9)
    assert read_map(two, uncertainty=False).depth_std is None
    none = netcdf_grid(tmp_path / "none.nc", {})
    assert read_map(none).depth_std is None
    with pytest.raises(MapFormatError, match=r"none\.nc: no uncertainty variable for 'depth'"):
        read_map(none, uncertainty=True)
    with pytest.raises(MapFormatError, match=r"none\.nc: no uncertainty variable 'tvu'"):
        read_map(none, uncertainty="tvu")


def test_an_uncertainty_in_feet_is_converted(tmp_path):
    own_units = netcdf_grid(tmp_path / "ft.nc", {"uncertainty": (np.full((4, 5), 1.0), {"units": "ft"})})
    assert np.allclose(read_map(own_units).depth_std, 0.3048)
    as_depth = netcdf_grid(tmp_path / "both_ft.nc", {"uncertainty": (np.full((4, 5), 2.0), {})},
                           depth_units="US survey foot")
    m = read_map(as_depth)
    assert np.allclose(m.depth_std, 2 * 1200 / 3937) and m.depth[0, 0] == pytest.approx(10 * 1200 / 3937)


def test_gridded_soundings_read_back_with_their_error_not_their_spread(tmp_path):
    rng = np.random.default_rng(5)
    pts = np.column_stack([rng.uniform(0, 40, 3000), rng.uniform(0, 40, 3000), 20 + rng.normal(0, 0.3, 3000)])
    grid = fill_gaps(block_reduce(pts, cell=4.0), 2)
    path = write_sounding_grid(grid, tmp_path / "grid.nc")
    back = read_map(path)
    np.testing.assert_allclose(back.depth_std, grid.depth.depth_std)
    assert back.correlation_length == grid.depth.correlation_length
    with xr.open_dataset(path) as ds:
        assert ds.attrs["tangraph_error_semivariance_m2"] == pytest.approx(grid.error.semivariance)
        # the soundings' spread is another layer
        assert not np.allclose(ds["std"].values, back.depth_std, equal_nan=True)
    old = tmp_path / "old.nc"  # a grid written before depth_std: its "std" is the spread, never the error
    with xr.open_dataset(path) as ds:
        ds.drop_vars("depth_std").assign(depth=ds["depth"].assign_attrs(ancillary_variables="")).to_netcdf(old)
    assert read_map(old).depth_std is None


# -- bad input: one line naming the file and the field ------------------------------------------
BAD = {
    "negative": (np.where(np.eye(4, 5) > 0, -0.5, 0.3),
                 r"holds 4 negative value\(s\) \(e\.g\. -0\.5 m at index \(0, 0\)\)"),
    "nan": (np.where(np.eye(4, 5) > 0, np.nan, 0.3), r"is NaN in 4 cell\(s\) where depth holds data"),
    "fill": (np.where(np.eye(4, 5) > 0, 1e20, 0.3), r"holds 4 value\(s\) beyond 12000 m .*pass nodata="),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_a_bad_netcdf_uncertainty_is_refused_in_one_line(tmp_path, case):
    values, match = BAD[case]
    path = netcdf_grid(tmp_path / f"{case}.nc", {"uncertainty": (values, {"units": "m"})})
    where = rf"{case}\.nc: uncertainty variable 'uncertainty' "
    with pytest.raises(MapFormatError, match=where + match) as info:
        read_map(path)
    assert "\n" not in str(info.value)
    assert read_map(path, uncertainty=False).depth_std is None


def test_an_uncertainty_of_another_shape_is_refused(tmp_path):
    y, x = 1000.0 + 5 * np.arange(4), 2000.0 + 5 * np.arange(5)
    ds = xr.Dataset({"depth": (("y", "x"), np.ones((4, 5)), {"positive": "down"}),
                     "uncertainty": (("y2", "x"), np.ones((3, 5)))}, coords={"y": y, "x": x})
    ds.to_netcdf(tmp_path / "shape.nc")
    with pytest.raises(MapFormatError, match=r"shape\.nc: uncertainty variable 'uncertainty' has dims "
                                             r"\('y2', 'x'\) \(shape \(3, 5\)\), not the depths'"):
        read_map(tmp_path / "shape.nc")


@pytest.mark.parametrize("length", [0.0, -3.0])
def test_a_bad_correlation_length_is_refused(tmp_path, length):
    path = netcdf_grid(tmp_path / "l.nc", {"depth_std": (np.full((4, 5), 0.2), {})},
                       depth_attrs={"error_correlation_length_m": length})
    with pytest.raises(MapFormatError, match=r"l\.nc:depth_std: attribute 'error_correlation_length_m' "
                                             r"\(correlation length\) must be a finite length > 0 m"):
        read_map(path)
    m = error_map()
    np.savez(tmp_path / "l.npz", north=m.north, east=m.east, depth=m.depth, correlation_length=length)
    with pytest.raises(MapFormatError, match=r"l\.npz: attribute 'correlation_length' \(correlation len"):
        read_map(tmp_path / "l.npz")


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


# -- BAG -----------------------------------------------------------------------------------------
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


# -- S-102 as GDAL's own tests lay it out --------------------------------------------------------
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
