"""Tests of the dead-reckoning error model, odometry increments and their covariance."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.sensors import (
    DeadReckoning,
    DeadReckoningModel,
    NavigationModel,
    increment_covariance,
    odometry,
    simulate_dead_reckoning,
)
from tangraph.sensors.dead_reckoning import walk_variance


def straight_north(k: int = 101, dt: float = 1.0, speed: float = 1.0):
    t = dt * np.arange(k)
    return t, np.column_stack([speed * t, np.zeros(k), np.zeros(k)])


def curved_track(k: int = 121):
    """A turning track with uneven sampling and sideslip (course differs from heading)."""
    t = np.cumsum(np.r_[0.0, 1.0 + 0.5 * np.sin(np.arange(k - 1))])
    psi = 0.3 + 0.02 * t
    course = psi + 0.1
    dt = np.diff(t)
    north = np.r_[0.0, np.cumsum(1.5 * np.cos(course[:-1]) * dt)]
    east = np.r_[0.0, np.cumsum(1.5 * np.sin(course[:-1]) * dt)]
    return t, np.column_stack([north, east, psi])


def zigzag_track(k: int = 161):
    """Legs of 20 s at 1.2 m/s, each turning 135 deg in one sample, alternately either way."""
    t = np.arange(k, dtype=float)
    psi = np.radians(135.0) * (np.arange(k) // 20 % 2)
    north = np.r_[0.0, np.cumsum(1.2 * np.cos(psi[:-1]))]
    east = np.r_[0.0, np.cumsum(1.2 * np.sin(psi[:-1]))]
    return t, np.column_stack([north, east, psi])


def mc_tolerance(runs: int) -> float:
    """Four relative standard errors of a sample variance of ``runs`` Gaussian draws."""
    return 4 * np.sqrt(2 / (runs - 1))


def errors_at_end(model, t, truth, runs, seed):
    rngs = [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(runs)]
    return np.array([simulate_dead_reckoning(t, truth, model, rng=r).pose[-1] - truth[-1] for r in rngs])


# -- deterministic cases ---------------------------------------------------------------------
def test_ideal_dead_reckoning_reproduces_the_truth():
    t, truth = curved_track()
    before = truth.copy()
    dr = simulate_dead_reckoning(t, truth, DeadReckoningModel.ideal(), rng=np.random.default_rng(1))
    np.testing.assert_allclose(dr.pose, truth, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(dr.heading_error, 0.0)
    assert dr.dvl_valid.all() and dr.n_dropouts == 0
    np.testing.assert_array_equal(truth, before)  # input untouched
    assert not dr.pose.flags.writeable


@pytest.mark.parametrize("bias", [np.deg2rad(2.0), -0.3])
def test_constant_heading_bias_drifts_across_track_by_distance_sin_bias(bias):
    t, truth = straight_north(k=51, dt=2.0, speed=1.5)
    model = DeadReckoningModel(heading_bias=bias)
    dr = simulate_dead_reckoning(t, truth, model, rng=np.random.default_rng(0))
    distance = truth[:, 0]
    np.testing.assert_allclose(dr.pose[:, 1], distance * np.sin(bias), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(dr.pose[:, 0], distance * np.cos(bias), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(dr.heading_error, bias)


def test_speed_scale_gives_along_track_error_scale_times_distance():
    t, truth = straight_north(k=31, dt=3.0, speed=2.0)
    dr = simulate_dead_reckoning(t, truth, DeadReckoningModel(speed_scale=0.01), rng=np.random.default_rng(0))
    np.testing.assert_allclose(dr.pose[:, 0] - truth[:, 0], 0.01 * truth[:, 0], rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(dr.pose[:, 1], 0.0)


def test_start_pose_offsets_position_and_keeps_heading_misalignment():
    t, truth = straight_north(k=11)
    dr = simulate_dead_reckoning(t, truth, DeadReckoningModel.ideal(), rng=np.random.default_rng(0),
                                 start_pose=[5.0, -3.0, 0.1])
    np.testing.assert_allclose(dr.pose[0], [5.0, -3.0, 0.1])
    np.testing.assert_allclose(dr.heading_error, 0.1)
    np.testing.assert_allclose(dr.pose[-1, :2], [5.0 + 10 * np.cos(0.1), -3.0 + 10 * np.sin(0.1)])


def test_same_seed_same_run_and_chen2022_reading():
    t, truth = curved_track()
    model = DeadReckoningModel.chen2022()
    assert model.heading_bias == pytest.approx(np.deg2rad(2.0))
    assert model.speed_noise == 0.1 and model.heading_walk == 0.0 and model.heading_noise == 0.0
    a = simulate_dead_reckoning(t, truth, model, rng=np.random.default_rng(7))
    b = simulate_dead_reckoning(t, truth, model, rng=np.random.default_rng(7))
    np.testing.assert_array_equal(a.pose, b.pose)


def test_odometry_known_increments_and_composition():
    poses = np.array([[0.0, 0.0, np.pi / 2], [0.0, 10.0, np.pi / 2], [-5.0, 10.0, np.pi]])
    np.testing.assert_allclose(odometry(poses, 0, 1), [10.0, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(odometry(poses, 0, 2), [10.0, 5.0, np.pi / 2], atol=1e-12)
    np.testing.assert_allclose(odometry(poses, 2, 0), [-5.0, 10.0, -np.pi / 2], atol=1e-12)
    assert odometry(poses, np.array([[0, 1]]), np.array([[2], [1]])).shape == (2, 2, 3)
    # Composing each increment onto pose i gives pose j.
    _, truth = curved_track()
    i, j = np.array([0, 5, 40]), np.array([30, 100, 41])
    d = odometry(truth, i, j)
    c, s = np.cos(truth[i, 2]), np.sin(truth[i, 2])
    np.testing.assert_allclose(truth[i, 0] + c * d[:, 0] - s * d[:, 1], truth[j, 0], atol=1e-9)
    np.testing.assert_allclose(truth[i, 1] + s * d[:, 0] + c * d[:, 1], truth[j, 1], atol=1e-9)


def test_odometry_wraps_heading_change():
    poses = np.array([[0.0, 0.0, 3.1], [1.0, 0.0, -3.1]])
    assert odometry(poses, 0, 1)[2] == pytest.approx(2 * np.pi - 6.2)


def test_constant_heading_bias_cancels_in_increments():
    t, truth = curved_track()
    biased = DeadReckoningModel(heading_bias=0.05)
    dr = simulate_dead_reckoning(t, truth, biased, rng=np.random.default_rng(0))
    i, j = np.array([0, 10]), np.array([60, 120])
    np.testing.assert_allclose(odometry(dr.pose, i, j), odometry(truth, i, j), atol=1e-9)
    model = DeadReckoningModel(heading_bias=0.05, speed_scale=0.02)
    np.testing.assert_array_equal(increment_covariance(model, t, truth, i, j), 0.0)
    cov = increment_covariance(model, t, truth, i, j, include_bias=True)
    d = odometry(truth, i, j)[:, :2]
    chord = np.linalg.norm(d, axis=1)
    across = np.column_stack([-d[:, 1], d[:, 0]]) / chord[:, None]
    along = d / chord[:, None]
    np.testing.assert_allclose(np.einsum("na,nab,nb->n", across, cov[:, :2, :2], across),
                               (0.05 * chord) ** 2, rtol=1e-12)
    np.testing.assert_allclose(np.einsum("na,nab,nb->n", along, cov[:, :2, :2], along),
                               (0.02 * chord) ** 2, rtol=1e-12)


def test_increment_covariance_of_white_speed_noise_on_a_line():
    t, truth = straight_north(k=11, dt=2.0)
    cov = increment_covariance(DeadReckoningModel(speed_noise=0.1), t, truth, [0, 3, 4], [10, 4, 4])
    np.testing.assert_allclose(cov[:, 0, 0], [10 * 4 * 0.01, 4 * 0.01, 0.0])
    np.testing.assert_allclose(cov[:, 1, 1], cov[:, 0, 0])
    np.testing.assert_array_equal(cov[:, 2], 0.0)


# -- statistics against the model -------------------------------------------------------------
def test_white_speed_noise_along_track_variance():
    runs, sigma, dt = 2000, 0.1, 2.0
    t, truth = straight_north(k=101, dt=dt)
    err = errors_at_end(DeadReckoningModel(speed_noise=sigma), t, truth, runs, seed=11)
    expected = (t.size - 1) * dt**2 * sigma**2
    for axis in (0, 1):  # along and across track (both DVL axes are noisy)
        assert abs(err[:, axis].var(ddof=1) / expected - 1) < mc_tolerance(runs)
        assert abs(err[:, axis].mean()) < 4 * np.sqrt(expected / runs)


def test_heading_walk_variance_grows_linearly():
    runs, walk = 2000, 0.002
    t, truth = straight_north(k=201, dt=1.5)
    rngs = [np.random.default_rng(s) for s in np.random.SeedSequence(12).spawn(runs)]
    err = np.array([simulate_dead_reckoning(t, truth, DeadReckoningModel(heading_walk=walk), rng=r)
                    .heading_error[[100, -1]] for r in rngs])
    expected = walk**2 * (t[[100, -1]] - t[0])
    assert np.all(np.abs(err.var(axis=0, ddof=1) / expected - 1) < mc_tolerance(runs))
    assert np.all(np.abs(err.mean(axis=0)) < 4 * np.sqrt(expected / runs))


@pytest.mark.parametrize(("track", "model", "i", "j", "seed"), [
    (curved_track, DeadReckoningModel(speed_noise=0.05, heading_walk=0.003, heading_noise=0.01),
     [0, 30, 10], [40, 120, 11], 13),
    (zigzag_track, DeadReckoningModel(speed_noise=0.02, heading_turn_std=0.05, heading_noise=0.005),
     [0, 10, 30], [160, 50, 31], 16),
], ids=["time-walk", "turn-walk"])
def test_increment_covariance_matches_monte_carlo(track, model, i, j, seed):
    runs = 3000
    t, truth = track()
    i, j = np.array(i), np.array(j)
    rngs = [np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(runs)]
    truth_odo = odometry(truth, i, j)
    err = np.array([odometry(simulate_dead_reckoning(t, truth, model, rng=r).pose, i, j) - truth_odo
                    for r in rngs])
    cov = increment_covariance(model, t, truth, i, j)
    for n in range(i.size):
        sample = np.cov(err[:, n].T)
        var = np.diag(cov[n])
        assert np.all(np.abs(np.diag(sample) / var - 1) < mc_tolerance(runs) + 0.02)  # + linearisation
        # Off-diagonal: standard error of a sample covariance, sqrt((s_a s_b + s_ab^2) / (R - 1)).
        se = np.sqrt((np.outer(var, var) + cov[n] ** 2) / (runs - 1))
        assert np.all(np.abs(sample - cov[n]) < 4 * se + 0.02 * np.sqrt(np.outer(var, var)))


def test_the_heading_error_walks_with_the_angle_turned():
    """The walk's variance is heading_walk^2 t plus heading_turn_std^2 / pi per radian turned."""
    runs = 2000
    t, truth = zigzag_track()
    model = DeadReckoningModel(heading_walk=0.002, heading_turn_std=0.05)
    rngs = [np.random.default_rng(s) for s in np.random.SeedSequence(15).spawn(runs)]
    err = np.array([simulate_dead_reckoning(t, truth, model, rng=r).heading_error[[19, 21, -1]]
                    for r in rngs])
    turns = np.array([0, 1, 8]) * np.radians(135.0)
    expected = 0.002**2 * t[[19, 21, -1]] + 0.05**2 / np.pi * turns
    assert np.all(np.abs(err.var(axis=0, ddof=1) / expected - 1) < mc_tolerance(runs))
    np.testing.assert_allclose(walk_variance(0.002, 0.05, t[[19, 21, -1]], turns), expected)


