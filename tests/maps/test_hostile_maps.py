"""Maps that would be read wrongly without a word: each is refused in one line naming the file,
the variable, the value and the option that settles it, or read right when that option is given."""

from __future__ import annotations

import numpy as np
import pyproj
import pytest

from tangraph.errors import MapFormatError
from tangraph.maps import BathymetryMap, read_map, to_lonlat
from tangraph.maps.projection import project_geographic_grid

netCDF4 = pytest.importorskip("netCDF4")

NY, NX = 20, 30


def _depths() -> np.ndarray:
    return 100.0 + np.arange(NY * NX, dtype=float).reshape(NY, NX) / 10.0


def _classic(path, values=None, *, var="depth", y=None, x=None, ydim="y", xdim="x",
             attrs=None, coord_attrs=None):
    """A classic (CDF-1) NetCDF with coordinates first, then one 2-D variable, no fill value."""
    values = _depths() if values is None else values
    with netCDF4.Dataset(path, "w", format="NETCDF3_CLASSIC") as ds:
        ds.createDimension(ydim, values.shape[0])
        ds.createDimension(xdim, values.shape[1])
        for dim, coords in ((ydim, y), (xdim, x)):
            c = ds.createVariable(dim, "f8", (dim,))
            c[:] = np.arange(values.shape[dim == xdim], dtype=float) * 10.0 if coords is None else coords
            for k, v in (coord_attrs or {}).get(dim, {}).items():
                c.setncattr(k, v)
        v = ds.createVariable(var, "f4", (ydim, xdim), fill_value=False)
        v[:] = values
        for k, val in (attrs if attrs is not None else {"positive": "down"}).items():
            v.setncattr(k, val)
    return path


# -- 1. truncated classic NetCDF / GMT grd ---------------------------------------------------
@pytest.mark.parametrize("suffix", [".nc", ".grd"])
def test_truncated_classic_netcdf_is_refused_naming_file_and_variable(tmp_path, suffix):
    path = _classic(tmp_path / f"cut{suffix}")
    assert read_map(path).shape == (NY, NX)  # the whole file reads
    size = path.stat().st_size
    with open(path, "r+b") as f:
        f.truncate(size - 1000)  # a cut inside the data
    with pytest.raises(MapFormatError, match=rf"cut\{suffix}: truncated classic NetCDF: variable 'depth' "
                                             rf"declares \d+ bytes .* the file has {size - 1000} bytes"):
        read_map(path)


# -- 2. fill values without _FillValue / missing_value ----------------------------------------
def test_unmarked_netcdf_fill_value_is_refused_then_masked_with_nodata(tmp_path):
    values = _depths()
    values[3, 4] = 1e20
    path = _classic(tmp_path / "fill.nc", values)
    with pytest.raises(MapFormatError, match=r"fill\.nc:depth: variable 'depth' holds 1 value\(s\) beyond "
                                             r"12000 m \(e\.g\. 1e\+20 m at index \(3, 4\)\).*"
                                             r"pass nodata=VALUE \(CLI: --nodata\)"):
        read_map(path)
    m = read_map(path, nodata=1e20)
    assert np.isnan(m.depth[3, 4]) and np.nanmax(m.depth) < 200


def test_xyz_minus_99999_is_refused_then_masked_with_nodata(tmp_path):
    nn, ee = np.meshgrid(np.arange(5.0), np.arange(6.0), indexing="ij")
    z = 50.0 + nn + ee
    z[2, 3] = -99999.0
    path = tmp_path / "grid.xyz"
    np.savetxt(path, np.column_stack([ee.ravel(), nn.ravel(), z.ravel()]))
    with pytest.raises(MapFormatError, match=r"grid\.xyz: variable 'z' holds 1 value\(s\) beyond 12000 m "
                                             r"\(e\.g\. -99999 m.*pass nodata=VALUE"):
        read_map(path, sign="depth")
    m = read_map(path, sign="depth", nodata=-99999)
    assert int(np.isnan(m.depth).sum()) == 1


def test_npz_reader_honours_nodata(tmp_path):
    values = _depths()
    values[0, 0] = -32767.0
    path = tmp_path / "grid.npz"
    np.savez(path, y=np.arange(NY) * 10.0, x=np.arange(NX) * 10.0, depth_grid=values)
    with pytest.raises(MapFormatError, match=r"grid\.npz:depth_grid: .*-32767 m.*nodata=VALUE"):
        read_map(path, sign="depth")
    m = read_map(path, sign="depth", nodata=-32767)
    assert np.isnan(m.depth[0, 0]) and np.isfinite(m.depth[0, 1])


# -- 3. sign: a guess the data contradict ---------------------------------------------------
@pytest.mark.parametrize("var", ["bathy", "bathymetry"])
def test_water_named_variable_holding_positive_depths_is_not_negated(tmp_path, var):
    path = _classic(tmp_path / "b.nc", var=var, attrs={})
    with pytest.raises(MapFormatError, match=rf"b\.nc: variable '{var}' .*names water but would be read as "
                                             r"elevations from its name.*100% of its values are positive.*"
                                             r"sign='depth' or sign='elevation' \(CLI: --sign\)"):
        read_map(path)
    assert np.allclose(read_map(path, sign="depth").depth, _depths(), atol=1e-3)


