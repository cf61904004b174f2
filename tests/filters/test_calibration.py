"""The particles' constant DR errors, tempering and the lost test: recovery of a known speed scale
and heading bias, the ESS of tempered updates, and a filter that reports itself lost."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.filters import FilterHealth, PFConfig, config_type, run_filter
from tangraph.filters.belief import calibration_estimate, initial_belief, state_moments
from tangraph.filters.model import FilterModel, Ping
from tangraph.filters.steps import measure, shrink_calibration
from tangraph.sensors import DeadReckoningModel
from tests.filters.synthetic import multibeam_survey, navigation, rough_map

MAP = rough_map(0, shape=(300, 300))
DR = DeadReckoningModel(speed_scale=0.03, heading_bias=np.radians(3.0), speed_noise=0.05)


def calibrated_survey(seed, pings=80):
    """80 pings of 30 beams (800 m) from a DR reading 3 % fast and turned 3 deg clockwise."""
    return multibeam_survey(MAP, seed=seed, pings=pings, dr_model=DR, start=(300.0, 300.0), heading_deg=45.0)


# Measured (one-off study, not run here) on surveys 1-5, filters seeded 50 + survey, 2000
# particles: the errors of k and b in reported sigmas were within 1.6 and 1.0 (PF), 0.9 and 2.5
# (IPF), 2.9 and 2.7 (JBPF); the posterior std of k was 0.0025-0.0035 (prior 0.03) and of b
# 0.04-0.11 deg (prior 3 deg). The test asks for 3 sigma on the survey where all were within 1.6.
@pytest.mark.parametrize("method", ["pf", "ipf", "jbpf"])
def test_a_known_speed_scale_and_heading_bias_are_recovered(method):
    survey = calibrated_survey(1)
    model = navigation(survey)  # priors of mean 0: std 3 % (k) and 3 deg (b)
    assert model.speed_scale == 0.0 and model.heading_bias == 0.0
    config = config_type(method)(n_particles=2000)
    track = run_filter(method, survey, MAP, config, model=model, rng=np.random.default_rng(51))
    c = track.meta["calibration"]
    truth_b = survey.dr_pose[-1, 2] - survey.true_pose[-1, 2]
    assert truth_b == pytest.approx(np.radians(3.0))
    assert abs(c["speed_scale"] - 0.03) < 3 * c["speed_scale_std"], c
    assert abs(c["heading_error"] - truth_b) < 3 * c["heading_error_std"], c
    assert c["speed_scale_std"] < 0.2 * model.speed_scale_std  # learnt, not the prior
    assert c["heading_error_std"] < 0.2 * model.heading_bias_std
    assert track.meta["n_lost"] == 0 and track.meta["n_divergences"] == 0
    assert np.hypot(*(track.pose[-1, :2] - survey.true_pose[-1, :2])) < 2.0


def test_tempering_keeps_the_ess_above_its_threshold_on_a_very_peaked_likelihood():
    """A cloud of 50 m std and a ping of 30 soundings with a 5 cm sounding std: one update leaves
    a handful of particles; the tempered one keeps every stage's ESS at or above half the ESS
    before it (the threshold), ends near the truth, and its exponents sum to 1."""
    survey = calibrated_survey(2, pings=3)
    model = FilterModel.from_model(navigation(survey, sounding_std=0.05, tide_std=0.0), MAP)
    truth = survey.true_pose[0, :2]
    north, east = survey.footprints(survey.true_pose)  # offsets without heading error
    offsets = np.column_stack([north[0] - truth[0], east[0] - truth[1]])
    ping = Ping(1, np.zeros(2), offsets, survey.beam_depth[0], dt=0.0)
    n = 4000
    belief = initial_belief(truth, 50.0, n, rng=np.random.default_rng(3))
    plain = measure(belief, ping, model)
    assert plain.stage_ess[0] < 10
    config = PFConfig(n_particles=n, tempering_ess=0.5, max_stages=100,  # tempering alone
                      health=FilterHealth(ping_gate=False))
    tempered = measure(belief, ping, model, config, rng=np.random.default_rng(4))
    assert len(tempered.exponents) > 3 and tempered.tempered
    assert sum(tempered.exponents) == pytest.approx(1.0)
    assert all(0 < phi <= 1 for phi in tempered.exponents)
    assert min(tempered.stage_ess) >= 0.5 * n * (1 - 1e-6)  # after each resampling the ESS is n
    mean = tempered.belief.weights @ tempered.belief.particles
    assert np.hypot(*(mean - truth)) < 1.0


def test_a_dead_reckoning_500_m_off_the_truth_reports_itself_lost():
    """The DR (and so the cloud) 500 m north of the truth, still on the map: no particle is ever
    off the map (no divergence), but no particle explains the soundings either: after the first
    lost_pings inconsistent pings, every ping is lost. The same survey unshifted is never lost."""
    survey = calibrated_survey(3, pings=40)
    model = navigation(survey)
    config = PFConfig(n_particles=500)
    good = run_filter("pf", survey, MAP, config, model=model, rng=np.random.default_rng(5))
    assert good.meta["n_lost"] == 0 and good.meta["lost_steps"] == []
    shifted = survey.replace(dr_pose=survey.dr_pose + np.array([500.0, 0.0, 0.0]))
    lost = run_filter("pf", shifted, MAP, config, model=model, rng=np.random.default_rng(5))
    assert lost.meta["n_divergences"] == 0
    steps = lost.meta["lost_steps"]
    assert lost.meta["n_lost"] == len(steps) >= survey.n_pings - 5
    assert steps[0] == config.health.lost_pings - 1  # the third inconsistent ping in a row
    assert steps == sorted(steps)


def test_the_calibration_kernel_keeps_the_cloud_s_moments():
    """Liu-West shrinkage conditional on the position: over many draws the calibration's mean,
    covariance and covariance with the position are those of the cloud before."""
    rng = np.random.default_rng(6)
    n = 200000
    cov = np.array([[4.0, 1.0, 0.02, 0.001], [1.0, 9.0, -0.01, 0.002], [0.02, -0.01, 1e-3, 1e-5],
                    [0.001, 0.002, 1e-5, 4e-4]])  # fmt: skip
    state = rng.multivariate_normal([10.0, 20.0, 0.03, 0.05], cov, n)
    belief = initial_belief([0.0, 0.0], 1.0, n, rng=rng).replace(
        particles=state[:, :2], calibration=state[:, 2:]
    )
    moments = state_moments(belief)
    moved = shrink_calibration(belief, moments, 0.5, np.zeros(2), rng=rng)
    np.testing.assert_array_equal(moved.particles, belief.particles)
    after = state_moments(moved)
    sd = np.sqrt(np.diag(cov))
    assert np.all(np.abs(after[0] - moments[0]) < 4 * sd / np.sqrt(n))
    assert np.all(np.abs(after[1] - moments[1]) < 4 * np.sqrt(2) * np.outer(sd, sd) / np.sqrt(n))
    assert not np.allclose(moved.calibration, belief.calibration)
    estimate = calibration_estimate(moved)
    assert estimate["speed_scale_std"] == pytest.approx(np.sqrt(cov[2, 2]), rel=0.01)


def test_the_reported_spreads_are_those_of_the_cramer_rao_bound():
    """On a linearisable run (the cloud stays in one basin) the PF's reported final position,
    speed-scale and heading-error stds are those of the recursive posterior CRB of the same model.
    Measured (one-off, surveys 1-5, 2000 particles): ratios 0.97-1.07 and 0.97-1.09 (position),
    1.04-1.25 (k), 0.92-1.01 (b); the bounds are 0.8 and 1.4."""
    from tangraph.eval.crb import posterior_crb

    survey = calibrated_survey(1)
    model = navigation(survey)
    config = PFConfig(n_particles=2000)
    track = run_filter("pf", survey, MAP, config, model=model, rng=np.random.default_rng(51))
    bound = posterior_crb(survey, MAP, model, kind="filter")
    c = track.meta["calibration"]
    cal = np.asarray(bound.calibration_cov)
    cal = cal[-1] if cal.ndim == 3 else cal
    ratios = np.concatenate([
        np.sqrt(np.diag(track.covariance[-1, :2, :2]) / np.diag(bound.position_cov[-1])),
        [c["speed_scale_std"] / np.sqrt(cal[0, 0]), c["heading_error_std"] / np.sqrt(cal[1, 1])],
    ])  # fmt: skip
    assert np.all((0.8 < ratios) & (ratios < 1.4)), ratios
