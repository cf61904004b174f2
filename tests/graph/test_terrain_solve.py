"""The smoother that weighs every sounding (tangraph.graph.terrain_solve, smoother_terrain="soundings"):
what a plane, a flat map and textured terrain tell it, and a map no sounding falls on."""

import numpy as np
import pytest

from tangraph.maps import BathymetryMap
from tangraph.sensors import NavigationModel
from tests.graph.terrain_cases import AXIS, lawnmower, noise_free, smooth_map


def smooth(survey, bathymetry, terrain, model, **options):
    from tangraph.graph import GraphConfig, smooth_survey

    config = GraphConfig().replace(smoother_terrain=terrain, rematch_iterations=0, **options)
    known = model.replace(speed_scale_std=0.0, heading_bias_std=0.0)  # no calibration variable
    return smooth_survey(survey, bathymetry, config, model=known)


def test_a_plane_sloped_north_gives_the_north_offset_and_nothing_east():
    # noise-free soundings of a plane rising to the north: the soundings say exactly where the
    # track lies across the slope, and nothing along it: the east covariance stays the DR's
    n, e = AXIS[:, None], AXIS[None, :]
    plane = BathymetryMap(AXIS, AXIS, 50.0 + 0.05 * n + 0.0 * e)
    model = NavigationModel(sounding_std=0.1, tide_std=0.0, speed_noise=0.02, initial_position_std=30.0)
    truth, survey = lawnmower()
    survey = noise_free(survey, plane)
    track = smooth(survey, plane, "soundings", model)
    assert track.meta["soundings"]["soundings_used"] == np.isfinite(survey.beam_depth).sum()
    np.testing.assert_allclose(track.pose[:, 0], truth[:, 0], atol=1e-4)
    dr_only = smooth(survey, BathymetryMap(AXIS, AXIS, np.full(plane.shape, 50.0)), "soundings", model)
    # (to 1e-4: the heading, which the soundings do tell, reaches east only through the turns)
    np.testing.assert_allclose(track.covariance[:, 1, 1], dr_only.covariance[:, 1, 1], rtol=1e-4)
    assert np.all(track.covariance[:, 0, 0] < 1e-3 * dr_only.covariance[:, 0, 0])


def test_a_flat_map_leaves_the_dead_reckoning_as_it_is():
    flat = BathymetryMap(AXIS, AXIS, np.full((AXIS.size, AXIS.size), 50.0))
    model = NavigationModel(sounding_std=0.1, tide_std=1.0, speed_noise=0.02, initial_position_std=10.0)
    _, survey = lawnmower()
    survey = noise_free(survey, flat)
    with_soundings = smooth(survey, flat, "soundings", model, key_interval=0.5)
    with_fixes = smooth(survey, flat, "fixes", model, key_interval=0.5)  # a key at every ping too
    assert with_fixes.meta["n_fixes_accepted"] == 0
    np.testing.assert_allclose(with_soundings.pose[:, :2], survey.dr_pose[:, :2], atol=1e-6)
    np.testing.assert_allclose(np.angle(np.exp(1j * (with_soundings.pose[:, 2] - survey.dr_pose[:, 2]))), 0.0,
                               atol=1e-9)
    # the DR's covariance, as the smoother with no fix gives it
    np.testing.assert_allclose(with_soundings.covariance, with_fixes.covariance, rtol=1e-6, atol=1e-9)
    assert with_soundings.meta["soundings"]["tide"] == pytest.approx(0.0, abs=1e-6)


def test_every_sounding_recovers_a_start_error_on_textured_terrain():
    # sounding noise, a start 6 m off: the soundings smoother ends nearer the truth than the
    # DR and within its covariance
    bathymetry = smooth_map(wavy=1.0)
    model = NavigationModel(sounding_std=0.2, tide_std=1.0, speed_noise=0.02, initial_position_std=10.0)
    truth, survey = lawnmower()
    rng = np.random.default_rng(7)
    survey = noise_free(survey, bathymetry)
    noise = 0.2 * rng.standard_normal(survey.beam_depth.shape)
    survey = survey.replace(beam_depth=survey.beam_depth + 0.3 + noise)
    track = smooth(survey, bathymetry, "soundings", model)
    error = track.pose[:, :2] - truth[:, :2]
    assert np.sqrt(np.mean(np.sum(error**2, axis=1))) < 0.2
    nees = np.einsum("ki,kij,kj->k", error, np.linalg.inv(track.covariance[:, :2, :2]), error)
    # one run's ANEES: over 60 seeds of the sounding noise (the DR, its 6 m start error and the
    # tide fixed, so the Monte Carlo is conditional on them and 2 is not its expected value) it
    # measured mean 1.05, sd 0.70, 1st-99th percentile 0.23-2.94, extremes 0.20-3.18; the band
    # covers that with a margin (covariance 10x too large or too small leaves it)
    assert 0.15 < np.mean(nees) < 4.0, np.mean(nees)
    assert track.meta["soundings"]["tide"] == pytest.approx(0.3, abs=0.02)
    from tangraph.navigation import track_summary

    used, total = track.meta["soundings"]["soundings_used"], np.isfinite(survey.beam_depth).sum()
    assert f"soundings    {used} of {total} weighed" in track_summary(track, survey)


