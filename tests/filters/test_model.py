"""The shared model (tangraph.filters.model): motion, the terrain likelihood with a known or an
estimated (Rao-Blackwellised) tide against direct computations, and the pings: checked, NaN
soundings dropped, carrying the terrain model's variances."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import integrate

from tangraph.errors import TangraphError
from tangraph.filters import PFConfig, run_filter
from tangraph.filters.belief import initial_belief
from tangraph.filters.likelihood import TerrainLikelihood
from tangraph.filters.model import FilterModel, MotionModel, Ping, TerrainModel, survey_pings
from tangraph.filters.pf import pf_step
from tangraph.sensors import NavigationModel, sounding_variances
from tests.filters.synthetic import multibeam_survey, navigation, rough_map

MAP = rough_map(0)
SURVEY = multibeam_survey(MAP, pings=12)
MODEL = navigation(SURVEY, initial_position_std=10.0, sounding_std=0.5)


def ping(offsets, depths, index=1, increment=(0.0, 0.0)):
    return Ping(index, np.asarray(increment, float), np.asarray(offsets, float), np.asarray(depths, float))


def test_motion_without_noise_is_the_calibrated_dead_reckoned_increment():
    particles = np.array([[0.0, 0.0], [10.0, -5.0]])
    calibration = np.array([[0.0, 0.0], [0.04, np.radians(3.0)]])
    p = ping(np.zeros((0, 2)), np.zeros(0), increment=(3.0, 4.0))
    moved, kept = MotionModel(0.0).predict(particles, calibration, p, rng=np.random.default_rng(0))
    np.testing.assert_array_equal(moved[0], [3.0, 4.0])
    c, s = np.cos(np.radians(3.0)), np.sin(np.radians(3.0))
    # the DR reads 4 % long and turned 3 deg clockwise: the truth is the step turned back, shortened
    true_step = np.array([c * 3.0 + s * 4.0, -s * 3.0 + c * 4.0]) / 1.04
    np.testing.assert_allclose(moved[1], np.array([10.0, -5.0]) + true_step)
    np.testing.assert_array_equal(kept, calibration)  # no walk: the calibration stays
    first = Ping(0, np.zeros(2), np.zeros((0, 2)), np.zeros(0), first=True)
    same = MotionModel(1.0, 0.1, 0.1).predict(particles, calibration, first, rng=np.random.default_rng(0))
    assert same[0] is particles and same[1] is calibration


def test_motion_noise_is_the_model_s_white_dr_errors():
    """Speed noise over dt per axis, the white heading error across the step, jitter on top,
    and the heading error walking by heading_walk sqrt(dt)."""
    n = 20000
    p = ping(np.zeros((0, 2)), np.zeros(0), increment=(60.0, 0.0))
    p = Ping(1, p.increment, p.offsets, p.depths, dt=4.0)
    model = MotionModel(speed_noise=0.5, heading_noise=0.05, heading_walk=0.01)
    rng = np.random.default_rng(1)
    moved, cal = model.predict(np.zeros((n, 2)), np.zeros((n, 2)), p, rng=rng, extra_std=1.0)
    want = np.sqrt([2.0**2 + 1.0, 2.0**2 + 1.0 + (0.05 * 60.0) ** 2])  # along (north), across (east)
    np.testing.assert_allclose(moved.mean(axis=0), [60.0, 0.0], atol=4 * want.max() / np.sqrt(n))
    np.testing.assert_allclose(moved.std(axis=0), want, rtol=4 * np.sqrt(0.5 / n))
    np.testing.assert_allclose(np.cov(moved.T), np.diag(want**2), atol=4 * want.max() ** 2 / np.sqrt(n))
    np.testing.assert_allclose(model.noise_covariance(p, 1.0), np.diag(want**2))
    assert np.all(cal[:, 0] == 0.0)
    np.testing.assert_allclose(cal[:, 1].std(), 0.01 * 2.0, rtol=4 * np.sqrt(0.5 / n))


def test_motion_model_from_the_navigation_model():
    nav = NavigationModel(speed_noise=0.2, heading_noise=0.01, heading_walk=0.003)
    assert MotionModel.from_model(nav, floor=0.5) == MotionModel(0.2, 0.01, 0.003, 0.5)
    turning = nav.replace(heading_turn_std=0.05)
    assert MotionModel.from_model(turning).heading_turn_std == 0.05


def test_the_heading_error_walks_with_the_angle_turned():
    """A turn of 90 deg walks b by heading_turn_std^2 / 2 on top of the time walk; a ping that
    does not turn walks it by the time alone, and a model without the turn term ignores turns."""
    n = 20000
    model = MotionModel(speed_noise=0.0, heading_walk=0.01, heading_turn_std=0.1)
    turning = Ping(1, np.array([10.0, 0.0]), np.zeros((0, 2)), np.zeros(0), dt=4.0, turn=-np.pi / 2)
    straight = Ping(1, np.array([10.0, 0.0]), np.zeros((0, 2)), np.zeros(0), dt=4.0)
    tolerance = 4 * np.sqrt(0.5 / n)
    for p, variance in ((turning, 0.01**2 * 4.0 + 0.1**2 / 2), (straight, 0.01**2 * 4.0)):
        _, cal = model.predict(np.zeros((n, 2)), np.zeros((n, 2)), p, rng=np.random.default_rng(2))
        assert model.walk_variance(p) == pytest.approx(variance)
        np.testing.assert_allclose(cal[:, 1].std(), np.sqrt(variance), rtol=tolerance)
    _, cal = MotionModel(speed_noise=0.0, heading_walk=0.01).predict(
        np.zeros((n, 2)), np.zeros((n, 2)), turning, rng=np.random.default_rng(2))
    np.testing.assert_allclose(cal[:, 1].std(), 0.01 * 2.0, rtol=tolerance)


def test_known_tide_is_the_plain_gaussian_likelihood():
    m = rough_map(2, shape=(60, 60))
    rng = np.random.default_rng(3)
    particles = rng.uniform(50, 250, (100, 2))
    p = ping(rng.normal(0, 15, (20, 2)), rng.uniform(75, 85, 20))
    update = TerrainModel(m, 0.7, tide_std=0.0).evaluate(particles, np.full(100, 1.5), 0.0, p)
    want = TerrainLikelihood(m, 0.7, tide=1.5).log_likelihood(particles, p.offsets, p.depths)
    np.testing.assert_allclose(update.log_likelihood, want, rtol=1e-12)
    assert np.all(update.tide == 1.5) and update.tide_var == 0.0


def test_uncertain_tide_is_marginalised_exactly():
    """The Rao-Blackwellised weight and tide posterior against numerical integration over the tide."""
    m = rough_map(4, shape=(60, 60))
    rng = np.random.default_rng(5)
    particles = rng.uniform(80, 200, (3, 2))
    offsets = rng.normal(0, 15, (8, 2))
    sigma, tide0, tide_sd = 0.6, 1.0, 2.0
    h = m.depth_at(particles[:, 0:1] + offsets[:, 0], particles[:, 1:2] + offsets[:, 1])
    depths = h[0] + 2.2 + sigma * rng.standard_normal(8)
    update = TerrainModel(m, sigma, tide_std=tide_sd).evaluate(
        particles, np.full(3, tide0), tide_sd**2, ping(offsets, depths)
    )

    def log_joint(t, row):  # log p(z | x, t) p(t), up to the constant the model drops
        return -0.5 * np.sum((depths - h[row] - t) ** 2) / sigma**2 - 0.5 * (t - tide0) ** 2 / tide_sd**2

    log_marginal, means = np.empty(3), np.empty(3)
    for r in range(3):
        peak = float(np.mean(depths - h[r]))
        top = log_joint(peak, r)
        f = lambda t, r=r, top=top: np.exp(log_joint(t, r) - top)  # noqa: E731
        mass = integrate.quad(f, peak - 10, peak + 10, points=[peak])[0]
        log_marginal[r] = np.log(mass) + top
        means[r] = integrate.quad(lambda t, f=f: t * f(t), peak - 10, peak + 10, points=[peak])[0] / mass
    marginal = np.exp(log_marginal - log_marginal[0])
    got = update.log_likelihood - update.log_likelihood[0]
    np.testing.assert_allclose(got, np.log(marginal), atol=1e-6)
    np.testing.assert_allclose(update.tide, means, atol=1e-6)
    assert update.tide_var == pytest.approx(1 / (1 / tide_sd**2 + 8 / sigma**2))


def test_heading_error_turns_the_soundings_back():
    """A particle whose heading error is b sees its world-aligned (DR-heading) offsets turned by -b:
    with the truth's b, the soundings of a turned swath match the map again."""
    m = rough_map(3, shape=(80, 80))
    truth = np.array([200.0, 200.0])
    true_offsets = np.column_stack([np.zeros(21), np.linspace(-60, 60, 21)])
    depths = m.depth_at(truth[0] + true_offsets[:, 0], truth[1] + true_offsets[:, 1])
    b = np.radians(5.0)
    c, s = np.cos(b), np.sin(b)  # the DR heading is the true one plus b: offsets turned by +b
    dr_offsets = np.column_stack(
        [c * true_offsets[:, 0] - s * true_offsets[:, 1], s * true_offsets[:, 0] + c * true_offsets[:, 1]]
    )
    terrain = TerrainModel(m, 0.1)
    got = terrain.evaluate(np.tile(truth, (2, 1)), np.zeros(2), 0.0, ping(dr_offsets, depths), [0.0, b])
    assert got.log_likelihood[1] == pytest.approx(0.0, abs=1e-9)
    assert got.log_likelihood[0] < -10.0


