"""The calibration variable: the DR-frame map, its factor's Jacobians, recovery of a known scale and
heading bias, and the honesty of the DR covariance it carries when nothing corrects it."""

from __future__ import annotations

import gtsam
import numpy as np
import pytest
from scipy import stats

from tangraph.graph import GraphConfig, GraphNavigator, navigate_online, smooth_survey
from tangraph.graph.calibration import (
    CALIBRATION,
    to_world,
    world_jacobian,
    world_position_factor,
)
from tangraph.sensors import DeadReckoningModel, NavigationModel, simulate_dead_reckoning
from tangraph.survey import Survey


def _numerical(f, x, eps=1e-6):
    x = np.asarray(x, float)
    cols = []
    for i in range(x.size):
        d = np.zeros_like(x)
        d[i] = eps
        cols.append((f(x + d) - f(x - d)) / (2 * eps))
    return np.column_stack(cols)


def test_the_dr_frame_maps_a_scaled_turned_track_back_onto_the_truth():
    rng = np.random.default_rng(1)
    truth = np.column_stack([rng.normal(0, 100, (20, 2)), rng.uniform(-3, 3, 20)])
    origin, k, b = np.array([5.0, -7.0]), 0.03, np.deg2rad(3.5)
    c, s = np.cos(b), np.sin(b)
    dr = truth.copy()
    dr[:, :2] = origin + (1 + k) * (truth[:, :2] - origin) @ np.array([[c, -s], [s, c]]).T
    dr[:, 2] = truth[:, 2] + b
    np.testing.assert_allclose(to_world(dr, [k, b], origin), truth, atol=1e-9)


def test_world_jacobian_matches_numerical_derivatives():
    origin = np.array([10.0, 20.0])
    y = np.array([130.0, -45.0, 0.7, 0.03, 0.05])
    num = _numerical(lambda v: to_world(v[:3], v[3:], origin), y)
    np.testing.assert_allclose(world_jacobian(y[:3], y[3:], origin), num, atol=1e-6)


def test_world_position_factor_jacobians_match_numerical_derivatives():
    origin = np.array([3.0, -4.0])
    factor = world_position_factor(7, [120.0, 80.0], np.array([[4.0, 1.0], [1.0, 2.0]]), origin)
    pose, calib = gtsam.Pose2(150.0, 60.0, 0.4), np.array([0.02, -0.04])
    values = gtsam.Values()
    values.insert(7, pose)
    values.insert(CALIBRATION, calib)
    linear = factor.linearize(values)
    a, _ = linear.jacobian()  # whitened [H_pose H_c]

    def whitened(delta):
        v = gtsam.Values()
        v.insert(7, pose.retract(delta[:3]))
        v.insert(CALIBRATION, calib + delta[3:])
        return factor.whitenedError(v)

    np.testing.assert_allclose(a, _numerical(whitened, np.zeros(5)), atol=1e-6)


@pytest.mark.parametrize("run", [navigate_online, smooth_survey])
def test_recovers_a_known_scale_and_heading_bias(biased_survey, rough_map, run):
    track = run(biased_survey, rough_map, GraphConfig(key_interval=20.0))
    c = track.meta["calibration"]
    assert abs(c["speed_scale"] - 0.03) < 3 * c["speed_scale_std"] and c["speed_scale_std"] < 0.005
    truth = biased_survey.dr_pose[-1, 2] - biased_survey.true_pose[-1, 2]
    assert abs(c["heading_error"] - truth) < 3 * c["heading_error_std"] and c["heading_error_std"] < 0.005
    error = np.hypot(*(track.pose[:, :2] - biased_survey.true_pose[:, :2]).T)
    # the DR is off by tens of metres; the online track starts 10 m uncertain (the start error)
    assert np.sqrt(np.mean(error**2)) < (4.0 if run is navigate_online else 2.0)


