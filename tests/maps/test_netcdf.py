"""NetCDF maps (tangraph.maps.netcdf): real files (a depth-named variable holding elevations, an
ETOPO crop, a GMT grid with descending y); the frame kept through a round trip, CF grid mappings,
as GDAL and GMT place them, and older tangraph files; several variables, coordinates not
monotonic; the map's error: its std linked as CF says, found by ancillary_variables or by name,
in feet, projected with a geographic grid, a sounding grid's error rather than its spread, and
bad uncertainty variables refused in one line."""

from __future__ import annotations

import shutil
import subprocess

import numpy as np
import pyproj
import pytest
import xarray as xr

from tangraph.errors import MapFormatError
from tangraph.maps import block_reduce, catalogue_path, fill_gaps, read_map, write_map
from tangraph.maps.io import write_sounding_grid
from tangraph.maps.projection import local_crs
from tests.maps.io_cases import (
    CELL,
    LCC_WKT,
    NX,
    NY,
    TOP,
    WEST,
    assert_placed,
    assert_same_error,
    error_map,
    raster,
    tangraph_map,
)

rasterio = pytest.importorskip("rasterio")
MAPS = catalogue_path()


# -- real files --------------------------------------------------------------------------------
def test_netcdf_isobath_depth_named_variable_holding_elevation_needs_a_sign():
    path = MAPS / "isobath_arabian_sea.nc"
    with pytest.raises(MapFormatError, match=r"'DEPTH' is named like a depth but \d+% of its values"):
        read_map(path)
    with pytest.raises(MapFormatError, match=r"scale error reaches 0\.\d+% .*max_scale_error="):
        read_map(path, sign="elevation")  # 13 degrees wide: too wide for one transverse Mercator
    m = read_map(path, sign="elevation", max_scale_error=0.007)
    raw = xr.open_dataset(path)["DEPTH"]
    # the deepest point of the file becomes the deepest point of the map (bilinear keeps extrema
    # at or inside the range)
    assert np.nanmax(m.depth) <= -float(raw.min()) + 1e-6
    assert np.nanmax(m.depth) > 0.95 * -float(raw.min())
    assert m.crs.startswith("+proj=tmerc")


def test_netcdf_etopo5_crop_elevation_told_by_name_and_projected():
    m = read_map(MAPS / "etopo5_arctic.nc")  # variable ROSE: elevation by name
    raw = xr.open_dataset(MAPS / "etopo5_arctic.nc")["ROSE"]
    assert np.nanmin(m.depth) >= -float(raw.max()) - 1e-6
    # 5 arc-minutes of longitude at 75.5 N is about 2.3 km: the finer spacing sets the cell
    assert m.cell_size[0] == pytest.approx(9276.67 * np.cos(np.radians(75.5)), rel=0.01)


def test_gmt_grd_with_x_y_z_and_descending_y(tmp_path):
    x = np.linspace(500000, 500900, 10)
    y = np.linspace(4001000, 4000000, 11)  # descending, as in north-up rasters
    z = -100 - np.add.outer(y - y.min(), x - x.min()) * 0.01
    ds = xr.Dataset({"z": (("y", "x"), z, {"positive": "up"})}, coords={"x": x, "y": y})
    path = tmp_path / "grid.grd"
    ds.to_netcdf(path)
    m = read_map(path, crs="EPSG:32633")
    assert m.origin == (4000000.0, 500000.0)
    np.testing.assert_allclose(m.depth, -z[::-1])
    # the same grid without 'positive': 'z' cannot be told
    ds["z"].attrs = {}
    ds.to_netcdf(tmp_path / "bare.grd")
    with pytest.raises(MapFormatError, match="cannot tell whether variable 'z'"):
        read_map(tmp_path / "bare.grd")


# -- the frame, as GDAL and GMT place it -------------------------------------------------------
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


@pytest.mark.skipif("netCDF" not in rasterio.drivers.raster_driver_extensions().values(),
                    reason="rasterio's GDAL has no netCDF driver")
