"""SJCPF (tangraph.filters.sjcpf): the correlation correction step by step, and the truth recovered
from a single beam on a coarse chart."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.filters import FilterHealth, SJCPFConfig, run_filter
from tangraph.filters.belief import Belief
from tangraph.filters.correlation import pearson_rows
from tangraph.filters.model import FilterModel, MotionModel, TerrainModel, survey_pings
from tangraph.filters.sjcpf import signal_share, sjcpf_step
from tangraph.maps import fractal
from tangraph.sensors import DeadReckoningModel, NavigationModel, simulate_dead_reckoning
from tangraph.sim import trajectories
from tangraph.survey import Survey
from tests.filters.synthetic import multibeam_survey, rough_map

MAP = rough_map(0)
SURVEY = multibeam_survey(MAP, pings=6)


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
    share = signal_share(measured, 2.0**2 / ping.n_soundings)  # the gate: the terrain's share
    assert 0.5 < share < 1.0
    logw = update.log_likelihood + 3.0 * share * rho
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


def test_sjcpf_recovers_the_truth_from_a_single_beam_on_a_coarse_chart():
    """Chen & Che's setting, scaled down: 500 m cells, one sounding per 100 m, 5 m depth noise,
    2 deg heading bias and 0.1 m/s speed noise; 300 pings."""
    rng = np.random.default_rng(0)
    chart = fractal((120, 120), 500.0, rng=rng, beta=3.0, relief=300.0, mean_depth=2000.0)
    k = 300
    time, truth = trajectories.straight_line(
        np.array([5000.0, 5000.0]), np.radians(45.0), 1.0, (k - 1) * 100.0, 0.01
    )
    dr = simulate_dead_reckoning(time, truth, DeadReckoningModel.chen2022(), rng=rng).pose
    depth = chart.depth_at(truth[:, 0], truth[:, 1])[:, None] + 5.0 * rng.standard_normal((k, 1))
    zeros = np.zeros((k, 1))
    survey = Survey(time, dr, np.full(k, 100.0), zeros, zeros, depth, true_pose=truth)
    model = NavigationModel.from_dead_reckoning(
        DeadReckoningModel.chen2022(), initial_position_std=300.0, sounding_std=7.5
    )
    track = run_filter("sjcpf", survey, chart, SJCPFConfig(), model=model, rng=np.random.default_rng(1))
    rmse = np.sqrt(np.mean(np.sum((track.pose[:, :2] - truth[:, :2]) ** 2, axis=1)))
    dr_rmse = np.sqrt(np.mean(np.sum((dr[:, :2] - truth[:, :2]) ** 2, axis=1)))
    assert rmse < dr_rmse / 4, (rmse, dr_rmse)


def test_the_signal_gate_keeps_the_correlation_from_weighing_noise_on_flat_ground():
    """A seafloor whose depths vary by centimetres over the window (2 m of relief over 1 km, 0.2 m
    sounding noise): every particle's correlation is noise. The paper's kernel multiplies the
    weights by it at every ping and the cloud collapses onto a wrong place (mean final NEES over
    six runs in the hundreds); gated, the correlation weighs next to nothing and the filter
    stays within its covariance (below the chi-square(12)/6 band's 99.9 % point, 5.5)."""
    flat = rough_map(2, relief=0.3)
    nees = {False: [], True: []}
    for gate in nees:
        for seed in range(6):
            survey = multibeam_survey(flat, seed=seed, pings=150, beams=5, swath=10.0, speed=1.0, rate=1.0,
                                      noise=0.2)
            model = NavigationModel.from_survey(survey, initial_position_std=5.0, sounding_std=0.2)
            track = run_filter("sjcpf", survey, flat, SJCPFConfig(n_particles=300, signal_gate=gate),
                               model=model, rng=np.random.default_rng(seed))
            e = track.pose[-1, :2] - survey.true_pose[-1, :2]
            nees[gate].append(float(e @ np.linalg.solve(track.covariance[-1, :2, :2], e)))
    assert np.mean(nees[False]) > 20.0, nees
    assert np.mean(nees[True]) < 5.5, nees


def test_the_signal_share_of_a_sequence():
    assert signal_share(np.array([1.0, 1.0, 1.0]), 0.0) == 1.0  # no noise: all terrain
    ramp = np.arange(10.0)
    variance = float(np.var(ramp, ddof=1))
    assert signal_share(ramp, variance / 4) == pytest.approx(0.75)
    assert signal_share(ramp, variance) == 0.0
    with pytest.raises(TangraphError, match="SJCPFConfig.signal_gate must be true or false, got 'yes'"):
        SJCPFConfig(signal_gate="yes")
