"""Readers and writers: every reader on a real file, round trips, and bad input."""

from __future__ import annotations

import os

import numpy as np
import pytest
import xarray as xr

from tangraph.errors import MapFormatError, TangraphError
from tangraph.maps import BathymetryMap, catalogue_path, read_map, read_soundings, write_map

MAPS = catalogue_path()


def small_map(crs=None, origin=(0.0, 0.0)):
    rng = np.random.default_rng(3)
    depth = 40 + rng.normal(size=(12, 15)).cumsum(axis=1)
    depth[3, 4] = np.nan
    return BathymetryMap(north=np.arange(12) * 2.5, east=np.arange(15) * 2.5, depth=depth,
                         crs=crs, origin=origin, name="small")


# -- every reader on a real file -------------------------------------------------------------
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


def test_npz_topobathy_irregular_latitudes_projected():
    m = read_map(MAPS / "topobathy_vancouver.npz")  # variable topo: elevation by name
    raw = np.load(MAPS / "topobathy_vancouver.npz")
    assert np.nanmin(m.depth) >= -raw["topo"].max() - 1e-6
    assert np.nanmax(m.depth) <= -raw["topo"].min() + 1e-6
    assert m.valid_fraction > 0.95


def test_tsh_merimbula_tin():
    m = read_map(MAPS / "merimbula_10785_1.tsh", crs="EPSG:32755", cell=20.0)
    assert m.cell_size == (20.0, 20.0)
    assert 0.15 < m.valid_fraction < 0.5  # a lake: NaN outside the shoreline
    assert 13.0 < np.nanmax(m.depth) < 14.0  # deepest node -13.908 elevation, gridded
    with pytest.raises(TangraphError, match="cell size"):
        read_map(MAPS / "merimbula_10785_1.tsh")


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


# -- round trips -----------------------------------------------------------------------------
@pytest.mark.parametrize("suffix", [".nc", ".tif", ".xyz", ".npz"])
def test_write_read_round_trip(tmp_path, suffix):
    m = small_map(crs="EPSG:32755", origin=(5.9e6, 7.5e5))
    path = write_map(m, tmp_path / f"m{suffix}")
    back = read_map(path, sign="depth" if suffix == ".xyz" else None,
                    crs="EPSG:32755" if suffix == ".xyz" else None)
    atol = 1e-3 if suffix == ".xyz" else 1e-5  # text keeps 3 decimals, GeoTIFF float32
    np.testing.assert_allclose(back.depth, m.depth, atol=atol)
    np.testing.assert_allclose(back.north + back.origin[0], m.north + m.origin[0], atol=1e-6)
    np.testing.assert_allclose(back.east + back.origin[1], m.east + m.origin[1], atol=1e-6)
    assert back.crs == m.crs


def test_write_refuses_to_overwrite_and_leaves_no_temporary(tmp_path):
    m = small_map()
    path = write_map(m, tmp_path / "m.nc")
    before = path.read_bytes()
    with pytest.raises(FileExistsError, match="--force"):
        write_map(m.replace(depth=m.depth + 1), path)
    assert path.read_bytes() == before
    write_map(m.replace(depth=m.depth + 1), path, overwrite=True)
    assert read_map(path).depth[0, 0] == m.depth[0, 0] + 1
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.nc"]
    umask = os.umask(0)
    os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask  # not mkstemp's private 0600


def test_scattered_xyz_is_refused_as_a_grid_and_read_as_soundings(tmp_path):
    rng = np.random.default_rng(0)
    pts = np.column_stack([rng.uniform(0, 100, 50) + 3e5, rng.uniform(0, 50, 50) + 6e6,
                           rng.uniform(10, 20, 50)])
    path = tmp_path / "soundings.xyz"
    np.savetxt(path, pts, header="east north depth")
    with pytest.raises(MapFormatError, match="do not form a full regular grid"):
        read_map(path, sign="depth")
    s = read_soundings(path, sign="depth", crs="EPSG:32755")
    np.testing.assert_allclose(s.points[:, 0] + s.origin[0], pts[:, 1])
    np.testing.assert_allclose(s.points[:, 1] + s.origin[1], pts[:, 0])
    np.testing.assert_allclose(s.points[:, 2], pts[:, 2])


def test_geographic_soundings_are_projected(tmp_path):
    path = tmp_path / "lonlat.csv"
    np.savetxt(path, [[150.0, -37.0, 5.0], [150.001, -37.0, 6.0]], delimiter=",")
    s = read_soundings(path, sign="depth", crs="EPSG:4326")
    # 0.001 deg of longitude at 37 S is about 89 m
    assert np.hypot(*(s.points[1, :2] - s.points[0, :2])) == pytest.approx(88.9, abs=0.3)


# -- bad input -------------------------------------------------------------------------------
def test_missing_and_unreadable_files_are_named(tmp_path):
    with pytest.raises(FileNotFoundError, match="nowhere.nc"):
        read_map(tmp_path / "nowhere.nc")
    bad = tmp_path / "garbage.nc"
    bad.write_bytes(b"not a netcdf file at all")
    with pytest.raises(MapFormatError, match="garbage.nc: not a readable NetCDF"):
        read_map(bad)
    bad_tif = tmp_path / "garbage.tif"
    bad_tif.write_bytes(b"II*\x00 nonsense")
    with pytest.raises(MapFormatError, match="garbage.tif"):
        read_map(bad_tif)
    with pytest.raises(MapFormatError, match="suffix '.dat'"):
        read_map(tmp_path / "x.dat")


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