def test_a_netcdf_gdal_wrote_reads_in_its_crs_and_refuses_another(tmp_path):
    """GDAL's netCDF driver writes the CRS as a WKT grid mapping and a variable 'Band1' (with the
    GeoTIFF's positive down and units m): crs= and units= may agree with the file, not contradict it."""
    from rasterio.shutil import copy

    m = tangraph_map("EPSG:32755")
    copy(write_map(m, tmp_path / "m.tif"), tmp_path / "g.nc", driver="netCDF")
    back = read_map(tmp_path / "g.nc", sign="depth")
    assert pyproj.CRS(back.crs).equals(pyproj.CRS("EPSG:32755"))
    np.testing.assert_allclose(back.depth, m.depth, rtol=1e-6)
    assert read_map(tmp_path / "g.nc", sign="depth", crs="EPSG:32755").crs == "EPSG:32755"
    with pytest.raises(MapFormatError, match=r"g\.nc:Band1: the file states its CRS, EPSG:32755, and "
                                             r"crs='EPSG:32756' \(CLI: --crs\) says otherwise"):
        read_map(tmp_path / "g.nc", sign="depth", crs="EPSG:32756")
    np.testing.assert_allclose(read_map(tmp_path / "g.nc", units="m").depth, m.depth, rtol=1e-6)
    with pytest.raises(MapFormatError, match=r"variable 'Band1' states its units, 'm', and units='ft'"):
        read_map(tmp_path / "g.nc", units="ft")


def test_netcdf_maps_of_older_tangraph_still_read(tmp_path):
    """tangraph <= 0.1 wrote dims (north, east) in local metres, CRS and origin as attributes."""
    m = tangraph_map(local_crs(-37.0, 150.0))
    m.to_xarray().to_dataset().to_netcdf(tmp_path / "old.nc")
    back = read_map(tmp_path / "old.nc")
    assert back.crs == m.crs and back.origin == m.origin and back.name == m.name
    np.testing.assert_array_equal(back.north, m.north)
    np.testing.assert_array_equal(back.depth, m.depth)


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


# -- bad input ---------------------------------------------------------------------------------
def test_non_monotonic_coordinates_and_all_nan_are_named(tmp_path):
    x = np.array([0.0, 1.0, 3.0, 2.0])
    ds = xr.Dataset({"depth": (("y", "x"), np.ones((3, 4)))}, coords={"x": x, "y": [0.0, 1, 2]})
    ds.to_netcdf(tmp_path / "zigzag.nc")
    with pytest.raises(MapFormatError, match=r"zigzag.nc:depth: .*east is not strictly ascending"):
        read_map(tmp_path / "zigzag.nc")
    ds = xr.Dataset({"depth": (("y", "x"), np.full((3, 3), np.nan))},
                    coords={"x": [0.0, 1, 2], "y": [0.0, 1, 2]})
    ds.to_netcdf(tmp_path / "empty.nc")
    with pytest.raises(MapFormatError, match="empty.nc:depth: .*all NaN"):
        read_map(tmp_path / "empty.nc")


def test_several_grids_need_a_variable(tmp_path):
    ds = xr.Dataset({k: (("y", "x"), np.ones((2, 2))) for k in ("depth", "slope")},
                    coords={"x": [0.0, 1], "y": [0.0, 1]})
    ds.to_netcdf(tmp_path / "two.nc")
    with pytest.raises(MapFormatError, match=r"2 2-D variables \['depth', 'slope'\]"):
        read_map(tmp_path / "two.nc")
    assert read_map(tmp_path / "two.nc", variable="depth").shape == (2, 2)
    with pytest.raises(MapFormatError, match="no variable 'nope'"):
        read_map(tmp_path / "two.nc", variable="nope")
    # a second grid named like an uncertainty is the depths' std, not a rival grid
    ds.rename({"slope": "error"}).to_netcdf(tmp_path / "with_error.nc")
    m = read_map(tmp_path / "with_error.nc")
    assert m.depth_std is not None and np.all(m.depth_std == 1.0)
    assert read_map(tmp_path / "with_error.nc", uncertainty=False).depth_std is None


# -- the map's error ---------------------------------------------------------------------------
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


# -- finding the uncertainty -------------------------------------------------------------------
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


# -- bad uncertainty: one line naming the file and the field -----------------------------------
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
