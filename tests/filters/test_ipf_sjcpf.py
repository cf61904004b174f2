"""IPF's auxiliary resampling and SJCPF's correlation correction, step by step."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.filters import FilterHealth, IPFConfig, SJCPFConfig
from tangraph.filters.belief import Belief, initial_belief, state_moments
from tangraph.filters.correlation import pearson_rows
from tangraph.filters.ipf import ipf_step
from tangraph.filters.model import FilterModel, MotionModel, TerrainModel, survey_pings
from tangraph.filters.resampling import resample
from tangraph.filters.sjcpf import sjcpf_step
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


def sjcpf_belief(n=6, window=4, filled=3):
    rng = np.random.default_rng(3)
    particles = SURVEY.true_pose[1, :2] + rng.normal(0, 8, (n, 2))
    history = np.arange(n * window, dtype=float).reshape(n, window) ** 1.5
    measured = np.array([1.0, 4.0, 2.0, 8.0])[:window]
    return Belief(particles, np.full(n, -np.log(n)), np.zeros(n), 0.0, history, measured, n_history=filled)


def test_sjcpf_weights_by_likelihood_times_the_correlation_kernel():
    config = SJCPFConfig(
        n_particles=6, window=4, jitter_std=0.0, ess_threshold=0.0, kernel_constant=3.0, tempering=False
    )
    model = FilterModel(MotionModel(0.0, 0.0), TerrainModel(MAP, 2.0, 0.0))
    belief = sjcpf_belief()
    ping = survey_pings(SURVEY)[1]
    result = sjcpf_step(belief, ping, model, config, rng=np.random.default_rng(0))
    moved = belief.particles + ping.increment
    update = model.terrain.evaluate(moved, belief.tide, 0.0, ping)
    history = np.column_stack([belief.history[:, 1:], update.predicted])
    measured = np.append(belief.measured[1:], np.mean(ping.depths))
    rho = pearson_rows(history, measured)
    logw = update.log_likelihood + 3.0 * rho
    np.testing.assert_allclose(
        result.belief.log_weights, logw - np.log(np.sum(np.exp(logw - logw.max()))) - logw.max()
    )
    np.testing.assert_allclose(result.belief.history, history)
    np.testing.assert_allclose(result.belief.measured, measured)
    assert result.belief.n_history == 4 and not result.resampled


def test_sjcpf_does_not_correct_before_the_window_is_full():
    config = SJCPFConfig(n_particles=6, window=4, jitter_std=0.0, ess_threshold=0.0, tempering=False)
    model = FilterModel(MotionModel(0.0, 0.0), TerrainModel(MAP, 2.0, 0.0))
    belief = sjcpf_belief(filled=1)
    ping = survey_pings(SURVEY)[1]
    result = sjcpf_step(belief, ping, model, config, rng=np.random.default_rng(0))
    update = model.terrain.evaluate(belief.particles + ping.increment, belief.tide, 0.0, ping)
    expected = update.log_likelihood - np.max(update.log_likelihood)
    expected -= np.log(np.exp(expected).sum())
    np.testing.assert_allclose(result.belief.log_weights, expected)
    assert result.belief.n_history == 2


def test_sjcpf_history_follows_the_particles_through_resampling():
    config = SJCPFConfig(n_particles=6, window=4, jitter_std=0.0, ess_threshold=1.0, tempering=False,
                         health=FilterHealth(ping_gate=False))
    model = FilterModel(MotionModel(0.0, 0.0), TerrainModel(MAP, 0.5, 0.0))
    belief = sjcpf_belief()
    ping = survey_pings(SURVEY)[1]
    result = sjcpf_step(belief, ping, model, config, rng=np.random.default_rng(4))
    ancestors = result.info["ancestors"]
    assert result.resampled and len(set(ancestors.tolist())) < 6  # some particles were copied
    update = model.terrain.evaluate(belief.particles + ping.increment, belief.tide, 0.0, ping)
    np.testing.assert_array_equal(result.belief.particles, (belief.particles + ping.increment)[ancestors])
    np.testing.assert_array_equal(result.belief.history[:, :-1], belief.history[ancestors, 1:])
    np.testing.assert_array_equal(result.belief.history[:, -1], update.predicted[ancestors])


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