def test_a_known_calibration_is_used_as_given_and_not_estimated(biased_survey, rough_map):
    """A model that knows the DR's constant errors (stds 0) holds the calibration at them: the
    smoothed track is as good as the one that estimates them, its reported calibration is the
    given one with no uncertainty; an old config asking not to estimate it is refused, naming
    the model's way to say so."""
    from tangraph.errors import TangraphError

    heading = float(np.deg2rad(3.0))
    known = NavigationModel.from_survey(biased_survey, speed_scale=0.03, heading_bias=heading,
                                        speed_scale_std=0.0, heading_bias_std=0.0)
    track = smooth_survey(biased_survey, rough_map, GraphConfig(key_interval=20.0), model=known)
    c = track.meta["calibration"]
    assert c["speed_scale"] == pytest.approx(0.03, abs=1e-5) and c["speed_scale_std"] < 1e-5
    assert c["heading_bias"] == pytest.approx(heading, abs=1e-5) and c["heading_bias_std"] < 1e-5
    error = np.hypot(*(track.pose[:, :2] - biased_survey.true_pose[:, :2]).T)
    assert np.sqrt(np.mean(error**2)) < 2.0
    with pytest.raises(TangraphError, match="estimate_calibration is no longer a setting: .*bias_std"):
        GraphConfig.from_mapping({"estimate_calibration": False})


def test_without_the_calibration_the_same_survey_is_lost(biased_survey, rough_map):
    known = NavigationModel.from_survey(biased_survey, speed_scale_std=0.0, heading_bias_std=0.0)
    raw = smooth_survey(biased_survey, rough_map, GraphConfig(key_interval=20.0), model=known)
    error = np.hypot(*(raw.pose[:, :2] - biased_survey.true_pose[:, :2]).T)
    assert np.sqrt(np.mean(error**2)) > 5.0


def _dr_survey(model: NavigationModel, scale: float, bias: float, rng, n: int = 200) -> Survey:
    t = np.arange(n) * 2.0
    psi = 0.4 + 0.002 * t
    step = 2.0 * np.column_stack([np.cos(psi), np.sin(psi)])
    truth = np.column_stack([np.cumsum(step, axis=0) - step[0], psi])
    start = truth[0] + np.array([*rng.normal(0.0, model.initial_position_std, 2), 0.0])
    dr = simulate_dead_reckoning(t, truth, DeadReckoningModel(
        heading_bias=bias, speed_scale=scale, speed_noise=model.speed_noise, heading_walk=model.heading_walk),
        rng=rng, start_pose=start)
    ones = np.ones((n, 1))
    return Survey(time=t, dr_pose=dr.pose, vehicle_depth=ones[:, 0], beam_forward=0 * ones,
                  beam_starboard=0 * ones, beam_depth=50 * ones, true_pose=truth)


def test_dr_covariance_is_honest_when_nothing_corrects_it(rough_map):
    """Constant errors drawn from their prior, no fix: the final NEES over independent runs lies in
    the chi-square band (the scale and bias are uncertain calibration, not white noise)."""
    model = NavigationModel(speed_noise=0.05, heading_walk=1e-4, speed_scale_std=0.02,
                            heading_bias_std=np.deg2rad(2.0), initial_position_std=2.0)
    rng = np.random.default_rng(11)
    nees = []
    runs = 60
    for _ in range(runs):
        k, b = rng.normal(0.0, model.speed_scale_std), rng.normal(0.0, model.heading_bias_std)
        survey = _dr_survey(model, k, b, rng)
        config = GraphConfig().replace(n_pings=10_000, ramp_pings=None, key_interval=30.0)
        track = GraphNavigator(survey, rough_map, config, model=model).run().track()
        e = track.pose[-1, :2] - survey.true_pose[-1, :2]
        nees.append(e @ np.linalg.solve(track.covariance[-1, :2, :2], e))
    lo, hi = stats.chi2.ppf([0.005, 0.995], 2 * runs) / runs
    assert lo < np.mean(nees) < hi
