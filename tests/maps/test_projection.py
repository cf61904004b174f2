"""The projection step: geographic grids to a local metric frame and back."""

from __future__ import annotations

import numpy as np
import pyproj
import pytest

from tangraph.maps import from_lonlat, project_geographic_grid, to_lonlat


def linear_field(lat, lon):
    return 1000 + 200 * (lat - 45) - 100 * (lon - 10)


def geographic_grid(lat_step=0.02, lon_step=0.03):
    lat = np.arange(44.5, 45.5 + 1e-9, lat_step)
    lon = np.arange(9.0, 11.0 + 1e-9, lon_step)
    return lat, lon, linear_field(*np.meshgrid(lat, lon, indexing="ij"))


def test_projected_grid_samples_the_geographic_grid_at_the_right_places():
    lat, lon, depth = geographic_grid()
    m = project_geographic_grid(lat, lon, depth, name="g")
    nn, ee = np.meshgrid(m.north, m.east, indexing="ij")
    q_lat, q_lon = to_lonlat(m, nn, ee)
    valid = np.isfinite(m.depth)
    assert valid.mean() > 0.9
    # bilinear interpolation of a field linear in lat/lon is exact
    np.testing.assert_allclose(m.depth[valid], linear_field(q_lat, q_lon)[valid], atol=1e-6)
    # outside the geographic grid: NaN
    assert np.all((q_lat[~valid] < lat[0]) | (q_lat[~valid] > lat[-1]) | (q_lon[~valid] < lon[0])
                  | (q_lon[~valid] > lon[-1]))


def test_cell_size_is_metres_on_the_ground():
    lat, lon, depth = geographic_grid()
    m = project_geographic_grid(lat, lon, depth, cell=500.0)
    lat_a, lon_a = to_lonlat(m, 0.0, 0.0)
    lat_b, lon_b = to_lonlat(m, 0.0, 500.0 * 20)
    _, _, distance = pyproj.Geod(ellps="WGS84").inv(lon_a, lat_a, lon_b, lat_b)
    assert distance == pytest.approx(10000.0, rel=1e-4)


def test_longitudes_0_360_and_lonlat_round_trip():
    lat, lon, depth = geographic_grid()
    east_of_greenwich = project_geographic_grid(lat, lon, depth)
    shifted = project_geographic_grid(lat, lon + 360.0, depth)
    np.testing.assert_allclose(shifted.depth, east_of_greenwich.depth, equal_nan=True)
    n, e = from_lonlat(east_of_greenwich, [45.1, 44.9], [10.2, 9.5])
    back_lat, back_lon = to_lonlat(east_of_greenwich, n, e)
    np.testing.assert_allclose(back_lat, [45.1, 44.9], atol=1e-9)
    np.testing.assert_allclose(back_lon, [10.2, 9.5], atol=1e-9)
