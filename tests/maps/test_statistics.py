"""Terrain statistics: exact values on planes and flats, recovery of known noise, NaN, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.maps import BathymetryMap
from tangraph.maps.statistics import (
    RELATIVE_EPSILON,
    crlb,
    fisher_information,
    region_entropy,
    roughness,
    slope,
    terrain_entropy,
    terrain_std,
    window_information,
)

GN, GE = 0.08, -0.05  # gradient of the test plane, (d/dnorth, d/deast)


def plane(shape=(30, 40), cell=(4.0, 5.0), noise=None, a=1000.0):
    north = 100.0 + cell[0] * np.arange(shape[0])
    east = -60.0 + cell[1] * np.arange(shape[1])
    depth = a + GN * north[:, None] + GE * east[None, :]
    if noise is not None:
        depth = depth + noise
    return BathymetryMap(north=north, east=east, depth=depth, name="plane")


def flat(shape=(12, 14), depth=850.0):
    return BathymetryMap(north=np.arange(shape[0]) * 3.0, east=np.arange(shape[1]) * 3.0,
                         depth=np.full(shape, depth))


def interior(a, r):
    return a[r:-r, r:-r]


def with_nan(m, i, j):
    depth = np.array(m.depth)
    depth[i, j] = np.nan
    return m.replace(depth=depth)


# -- slope, roughness, spread ----------------------------------------------------------------
@pytest.mark.parametrize("order", [1, 3])
def test_slope_of_a_plane_is_atan_of_its_gradient(order):
    s = slope(plane(), order=order)
    np.testing.assert_allclose(s, np.degrees(np.arctan(np.hypot(GN, GE))), rtol=1e-10)


@pytest.mark.parametrize("window", [3, 7])
def test_plane_has_zero_roughness(window):
    r = roughness(plane(), window)
    assert np.all(np.isnan(r[: window // 2]))  # windows leaving the map
    assert np.nanmax(np.abs(r)) < 1e-9
    assert np.sum(np.isfinite(r)) == (30 - window + 1) * (40 - window + 1)


def test_roughness_recovers_white_noise_on_a_plane():
    s = 0.7
    noise = np.random.default_rng(11).normal(0.0, s, (120, 120))
    r = roughness(plane((120, 120), noise=noise), 9)
    n = np.sum(np.isfinite(r)) / 81  # roughly independent windows
    # Each window's variance estimate has relative std sqrt(2 / 78); the mean of ~n of them.
    assert np.nanmean(r**2) == pytest.approx(s**2, rel=4 * np.sqrt(2 / 78 / n))
    # The plain local std also sees the plane: s^2 plus the plane's spread over the window.
    u = np.arange(9.0) - 4
    plane_var = ((GN * 4.0) ** 2 + (GE * 5.0) ** 2) * np.sum(u**2) * 9 / 80
    std = terrain_std(plane((120, 120), noise=noise), 9)
    assert np.nanmean(std**2) == pytest.approx(s**2 + plane_var, rel=4 * np.sqrt(2 / 80 / n))


def test_roughness_matches_a_direct_least_squares_fit():
    rng = np.random.default_rng(3)
    m = plane((9, 11), noise=rng.normal(0.0, 2.0, (9, 11)))
    i, j, w = 5, 4, 5
    block = m.depth[i - 2 : i + 3, j - 2 : j + 3].ravel()
    u, v = np.meshgrid(np.arange(w), np.arange(w), indexing="ij")
    design = np.column_stack([np.ones(w * w), u.ravel(), v.ravel()])
    residual = block - design @ np.linalg.lstsq(design, block, rcond=None)[0]
    assert roughness(m, w)[i, j] == pytest.approx(np.sqrt(residual @ residual / (w * w - 3)))
    assert terrain_std(m, w)[i, j] == pytest.approx(np.std(block, ddof=1))


def test_terrain_std_of_a_flat_map_is_zero():
    assert np.nanmax(terrain_std(flat(), 5)) < 1e-9


@pytest.mark.parametrize("stat", [roughness, terrain_std, terrain_entropy])
def test_nan_cell_spoils_exactly_the_windows_that_hold_it(stat):
    m = with_nan(plane(noise=np.random.default_rng(0).normal(0, 1, (30, 40))), 10, 20)
    out = stat(m, 5)
    spoiled = np.isnan(out)
    expected = np.zeros(m.shape, bool)
    expected[8:13, 18:23] = True
    expected[:2], expected[-2:], expected[:, :2], expected[:, -2:] = True, True, True, True
    np.testing.assert_array_equal(spoiled, expected)


# -- entropy ---------------------------------------------------------------------------------
@pytest.mark.parametrize("relative", [False, True])
@pytest.mark.parametrize("window", [3, 5, 9])
def test_entropy_of_a_flat_map_is_log_of_the_window_cells(window, relative):
    h = terrain_entropy(flat(), window, relative=relative)
    np.testing.assert_allclose(interior(h, window // 2), np.log(window**2), rtol=1e-13)
    assert region_entropy(flat(), relative=relative) == pytest.approx(np.log(12 * 14), rel=1e-13)


def test_entropy_is_lower_on_rough_terrain_than_on_flat():
    rng = np.random.default_rng(4)
    rough = plane(noise=rng.normal(0.0, 50.0, (30, 40)), a=300.0)
    gentle = plane(noise=rng.normal(0.0, 0.5, (30, 40)), a=300.0)
    ln_n = np.log(49)
    h_rough, h_gentle = (interior(terrain_entropy(m, 7), 3) for m in (rough, gentle))
    assert np.all(h_gentle < ln_n)
    assert np.all(h_rough < h_gentle)
    assert np.all(interior(terrain_entropy(rough, 7, relative=True), 3) < ln_n)


def test_entropy_matches_the_definition():
    rng = np.random.default_rng(5)
    m = plane((8, 8), noise=rng.normal(0.0, 3.0, (8, 8)))
    h = m.depth[1:6, 2:7].ravel()
    for relative, values in ((False, h), (True, h - h.min() + RELATIVE_EPSILON)):
        p = values / values.sum()
        expected = -np.sum(p * np.log(p))
        assert terrain_entropy(m, 5, relative=relative)[3, 4] == pytest.approx(expected)
    region = region_entropy(m, north=m.north[[1, 5]], east=m.east[[2, 6]])
    assert region == pytest.approx(-np.sum(h / h.sum() * np.log(h / h.sum())))


def test_relative_entropy_ignores_depth_and_relief_scale():
    noise = np.random.default_rng(6).normal(0.0, 1.0, (20, 20))
    a = terrain_entropy(plane((20, 20), noise=noise, a=200.0), 5, relative=True)
    b = terrain_entropy(plane((20, 20), noise=noise, a=2000.0), 5, relative=True)
    np.testing.assert_allclose(a, b, rtol=1e-6)
    absolute = terrain_entropy(plane((20, 20), noise=noise, a=2000.0), 5)
    assert np.nanmax(np.abs(interior(absolute, 2) - np.log(25))) < 1e-4  # the literal figure


def test_region_entropy_nan_and_nonpositive_depth():
    m = with_nan(flat(), 2, 3)
    assert np.isnan(region_entropy(m, north=(0, 9), east=(0, 12)))
    assert np.isfinite(region_entropy(m, north=(12, 30), east=(0, 30)))
    land = flat().replace(depth=np.where(np.arange(14) < 3, -5.0, 20.0) * np.ones((12, 1)))
    with pytest.raises(TangraphError, match="relative=True"):
        terrain_entropy(land, 3)
    with pytest.raises(TangraphError, match="relative=True"):
        region_entropy(land)
    assert np.isfinite(region_entropy(land, relative=True))


# -- Fisher information and the CRLB ---------------------------------------------------------
@pytest.mark.parametrize("order", [1, 3])
def test_fisher_information_of_a_plane_is_g_gt_over_sigma2(order):
    sigma = 0.4
    info = fisher_information(plane(), sigma=sigma, order=order)
    g = np.array([GN, GE])
    assert info.shape == (30, 40, 2, 2)
    np.testing.assert_allclose(info, np.broadcast_to(np.outer(g, g) / sigma**2, info.shape),
                               rtol=1e-9, atol=1e-15)


def test_window_information_sums_the_soundings():
    m, sigma = plane(), 0.5
    n = np.array([110.0, 130.0, 150.5])
    e = np.array([-40.0, 0.0, 33.3])
    g = np.array([GN, GE])
    expected = 3 * np.outer(g, g) / sigma**2
    np.testing.assert_allclose(window_information(m, n, e, sigma=sigma), expected, rtol=1e-9)
    np.testing.assert_array_equal(window_information(m, [], [], sigma=sigma), np.zeros((2, 2)))
    assert np.all(np.isnan(window_information(m, [110.0, -1e6], [0.0, 0.0], sigma=sigma)))


def test_fisher_information_is_nan_next_to_nan_cells():
    info = fisher_information(with_nan(plane(), 10, 20), sigma=1.0)
    assert np.all(np.isnan(info[10, 20]))
    assert np.all(np.isnan(info[9, 19]))  # the bilinear stencil of cell (9, 19) holds (10, 20)
    assert np.all(np.isfinite(info[0, 0]))


def test_crlb_inverts_and_flags_singular_information():
    rng = np.random.default_rng(8)
    a = rng.normal(size=(5, 2, 2))
    info = a @ np.swapaxes(a, -1, -2) + 0.1 * np.eye(2)
    np.testing.assert_allclose(crlb(info) @ info, np.broadcast_to(np.eye(2), info.shape), atol=1e-9)
    # One sounding, or any number on a plane: rank 1, the position is unobservable.
    assert np.all(np.isinf(crlb(fisher_information(plane(), sigma=1.0)[3, 4])))
    assert np.all(np.isinf(crlb(np.zeros((2, 2)))))
    assert np.all(np.isnan(crlb(np.full((2, 2), np.nan))))
    # Two soundings on different gradients: the exact inverse.
    two = np.outer([1.0, 0.0], [1.0, 0.0]) + np.outer([0.0, 2.0], [0.0, 2.0])
    np.testing.assert_allclose(crlb(two), np.diag([1.0, 0.25]))


# -- bad input -------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("call", "names"),
    [
        (lambda: roughness(plane(), 4), "window"),
        (lambda: roughness(plane(), 1), "window"),
        (lambda: terrain_std(plane(), 2.5), "window"),
        (lambda: terrain_entropy(plane(), 41), "window"),
        (lambda: fisher_information(plane(), sigma=0.0), "sigma"),
        (lambda: window_information(plane(), [110.0], [0.0], sigma=-1.0), "sigma"),
        (lambda: crlb(np.eye(3)), "shape"),
        (lambda: crlb([[1.0, 2.0], [0.0, 1.0]]), "symmetric"),
        (lambda: crlb(-np.eye(2)), "semi-definite"),
        (lambda: region_entropy(plane(), north=(0.0, 1.0)), "north"),
    ],
)
def test_bad_arguments_raise_naming_the_parameter(call, names):
    with pytest.raises(TangraphError, match=names):
        call()
