"""Maps for the readers' and writers' tests: one with an error layer (a std that varies, NaN holes,
a correlation length) and the check that a map read back has it; rasters as GDAL writes them (in
a Lambert conformal conic without an EPSG code, a no-data cell), tangraph maps to write, and the
check that a map holds a raster on its cell centres."""

from __future__ import annotations

import numpy as np
import pyproj
import pytest

from tangraph.maps import BathymetryMap

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


def assert_placed(m, data, crs_wkt):
    """The map holds ``data`` (north-up rows) on cell centres of the test geotransform."""
    expected = np.where(data == -9999.0, np.nan, data)[::-1].astype(float)
    np.testing.assert_array_equal(m.depth, expected)
    np.testing.assert_allclose(m.east + m.origin[1], WEST + (np.arange(NX) + 0.5) * CELL, rtol=0, atol=1e-9)
    np.testing.assert_allclose(m.north + m.origin[0], TOP - (np.arange(NY)[::-1] + 0.5) * CELL,
                               rtol=0, atol=1e-9)
    assert pyproj.CRS(m.crs).equals(pyproj.CRS(crs_wkt))


def tangraph_map(crs, origin=(5_900_123.5, 750_456.25)):
    rng = np.random.default_rng(3)
    depth = 40 + rng.normal(size=(12, 15)).cumsum(axis=1)
    depth[3, 4] = np.nan
    return BathymetryMap(north=100 + np.arange(12) * 2.5, east=-50 + np.arange(15) * 2.5, depth=depth,
                         crs=crs, origin=origin, name="small")