def test_a_compass_deviation_curve_is_the_same_at_every_return_to_a_heading():
    t, truth = zigzag_track()
    model = DeadReckoningModel(heading_bias=0.01, heading_deviation=0.05, heading_deviation_phase=0.3)
    dr = simulate_dead_reckoning(t, truth, model, rng=np.random.default_rng(0))
    np.testing.assert_allclose(dr.heading_error, 0.01 + 0.05 * np.sin(truth[:, 2] + 0.3), atol=1e-12)
    # the walk the estimators are given for it: over a U-turn from a heading drawn at random
    # the curve changes by sqrt(2) A in RMS, as the walk of heading_turn_std over pi
    model = NavigationModel.from_dead_reckoning(DeadReckoningModel(heading_deviation=0.05))
    psi = np.linspace(0.0, 2 * np.pi, 3601)[:-1]
    change = 0.05 * (np.sin(psi + np.pi) - np.sin(psi))
    assert model.heading_turn_std == pytest.approx(np.sqrt(np.mean(change**2)), rel=1e-9)
    assert walk_variance(0.0, model.heading_turn_std, 1.0, np.pi) == pytest.approx(np.mean(change**2))
    with pytest.raises(TangraphError, match="DeadReckoningModel.heading_deviation must be >= 0"):
        DeadReckoningModel(heading_deviation=-0.01)