def test_survey_pings_drop_nan_soundings_and_keep_empty_pings():
    m = rough_map(0)
    s = multibeam_survey(m, pings=5, beams=4)
    depth = np.array(s.beam_depth)
    depth[1, 2] = np.nan
    depth[3] = np.nan
    pings = survey_pings(s.replace(beam_depth=depth))
    assert [p.n_soundings for p in pings] == [4, 3, 4, 0, 4]
    assert pings[0].first and not pings[1].first
    np.testing.assert_allclose(pings[2].increment, s.dr_pose[2, :2] - s.dr_pose[1, :2])
    assert pings[0].dt == 0.0 and pings[2].dt == pytest.approx(s.time[2] - s.time[1])
    turned = np.angle(np.exp(1j * np.diff(s.dr_pose[:, 2])))
    np.testing.assert_allclose([p.turn for p in pings], np.r_[0.0, turned], atol=1e-12)


def test_nan_soundings_are_skipped():
    """A survey with NaN beams gives exactly the track of the survey without those beams."""
    depth = np.array(SURVEY.beam_depth)
    depth[:, 0] = np.nan
    depth[5] = np.nan  # one ping with no return at all
    with_nan = SURVEY.replace(beam_depth=depth)
    cut = with_nan.replace(
        beam_forward=SURVEY.beam_forward[:, 1:],
        beam_starboard=SURVEY.beam_starboard[:, 1:],
        beam_depth=depth[:, 1:],
    )
    config = PFConfig(n_particles=300)
    a = run_filter("pf", with_nan, MAP, config, model=MODEL, rng=np.random.default_rng(4))
    b = run_filter("pf", cut, MAP, config, model=MODEL, rng=np.random.default_rng(4))
    assert np.all(np.isfinite(a.pose))
    np.testing.assert_array_equal(a.pose, b.pose)


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"offsets": np.zeros((3, 3))}, r"offsets \(B, 2\) and depths \(B,\) do not match"),
        ({"depths": np.zeros(2)}, r"offsets \(B, 2\) and depths \(B,\) do not match"),
        ({"offsets": np.array([[0.0, 0.0], [np.nan, 1.0], [0.0, 1.0]])}, "offsets must be finite"),
        ({"depths": np.array([1.0, np.inf, 2.0])}, "depths must be finite or NaN, got inf"),
        ({"increment": np.zeros(3)}, r"increment must be a finite \(2,\) array"),
        ({"increment": np.array([np.nan, 0.0])}, r"increment must be a finite \(2,\) array"),
        ({"turn": 4.0}, r"turn must be a finite angle in \[-pi, pi\] rad, got 4.0"),
        ({"turn": "left"}, r"turn must be a finite angle in \[-pi, pi\] rad, got 'left'"),
        ({"map_variance": np.ones((2, 4))}, r"map_variance must have shape \(3,\) as depths, got \(2, 4\)"),
        ({"map_variance": np.full(3, -1.0)}, "map_variance must be finite and >= 0"),
    ],
)
def test_a_bad_ping_is_refused(fields, message):
    args = {"index": 2, "increment": np.zeros(2), "offsets": np.zeros((3, 2)), "depths": np.ones(3)}
    with pytest.raises(TangraphError, match=f"Ping 2: {message}"):
        Ping(**(args | fields))


