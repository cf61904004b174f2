"""BathymetryMap (tangraph.maps.grid): query shapes, geometry and derived maps, bad input; and the
map's error as data: ``depth_std`` and ``correlation_length``, their queries, and the maps made
from one that has them."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from tangraph.errors import MapFormatError, TangraphError
from tangraph.maps import BathymetryMap
from tests.maps.grid_cases import plane, rough
from tests.maps.reference import interpolate as reference


def mapped(seed=0, shape=(30, 40), nan_fraction=0.05, correlation_length=40.0):
    """A rough map with NaN holes and a std layer that varies from cell to cell."""
    rng = np.random.default_rng(seed)
    depth = 50 + rng.normal(size=shape).cumsum(axis=0) * 0.2
    depth[rng.random(shape) < nan_fraction] = np.nan
    std = 0.1 + rng.random(shape)
    return BathymetryMap(north=np.arange(shape[0]) * 5.0, east=200 + np.arange(shape[1]) * 4.0,
                         depth=depth, crs="EPSG:32633", origin=(6e6, 5e5), name="rough",
                         depth_std=std, correlation_length=correlation_length)


# -- queries -----------------------------------------------------------------------------------
def test_shapes_broadcast_and_scalars_stay_scalar():
    m = plane()
    assert np.ndim(m.depth_at(20.0, 0.0)) == 0
    assert m.depth_at(np.full((3, 4), 20.0), 0.0).shape == (3, 4)
    assert m.gradient_at(np.full((3, 4), 20.0), np.zeros((3, 4))).shape == (3, 4, 2)


# -- geometry and derived maps -----------------------------------------------------------------
def test_cell_size_extent_contains():
    m = plane()
    assert m.cell_size == (5.0, 4.0)
    assert m.extent == (10.0, 105.0, -50.0, 66.0)
    assert m.contains([20.0, 200.0], [0.0, 0.0]).tolist() == [True, False]


def test_cells_under_points_are_the_nearest_cells_on_the_grid():
    m = plane()  # north 10, 15, ... 105; east -50, -46, ... 66
    under = m.cells_under([11.0, 12.4, 14.0, 500.0, np.nan], [-50.0, -47.9, -48.1, 0.0, 0.0])
    assert under.shape == m.shape
    assert sorted(zip(*np.nonzero(under), strict=True)) == [(0, 0), (0, 1), (1, 0)]
    i, j = m.nearest_cells([[11.0, 12.4], [14.0, 500.0]], [[-50.0, -47.9], [-48.1, 0.0]])
    assert i.shape == (2, 2) and i.dtype == np.int64
    assert i.tolist() == [[0, 0], [1, -1]] and j.tolist() == [[0, 1], [0, -1]]
    assert m.nearest_cells(np.nan, 0.0) == (-1, -1) and m.nearest_cells(12.6, 66.0 + 1.9) == (1, 29)


def test_crop_keeps_cells_inside_bounds():
    m = plane()
    c = m.crop(north=(20, 40), east=(-42, -30))
    np.testing.assert_array_equal(c.north, [20, 25, 30, 35, 40])
    np.testing.assert_array_equal(c.east, [-42, -38, -34, -30])
    np.testing.assert_array_equal(c.depth, m.depth[2:7, 2:6])
    with pytest.raises(TangraphError, match="north range"):
        m.crop(north=(1000, 2000))


def test_resample_finer_is_exact_on_a_plane_and_coarser_averages():
    m = plane()
    fine = m.resample(1.0)
    assert fine.cell_size == (1.0, 1.0)
    nn, ee = np.meshgrid(fine.north, fine.east, indexing="ij")
    np.testing.assert_allclose(fine.depth, 100 + 0.1 * nn - 0.05 * ee, atol=1e-9)
    noisy = rough(nan_fraction=0, shape=(200, 200))
    coarse = noisy.resample(30.0)
    assert coarse.cell_size == (30.0, 30.0)
    # box-averaged: much smoother than point samples of the noisy grid
    assert np.nanstd(np.diff(coarse.depth, axis=0)) < np.nanstd(np.diff(noisy.depth, axis=0)) * 15


def test_xarray_round_trip_and_elevation_sign():
    m = rough().replace(crs="EPSG:32755", origin=(5.9e6, 7.5e5), name="r")
    back = BathymetryMap.from_xarray(m.to_xarray())
    np.testing.assert_array_equal(back.depth, m.depth)
    np.testing.assert_array_equal(back.north, m.north)
    assert (back.crs, back.origin, back.name) == (m.crs, m.origin, "r")
    da = m.to_xarray()[::-1]  # descending north
    da = da.copy(data=-da.values)
    da.attrs["positive"] = "up"
    np.testing.assert_array_equal(BathymetryMap.from_xarray(da).depth, m.depth)


def test_map_copies_and_freezes_its_inputs():
    depth = np.ones((3, 3))
    m = BathymetryMap(north=np.arange(3.0), east=np.arange(3.0), depth=depth)
    depth[0, 0] = 99
    assert m.depth[0, 0] == 1
    with pytest.raises(ValueError, match="read-only"):
        m.depth[0, 0] = 5


# -- bad input ---------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("north", "east", "depth", "message"),
    [
        ([0, 2, 1], [0, 1], np.ones((3, 2)), "north is not strictly ascending"),
        ([0, 1, 3], [0, 1], np.ones((3, 2)), "north is not regularly spaced"),
        ([0, 1], [0, 1, 2], np.ones((2, 2)), "depth has shape"),
        ([0], [0, 1], np.ones((1, 2)), "at least 2"),
        ([0, 1], [0, np.nan], np.ones((2, 2)), "east holds non-finite"),
        ([0, 1], [0, 1], np.full((2, 2), np.nan), "all NaN"),
        ([0, 1], [0, 1], np.array([[1, np.inf], [1, 1]]), "infinite"),
    ],
)
def test_bad_grids_are_refused_with_the_problem_named(north, east, depth, message):
    with pytest.raises(MapFormatError, match=message):
        BathymetryMap(north=north, east=east, depth=depth, name="bad")


def test_bad_queries_are_refused():
    m = plane()
    with pytest.raises(TangraphError, match=r"shapes \(3,\) and \(4,\)"):
        m.depth_at(np.zeros(3), np.zeros(4))
    with pytest.raises(TangraphError, match="order must be"):
        m.depth_at(0.0, 0.0, order=2)
    with pytest.raises(MapFormatError, match="positive"):
        BathymetryMap.from_xarray(xr.DataArray(np.ones((2, 2)), dims=("north", "east"),
                                               coords={"north": [0, 1], "east": [0, 1]}))


# -- the map's error: the fields ---------------------------------------------------------------
def test_depth_std_is_copied_read_only_and_nan_over_no_data():
    m = mapped()
    std = np.full(m.shape, 0.5)
    e = BathymetryMap(m.north, m.east, m.depth, depth_std=std, correlation_length=12)
    std[0, 0] = 99.0  # the caller's array does not reach the map
    assert not e.depth_std.flags.writeable and e.depth_std.dtype == np.float64
    np.testing.assert_array_equal(np.isnan(e.depth_std), np.isnan(m.depth))  # finite std over NaN depth: NaN
    assert np.nanmax(e.depth_std) == 0.5
    assert e.correlation_length == 12.0 and isinstance(e.correlation_length, float)
    plain = BathymetryMap(m.north, m.east, m.depth)
    assert plain.depth_std is None and plain.correlation_length is None and plain.error_summary() == {}


def test_repr_mentions_the_error_layer():
    text = repr(mapped())
    assert "depth_std=[" in text and "correlation_length=40 m" in text
    assert "depth_std" not in repr(mapped().replace(depth_std=None, correlation_length=None))


DIAGONAL = np.eye(3, 4) > 0


@pytest.mark.parametrize(("std", "match"), [
    (np.full((3, 5), 0.1), r"map 'bad': depth_std has shape \(3, 5\), expected the depth's \(3, 4\)"),
    (np.where(DIAGONAL, -0.2, 0.1), r"map 'bad': depth_std holds 3 negative value\(s\) \(e\.g\. -0\.2 m"),
    (np.where(DIAGONAL, np.inf, 0.1), r"map 'bad': depth_std holds 3 infinite value"),
    (np.where(DIAGONAL, np.nan, 0.1), r"map 'bad': depth_std is NaN in 3 cell\(s\) where depth holds data"),
])
def test_bad_depth_std_is_refused_in_one_line(std, match):
    with pytest.raises(MapFormatError, match=match) as info:
        BathymetryMap(north=[0.0, 1, 2], east=[0.0, 1, 2, 3], depth=np.ones((3, 4)), name="bad",
                      depth_std=std)
    assert "\n" not in str(info.value)


@pytest.mark.parametrize("length", [0.0, -5.0, np.inf, np.nan, "abc", True])
def test_bad_correlation_length_is_refused(length):
    with pytest.raises(MapFormatError, match=r"map 'bad': correlation_length must be a finite length > 0 m"):
        BathymetryMap(north=[0.0, 1], east=[0.0, 1], depth=np.ones((2, 2)), name="bad",
                      correlation_length=length)


def test_std_on_no_data_only_is_not_an_error():
    depth = np.array([[1.0, np.nan], [1.0, 1.0]])
    m = BathymetryMap(north=[0.0, 1], east=[0.0, 1], depth=depth, depth_std=[[0.1, np.nan], [0.1, 0.1]])
    assert np.isnan(m.depth_std[0, 1])


# -- the map's error: queries ------------------------------------------------------------------
def test_depth_std_at_matches_the_numpy_reference_and_is_nan_where_depth_is():
    m = mapped(seed=3)
    rng = np.random.default_rng(4)
    qn = rng.uniform(-10, m.north[-1] + 10, 4000)
    qe = rng.uniform(m.east[0] - 10, m.east[-1] + 10, 4000)
    expected, _ = reference(m.north, m.east, np.asarray(m.depth_std), qn, qe, order=1, with_gradient=False)
    got = m.depth_std_at(qn, qe)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12, equal_nan=True)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(m.depth_at(qn, qe)))
    assert np.isnan(got).any() and np.isfinite(got).any()  # the case tests both


def test_depth_std_at_keeps_the_query_shape_and_is_exact_on_cells():
    m = mapped(nan_fraction=0.0)
    assert m.depth_std_at(np.zeros((2, 3)), 200.0).shape == (2, 3)
    i, j = 7, 11
    assert m.depth_std_at(m.north[i], m.east[j]) == pytest.approx(m.depth_std[i, j], abs=1e-12)


def test_depth_std_at_without_a_layer_says_so():
    with pytest.raises(TangraphError, match=r"map 'rough' has no depth_std"):
        mapped().replace(depth_std=None).depth_std_at(0.0, 200.0)


# -- the map's error: new maps from this one ---------------------------------------------------
def test_crop_carries_the_error_layer():
    m = mapped()
    c = m.crop(north=(20, 80), east=(220, 300))
    rows = (m.north >= 20) & (m.north <= 80)
    cols = (m.east >= 220) & (m.east <= 300)
    np.testing.assert_array_equal(c.depth_std, m.depth_std[np.ix_(rows, cols)])
    assert c.correlation_length == m.correlation_length


def test_resample_finer_interpolates_the_std_bilinearly():
    m = mapped(nan_fraction=0.0)
    r = m.resample(2.5, order=3)
    nn, ee = np.meshgrid(r.north, r.east, indexing="ij")
    np.testing.assert_allclose(r.depth_std, m.depth_std_at(nn, ee), atol=1e-12)
    assert np.nanmin(r.depth_std) >= np.min(m.depth_std) and r.correlation_length == 40.0


def test_resample_coarser_averages_the_std_and_keeps_its_nan_with_depth():
    m = mapped(seed=5, nan_fraction=0.1)
    r = m.resample(10.0)
    np.testing.assert_array_equal(np.isnan(r.depth_std), np.isnan(r.depth))
    assert np.nanmin(m.depth_std) <= np.nanmin(r.depth_std)
    assert np.nanmax(r.depth_std) <= np.nanmax(m.depth_std)
    flat = mapped(nan_fraction=0.0).replace(depth_std=np.full((30, 40), 0.7))
    np.testing.assert_allclose(flat.resample(20.0).depth_std, 0.7)


def test_replace_keeps_the_layer_and_refuses_a_new_shape_without_one():
    m = mapped()
    deeper = m.replace(depth=m.depth + 1)
    assert deeper.depth_std is m.depth_std or np.array_equal(deeper.depth_std, m.depth_std, equal_nan=True)
    with pytest.raises(TangraphError, match=r"changes shape \(30, 40\) -> \(2, 2\) but depth_std was not"):
        m.replace(north=[0.0, 1], east=[0.0, 1], depth=np.ones((2, 2)))
    small = m.replace(north=[0.0, 1], east=[0.0, 1], depth=np.ones((2, 2)), depth_std=None)
    assert small.depth_std is None and small.correlation_length == 40.0
    filled = np.where(np.isnan(m.depth), 50.0, m.depth)  # new data where the std is NaN
    with pytest.raises(MapFormatError, match=r"depth_std is NaN in \d+ cell\(s\) where depth holds data"):
        m.replace(depth=filled)


def test_dataset_round_trip_and_descending_coordinates():
    m = mapped()
    ds = m.to_dataset()
    assert ds["depth"].attrs["ancillary_variables"] == "depth_std"
    assert ds["depth_std"].attrs["units"] == "m"
    back = BathymetryMap.from_xarray(ds)
    np.testing.assert_array_equal(back.depth_std, m.depth_std)
    assert back.correlation_length == 40.0 and back.crs == m.crs and back.origin == m.origin
    flipped = BathymetryMap.from_xarray(ds.isel(north=slice(None, None, -1), east=slice(None, None, -1)))
    np.testing.assert_array_equal(flipped.depth_std, m.depth_std)
    np.testing.assert_array_equal(flipped.depth, m.depth)
    assert BathymetryMap.from_xarray(m.to_xarray()).depth_std is None  # the DataArray: depth only
    assert "depth_std" not in mapped().replace(depth_std=None).to_dataset()


def test_error_summary():
    m = mapped()
    s = m.error_summary()
    assert s["depth_std_m"]["median"] == pytest.approx(np.nanmedian(m.depth_std))
    assert s["depth_std_m"]["max"] == pytest.approx(np.nanmax(m.depth_std))
    assert s["correlation_length_m"] == 40.0