def test_on_a_zigzag_the_turns_dominate_the_heading_walk():
    t, truth = zigzag_track()
    turning = DeadReckoningModel(speed_noise=0.02, heading_turn_std=0.05, heading_noise=0.005)
    straight = DeadReckoningModel(speed_noise=0.02, heading_noise=0.005)
    assert (increment_covariance(turning, t, truth, 0, 160)[2, 2]
            > 10 * increment_covariance(straight, t, truth, 0, 160)[2, 2])


def test_increment_covariance_with_dvl_dropouts_whitens_the_errors():
    runs = 1500
    t, truth = curved_track()
    model = DeadReckoningModel(speed_noise=0.01, dropout_rate=40.0, dropout_duration=40.0,
                               dropout_speed_noise=0.02)
    i, j = np.array([0, 30, 60]), np.array([120, 90, 75])
    truth_odo = odometry(truth, i, j)
    z = []
    for s in np.random.SeedSequence(14).spawn(runs):
        dr = simulate_dead_reckoning(t, truth, model, rng=np.random.default_rng(s))
        cov = increment_covariance(model, t, dr.pose, i, j, dvl_valid=dr.dvl_valid)
        z.append((odometry(dr.pose, i, j) - truth_odo)[:, :2] / np.sqrt(np.diagonal(cov, 0, 1, 2)[:, :2]))
    z = np.array(z)
    assert np.all(np.abs(z.var(axis=0, ddof=1) - 1) < mc_tolerance(runs))
    # Without the dropout term the covariance is far too small.
    dr = simulate_dead_reckoning(t, truth, model, rng=np.random.default_rng(99))
    full = increment_covariance(model, t, dr.pose, 0, 120, dvl_valid=dr.dvl_valid)
    lock = increment_covariance(model, t, dr.pose, 0, 120)
    assert (~dr.dvl_valid).any() and full[0, 0] > 2 * lock[0, 0]


