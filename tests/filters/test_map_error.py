"""The filters on a map that is not the truth: per-sounding variances of the terrain model, no data
as no evidence, the information exponent, and no collapse at the edge of the map's data."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tangraph.filters import PFConfig, default_config, run_filter
from tangraph.filters.belief import model_belief
from tangraph.filters.model import FilterModel, survey_pings
from tangraph.filters.steps import evaluate, measure, reweight
from tangraph.sensors import sounding_variances
from tests.filters.synthetic import multibeam_survey, navigation, rough_map

MAP = rough_map(0)
SURVEY = multibeam_survey(MAP, pings=12)
MODEL = navigation(SURVEY, initial_position_std=10.0, sounding_std=0.5)


def test_pings_carry_the_terrain_models_variances():
    model = MODEL.replace(map_std=0.3, map_correlation_length=20.0)
    pings = survey_pings(SURVEY, MAP, model)
    want = sounding_variances(SURVEY, MAP, model)
    for ping in pings:
        keep = np.isfinite(SURVEY.beam_depth[ping.index])
        np.testing.assert_allclose(ping.variance, want[ping.index, keep])
        np.testing.assert_allclose(ping.map_variance, 0.09)
    # soundings that share a map error count as fewer: each variance is above noise + map error
    assert all(np.all(p.variance > 0.5**2 + 0.3**2) for p in pings)
    # a perfect map: the sounding noise alone; no model: nothing carried
    perfect = survey_pings(SURVEY, MAP, MODEL)
    assert all(np.allclose(p.variance, 0.25) and np.allclose(p.map_variance, 0.0) for p in perfect)
    assert all(p.variance is None for p in survey_pings(SURVEY))


def test_a_filter_that_knows_the_map_is_wrong_is_less_confident():
    config = PFConfig(n_particles=500)
    plain = run_filter("pf", SURVEY, MAP, config, model=MODEL, rng=np.random.default_rng(4))
    model = MODEL.replace(map_std=0.3, map_correlation_length=30.0)
    wrong = run_filter("pf", SURVEY, MAP, config, model=model, rng=np.random.default_rng(4))
    det = [np.linalg.det(t.covariance[-1, :2, :2]) for t in (plain, wrong)]
    assert det[1] > 2 * det[0], det


def test_the_information_exponent_is_computed_once_per_ping():
    """Tempering stages reuse the first evaluation's exponents, so their product is one
    likelihood raised to the stages' exponents (which sum to one)."""
    model = MODEL.replace(map_std=0.3, map_correlation_length=20.0)
    fm = FilterModel.from_model(model, MAP)
    ping = survey_pings(SURVEY, MAP, model)[3]
    belief = model_belief(SURVEY.dr_pose[3, :2], fm, 400, rng=np.random.default_rng(2))
    first = evaluate(belief, ping, fm)
    assert np.all((first.exponent >= 0) & (first.exponent <= 1)) and np.any(first.exponent < 1)
    again = evaluate(reweight(belief, first.log_likelihood, where="t"), ping, fm, exponent=first.exponent)
    np.testing.assert_array_equal(again.exponent, first.exponent)
    np.testing.assert_allclose(again.log_likelihood, first.log_likelihood, rtol=1e-12)
    # without the map error every exponent is one
    plain = evaluate(belief, survey_pings(SURVEY, MAP, MODEL)[3], FilterModel.from_model(MODEL, MAP))
    assert np.all(plain.exponent == 1.0)
    assert measure(belief, ping, fm).update is not None


@pytest.mark.parametrize("method", ["pf", "ipf"])
def test_a_filter_started_at_the_edge_of_the_maps_data_does_not_collapse(method):
    """Half the cloud's soundings fall where the map has no data: no data is no evidence, so the
    cloud keeps its particles there instead of collapsing onto the few with the map under every
    sounding (with the old rule one ping took the spread to zero)."""
    depth = np.array(MAP.depth)
    edge = 215.0  # north of the start: the map's data stop here
    depth[MAP.north > edge, :] = np.nan
    cut = MAP.replace(depth=depth)
    survey = multibeam_survey(MAP, pings=8, start=(200.0, 150.0), heading_deg=90.0, rate=0.5)
    model = navigation(survey, initial_position_std=15.0, sounding_std=0.5)
    config = dataclasses.replace(default_config(method), n_particles=800)
    track = run_filter(method, survey, cut, config, model=model, rng=np.random.default_rng(0))
    spread = np.sqrt(np.trace(track.covariance[:, :2, :2], axis1=1, axis2=2))
    error = np.hypot(*(track.pose[:, :2] - survey.true_pose[:, :2]).T)
    # the old rule: 37-45 m off with a spread of 0.2-0.6 m; now within its spread at every ping
    assert np.all(error < 3 * spread + 0.5), (error.round(2), spread.round(2))
    assert track.meta["n_divergences"] == 0


def test_the_compiled_exponents_match_the_reference():
    """The likelihood kernel's exponents against :func:`tangraph.sensors.information_exponent` on
    the cloud's predicted depths (a weighted cloud, some particles off the map's data)."""
    from tangraph.sensors import information_exponent

    model = MODEL.replace(map_std=0.3, map_correlation_length=20.0)
    depth = np.array(MAP.depth)
    depth[MAP.north > 240.0, :] = np.nan  # the map's data stop by the survey
    cut = MAP.replace(depth=depth)
    fm = FilterModel.from_model(model, cut)
    ping = survey_pings(SURVEY, cut, model)[5]
    rng = np.random.default_rng(7)
    belief = model_belief(SURVEY.dr_pose[5, :2], fm, 300, rng=rng, std=40.0)
    belief = reweight(belief, rng.normal(0, 1, 300), where="test")
    got = evaluate(belief, ping, fm).exponent
    residual = fm.terrain.likelihood.residuals(belief.particles, ping.offsets, ping.depths, belief.tide,
                                               turn=-belief.calibration[:, 1])
    predicted = ping.depths[None, :] - residual.T  # (N, B), NaN off the map
    assert np.isnan(predicted).any()
    want = information_exponent(predicted, belief.weights, ping.map_variance)
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)


def test_a_sounding_whose_map_lies_under_negligible_weight_is_left_out():
    """Only particles of tiny weight (1e-200) have the map under some soundings: those soundings
    are left out for all (no NaN from their weighted spread), the others weigh as usual."""
    from tangraph.filters.likelihood import TerrainLikelihood

    depth = np.array(MAP.depth)
    depth[MAP.north > 300.0, :] = np.nan
    cut = MAP.replace(depth=depth)
    like = TerrainLikelihood(cut, 0.5)
    rng = np.random.default_rng(3)
    north = np.concatenate([np.full(3, 350.0), np.full(57, 210.0), np.full(40, 260.0)])
    particles = np.column_stack([north + rng.uniform(-2, 2, 100), rng.uniform(200, 300, 100)])
    # three far north, off the map; 57 whose second sounding (80 m north) has the map; 40 without
    offsets = np.array([[0.0, 0.0], [80.0, 0.0], [-5.0, 10.0]])  # the second: north of most
    depths = np.array([80.0, 80.0, 80.0])
    weights = np.full(100, 1.0)
    weights[3:60] = 1e-200  # the particles whose second sounding has the map: negligible weight
    update = like.ping_update(particles, offsets, depths, np.zeros(100), 0.1, weights=weights,
                              variance=np.full(3, 0.5), map_variance=np.full(3, 0.04))
    assert np.all(np.isfinite(update.log_likelihood))
    assert update.exponent[1] == 0.0
    assert update.exponent[0] > 0.0 and update.exponent[2] > 0.0
