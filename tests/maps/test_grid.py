"""BathymetryMap and its kernels: deterministic cases, the numpy reference, bad input."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from tangraph.errors import MapFormatError, TangraphError
from tangraph.maps import BathymetryMap
from tests.maps.reference import interpolate as reference


def plane(a=100.0, gn=0.1, ge=-0.05, shape=(20, 30), cell=(5.0, 4.0)):
    north = 10.0 + cell[0] * np.arange(shape[0])
    east = -50.0 + cell[1] * np.arange(shape[1])
    nn, ee = np.meshgrid(north, east, indexing="ij")
    return BathymetryMap(north=north, east=east, depth=a + gn * nn + ge * ee, name="plane")


def rough(seed=0, shape=(60, 50), nan_fraction=0.02):
    rng = np.random.default_rng(seed)
    depth = 50 + rng.normal(size=shape).cumsum(axis=0).cumsum(axis=1) * 0.1
    depth[rng.random(shape) < nan_fraction] = np.nan
    return BathymetryMap(north=np.arange(shape[0]) * 2.0, east=100 + np.arange(shape[1]) * 3.0,
                         depth=depth)


# -- deterministic cases -------------------------------------------------------------------
@pytest.mark.parametrize("order", [1, 3])
def test_plane_is_reproduced_exactly_with_its_gradient(order):
    m = plane()
    rng = np.random.default_rng(1)
    qn = rng.uniform(m.north[0], m.north[-1], 500)
    qe = rng.uniform(m.east[0], m.east[-1], 500)
    np.testing.assert_allclose(m.depth_at(qn, qe, order=order), 100 + 0.1 * qn - 0.05 * qe, atol=1e-9)
    grad = m.gradient_at(qn, qe, order=order)
    np.testing.assert_allclose(grad[:, 0], 0.1, atol=1e-9)
    np.testing.assert_allclose(grad[:, 1], -0.05, atol=1e-9)


@pytest.mark.parametrize("order", [1, 3])
def test_cell_centres_return_the_stored_depth(order):
    m = rough(nan_fraction=0)
    nn, ee = np.meshgrid(m.north, m.east, indexing="ij")
    np.testing.assert_allclose(m.depth_at(nn, ee, order=order), m.depth, atol=1e-9)


@pytest.mark.parametrize("order", [1, 3])
def test_off_the_map_is_nan_never_clamped(order):
    m = plane()
    n_lo, n_hi, e_lo, e_hi = m.extent
    qn = np.array([n_lo - 1e-6, n_hi + 1e-6, n_lo, n_hi, np.nan, 20.0])
    qe = np.array([e_lo, e_lo, e_lo - 1e-6, e_hi + 1e-6, 0.0, np.nan])
    assert np.all(np.isnan(m.depth_at(qn, qe, order=order)))
    assert np.all(np.isnan(m.gradient_at(qn, qe, order=order)))
    # the corners themselves are on the map
    assert np.isfinite(m.depth_at(n_hi, e_hi, order=order))


def test_nan_cell_poisons_bilinear_neighbourhood_only():
    depth = np.full((5, 5), 10.0)
    depth[2, 2] = np.nan
    m = BathymetryMap(north=np.arange(5.0), east=np.arange(5.0), depth=depth)
    assert np.isnan(m.depth_at(1.5, 1.5))
    assert np.isnan(m.depth_at(2.5, 2.9))
    assert m.depth_at(0.5, 0.5) == 10.0
    assert m.depth_at(3.1, 0.2) == 10.0
    # bicubic falls back to bilinear next to the NaN, so it is finite where bilinear is
    assert m.depth_at(0.5, 0.5, order=3) == 10.0


def test_shapes_broadcast_and_scalars_stay_scalar():
    m = plane()
    assert np.ndim(m.depth_at(20.0, 0.0)) == 0
    assert m.depth_at(np.full((3, 4), 20.0), 0.0).shape == (3, 4)
    assert m.gradient_at(np.full((3, 4), 20.0), np.zeros((3, 4))).shape == (3, 4, 2)


# -- against the numpy reference -----------------------------------------------------------
@pytest.mark.parametrize("order", [1, 3])
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_kernel_matches_numpy_reference(order, seed):
    m = rough(seed=seed)
    rng = np.random.default_rng(seed + 10)
    n_lo, n_hi, e_lo, e_hi = m.extent
    # inside, outside, on the edges and exactly on cell centres
    qn = np.concatenate([rng.uniform(n_lo - 5, n_hi + 5, 4000), m.north[[0, -1, 3]]])
    qe = np.concatenate([rng.uniform(e_lo - 5, e_hi + 5, 4000), m.east[[0, -1, 7]]])
    value_ref, grad_ref = reference(m.north, m.east, m.depth, qn, qe, order=order)
    np.testing.assert_allclose(m.depth_at(qn, qe, order=order), value_ref, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(m.gradient_at(qn, qe, order=order), grad_ref, rtol=1e-10, atol=1e-9)
    assert np.isnan(value_ref).sum() > 100  # the comparison covered NaN cases


@pytest.mark.parametrize("order", [1, 3])
def test_gradient_matches_finite_differences(order):
    m = rough(nan_fraction=0)
    rng = np.random.default_rng(5)
    qn = rng.uniform(m.north[2], m.north[-3], 300)
    qe = rng.uniform(m.east[2], m.east[-3], 300)
    h = 1e-6
    fd_n = (m.depth_at(qn + h, qe, order=order) - m.depth_at(qn - h, qe, order=order)) / (2 * h)
    fd_e = (m.depth_at(qn, qe + h, order=order) - m.depth_at(qn, qe - h, order=order)) / (2 * h)
    grad = m.gradient_at(qn, qe, order=order)
    np.testing.assert_allclose(grad[:, 0], fd_n, atol=1e-5)
    np.testing.assert_allclose(grad[:, 1], fd_e, atol=1e-5)


def test_bicubic_is_more_accurate_than_bilinear_on_a_smooth_surface():
    north = np.arange(0, 200.0, 10)
    east = np.arange(0, 200.0, 10)
    f = lambda n, e: 50 + 5 * np.sin(n / 30) * np.cos(e / 40)  # noqa: E731
    nn, ee = np.meshgrid(north, east, indexing="ij")
    m = BathymetryMap(north=north, east=east, depth=f(nn, ee))
    rng = np.random.default_rng(0)
    qn, qe = rng.uniform(20, 170, (2, 2000))
    err1 = np.abs(m.depth_at(qn, qe, order=1) - f(qn, qe)).max()
    err3 = np.abs(m.depth_at(qn, qe, order=3) - f(qn, qe)).max()
    assert err3 < err1 / 4


# -- geometry and derived maps -------------------------------------------------------------
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


# -- bad input -----------------------------------------------------------------------------
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