@pytest.mark.parametrize("index", [-1, 1.5, True])
def test_a_ping_index_is_a_count(index):
    with pytest.raises(TangraphError, match="Ping: index must be an integer >= 0"):
        Ping(index, np.zeros(2), np.zeros((0, 2)), np.zeros(0))


def test_nan_depths_in_a_ping_are_dropped_not_a_divergence():
    """A NaN depth handed straight to a step (not through survey_pings) is a missing sounding:
    the step weighs the ping by the other soundings, as if the NaN one were not there."""
    config = PFConfig(n_particles=100, ess_threshold=0.0, tempering=False)
    model = FilterModel.from_model(MODEL, MAP, config)
    ping = survey_pings(SURVEY)[1]
    depths = ping.depths.copy()
    depths[[0, 7]] = np.nan
    with_nan = Ping(ping.index, ping.increment, ping.offsets, depths)
    keep = np.isfinite(depths)
    without = Ping(ping.index, ping.increment, ping.offsets[keep], depths[keep])
    assert with_nan.n_soundings == without.n_soundings == depths.size - 2
    np.testing.assert_array_equal(with_nan.offsets, without.offsets)
    belief = initial_belief(SURVEY.dr_pose[0, :2], 5.0, 100, rng=np.random.default_rng(0))
    a = pf_step(belief, with_nan, model, config, rng=np.random.default_rng(1))
    b = pf_step(belief, without, model, config, rng=np.random.default_rng(1))
    np.testing.assert_array_equal(a.belief.log_weights, b.belief.log_weights)
    all_nan = Ping(ping.index, ping.increment, ping.offsets, np.full(depths.size, np.nan))
    result = pf_step(belief, all_nan, model, config, rng=np.random.default_rng(1))  # no divergence
    np.testing.assert_array_equal(result.belief.log_weights, belief.log_weights)


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