def test_dropout_fraction_and_count():
    rate, duration, hours, dt = 2.0, 300.0, 10_000.0, 30.0
    t = np.arange(0.0, hours * 3600 + dt, dt)
    truth = np.column_stack([t, np.zeros_like(t), np.zeros_like(t)])
    model = DeadReckoningModel(dropout_rate=rate, dropout_duration=duration)
    dr = simulate_dead_reckoning(t, truth, model, rng=np.random.default_rng(15))
    expected_n = rate * hours
    assert abs(dr.n_dropouts - expected_n) < 4 * np.sqrt(expected_n)
    # A point is covered with probability 1 - exp(-rate * mean duration) (Poisson boolean model);
    # the covered time is about a compound Poisson sum, std sqrt(2 n) * duration / T.
    lam = rate / 3600
    expected = 1 - np.exp(-lam * duration)
    std = np.sqrt(2 * expected_n) * duration / t[-1]
    assert abs(np.mean(~dr.dvl_valid) - expected) < 4 * std
    # DVL dropouts alone change nothing of a straight, error-free track... with no INS error.
    np.testing.assert_allclose(dr.pose, truth, atol=1e-6)


# -- validation -------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("field", "value"),
    [("heading_walk", -0.1), ("speed_noise", np.nan), ("speed_scale", -1.0), ("heading_bias", np.inf),
     ("dropout_rate", "often"), ("dropout_speed_noise", -1e-3)],
)
def test_model_validation_names_the_field(field, value):
    with pytest.raises(TangraphError, match=f"DeadReckoningModel.{field}"):
        DeadReckoningModel(**{field: value})


def test_dropouts_need_a_duration():
    with pytest.raises(TangraphError, match="dropout_duration"):
        DeadReckoningModel(dropout_rate=1.0)


def test_bad_inputs_are_named():
    t, truth = straight_north(k=5)
    rng = np.random.default_rng(0)
    with pytest.raises(TangraphError, match="increasing"):
        simulate_dead_reckoning(t[::-1], truth, DeadReckoningModel(), rng=rng)
    with pytest.raises(TangraphError, match="true_pose"):
        simulate_dead_reckoning(t, truth[:, :2], DeadReckoningModel(), rng=rng)
    with pytest.raises(TangraphError, match="start_pose"):
        simulate_dead_reckoning(t, truth, DeadReckoningModel(), rng=rng, start_pose=[0.0, 1.0])
    with pytest.raises(TangraphError, match="indexes poses"):
        odometry(truth, 0, 5)
    with pytest.raises(TangraphError, match="integer"):
        odometry(truth, 0.0, 1)
    with pytest.raises(TangraphError, match="i <= j"):
        increment_covariance(DeadReckoningModel(), t, truth, 3, 1)
    with pytest.raises(TangraphError, match="dvl_valid"):
        increment_covariance(DeadReckoningModel(), t, truth, 0, 1, dvl_valid=[True])
    with pytest.raises(TangraphError, match="heading_error"):
        DeadReckoning(truth, np.zeros(4), np.ones(5, bool), 0)
