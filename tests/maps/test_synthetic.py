"""Synthetic terrain: reproducibility, requested statistics and geometry, the charts, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.maps import BathymetryMap
from tangraph.maps.statistics import region_entropy, roughness
from tangraph.maps.synthetic import (
    HAN2020_AREAS,
    flat_with_noise,
    fractal,
    han2020_chart,
    polar_chart,
    ridges,
    seamounts,
)

SMALL = {
    "fractal": lambda rng: fractal((40, 50), 5.0, rng=rng),
    "seamounts": lambda rng: seamounts((40, 50), 5.0, rng=rng, count=3, radius=(10.0, 40.0)),
    "ridges": lambda rng: ridges((40, 50), 5.0, rng=rng, spacing=60.0),
    "flat_with_noise": lambda rng: flat_with_noise((40, 50), 5.0, rng=rng, correlation_length=8.0),
}


def rng(seed: int) -> np.random.Generator:
    return np.random.default_rng(seed)


# -- reproducibility and shape ---------------------------------------------------------------
@pytest.mark.parametrize("make", SMALL.values(), ids=SMALL.keys())
def test_same_seed_same_map_other_seed_other_map(make):
    a, b, c = make(rng(7)), make(rng(7)), make(rng(8))
    assert isinstance(a, BathymetryMap)
    np.testing.assert_array_equal(a.depth, b.depth)
    assert not np.array_equal(a.depth, c.depth)


@pytest.mark.parametrize("make", SMALL.values(), ids=SMALL.keys())
def test_shape_cells_and_frame(make):
    m = make(rng(0))
    assert m.shape == (40, 50)
    assert m.cell_size == (5.0, 5.0)
    assert m.extent == (0.0, 195.0, 0.0, 245.0)
    assert m.crs is None
    assert np.all(np.isfinite(m.depth))


def test_generators_never_touch_the_global_random_state():
    np.random.seed(3)  # noqa: NPY002 (the legacy global state is what is checked)
    before = np.random.random()  # noqa: NPY002
    np.random.seed(3)  # noqa: NPY002
    for make in SMALL.values():
        make(rng(0))
    assert np.random.random() == before  # noqa: NPY002


# -- fractal ---------------------------------------------------------------------------------
@pytest.mark.parametrize("relief", [0.5, 12.0])
def test_fractal_meets_requested_relief_and_mean(relief):
    m = fractal((64, 48), 2.0, rng=rng(1), beta=2.5, relief=relief, mean_depth=300.0)
    assert np.std(m.depth) == pytest.approx(relief, rel=1e-12)
    assert np.mean(m.depth) == pytest.approx(300.0, rel=1e-12)


def test_higher_beta_is_smoother():
    means = [
        np.nanmean(roughness(fractal((96, 96), 5.0, rng=rng(2), beta=beta, relief=5.0), 5))
        for beta in (1.0, 2.5, 4.0)
    ]
    assert means[0] > 2 * means[1] > 4 * means[2]


def test_beta_zero_is_white_noise():
    d = fractal((128, 128), 1.0, rng=rng(3), beta=0.0, relief=1.0).depth
    lag1 = np.corrcoef(d[:, :-1].ravel(), d[:, 1:].ravel())[0, 1]
    assert abs(lag1) < 4 / 128  # ~4 standard errors of a correlation over 128^2 pairs


# -- seamounts, ridges, flat -----------------------------------------------------------------
def test_given_seamount_has_its_height_and_radius():
    m = seamounts((101, 101), 2.0, rng=rng(0), centres=[[100.0, 100.0]], height=[50.0],
                  radius=[20.0], base_depth=400.0)
    assert m.depth_at(100.0, 100.0) == pytest.approx(350.0)
    assert m.depth_at(120.0, 100.0) == pytest.approx(400.0 - 50.0 * np.exp(-0.5))
    assert m.depth[0, 0] == pytest.approx(400.0, abs=1e-6)


def test_drawn_seamounts_stay_in_their_ranges():
    m = seamounts((80, 80), 10.0, rng=rng(4), count=1, height=(100.0, 200.0), radius=50.0,
                  base_depth=1000.0)
    assert 800.0 <= m.depth.min() <= 900.0 + 1e-9
    assert m.depth.max() <= 1000.0
    assert seamounts((10, 10), 1.0, rng=rng(0), count=0).depth.min() == 1000.0


@pytest.mark.parametrize("profile", ["sine", "gaussian"])
def test_ridges_run_along_their_orientation(profile):
    along_north = ridges((30, 40), 5.0, rng=rng(0), orientation=0.0, spacing=50.0, height=8.0,
                         profile=profile)
    np.testing.assert_allclose(along_north.depth, np.broadcast_to(along_north.depth[0], (30, 40)))
    along_east = ridges((30, 40), 5.0, rng=rng(0), orientation=90.0, spacing=50.0, height=8.0,
                        profile=profile)
    first_column = along_east.depth[:, :1]
    np.testing.assert_allclose(along_east.depth, np.broadcast_to(first_column, (30, 40)))
    assert along_north.depth.max() - along_north.depth.min() == pytest.approx(8.0, rel=0.05)


def test_sine_ridges_repeat_at_their_spacing():
    m = ridges((20, 60), 5.0, rng=rng(1), orientation=0.0, spacing=50.0, height=5.0)
    np.testing.assert_allclose(m.depth[:, 10:], m.depth[:, :-10], atol=1e-9)  # 10 cells = 50 m


def test_flat_with_noise_is_a_plane_plus_noise_of_the_requested_std():
    m = flat_with_noise((50, 60), 4.0, rng=rng(5), depth=200.0, gradient=(0.02, -0.01),
                        noise_std=0.3)
    plane = 200.0 + 0.02 * m.north[:, None] - 0.01 * m.east[None, :]
    assert np.std(m.depth - plane) == pytest.approx(0.3, rel=1e-12)
    assert np.mean(m.depth - plane) == pytest.approx(0.0, abs=1e-12)
    noiseless = flat_with_noise((5, 5), 1.0, rng=rng(5), depth=50.0, noise_std=0.0)
    np.testing.assert_array_equal(noiseless.depth, 50.0)


def test_correlated_noise_is_smoother_than_white():
    white = flat_with_noise((64, 64), 1.0, rng=rng(6), noise_std=1.0).depth
    smooth = flat_with_noise((64, 64), 1.0, rng=rng(6), noise_std=1.0, correlation_length=3.0).depth
    assert np.std(np.diff(smooth, axis=1)) < 0.5 * np.std(np.diff(white, axis=1))


# -- the charts ------------------------------------------------------------------------------
def test_han2020_chart_setting_and_entropy_rising_along_the_path():
    m = han2020_chart(rng=rng(0))
    assert m.shape == (1000, 1000)
    assert m.cell_size == (5.0, 5.0)
    assert m.extent == (0.0, 4995.0, 0.0, 4995.0)
    assert np.nanmin(m.depth) > 0
    entropy = [region_entropy(m, north, east) for north, east in HAN2020_AREAS]
    assert np.all(np.diff(entropy) > 0)
    assert np.all(np.array(entropy) < np.log(81 * 81))
    np.testing.assert_array_equal(han2020_chart(rng=rng(0)).depth, m.depth)


def test_polar_chart_setting():
    m = polar_chart(rng=rng(0))
    assert m.cell_size == (500.0, 500.0)
    n_lo, n_hi, e_lo, e_hi = m.extent
    assert min(n_hi - n_lo, e_hi - e_lo) >= 100_000.0
    assert 100.0 <= m.depth.min() < 600.0
    assert m.depth.max() == 2000.0
    assert 0.3 < np.mean(m.depth == 2000.0) < 0.45  # the flat plain (40 % minus seamounts)
    assert not np.array_equal(polar_chart(rng=rng(1)).depth, m.depth)


# -- bad input -------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("call", "names"),
    [
        (lambda: fractal((10, 10), -1.0, rng=rng(0)), "cell"),
        (lambda: fractal((10, 10), 0.0, rng=rng(0)), "cell"),
        (lambda: fractal((1, 10), 1.0, rng=rng(0)), "shape"),
        (lambda: fractal((10,), 1.0, rng=rng(0)), "shape"),
        (lambda: fractal((10, 10), 1.0, rng=rng(0), beta=-1.0), "beta"),
        (lambda: fractal((10, 10), 1.0, rng=rng(0), relief=np.nan), "relief"),
        (lambda: seamounts((10, 10), 1.0, rng=rng(0), count=-2), "count"),
        (lambda: seamounts((10, 10), 1.0, rng=rng(0), height=(5.0, 1.0)), "height"),
        (lambda: seamounts((10, 10), 1.0, rng=rng(0), count=2, radius=[1.0, 2.0, 3.0]), "radius"),
        (lambda: seamounts((10, 10), 1.0, rng=rng(0), centres=[1.0, 2.0]), "centres"),
        (lambda: ridges((10, 10), 1.0, rng=rng(0), spacing=0.0), "spacing"),
        (lambda: ridges((10, 10), 1.0, rng=rng(0), profile="square"), "profile"),
        (lambda: flat_with_noise((10, 10), 1.0, rng=rng(0), noise_std=-0.1), "noise_std"),
        (lambda: polar_chart(rng=rng(0), flat_fraction=1.0), "flat_fraction"),
        (lambda: polar_chart(rng=rng(0), depth_range=(900.0, 300.0)), "depth_range"),
    ],
)
def test_bad_arguments_raise_naming_the_parameter(call, names):
    with pytest.raises(TangraphError, match=names):
        call()
