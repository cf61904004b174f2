"""One dispatch over every estimator (tangraph.navigation): the methods and their refusals, every
method on a real map, and a recorded survey put on its map (``survey_on_map``) before it is
navigated, its dead reckoning in the same frame."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.navigation import Method, dead_reckoning_track, navigate, survey_on_map, track_summary
from tests.recorded_cases import horizontal_rmse, model_for, recorded


def test_the_cli_methods_are_the_filters_and_the_graph():
    from tangraph.filters import FilterMethod

    assert {m.value for m in Method} == {m.value for m in FilterMethod} | {"isam2", "smoother"}
    assert {m.value for m in Method if m.is_graph} == {"isam2", "smoother"}


def test_unknown_method_and_missing_rng_are_named(wang_survey):
    survey, bathymetry = wang_survey
    with pytest.raises(TangraphError, match="unknown navigation method 'kalman'.*tercom-pf"):
        navigate(survey, bathymetry, "kalman")
    with pytest.raises(TangraphError, match="'pf' is random: pass rng"):
        navigate(survey, bathymetry, "pf")


@pytest.mark.parametrize("method", [m.value for m in Method])
def test_every_method_beats_dead_reckoning_on_a_real_map(wang_survey, method):
    survey, bathymetry = wang_survey
    track = navigate(survey, bathymetry, method, rng=np.random.default_rng(11))
    assert track.method == method and track.n_poses == survey.n_pings
    np.testing.assert_array_equal(track.time, survey.time)
    from tangraph.eval import track_metrics

    got = track_metrics(track, survey.true_pose, skip=30)
    dr = track_metrics(dead_reckoning_track(survey), survey.true_pose, skip=30)
    assert got["rmse"] < dr["rmse"], (got, dr)
    text = track_summary(track, survey)
    assert f"method       {method}" in text and "dead reckoning: RMSE" in text


def test_navigate_puts_a_recorded_survey_in_the_map_frame(simulated, merimbula):
    rec = recorded(simulated)
    assert np.abs(rec.dr_pose[:, :2] - simulated.dr_pose[:, :2]).min() > 1000.0  # km apart as numbers
    model = model_for(simulated)
    track = navigate(rec, merimbula, "smoother", model=model)
    dr = horizontal_rmse(simulated.dr_pose, simulated.true_pose)
    assert horizontal_rmse(track.pose, simulated.true_pose) < 0.5 * dr
    on_map = survey_on_map(rec, merimbula)
    np.testing.assert_allclose(on_map.true_pose[:, :2], simulated.true_pose[:, :2], atol=1e-3)
    assert survey_on_map(on_map, merimbula) is on_map  # twice is harmless
    again = navigate(on_map, merimbula, "smoother", model=model)
    np.testing.assert_allclose(again.pose, track.pose, atol=1e-9)
    pf = navigate(rec, merimbula, "pf", model=model, rng=np.random.default_rng(5))
    assert horizontal_rmse(pf.pose, simulated.true_pose) < dr


def test_the_dead_reckoning_of_a_recorded_survey_is_written_on_the_map(simulated, merimbula):
    """The baseline in the same frame as the tracks: survey_on_map first."""
    rec = recorded(simulated)
    dr = dead_reckoning_track(survey_on_map(rec, merimbula))
    np.testing.assert_allclose(dr.pose[:, :2], simulated.dr_pose[:, :2], atol=1e-3)
