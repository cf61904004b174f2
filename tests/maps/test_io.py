"""Reading and writing maps (tangraph.maps.io): round trips through every format by its suffix,
with the map's error; no clobbering; NPZ, TIN and x y z text files (grids with the std as a
fourth column, scattered soundings); missing and unreadable files named."""

from __future__ import annotations

import os

import numpy as np
import pyproj
import pytest

from tangraph.errors import MapFormatError, TangraphError
from tangraph.maps import BathymetryMap, catalogue_path, read_map, read_soundings, write_map
from tests.maps.io_cases import assert_same_error, error_map

MAPS = catalogue_path()


def small_map(crs=None, origin=(0.0, 0.0)):
    rng = np.random.default_rng(3)
    depth = 40 + rng.normal(size=(12, 15)).cumsum(axis=1)
    depth[3, 4] = np.nan
    return BathymetryMap(north=np.arange(12) * 2.5, east=np.arange(15) * 2.5, depth=depth,
                         crs=crs, origin=origin, name="small")


# -- real files --------------------------------------------------------------------------------
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


# -- round trips -------------------------------------------------------------------------------
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


@pytest.mark.parametrize("suffix", [".nc", ".tif", ".npz", ".xyz", ".bag"])
def test_the_error_layer_round_trips(tmp_path, suffix):
    m = error_map()
    back = read_map(write_map(m, tmp_path / f"m{suffix}"), **({"crs": m.crs} if suffix == ".xyz" else {}))
    exact = suffix in (".nc", ".npz")
    assert_same_error(back, m, atol=0.0 if exact else 1e-3 if suffix == ".xyz" else 1e-5)
    assert pyproj.CRS(back.crs).equals(pyproj.CRS(m.crs))
    assert read_map(tmp_path / f"m{suffix}", uncertainty=False,
                    **({"crs": m.crs} if suffix == ".xyz" else {})).depth_std is None


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


# -- x y z text --------------------------------------------------------------------------------
def test_xyz_carries_the_std_as_a_fourth_column(tmp_path):
    m = error_map()
    path = write_map(m, tmp_path / "m.xyz")
    header = path.read_text().splitlines()[0]
    assert "columns: east north depth depth_std" in header and "correlation_length_m 35.5;" in header
    assert np.loadtxt(path).shape == (m.depth.size, 4)
    data = np.loadtxt(path)[:, :3]  # a foreign file's fourth column is not read as a std
    np.savetxt(tmp_path / "foreign.xyz", np.column_stack([data, np.ones(len(data))]))
    assert read_map(tmp_path / "foreign.xyz", sign="depth", crs=m.crs).depth_std is None


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
    # UTM metres said to be degrees: refused naming the option, not a PROJ error about lat_0
    np.savetxt(path, [[363463.7, 5800997.7, 5.0], [363426.9, 5800906.0, 6.0]], delimiter=",")
    with pytest.raises(MapFormatError, match=r"lonlat.csv: crs=.EPSG:4326. is in degrees, but the points "
                                             r"reach latitude 5,800,998 and longitude 363,464"):
        read_soundings(path, sign="depth", crs="EPSG:4326")


# -- bad input ---------------------------------------------------------------------------------
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


@pytest.mark.parametrize("suffix", [".nc", ".tif", ".npz"])
def test_the_tail_of_the_map_error_round_trips(tmp_path, suffix):
    m = error_map().replace(error_dof=1.9)
    back = read_map(write_map(m, tmp_path / f"m{suffix}"))
    assert back.error_dof == 1.9
    assert read_map(tmp_path / f"m{suffix}", uncertainty=False).error_dof is None
    assert read_map(write_map(error_map(), tmp_path / f"plain{suffix}")).error_dof is None


def test_a_bad_tail_of_the_map_error_is_refused_naming_the_file(tmp_path):
    import xarray as xr

    path = write_map(error_map().replace(error_dof=1.9), tmp_path / "m.nc")
    with xr.open_dataset(path) as ds:
        bad = ds.load()
    bad["depth"].attrs["error_student_t_dof"] = -2.0
    bad.to_netcdf(tmp_path / "bad.nc")
    with pytest.raises(MapFormatError, match=r"bad.nc.*'error_student_t_dof'.*> 0, got -2.0"):
        read_map(tmp_path / "bad.nc")


@pytest.mark.parametrize("suffix", [".nc", ".tif", ".npz"])
def test_the_drift_of_the_map_error_round_trips(tmp_path, suffix):
    m = error_map().replace(error_drift=(0.196, 172.0))
    back = read_map(write_map(m, tmp_path / f"m{suffix}"))
    assert back.error_drift == (0.196, 172.0)
    assert back.error_summary()["error_drift"] == {"std_m": 0.196, "time_s": 172.0}
    assert read_map(tmp_path / f"m{suffix}", uncertainty=False).error_drift is None
    assert read_map(write_map(error_map(), tmp_path / f"plain{suffix}")).error_drift is None
    without_std = m.replace(depth_std=None)  # a drift needs no per-cell error to be stated
    assert read_map(write_map(without_std, tmp_path / f"bare{suffix}")).error_drift == (0.196, 172.0)


@pytest.mark.parametrize("value, message", [
    ((0.2,), r"error_drift must be two numbers \(std in m, time in s\), got \(0.2,\)"),
    ((-0.2, 100.0), "error_drift std must be a finite std > 0 m, got -0.2"),
    ((0.2, 0.0), "error_drift time must be a finite time > 0 s, got 0.0"),
    ((float("nan"), 100.0), "error_drift std must be a finite std > 0 m, got nan"),
    ("a b", "error_drift std must be a finite std > 0 m, got 'a'"),
])
def test_a_bad_drift_of_the_map_error_is_refused_naming_the_map(value, message):
    with pytest.raises(MapFormatError, match=r"map 'prior': " + message):
        error_map().replace(error_drift=value)


def test_a_bad_drift_in_a_file_is_refused_naming_the_file_and_attribute(tmp_path):
    import xarray as xr

    path = write_map(error_map().replace(error_drift=(0.2, 100.0)), tmp_path / "m.nc")
    with xr.open_dataset(path) as ds:
        bad = ds.load()
    bad["depth"].attrs["error_drift_std_m_time_s"] = np.array([0.2, -5.0])
    bad.to_netcdf(tmp_path / "bad.nc")
    with pytest.raises(MapFormatError, match=r"bad.nc.*'error_drift_std_m_time_s'.*time must be a finite "
                                             r"time > 0 s, got -5.0"):
        read_map(tmp_path / "bad.nc")
