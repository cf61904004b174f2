"""The pieces of a filter's step (tangraph.filters.steps): every step returns a new belief and leaves
its inputs alone, a ping without soundings only predicts, the information exponent is computed once
per ping, tempering keeps the ESS above its threshold, the calibration kernel keeps the cloud's
moments."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from tangraph.filters import (
    FilterHealth,
    IPFConfig,
    JBPFConfig,
    PFConfig,
    SJCPFConfig,
    TercomPFConfig,
    steps,
)
from tangraph.filters.belief import Belief, calibration_estimate, initial_belief, model_belief, state_moments
from tangraph.filters.ipf import ipf_step
from tangraph.filters.jbpf import jbpf_step
from tangraph.filters.model import FilterModel, Ping, survey_pings
from tangraph.filters.pf import pf_step
from tangraph.filters.sjcpf import sjcpf_step
from tangraph.filters.steps import evaluate, measure, reweight, shrink_calibration
from tangraph.filters.tercom_pf import tercom_pf_step
from tests.filters.calibrated import MAP as CALIBRATED_MAP
from tests.filters.calibrated import calibrated_survey
from tests.filters.synthetic import multibeam_survey, navigation, rough_map

MAP = rough_map(0)
SURVEY = multibeam_survey(MAP, pings=12)
MODEL = navigation(SURVEY, initial_position_std=10.0, sounding_std=0.5)

STEPS = {
    "pf": (pf_step, PFConfig(n_particles=200)),
    "ipf": (ipf_step, IPFConfig(n_particles=200, ess_threshold=1.0)),
    "sjcpf": (sjcpf_step, SJCPFConfig(n_particles=200, window=3)),
    "jbpf": (jbpf_step, JBPFConfig(n_particles=200, ess_threshold=1.0)),
    "tercom-pf": (
        functools.partial(tercom_pf_step, survey=SURVEY, bathymetry=MAP),
        TercomPFConfig(n_particles=200, window=3),
    ),
}


@pytest.mark.parametrize("name", list(STEPS))
def test_steps_return_a_new_belief_and_leave_their_inputs_alone(name):
    step, config = STEPS[name]
    model = FilterModel.from_model(MODEL, MAP, config)
    pings = survey_pings(SURVEY)
    rng = np.random.default_rng(1)
    window = getattr(config, "window", 0) if name == "sjcpf" else 0
    belief = model_belief(SURVEY.dr_pose[0, :2], model, 200, rng=rng, history_length=window)
    for ping in pings[:4]:
        # a belief's arrays are read-only (writing would raise), a ping's are not: compare copies
        offsets, depths, increment = np.copy(ping.offsets), np.copy(ping.depths), np.copy(ping.increment)
        result = step(belief, ping, model, config, rng=rng)
        np.testing.assert_array_equal(ping.offsets, offsets)
        np.testing.assert_array_equal(ping.depths, depths)
        np.testing.assert_array_equal(ping.increment, increment)
        assert not belief.particles.flags.writeable and not belief.log_weights.flags.writeable
        assert not belief.calibration.flags.writeable
        assert result.belief is not belief
        assert np.isclose(np.exp(result.belief.log_weights).sum(), 1.0)
        belief = result.belief


def test_a_ping_without_soundings_only_predicts():
    config = PFConfig(n_particles=50, ess_threshold=0.0)
    model = FilterModel.from_model(MODEL, MAP, config)
    belief = initial_belief([300.0, 300.0], 5.0, 50, rng=np.random.default_rng(2))
    belief = belief.replace(log_weights=np.log(np.linspace(1, 2, 50) / np.linspace(1, 2, 50).sum()))
    empty = Ping(3, np.array([10.0, 0.0]), np.zeros((0, 2)), np.zeros(0), dt=5.0)
    result = pf_step(belief, empty, model, config, rng=np.random.default_rng(3))
    np.testing.assert_array_equal(result.belief.log_weights, belief.log_weights)
    std = np.sqrt(np.diag(model.motion.noise_covariance(empty)))
    assert np.all(std == MODEL.speed_noise * 5.0)
    assert np.all(np.abs(result.belief.particles - belief.particles - [10.0, 0.0]) < 6 * std)


def test_a_pings_exponents_and_variances_are_judged_once_per_ping():
    """Tempering stages reuse the first evaluation's judgement of the ping (its exponents and,
    where the map's error is read where the cloud puts the soundings, its variances), so their
    product is one likelihood raised to the stages' exponents (which sum to one); a cloud
    reweighted and judged afresh weighs the ping otherwise."""
    import dataclasses

    # a map whose error grows eastwards: where the cloud puts a sounding matters
    _, east = np.meshgrid(MAP.north, MAP.east, indexing="ij")
    varying = MAP.replace(depth_std=0.05 + 0.5 * (east - east.min()) / np.ptp(east), correlation_length=20.0)
    model = MODEL.replace(map_std=0.3, map_correlation_length=20.0)
    fm = FilterModel.from_model(model, varying)
    ping = survey_pings(SURVEY, varying, model)[3]
    belief = model_belief(SURVEY.dr_pose[3, :2], fm, 400, rng=np.random.default_rng(2))
    placed = dataclasses.replace(ping, map_counts=None)  # variances at the dead-reckoned footprints
    for each in (ping, placed):
        first = evaluate(belief, each, fm)
        moved = reweight(belief, first.log_likelihood, where="t")
        again = evaluate(moved, each, fm, earlier=first)
        np.testing.assert_array_equal(again.exponent, first.exponent)
        np.testing.assert_array_equal(again.variance, first.variance)
        np.testing.assert_allclose(again.log_likelihood, first.log_likelihood, rtol=1e-12)
        assert not np.allclose(evaluate(moved, each, fm).log_likelihood, first.log_likelihood, rtol=1e-6)
    # the exponents temper a ping whose map error is placed by the cloud, or not
    assert np.any(evaluate(belief, placed, fm).exponent < 1)
    assert np.any(evaluate(belief, ping, fm).exponent < 1)
    # without the map error every exponent is one
    plain = evaluate(belief, survey_pings(SURVEY, MAP, MODEL)[3], FilterModel.from_model(MODEL, MAP))
    assert np.all(plain.exponent == 1.0)
    assert measure(belief, ping, fm).update is not None


def test_tempering_keeps_the_ess_above_its_threshold_on_a_very_peaked_likelihood():
    """A cloud of 50 m std and a ping of 30 soundings with a 5 cm sounding std: one update leaves
    a handful of particles; the tempered one keeps every stage's ESS at or above half the ESS
    before it (the threshold), ends near the truth, and its exponents sum to 1."""
    survey = calibrated_survey(2, pings=3)
    model = FilterModel.from_model(navigation(survey, sounding_std=0.05, tide_std=0.0), CALIBRATED_MAP)
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


def test_the_calibration_kernel_moves_as_much_whether_resampled_at_every_ping_or_not():
    """Resampled at every ping with weights of squared coefficient of variation ``v`` each, the
    kernel moves each particle's calibration by a variance ``h^2 v`` per ping, so 500 such pings
    (``v = 0.002``: one PF resampling's worth at ``kernel_ess = 0.5``) move it as one full kernel
    does: each particle's calibration keeps a correlation of about ``a = sqrt(1 - h^2)`` with its
    ancestor's. At the full bandwidth at every ping (the old rule) it keeps ``a^500``, about 0:
    the constant errors walk."""
    rng = np.random.default_rng(3)
    n, pings, cv2 = 4000, 500, 0.002
    belief = initial_belief([0.0, 0.0], 1.0, n, rng=rng).replace(
        calibration=rng.normal(0.0, [0.02, 0.05], (n, 2)))
    model = FilterModel.from_model(MODEL, MAP)
    every_ping = SJCPFConfig(n_particles=n)
    assert every_ping.ess_threshold == 1.0 and every_ping.kernel_ess == 0.5
    start, current = belief.calibration.copy(), belief
    for _ in range(pings):
        log_w = np.sqrt(np.log1p(cv2)) * rng.standard_normal(n)  # lognormal: CV^2 = cv2
        current = current.replace(log_weights=log_w - np.log(np.exp(log_w).sum()))
        current, index, ess = steps.resample_if_needed(current, every_ping, rng=rng, model=model)
        assert index is not None and ess > 0.99 * n
        start = start[index]
    a = np.sqrt(1.0 - every_ping.kernel_bandwidth**2)
    for axis in range(2):
        r = np.corrcoef(start[:, axis], current.calibration[:, axis])[0, 1]
        assert abs(r - a) < 0.03, (axis, r, a)
    # a degenerate cloud (ESS below kernel_ess N) gets the full kernel in one step
    log_weights = np.where(np.arange(n) < n // 10, 0.0, -50.0)
    degenerate = belief.replace(log_weights=log_weights - np.log(n // 10))
    assert steps.kernel_bandwidth(every_ping, 0.1 * n, n) == every_ping.kernel_bandwidth
    moved, index, ess = steps.resample_if_needed(degenerate, every_ping, rng=rng, model=model)
    assert ess < 0.5 * n and not np.allclose(moved.calibration, belief.calibration[index])


def test_the_innovation_takes_the_map_s_misfit_scale_and_its_tail():
    """With a local misfit scale (a map that states a Student-t tail) the mean sounding's
    innovation is weighed at the scale's estimate and judged against ``F(1, 2 shape)``: a ping
    five stated sigma off is lost without the scale, not with one that has learnt that the
    patch errs at three times its stated variance; four times as far off, it still is."""
    from tangraph.filters.model import TerrainUpdate
    from tangraph.filters.steps import innovation
    from tangraph.sensors import MisfitScale

    n, b = 3, 4
    model = FilterModel.from_model(navigation(SURVEY, sounding_std=0.5, tide_std=0.0), MAP)
    belief = Belief(np.zeros((n, 2)), np.full(n, -np.log(n)), np.zeros(n), 0.0, np.empty((n, 0)), np.empty(0))
    sigma = 0.5 / np.sqrt(b)  # the stated std of a ping's mean sounding (a perfect map)
    scale = MisfitScale(shape=4.0, rate=12.0, dof=3.0, length=100.0)  # kappa = 3, 8 dof
    for off, lost_stated, lost_scaled in ((5.0, True, False), (20.0, True, True)):
        ping = Ping(1, np.zeros(2), np.zeros((b, 2)), np.full(b, 10.0 + off * sigma))
        for given, lost in ((None, lost_stated), (scale, lost_scaled)):
            update = TerrainUpdate(np.zeros(n), np.zeros(n), 0.0, np.full(n, 10.0), scale=given)
            check = innovation(belief, update, ping, model)
            expected = off**2 / (1.0 if given is None else 3.0)
            assert check.nis == pytest.approx(expected, rel=1e-9)
            assert check.dof == (np.inf if given is None else 8.0)
            assert check.nis_beyond(1e-3) is lost
    from scipy import stats

    from tangraph.filters.steps import _nis_quantile

    for dof in (1.9, 8.0, 300.0):  # the quantile is the F distribution's
        assert _nis_quantile(1e-3, dof) == pytest.approx(stats.f.isf(1e-3, 1, dof), rel=1e-9)