def test_no_sounding_on_the_map_keeps_the_fixes_solution(caplog):
    # the map's data lie in a corner the track never reaches: no sounding can be weighed, the
    # fixes' solve (here the DR) stands
    depth = np.full((AXIS.size, AXIS.size), np.nan)
    depth[:10, :10] = 50.0
    partial = BathymetryMap(AXIS, AXIS, depth)
    model = NavigationModel(sounding_std=0.1, tide_std=1.0, speed_noise=0.02, initial_position_std=10.0)
    _, survey = lawnmower()
    survey = survey.replace(beam_depth=np.full(survey.beam_depth.shape, 50.0))
    with_soundings = smooth(survey, partial, "soundings", model)
    with_fixes = smooth(survey, partial, "fixes", model)
    assert with_soundings.meta["soundings"]["soundings_used"] == 0
    assert "no sounding fits the map" in caplog.text
    np.testing.assert_array_equal(with_soundings.pose, with_fixes.pose)


def test_only_pings_that_ambiguous_windows_alone_cover_are_left_out():
    # an accepted window's pings are linearised even where another window found several places;
    # a window with one place or none standing out (uninformative, or its best on the search's
    # edge: a plane's strip) leaves its pings to the linearisation; a multimodal one's others
    # are left out
    from types import SimpleNamespace

    from tangraph.fix_records import FixRecord, FixStatus
    from tangraph.graph.terrain_solve import placed_pings

    nav = SimpleNamespace(survey=SimpleNamespace(n_pings=10), window_first={3: -2, 6: 2, 9: 5})

    def records(last):
        statuses = [(3, FixStatus.MULTIMODAL), (6, FixStatus.ACCEPTED), (9, last)]
        return [FixRecord.of(end, None, status, float("nan"), 10.0) for end, status in statuses]

    kept = [False, False, True, True, True, True, True]
    np.testing.assert_array_equal(placed_pings(nav, records(FixStatus.MULTIMODAL)), kept + [False] * 3)
    for status in (FixStatus.UNINFORMATIVE, FixStatus.OUTSIDE_SEARCH):
        np.testing.assert_array_equal(placed_pings(nav, records(status)), kept + [True] * 3)
    assert placed_pings(nav, []).all()


def test_an_egg_crate_seabed_whose_windows_fit_in_many_places_keeps_the_fixes_solution(caplog):
    # a seabed repeating every 12 m, searched around a DR start 6 m off with 10 m stated, its
    # multimodal fixes refused: every window fits in several places, so the soundings linearised
    # along the DR track would each take the slope under it for information (and narrow the
    # track to a dip of the egg crate); they are left out, and the track and its covariance are
    # the fixes'
    n, e = AXIS[:, None], AXIS[None, :]
    crate = BathymetryMap(AXIS, AXIS, 50.0 + 2.0 * np.sin(np.pi * n / 6.0) * np.sin(np.pi * e / 6.0))
    model = NavigationModel(sounding_std=0.1, tide_std=1.0, speed_noise=0.02, initial_position_std=10.0)
    _, survey = lawnmower()
    survey = noise_free(survey, crate)
    with_fixes = smooth(survey, crate, "fixes", model, accept_multimodal=False)
    assert {record.status.value for record in with_fixes.fixes} == {"multimodal"}
    with_soundings = smooth(survey, crate, "soundings", model, accept_multimodal=False)
    assert "every window found several places; the fixes' solution is kept" in caplog.text
    assert with_soundings.meta["soundings"]["soundings_used"] == 0
    assert with_soundings.meta["soundings"]["soundings"] == survey.beam_depth.size
    assert with_soundings.meta["soundings"]["pings_left_out"] == survey.n_pings
    np.testing.assert_array_equal(with_soundings.pose, with_fixes.pose)
    np.testing.assert_array_equal(with_soundings.covariance, with_fixes.covariance)
    from tangraph.navigation import track_summary

    assert f"0 of {survey.beam_depth.size} weighed (the others left out by the gate, and the " \
        f"{survey.n_pings} pings where windows found several places)" in track_summary(with_soundings, survey)