def test_water_named_variable_holding_negative_elevations_still_reads(tmp_path):
    path = _classic(tmp_path / "b.nc", -_depths(), var="bathy", attrs={})
    assert np.allclose(read_map(path).depth, _depths(), atol=1e-3)


def test_mean_sea_height_over_positive_depths_is_refused(tmp_path):
    path = _classic(tmp_path / "h.nc", var="z",
                    attrs={"standard_name": "mean_sea_height", "long_name": "bathymetrie"})
    with pytest.raises(MapFormatError, match=r"variable 'z' \(long_name 'bathymetrie'\) names water but "
                                             r"would be read as elevations from standard_name "
                                             r"'mean_sea_height'.*sign="):
        read_map(path)


def test_land_elevation_is_still_an_elevation(tmp_path):
    path = _classic(tmp_path / "dem.nc", var="elevation", attrs={})
    assert np.allclose(read_map(path).depth, -_depths(), atol=1e-3)


# -- 4. units ---------------------------------------------------------------------------------
@pytest.mark.parametrize(("unit", "metres"), [("ft", 0.3048), ("feet", 0.3048),
                                              ("US survey foot", 1200 / 3937), ("m", 1.0)])
def test_depth_units_attribute_is_converted_to_metres(tmp_path, unit, metres):
    path = _classic(tmp_path / "u.nc", attrs={"positive": "down", "units": unit})
    assert np.allclose(read_map(path).depth, _depths() * metres, rtol=1e-6)


def test_unknown_depth_unit_is_refused_naming_the_option(tmp_path):
    path = _classic(tmp_path / "u.nc", attrs={"positive": "down", "units": "furlong"})
    with pytest.raises(MapFormatError, match=r"u\.nc:depth: variable 'depth' has units 'furlong'.*"
                                             r"pass units='m'.*\(CLI: --units\)"):
        read_map(path)
    assert np.allclose(read_map(path, units="ft").depth, _depths() * 0.3048, rtol=1e-6)


def test_an_option_that_contradicts_what_the_file_states_is_refused(tmp_path):
    """--units, --sign and --crs are for files that do not say: one that contradicts the file is
    refused naming both (it once won silently: depths in feet beside their std in metres)."""
    from tangraph.maps import write_map

    path = _classic(tmp_path / "u.nc", attrs={"positive": "down", "units": "m"})
    assert np.allclose(read_map(path, units="m", sign="depth").depth, _depths(), rtol=1e-6)  # agreeing
    with pytest.raises(MapFormatError, match=r"u\.nc:depth: variable 'depth' states its units, 'm', and "
                                             r"units='ft' \(CLI: --units\) says otherwise"):
        read_map(path, units="ft")
    with pytest.raises(MapFormatError, match=r"states positive='down' \(depths\), and sign='elevation' "
                                             r"\(CLI: --sign\) says otherwise"):
        read_map(path, sign="elevation")
    placed = tmp_path / "placed.nc"
    write_map(BathymetryMap(np.arange(5.0) * 10, np.arange(6.0) * 10, np.full((5, 6), 30.0), crs="EPSG:25833",
                            origin=(5.8e6, 3.6e5)), placed)
    assert read_map(placed, crs="EPSG:25833").crs == "EPSG:25833"
    with pytest.raises(MapFormatError, match=r"the file states its CRS, EPSG:25833, and crs='EPSG:3035' "
                                             r"\(CLI: --crs\) says otherwise"):
        read_map(placed, crs="EPSG:3035")
    tif = tmp_path / "placed.tif"
    write_map(read_map(placed), tif)
    with pytest.raises(MapFormatError, match=r"placed\.tif: the file states its CRS, EPSG:25833"):
        read_map(tif, crs="EPSG:3035")
    # tangraph's own text map states its CRS in its header, and is read back in it, at the same place
    xyz = tmp_path / "placed.xyz"
    write_map(read_map(placed), xyz)
    back = read_map(xyz)
    assert back.crs == "EPSG:25833" and back.origin[0] + back.north[0] == pytest.approx(5.8e6)
    with pytest.raises(MapFormatError, match=r"placed\.xyz: the file states its CRS, EPSG:25833"):
        read_map(xyz, crs="EPSG:3035")


def test_coordinates_in_feet_are_converted_to_metres(tmp_path):
    path = _classic(tmp_path / "u.nc", coord_attrs={"y": {"units": "ft"}, "x": {"units": "ft"}})
    m = read_map(path)
    assert m.cell_size == pytest.approx((3.048, 3.048))


