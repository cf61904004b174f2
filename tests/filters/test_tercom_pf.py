"""TERCOM-PF (tangraph.filters.tercom_pf): its first fix initialises the cloud and later ones reweight
or redraw it; a fix far from the cloud re-centres it, at once or once a second fix confirms it; the
fixes it records."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from tangraph.filters import TercomPFConfig, run_filter
from tangraph.filters.belief import initial_belief, weighted_moments
from tangraph.filters.model import FilterModel, survey_pings
from tangraph.filters.steps import predict
from tangraph.filters.tercom_pf import tercom_pf_step
from tangraph.fix_records import FixStatus
from tests.filters.synthetic import multibeam_survey, navigation, rough_map

MAP = rough_map(0)
SURVEY = multibeam_survey(MAP, seed=1, pings=30)
MODEL = navigation(SURVEY, initial_position_std=20.0, sounding_std=0.5)


def tercom_steps(config, belief, upto):
    model = FilterModel.from_model(MODEL, MAP, config)
    step = functools.partial(tercom_pf_step, survey=SURVEY, bathymetry=MAP)
    rng = np.random.default_rng(0)
    results = []
    for ping in survey_pings(SURVEY)[:upto]:
        results.append(step(belief, ping, model, config, rng=rng))
        belief = results[-1].belief
    return results


def test_plain_tercom_pf_first_fix_initialises_the_cloud_then_fixes_reweight_it():
    config = TercomPFConfig(n_particles=500, window=5, confirm_probability=None)
    belief = initial_belief(SURVEY.dr_pose[0, :2], 20.0, 500, rng=np.random.default_rng(1))
    results = tercom_steps(config, belief, 15)
    fixes = [r.fixes for r in results]
    assert [i for i, f in enumerate(fixes) if f] == [4, 9, 14]  # non-overlapping windows of 5
    first = fixes[4][0]
    assert first.status is FixStatus.ACCEPTED and first.detail == "initialise"
    cloud = results[4].belief.particles
    np.testing.assert_allclose(
        cloud.mean(axis=0), first.position, atol=4 * np.sqrt(np.max(first.covariance))
    )
    assert np.hypot(*(results[4].mean - SURVEY.true_pose[4, :2])) < 5.0
    assert fixes[9][0].detail == "reweight" and fixes[14][0].detail == "reweight"
    assert results[0].belief.n_fixes == 0 and results[14].belief.n_fixes == 3


def test_tercom_pf_uses_a_fix_by_its_likelihood_redrawing_a_cloud_too_wide_for_it():
    """A fix near the prediction is Bayes' update of the cloud: a 20 m cloud holds too few
    particles inside a fix of a few metres, so the positions are drawn from the Gaussian product
    of the cloud's moments and the fix."""
    config = TercomPFConfig(n_particles=500, window=5, confirm_probability=0.9)
    belief = initial_belief(SURVEY.dr_pose[0, :2], 20.0, 500, rng=np.random.default_rng(1))
    results = tercom_steps(config, belief, 15)
    first = results[4].fixes[0]
    assert first.status is FixStatus.ACCEPTED and first.detail == "redraw"
    prior = tercom_steps(config, belief, 4)[-1]  # the prediction the first fix was judged against
    moved = predict(prior.belief, survey_pings(SURVEY)[4], FilterModel.from_model(MODEL, MAP, config),
                    rng=np.random.default_rng(0))
    mean, cov = weighted_moments(moved)
    gain = cov @ np.linalg.inv(cov + first.covariance)
    expected_mean, expected_cov = mean + gain @ (first.position - mean), cov - gain @ cov
    got_mean, got_cov = weighted_moments(results[4].belief)
    se = np.sqrt(np.diag(expected_cov) / 500)  # Monte Carlo error of the drawn cloud's mean
    assert np.all(np.abs(got_mean - expected_mean) < 4 * se)
    np.testing.assert_allclose(np.diag(got_cov), np.diag(expected_cov), rtol=4 * np.sqrt(2 / 500))
    assert np.hypot(*(results[14].mean - SURVEY.true_pose[14, :2])) < 5.0


def _shifted_steps(config, upto):
    """TERCOM-PF whose cloud is moved 40 m away after its first fix, run to ping ``upto``: the
    records its steps wrote, in order, and the last step."""
    belief = initial_belief(SURVEY.dr_pose[0, :2], 20.0, 500, rng=np.random.default_rng(1))
    results = tercom_steps(config, belief, 5)
    belief = results[4].belief.replace(particles=results[4].belief.particles + np.array([40.0, 0.0]))
    model = FilterModel.from_model(MODEL, MAP, config)
    step = functools.partial(tercom_pf_step, survey=SURVEY, bathymetry=MAP)
    rng = np.random.default_rng(2)
    results = []
    for ping in survey_pings(SURVEY)[5:upto]:
        results.append(step(belief, ping, model, config, rng=rng))
        belief = results[-1].belief
    return [f for r in results for f in r.fixes], results[-1]


def test_plain_tercom_pf_recentres_on_a_fix_far_from_the_cloud():
    config = TercomPFConfig(n_particles=500, window=5, gate=13.8, min_half_width=100.0,
                            confirm_probability=None)
    (record,), result = _shifted_steps(config, 10)
    assert record.accepted and record.detail == "recentre" and record.nis > 13.8
    assert result.counts["n_recentred"] == 1
    assert np.hypot(*(result.mean - SURVEY.true_pose[9, :2])) < 5.0


def test_tercom_pf_holds_a_surprising_fix_until_a_second_one_confirms_it():
    """A cloud 40 m off: the next fix is held (the cloud stays where it is), the one after it
    agrees with it through the particles' own displacements and is as surprising: the cloud is
    re-centred on it."""
    config = TercomPFConfig(n_particles=500, window=5, min_half_width=100.0, confirm_probability=0.9)
    (held, settled, confirming), result = _shifted_steps(config, 15)
    assert held.status is FixStatus.HELD and held.nis > 13.8 and held.index == settled.index == 9
    assert settled.status is FixStatus.CONFIRMED and settled.detail == "by the fix at ping 14"
    assert confirming.accepted and confirming.detail == "confirms the fix at ping 9; recentre"
    assert result.counts["n_recentred"] == 1 and result.belief.held is None
    assert np.hypot(*(result.mean - SURVEY.true_pose[14, :2])) < 5.0


@pytest.mark.parametrize("criterion", ["mle", "msd"])
def test_tercom_pf_records_its_fixes(criterion):
    track = run_filter(
        "tercom-pf",
        SURVEY,
        MAP,
        TercomPFConfig(n_particles=300, criterion=criterion),
        model=MODEL,
        rng=np.random.default_rng(3),
    )
    meta = track.meta
    assert len(track.fixes) == 6 == meta["n_fixes_accepted"] + meta["n_fixes_rejected"]
    assert meta["n_fixes_accepted"] >= 4
    assert np.hypot(*(track.pose[-1, :2] - SURVEY.true_pose[-1, :2])) < 5.0
