"""The compiled interpolation kernels behind ``BathymetryMap.depth_at`` and ``gradient_at``
(tangraph.maps._interp): deterministic cases (a plane, cell centres, off the map, NaN cells), and
against the pure-numpy reference (tests/maps/reference.py), finite differences and a smooth
surface."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.maps import BathymetryMap
from tests.maps.grid_cases import plane, rough
from tests.maps.reference import interpolate as reference


# -- deterministic cases -----------------------------------------------------------------------
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


# -- against the numpy reference ---------------------------------------------------------------
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
