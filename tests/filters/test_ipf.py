"""IPF's auxiliary resampling (tangraph.filters.ipf), step by step: children redrawn from their parents
and weighted by the likelihood ratio, the bootstrap update without resampling, plain copies at the
first ping, the ESS it records."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.filters import IPFConfig
from tangraph.filters.belief import initial_belief, state_moments
from tangraph.filters.ipf import ipf_step
from tangraph.filters.model import FilterModel, survey_pings
from tangraph.filters.resampling import resample
from tangraph.filters.steps import evaluate, predict, shrink_calibration
from tests.filters.synthetic import multibeam_survey, navigation, rough_map

MAP = rough_map(0)
SURVEY = multibeam_survey(MAP, pings=6)


def ipf_model(**changes):
    model = navigation(SURVEY, sounding_std=0.5, initial_position_std=15.0, **changes)
    return FilterModel.from_model(model, MAP)


def test_ipf_children_are_redrawn_from_their_parents_and_weighted_by_the_likelihood_ratio():
    config = IPFConfig(n_particles=300, ess_threshold=1.0, tempering=False)
    model = ipf_model(tide_std=1.0)
    ping = survey_pings(SURVEY)[1]
    belief = initial_belief(
        SURVEY.dr_pose[0, :2], 15.0, 300, rng=np.random.default_rng(0), tide_var=1.0,
        calibration=(0.0, 0.0), calibration_std=(0.02, 0.05),
    )  # fmt: skip
    result = ipf_step(belief, ping, model, config, rng=np.random.default_rng(7))
    # replay the step's random draws: prediction, resampling, the kernel, then the children's noise
    rng = np.random.default_rng(7)
    predicted = predict(belief, ping, model, rng=rng)
    moved = predicted.particles
    parent = evaluate(predicted, ping, model)
    w = np.exp(
        belief.log_weights + parent.log_likelihood - np.max(belief.log_weights + parent.log_likelihood)
    )
    ancestors = resample(w / w.sum(), config.resampler, rng=rng)
    np.testing.assert_array_equal(result.info["ancestors"], ancestors)
    with np.errstate(divide="ignore"):
        weighted = predicted.replace(log_weights=np.log(w / w.sum()))
    floor = config.kernel_floor * model.navigation.calibration_std
    shrunk = shrink_calibration(
        weighted.take(ancestors), state_moments(weighted), config.kernel_bandwidth, floor, rng=rng
    )
    parents, copies = result.info["parents"], result.info["copies"]
    assert copies.sum() == 300 and copies.max() > 1  # some parents have several children
    np.testing.assert_array_equal(np.repeat(parents, copies), np.sort(ancestors))
    children = result.belief.particles
    assert np.unique(children, axis=0).shape[0] == 300  # all distinct: no copies
    assert not np.any(np.all(children == moved[ancestors], axis=1))  # none is its parent
    previous = belief.take(ancestors).replace(calibration=shrunk.calibration)
    redrawn = predict(previous, ping, model, rng=rng)
    np.testing.assert_allclose(children, redrawn.particles)
    np.testing.assert_allclose(result.belief.calibration, redrawn.calibration)
    assert np.unique(result.belief.calibration[:, 0]).size == 300  # the scales were moved apart too
    child = evaluate(redrawn, ping, model)
    ratio = np.exp(child.log_likelihood - parent.log_likelihood[ancestors])
    np.testing.assert_allclose(result.belief.weights, ratio / ratio.sum(), rtol=1e-9)
    np.testing.assert_allclose(result.belief.tide, child.tide)


def test_ipf_without_resampling_is_the_bootstrap_update():
    config = IPFConfig(n_particles=200, ess_threshold=0.0, tempering=False)
    model = ipf_model()
    ping = survey_pings(SURVEY)[1]
    belief = initial_belief(SURVEY.dr_pose[0, :2], 5.0, 200, rng=np.random.default_rng(1))
    result = ipf_step(belief, ping, model, config, rng=np.random.default_rng(2))
    assert not result.resampled and "ancestors" not in result.info
    moved = predict(belief, ping, model, rng=np.random.default_rng(2)).particles
    np.testing.assert_allclose(result.belief.particles, moved)


def test_ipf_at_the_first_ping_resamples_plain_copies():
    """Ping 0 does not move the particles, so there is no transition to redraw children from
    (they would be their parents' copies, every ratio 1): the step resamples plainly."""
    config = IPFConfig(n_particles=300, ess_threshold=1.0, tempering=False)
    model = ipf_model()
    ping = survey_pings(SURVEY)[0]
    assert ping.first
    belief = initial_belief(SURVEY.dr_pose[0, :2], 15.0, 300, rng=np.random.default_rng(0))
    result = ipf_step(belief, ping, model, config, rng=np.random.default_rng(7))
    assert result.resampled and result.info["auxiliary"] is False
    parent = model.terrain.evaluate(belief.particles, belief.tide, belief.tide_var, ping)
    w = np.exp(parent.log_likelihood - parent.log_likelihood.max())
    ancestors = resample(w / w.sum(), config.resampler, rng=np.random.default_rng(7))
    np.testing.assert_array_equal(result.info["ancestors"], ancestors)
    np.testing.assert_array_equal(result.belief.particles, belief.particles[ancestors])
    np.testing.assert_allclose(result.belief.weights, 1 / 300)
    np.testing.assert_allclose(result.belief.tide, parent.tide[ancestors])
    w = w / w.sum()  # the estimate and ESS are those of the weighted cloud, as in the bootstrap PF
    assert result.ess == pytest.approx(1.0 / np.sum(w**2))
    np.testing.assert_allclose(result.mean, w @ belief.particles)


def test_ipf_records_the_ess_of_the_cloud_it_returns():
    """The estimate is taken from the re-weighted children, so the ESS recorded is theirs (after
    the likelihood-ratio weights), not the parents' before resampling."""
    config = IPFConfig(n_particles=300, ess_threshold=1.0, tempering=False)
    model = ipf_model()
    ping = survey_pings(SURVEY)[1]
    belief = initial_belief(SURVEY.dr_pose[0, :2], 15.0, 300, rng=np.random.default_rng(0))
    result = ipf_step(belief, ping, model, config, rng=np.random.default_rng(7))
    assert result.info["auxiliary"] is True
    w = result.belief.weights
    assert result.ess == pytest.approx(1.0 / np.sum(w**2))
    assert result.ess < 300 * (1 - 1e-6)  # the children's weights are not equal
    np.testing.assert_allclose(result.mean, w @ result.belief.particles)
