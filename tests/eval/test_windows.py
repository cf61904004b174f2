"""Check-line scores (tangraph.eval.windows): the standardised window means of held-out soundings
against a map, standard normal when the map errs as it says, heavy-tailed where the seafloor
changed."""

import numpy as np

from tangraph.eval.map_check import MapCheck
from tangraph.eval.windows import window_scores
from tangraph.maps import BathymetryMap
from tangraph.sensors import NavigationModel
from tangraph.sensors.matern import matern_field
from tests.eval.line_cases import AXIS_E, AXIS_N, SOUNDING_STD, line_survey, seafloor


def test_scores_are_standard_normal_when_the_map_errs_as_it_says():
    # the map is the seafloor less a Matérn field of the std and range it states: the window
    # means of held-out soundings, standardised, are N(0, 1) up to Monte Carlo error
    model = NavigationModel(sounding_std=SOUNDING_STD)
    scores = []
    for seed in range(6):
        rng = np.random.default_rng(seed)
        d = matern_field(AXIS_N, AXIS_E, 0.3, 20.0, rng=rng)
        grid = BathymetryMap(AXIS_N, AXIS_E, seafloor(AXIS_N[:, None], AXIS_E[None, :]) - d,
                             depth_std=np.full(d.shape, 0.3), correlation_length=20.0)
        truth = BathymetryMap(AXIS_N, AXIS_E, seafloor(AXIS_N[:, None], AXIS_E[None, :]))
        survey = line_survey(truth.depth_at, rng, lines=[100.0, 250.0])
        scores.append(window_scores(survey, grid, model, window=50.0))
    scores = np.concatenate(scores)
    # windows 50 m long, 2.5 ranges: nearly independent; RMS^2 of W normals has std sqrt(2 / W)
    assert scores.size > 400
    assert abs(np.mean(scores**2) - 1.0) < 4 * np.sqrt(2.0 / scores.size)
    assert np.mean(np.abs(scores) > 3.0) < 0.02


def test_a_patch_the_map_does_not_know_is_heavy_tailed():
    # the same, with the seafloor 2 m shallower over 400 m of one line: the bulk stays at 1,
    # the RMS and the share beyond 3 say a few windows are far worse than the map states
    model = NavigationModel(sounding_std=SOUNDING_STD)
    rng = np.random.default_rng(1)
    d = matern_field(AXIS_N, AXIS_E, 0.3, 20.0, rng=rng)
    grid = BathymetryMap(AXIS_N, AXIS_E, seafloor(AXIS_N[:, None], AXIS_E[None, :]) - d,
                         depth_std=np.full(d.shape, 0.3), correlation_length=20.0)
    truth = BathymetryMap(AXIS_N, AXIS_E, seafloor(AXIS_N[:, None], AXIS_E[None, :]))

    def changed(north, east):
        return truth.depth_at(north, east) - 2.0 * ((east > 800) & (east < 1200) & (north < 150))

    s = window_scores(line_survey(changed, rng, lines=[100.0, 250.0]), grid, model, window=50.0)
    check = MapCheck(s, np.zeros(s.size, int), ("changed",), 50.0)
    assert check.rms > 1.8
    assert 0.6 < check.robust < 1.4
    assert check.share_beyond_3 > 0.03