def test_crs_in_us_survey_feet_gives_metres_and_the_same_place(tmp_path):
    ft = 1200 / 3937
    x0, y0 = 6_000_000.0, 2_100_000.0  # EPSG:2227 (California zone 3, US survey feet)
    nn, ee = np.meshgrid(y0 + np.arange(5) * 100.0, x0 + np.arange(6) * 100.0, indexing="ij")
    path = tmp_path / "ca.xyz"
    np.savetxt(path, np.column_stack([ee.ravel(), nn.ravel(), 30.0 + 0 * nn.ravel()]))
    with pytest.raises(MapFormatError, match=r"ca\.xyz: the CRS is in units of 0\.3048\d* m but variable 'z' "
                                             r"has no units attribute; pass units="):
        read_map(path, sign="depth", crs="EPSG:2227")
    m = read_map(path, sign="depth", crs="EPSG:2227", units="ft")
    assert m.cell_size == pytest.approx((100 * ft, 100 * ft))
    assert np.allclose(m.depth, 30 * 0.3048)
    lat, lon = to_lonlat(m, 200 * ft, 300 * ft)
    lon_ref, lat_ref = pyproj.Transformer.from_crs("EPSG:2227", "EPSG:4326", always_xy=True).transform(
        x0 + 300.0, y0 + 200.0)
    assert lat == pytest.approx(lat_ref, abs=1e-8) and lon == pytest.approx(lon_ref, abs=1e-8)


def test_bathymetry_map_refuses_a_crs_in_feet():
    with pytest.raises(MapFormatError, match="has axes in US survey foot"):
        BathymetryMap(north=np.arange(3.0), east=np.arange(3.0), depth=np.ones((3, 3)), crs="EPSG:2227")


# -- 5. geographic grids ----------------------------------------------------------------------
def test_bathymetry_map_refuses_a_geographic_crs():
    with pytest.raises(MapFormatError, match=r"map 'g': its CRS 'WGS 84' is geographic \(degrees\)"):
        BathymetryMap(north=np.arange(3.0), east=np.arange(3.0), depth=np.ones((3, 3)),
                      crs="EPSG:4326", name="g")


def test_lat_lon_netcdf_without_units_is_projected(tmp_path):
    path = _classic(tmp_path / "ll.nc", ydim="lat", xdim="lon",
                    y=45.0 + np.arange(NY) * 0.01, x=-60.0 + np.arange(NX) * 0.01)
    m = read_map(path)
    assert m.crs.startswith("+proj=tmerc")
    assert 0.005 * 111_000 < m.cell_size[0] < 0.011 * 111_000  # metres, not degrees
    lat, lon = to_lonlat(m, 0.0, 0.0)
    assert abs(lat - 45.095) < 0.01 and abs(lon + 59.855) < 0.01


def test_netcdf_x_y_with_a_geographic_crs_given_is_projected(tmp_path):
    path = _classic(tmp_path / "xy.nc", y=45.0 + np.arange(NY) * 0.01, x=-60.0 + np.arange(NX) * 0.01)
    m = read_map(path, crs="EPSG:4326")
    assert m.crs.startswith("+proj=tmerc") and m.cell_size[0] > 100


def test_grid_too_wide_for_one_transverse_mercator_is_refused_with_its_figure(tmp_path):
    lat, lon = np.linspace(10, 12, 5), np.linspace(60, 80, 21)
    depth = np.full((5, 21), 1000.0)
    with pytest.raises(MapFormatError, match=r"wide: the grid spans 20 degrees of longitude; .*scale error "
                                             r"reaches 1\.51% at its edge \(limit 0\.10%\)"):
        project_geographic_grid(lat, lon, depth, name="wide")
    path = tmp_path / "wide.npz"
    np.savez(path, lat=lat, lon=lon, depth_grid=depth)
    with pytest.raises(MapFormatError, match=r"wide\.npz:depth_grid: .*scale error.*max_scale_error="):
        read_map(path, sign="depth")
    assert read_map(path, sign="depth", max_scale_error=0.02).crs.startswith("+proj=tmerc")


def test_geotiff_in_us_survey_feet_reads_in_metres(tmp_path):
    rasterio = pytest.importorskip("rasterio")
    from rasterio.transform import Affine

    ft = 1200 / 3937
    path = tmp_path / "ft.tif"
    profile = {"driver": "GTiff", "height": 4, "width": 5, "count": 1, "dtype": "float32",
               "crs": rasterio.crs.CRS.from_epsg(2227),
               "transform": Affine(10.0, 0.0, 6_000_000.0, 0.0, -10.0, 2_100_040.0)}
    with rasterio.open(path, "w", **profile) as dst:
        dst.write(np.full((4, 5), 100.0, dtype=np.float32), 1)
        dst.update_tags(1, positive="down")
    with pytest.raises(MapFormatError, match=r"ft\.tif: the CRS is in units of 0\.3048\d* m.*pass units="):
        read_map(path)
    with rasterio.open(path, "r+") as dst:
        dst.units = ("US survey foot",)
    m = read_map(path)
    assert m.cell_size == pytest.approx((10 * ft, 10 * ft))
    assert np.allclose(m.depth, 100 * ft)
    assert m.origin == pytest.approx(((2_100_000.0 + 5.0) * ft, (6_000_000.0 + 5.0) * ft))
