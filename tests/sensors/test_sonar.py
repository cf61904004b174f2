"""Tests of the multibeam and single-beam sonar simulation by ray casting."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.maps import BathymetryMap, raycasting_scene
from tangraph.sensors import (
    MultibeamConfig,
    Pings,
    SingleBeamConfig,
    beam_angles,
    simulate_pings,
)
from tangraph.survey import footprints

D, Z = 60.0, 12.0  # seafloor and vehicle depth of the flat tests


def footprint_positions(pose, forward, starboard):
    """(K, B, 2) map positions of footprints, through the one implementation in tangraph.survey."""
    return np.stack(footprints(pose, forward, starboard), axis=-1)


def plane_map(a=80.0, gn=0.0, ge=0.0, half=400.0, cell=50.0):
    axis = np.arange(-half, half + cell / 2, cell)
    nn, ee = np.meshgrid(axis, axis, indexing="ij")
    return BathymetryMap(axis, axis, a + gn * nn + ge * ee, name="plane")


FLAT = raycasting_scene(plane_map(D))


def random_poses(k, rng, spread=50.0):
    return np.column_stack([rng.uniform(-spread, spread, (k, 2)), rng.uniform(-np.pi, np.pi, k)])


def binomial_ok(count, n, p):
    return abs(count - n * p) <= 4 * np.sqrt(n * p * (1 - p))


# -- geometry, no noise -----------------------------------------------------------------------
def test_flat_seabed_geometry_is_exact():
    rng = np.random.default_rng(0)
    pose = random_poses(20, rng)
    before = pose.copy()
    config = MultibeamConfig(n_beams=21, swath=np.deg2rad(120))
    pings = simulate_pings(FLAT, pose, np.full(20, Z), config, rng=rng)
    angles = beam_angles(config)
    np.testing.assert_allclose(pings.beam_depth, D, rtol=0, atol=1e-9)
    np.testing.assert_allclose(pings.beam_starboard, np.broadcast_to((D - Z) * np.tan(angles), (20, 21)),
                               atol=1e-9)
    np.testing.assert_allclose(pings.beam_forward, 0.0, atol=1e-9)
    assert (pings.n_missing, pings.n_outliers, pings.n_off_map) == (0, 0, 0)
    np.testing.assert_array_equal(pose, before)
    assert not pings.beam_depth.flags.writeable


def test_tide_adds_to_measured_depth():
    config = MultibeamConfig(n_beams=5, swath=np.pi / 2, tide=1.5)
    pings = simulate_pings(FLAT, [[0.0, 0.0, 0.3]], [Z], config, rng=np.random.default_rng(0))
    np.testing.assert_allclose(pings.beam_depth, D + 1.5, atol=1e-9)
    expected = (D + 1.5 - Z) * np.tan(beam_angles(config))
    np.testing.assert_allclose(pings.beam_starboard[0], expected, atol=1e-9)


def test_known_roll_and_pitch_turn_the_fan():
    config = MultibeamConfig(n_beams=7, swath=np.deg2rad(90))
    angles = beam_angles(config)
    roll, pitch = 0.2, -0.1
    pings = simulate_pings(FLAT, [[10.0, -5.0, 1.0], [0.0, 0.0, 0.0]], [Z, Z], config,
                           rng=np.random.default_rng(0), roll=[roll, 0.0], pitch=[0.0, pitch])
    np.testing.assert_allclose(pings.beam_depth, D, atol=1e-9)
    # Starboard-down roll turns the fan to port; nose-up pitch turns it forward.
    np.testing.assert_allclose(pings.beam_starboard[0], (D - Z) * np.tan(angles - roll), atol=1e-9)
    np.testing.assert_allclose(pings.beam_forward[0], 0.0, atol=1e-9)
    np.testing.assert_allclose(pings.beam_forward[1], (D - Z) * np.tan(pitch), atol=1e-9)
    np.testing.assert_allclose(pings.beam_starboard[1], (D - Z) * np.tan(angles) / np.cos(pitch), atol=1e-9)


def test_sloped_plane_soundings_equal_the_map_at_the_footprint():
    rng = np.random.default_rng(1)
    bathymetry = plane_map(80.0, gn=0.05, ge=-0.08)
    k = 30
    pose = random_poses(k, rng)
    config = MultibeamConfig(n_beams=31, tide=0.7)
    pings = simulate_pings(raycasting_scene(bathymetry), pose, rng.uniform(5, 20, k), config, rng=rng,
                           roll=rng.normal(0, 0.05, k), pitch=rng.normal(0, 0.05, k))
    where = footprint_positions(pose, pings.beam_forward, pings.beam_starboard)
    assert np.isfinite(pings.beam_depth).all()
    np.testing.assert_allclose(pings.beam_depth, bathymetry.depth_at(where[..., 0], where[..., 1]) + 0.7,
                               atol=1e-8)


def test_heading_east_puts_starboard_south():
    bathymetry = plane_map(80.0, gn=0.1)  # deeper to the north
    config = MultibeamConfig(n_beams=3, swath=np.pi / 2)
    pings = simulate_pings(raycasting_scene(bathymetry), [[0.0, 0.0, np.pi / 2]], [Z], config,
                           rng=np.random.default_rng(0))
    stbd, port = pings.beam_starboard[0, 2], pings.beam_starboard[0, 0]
    assert stbd > 0 > port
    np.testing.assert_allclose(pings.beam_depth[0, 2], 80.0 - 0.1 * stbd, atol=1e-9)  # south: shallower
    np.testing.assert_allclose(pings.beam_depth[0, 0], 80.0 - 0.1 * port, atol=1e-9)
    np.testing.assert_allclose(footprint_positions([[0.0, 0.0, np.pi / 2]], [[0.0]], [[stbd]])[0, 0],
                               [-stbd, 0.0], atol=1e-12)


def test_smooth_seabed_ray_casting_agrees_with_bilinear_map_within_the_cell_bound():
    # depth = 60 + A sin(kn n) cos(ke e). The mesh is linear on triangles, the map bilinear in
    # cells; they agree at the nodes and differ by at most |mixed difference| / 4 inside a
    # cell, and the mixed difference is at most max|d2 depth / dn de| dn de = A kn ke dn de.
    amp, kn, ke, cell = 3.0, 2 * np.pi / 40, 2 * np.pi / 30, 2.0
    axis = np.arange(-150.0, 150.0 + cell / 2, cell)
    nn, ee = np.meshgrid(axis, axis, indexing="ij")
    bathymetry = BathymetryMap(axis, axis, 60.0 + amp * np.sin(kn * nn) * np.cos(ke * ee))
    rng = np.random.default_rng(2)
    pose = random_poses(25, rng, spread=10.0)
    pings = simulate_pings(raycasting_scene(bathymetry), pose, np.full(25, 10.0), MultibeamConfig(), rng=rng)
    where = footprint_positions(pose, pings.beam_forward, pings.beam_starboard)
    gap = np.abs(pings.beam_depth - bathymetry.depth_at(where[..., 0], where[..., 1]))
    bound = amp * kn * ke * cell * cell / 4
    assert np.isfinite(gap).all()
    assert gap.max() <= bound + 1e-9
    assert gap.max() > 0.1 * bound  # the two surfaces do differ: the test has teeth


# -- no returns -------------------------------------------------------------------------------
def test_off_map_and_out_of_range_beams_are_nan_and_counted():
    config = MultibeamConfig(n_beams=41)
    angles = beam_angles(config)
    east = 380.0  # 20 m inside the east edge, heading north: starboard beams leave the map
    pings = simulate_pings(FLAT, [[0.0, east, 0.0]], [Z], config, rng=np.random.default_rng(0))
    off = east + (D - Z) * np.tan(angles) > 400.0
    assert off.any() and not off.all()
    np.testing.assert_array_equal(np.isnan(pings.beam_depth[0]), off)
    np.testing.assert_array_equal(np.isnan(pings.beam_starboard[0]), off)
    assert pings.n_off_map == off.sum()
    short = MultibeamConfig(n_beams=41, max_range=70.0)
    pings = simulate_pings(FLAT, [[0.0, 0.0, 0.0]], [Z], short, rng=np.random.default_rng(0))
    far = (D - Z) / np.cos(angles) > 70.0
    assert far.any() and not far.all()
    np.testing.assert_array_equal(np.isnan(pings.beam_depth[0]), far)
    assert pings.n_off_map == far.sum()


# -- noise ------------------------------------------------------------------------------------
def test_missing_and_outlier_rates():
    rng = np.random.default_rng(3)
    k = 200
    config = MultibeamConfig(missing_rate=0.1, outlier_rate=0.03, outlier_std=20.0)
    pings = simulate_pings(FLAT, random_poses(k, rng), np.full(k, Z), config, rng=rng)
    n = k * config.n_beams
    assert binomial_ok(pings.n_missing, n, 0.1)
    assert np.isnan(pings.beam_depth).sum() == pings.n_missing
    kept = n - pings.n_missing
    assert binomial_ok(pings.n_outliers, kept, 0.03)
    # Without other noise the outliers are exactly the soundings off the true depth.
    assert np.sum(np.abs(pings.beam_depth - D) > 1e-6) == pings.n_outliers


def test_depth_noise_std():
    rng = np.random.default_rng(4)
    k = 200
    config = MultibeamConfig(depth_noise=0.3)
    pings = simulate_pings(FLAT, random_poses(k, rng), np.full(k, Z), config, rng=rng)
    err = (pings.beam_depth - D).ravel()
    assert abs(err.var(ddof=1) / 0.3**2 - 1) < 4 * np.sqrt(2 / (err.size - 1))
    assert abs(err.mean()) < 4 * 0.3 / np.sqrt(err.size)
    # Depth noise is vertical only: the footprint stays on the exact beam.
    expected = np.broadcast_to((D - Z) * np.tan(beam_angles(config)), (k, config.n_beams))
    np.testing.assert_allclose(pings.beam_starboard, expected, atol=1e-9)


def test_range_noise_moves_soundings_along_the_beam():
    rng = np.random.default_rng(5)
    k = 200
    config = MultibeamConfig(range_noise=0.01)
    angles = beam_angles(config)
    pings = simulate_pings(FLAT, random_poses(k, rng), np.full(k, Z), config, rng=rng)
    # Depth error = range error * cos(angle) = (D - Z) * range_noise * N(0, 1).
    z = ((pings.beam_depth - D) / ((D - Z) * 0.01)).ravel()
    assert abs(z.var(ddof=1) - 1) < 4 * np.sqrt(2 / (z.size - 1))
    np.testing.assert_allclose(pings.beam_starboard, (pings.beam_depth - Z) * np.tan(angles), atol=1e-9)


def test_attitude_noise_is_an_unmodelled_sounding_error():
    rng = np.random.default_rng(6)
    k = 100
    config = MultibeamConfig(n_beams=11, attitude_noise=np.deg2rad(1.0))
    angles = beam_angles(config)
    pings = simulate_pings(FLAT, random_poses(k, rng), np.full(k, Z), config, rng=rng)
    err = pings.beam_depth - D
    # Reduced with the nominal angles: footprints lie on the nominal beams ...
    np.testing.assert_allclose(pings.beam_starboard, (pings.beam_depth - Z) * np.tan(angles), atol=1e-9)
    # ... so a tilted centre beam reads too deep, by (D - Z) (1 / cos(tilt) - 1) >= 0.
    centre = err[:, 5]
    assert np.all(centre >= -1e-9) and centre.max() > 1e-4
    assert np.abs(err).max() > 0.1  # outer beams: first-order errors


def test_single_beam():
    rng = np.random.default_rng(7)
    k = 2000
    config = SingleBeamConfig.chen2022()
    assert (config.ping_rate, config.depth_noise) == (0.01, 5.0)
    pings = simulate_pings(FLAT, random_poses(k, rng), np.full(k, Z), config, rng=rng)
    assert pings.beam_depth.shape == (k, 1)
    np.testing.assert_allclose(pings.beam_starboard, 0.0, atol=1e-9)
    np.testing.assert_allclose(pings.beam_forward, 0.0, atol=1e-9)
    err = pings.beam_depth.ravel() - D
    assert abs(err.var(ddof=1) / 25.0 - 1) < 4 * np.sqrt(2 / (k - 1))
    tide = simulate_pings(FLAT, [[0.0, 0.0, 0.0]], [Z], SingleBeamConfig(tide=-2.0), rng=rng)
    np.testing.assert_allclose(tide.beam_depth, D - 2.0, atol=1e-9)


def test_same_seed_same_pings():
    config = MultibeamConfig.wang2019()
    pose = random_poses(5, np.random.default_rng(0))
    a = simulate_pings(FLAT, pose, np.full(5, Z), config, rng=np.random.default_rng(8))
    b = simulate_pings(FLAT, pose, np.full(5, Z), config, rng=np.random.default_rng(8))
    np.testing.assert_array_equal(a.beam_depth, b.beam_depth)


def test_presets():
    wang = MultibeamConfig.wang2019()
    assert wang.n_beams == 101 and wang.swath == pytest.approx(np.deg2rad(120))
    assert MultibeamConfig.han2020().n_beams == 60
    np.testing.assert_allclose(np.rad2deg(beam_angles(wang))[[0, 50, -1]], [-60.0, 0.0, 60.0])


# -- validation -------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("field", "value"),
    [("n_beams", 1), ("n_beams", 10.5), ("swath", 4.0), ("swath", 0.0), ("ping_rate", 0.0),
     ("range_noise", -0.1), ("missing_rate", 1.5), ("outlier_rate", -0.1), ("max_range", 0.0),
     ("tide", np.nan), ("attitude_noise", "big")],
)
def test_multibeam_validation_names_the_field(field, value):
    with pytest.raises(TangraphError, match=f"MultibeamConfig.{field}"):
        MultibeamConfig(**{field: value})


@pytest.mark.parametrize(("field", "value"), [("ping_rate", -1.0), ("depth_noise", -1.0), ("tide", np.inf)])
def test_single_beam_validation_names_the_field(field, value):
    with pytest.raises(TangraphError, match=f"SingleBeamConfig.{field}"):
        SingleBeamConfig(**{field: value})


def test_bad_ping_inputs_are_named():
    rng = np.random.default_rng(0)
    with pytest.raises(TangraphError, match="pose"):
        simulate_pings(FLAT, [[0.0, 0.0]], [Z], MultibeamConfig(), rng=rng)
    with pytest.raises(TangraphError, match="vehicle_depth"):
        simulate_pings(FLAT, [[0.0, 0.0, 0.0]], [Z, Z], MultibeamConfig(), rng=rng)
    with pytest.raises(TangraphError, match="roll"):
        simulate_pings(FLAT, [[0.0, 0.0, 0.0]], [Z], MultibeamConfig(), rng=rng, roll=[0.0, 0.1])
    with pytest.raises(TangraphError, match="finite"):
        simulate_pings(FLAT, [[np.nan, 0.0, 0.0]], [Z], MultibeamConfig(), rng=rng)
    with pytest.raises(TangraphError, match="share one"):
        Pings(np.zeros((2, 3)), np.zeros((2, 3)), np.zeros((2, 4)))
