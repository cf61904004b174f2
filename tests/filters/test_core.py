"""The shared loop pieces: pure steps, moments, empty pings, NaN soundings, divergence recovery,
bad configuration."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.filters import (
    FilterHealth,
    IPFConfig,
    JBPFConfig,
    MLEConfig,
    PFConfig,
    SJCPFConfig,
    TercomPFConfig,
    config_type,
    run_filter,
)
from tangraph.filters.belief import Belief, initial_belief, model_belief, weighted_moments
from tangraph.filters.ipf import ipf_step
from tangraph.filters.jbpf import jbpf_step
from tangraph.filters.likelihood import TerrainLikelihood
from tangraph.filters.model import FilterModel, Ping, survey_pings
from tangraph.filters.pf import pf_step
from tangraph.filters.resampling import resample
from tangraph.filters.runner import run_particle_filter
from tangraph.filters.sjcpf import sjcpf_step
from tangraph.filters.tercom_pf import tercom_pf_step
from tests.filters.synthetic import multibeam_survey, navigation, rough_map

MAP = rough_map(0)
SURVEY = multibeam_survey(MAP, pings=12)
MODEL = navigation(SURVEY, initial_position_std=10.0, sounding_std=0.5)


def one_particle_with_all_the_weight():
    particles = np.array([[1.0, 2.0], [30.0, 40.0], [-5.0, 7.0]])
    logw = np.log(np.array([0.0, 1.0, 0.0]) + 1e-300)
    return Belief(
        particles, logw - np.log(np.exp(logw).sum()), np.zeros(3), 0.0, np.zeros((3, 0)), np.zeros(0)
    )


def test_moments_of_a_certain_belief():
    mean, cov = weighted_moments(one_particle_with_all_the_weight())
    np.testing.assert_allclose(mean, [30.0, 40.0])
    np.testing.assert_allclose(cov, np.zeros((2, 2)), atol=1e-200)


def test_belief_arrays_are_read_only():
    b = initial_belief([0.0, 0.0], 1.0, 5, rng=np.random.default_rng(0))
    with pytest.raises(ValueError):
        b.particles[0, 0] = 1.0


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


@pytest.mark.parametrize("method", ["pf", "ipf", "sjcpf", "jbpf"])
def test_a_cloud_off_the_map_keeps_the_dead_reckoning_and_its_growing_covariance(method):
    """Dead reckoning starts 400 m south of the map: no particle has the map under any ping, so
    no ping is evidence; every step is the prediction alone, never a divergence, and the filter
    says so (``off_map_steps``)."""
    shift = np.array([-400.0, 0.0, 0.0])
    survey = SURVEY.replace(dr_pose=SURVEY.dr_pose + shift)
    config = {"pf": PFConfig, "ipf": IPFConfig, "sjcpf": SJCPFConfig, "jbpf": JBPFConfig}[method](
        n_particles=2000)
    track = run_filter(method, survey, MAP, config, model=MODEL, rng=np.random.default_rng(5))
    assert track.meta["off_map_steps"] == list(range(survey.n_pings))
    assert track.meta["n_divergences"] == 0 and track.meta["n_lost"] == 0
    spread = np.sqrt(track.covariance[:, 0, 0] + track.covariance[:, 1, 1])
    assert spread[-1] > spread[0]
    assert spread[0] == pytest.approx(np.sqrt(2) * MODEL.initial_position_std, rel=0.1)
    # the mean follows the calibrated DR: within its own spread of the DR track at every ping
    assert np.all(np.hypot(*(track.pose[:, :2] - survey.dr_pose[:, :2]).T) < 3.0 * spread)


@pytest.mark.parametrize("value", [0, -5, 2.5, True, "10"])
def test_bad_particle_count_is_named(value):
    for cls in (PFConfig, IPFConfig, SJCPFConfig, JBPFConfig, TercomPFConfig):
        with pytest.raises(TangraphError, match=f"{cls.__name__}.n_particles"):
            cls(n_particles=value)


@pytest.mark.parametrize(
    ("cls", "field", "value"),
    [
        (PFConfig, "tempering_ess", 0.0),
        (PFConfig, "process_floor", -1.0),
        (PFConfig, "kernel_bandwidth", np.nan),
        (PFConfig, "kernel_bandwidth", 1.5),
        (PFConfig, "kernel_floor", -1.0),
        (PFConfig, "max_stages", 0),
        (FilterHealth, "lost_alpha", 0.0),
        (FilterHealth, "lost_pings", 0),
        (PFConfig, "ess_threshold", 1.5),
        (PFConfig, "resampler", "bogus"),
        (FilterHealth, "reinit_std", 0.0),
        (FilterHealth, "reinit_growth", 0.5),
        (SJCPFConfig, "window", 2),
        (SJCPFConfig, "kernel", "gaussian"),
        (SJCPFConfig, "correlation", "cosine"),
        (SJCPFConfig, "jitter_std", -1.0),
        (JBPFConfig, "jitter_std", -1.0),
        (TercomPFConfig, "criterion", "mad"),
        (TercomPFConfig, "window", 0),
        (TercomPFConfig, "gate", 0.0),
        (MLEConfig, "window", 0),
        (MLEConfig, "max_half_width", -3.0),
    ],
)
def test_bad_configuration_is_named(cls, field, value):
    with pytest.raises(TangraphError, match=f"{cls.__name__}.{field}"):
        cls(**{field: value})


def test_the_health_settings_are_their_own_part():
    """A filter's lost test, gate and recovery settings live in its ``health``; ``replace``
    takes them by name, a table is read as one, anything else is refused naming the field."""
    config = PFConfig(n_particles=300).replace(ping_gate=True, lost_pings=4, n_particles=200)
    assert (config.n_particles, config.health.ping_gate, config.health.lost_pings) == (200, True, 4)
    assert config.health.gate_pings == FilterHealth().gate_pings
    assert PFConfig(health={"ping_gate": True}).health == FilterHealth(ping_gate=True)
    assert config.as_dict()["health"]["lost_pings"] == 4
    with pytest.raises(TangraphError, match="PFConfig.health must be a FilterHealth, got int"):
        PFConfig(health=3)
    with pytest.raises(TypeError):
        PFConfig(ping_gate=True)  # type: ignore[call-arg]


def test_a_vehicle_never_on_the_map_follows_dead_reckoning_and_says_so(caplog):
    survey = SURVEY.replace(dr_pose=SURVEY.dr_pose + np.array([1e5, 0.0, 0.0]))
    config = PFConfig(n_particles=200)
    with caplog.at_level("WARNING", logger="tangraph.filters.runner"):
        track = run_filter("pf", survey, MAP, config, model=MODEL, rng=np.random.default_rng(6))
    assert track.meta["off_map_steps"] == list(range(survey.n_pings))
    assert track.meta["divergence_steps"] == []
    assert np.all(np.isfinite(track.pose)) and np.all(np.isfinite(track.covariance[:, :2, :2]))
    assert any("off the map" in r.getMessage() for r in caplog.records)


def belief_arrays(n=5, length=0, **changes):
    arrays = {
        "particles": np.zeros((n, 2)),
        "log_weights": np.full(n, -np.log(n)),
        "tide": np.zeros(n),
        "tide_var": 0.0,
        "history": np.zeros((n, length)),
        "measured": np.zeros(length),
    }
    return arrays | changes


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"particles": np.zeros((3, 2))}, r"log_weights must have shape \(3,\).*got \(5,\)"),
        ({"particles": np.zeros((5, 3))}, r"particles must have shape \(N, 2\), got \(5, 3\)"),
        ({"particles": np.zeros(10)}, r"particles must have shape \(N, 2\), got \(10,\)"),
        ({"tide": np.zeros(4)}, r"tide must have shape \(5,\).*got \(4,\)"),
        ({"history": np.zeros((4, 3)), "measured": np.zeros(3)}, r"history must have shape \(5, L\)"),
        ({"history": np.zeros((5, 3)), "measured": np.zeros(2)}, r"measured must have shape \(3,\)"),
        ({"history": np.zeros(5), "measured": np.zeros(0)}, r"history must have shape \(5, L\)"),
        ({"tide_var": -1.0}, "tide_var must be >= 0, got -1.0"),
        ({"n_history": 1}, "n_history must be <= L = 0, got 1"),
        ({"n_fixes": -1}, "n_fixes must be an integer >= 0, got -1"),
    ],
)
def test_a_belief_of_mismatched_arrays_is_refused(changes, message):
    """Particles (3, 2) with five weights used to give garbage moments (the compiled loop read
    past the particles); every per-particle array must have the particles' N."""
    with pytest.raises(TangraphError, match=f"Belief.{message}"):
        Belief(**belief_arrays(**changes))


def test_moments_refuse_a_replaced_belief_of_mismatched_arrays():
    belief = Belief(**belief_arrays()).replace(particles=np.zeros((3, 2)))  # replace does not check
    with pytest.raises(TangraphError, match=r"weighted_moments: .*\(3, 2\), \(5,\)"):
        weighted_moments(belief)


@pytest.mark.parametrize("centre", [[1.0, 2.0, 0.3], [[1.0, 2.0]], [np.nan, 0.0], 5.0, "here"])
def test_initial_belief_wants_a_position_not_a_pose(centre):
    with pytest.raises(TangraphError, match=r"initial_belief: centre must be a .*\(north, east\) position"):
        initial_belief(centre, 1.0, 5, rng=np.random.default_rng(0))


@pytest.mark.parametrize(("name", "value"), [("std", -1.0), ("std", np.nan), ("n", 0), ("n", 2.5)])
def test_initial_belief_names_a_bad_spread_or_count(name, value):
    args = {"std": 1.0, "n": 5} | {name: value}
    with pytest.raises(TangraphError, match=f"initial_belief: {name} must be"):
        initial_belief([0.0, 0.0], args["std"], args["n"], rng=np.random.default_rng(0))


@pytest.mark.parametrize("n", [0, -3, 2.5, True])
def test_resample_needs_at_least_one_draw(n):
    with pytest.raises(TangraphError, match=f"resample: n must be an integer >= 1, got {n!r}"):
        resample([0.5, 0.5], "systematic", rng=np.random.default_rng(0), n=n)


def test_resample_names_an_unknown_scheme():
    with pytest.raises(TangraphError, match="resample: scheme must be one of .*got 'bogus'"):
        resample([0.5, 0.5], "bogus", rng=np.random.default_rng(0))


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"offsets": np.zeros((3, 3))}, r"offsets \(B, 2\) and depths \(B,\) do not match"),
        ({"depths": np.zeros(2)}, r"offsets \(B, 2\) and depths \(B,\) do not match"),
        ({"offsets": np.array([[0.0, 0.0], [np.nan, 1.0], [0.0, 1.0]])}, "offsets must be finite"),
        ({"depths": np.array([1.0, np.inf, 2.0])}, "depths must be finite or NaN, got inf"),
        ({"increment": np.zeros(3)}, r"increment must be a finite \(2,\) array"),
        ({"increment": np.array([np.nan, 0.0])}, r"increment must be a finite \(2,\) array"),
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


def test_tide_update_checks_its_inputs_as_log_likelihood_does():
    like = TerrainLikelihood(MAP, 0.5)
    particles, offsets, depths, tide = np.zeros((4, 2)), np.zeros((3, 2)), np.ones(3), np.zeros(4)
    with pytest.raises(TangraphError, match=r"particles must have shape \(N, 2\), got \(4, 3\)"):
        like.tide_update(np.zeros((4, 3)), offsets, depths, tide, 0.0)
    with pytest.raises(TangraphError, match="offsets .* and depths .* do not match"):
        like.tide_update(particles, offsets, np.ones(2), tide, 0.0)
    with pytest.raises(TangraphError, match=r"tide must have shape \(4,\) as particles, got \(3,\)"):
        like.tide_update(particles, offsets, depths, np.zeros(3), 0.0)
    with pytest.raises(TangraphError, match="tide_var must be a finite number >= 0, got -1.0"):
        like.tide_update(particles, offsets, depths, tide, -1.0)
    # NaN depths are skipped, as log_likelihood skips them
    centre = MAP.north[100], MAP.east[100]
    particles = np.array(centre) + np.random.default_rng(0).normal(0, 5, (4, 2))
    depths = MAP.depth_at(centre[0] + offsets[:, 0], centre[1] + offsets[:, 1])
    depths[1] = np.nan
    got = like.tide_update(particles, offsets, depths, tide, 0.0)[0]
    np.testing.assert_allclose(got, like.log_likelihood(particles, offsets[[0, 2]], depths[[0, 2]]))


@pytest.mark.parametrize("method", ["pf", "mle"])
@pytest.mark.parametrize(
    ("argument", "value"),
    [
        ("rng", 0),
        ("rng", np.random.RandomState(0)),
        ("survey", "survey.npz"),
        ("bathymetry", np.zeros((3, 3))),
    ],
)
def test_run_filter_names_an_argument_of_the_wrong_type(method, argument, value):
    args = {"survey": SURVEY, "bathymetry": MAP, "rng": np.random.default_rng(0)} | {argument: value}
    with pytest.raises(TangraphError, match=f"run_filter\\('{method}'\\): {argument} must be a"):
        run_filter(method, args["survey"], args["bathymetry"], rng=args["rng"])


def test_rng_none_is_refused_by_the_random_filters_and_accepted_by_mle():
    with pytest.raises(TangraphError, match=r"rng must be a numpy.random.Generator .*got None"):
        run_filter("pf", SURVEY, MAP, rng=None)
    assert run_filter("mle", SURVEY, MAP, MLEConfig(), model=MODEL, rng=None).pose.shape == (12, 3)


def test_the_runner_itself_checks_its_arguments():
    with pytest.raises(TangraphError, match="pf: rng must be a numpy.random.Generator"):
        run_particle_filter(SURVEY, MAP, PFConfig(n_particles=10), pf_step, method="pf", rng=None)
    with pytest.raises(TangraphError, match="pf: bathymetry must be a tangraph.maps.grid.BathymetryMap"):
        run_particle_filter(SURVEY, MAP.depth, PFConfig(), pf_step, method="pf", rng=np.random.default_rng(0))


def test_the_track_records_the_seed_of_its_generator():
    config = PFConfig(n_particles=50)
    track = run_filter("pf", SURVEY, MAP, config, rng=np.random.default_rng(42))
    assert track.meta["seed"] == {"entropy": 42, "spawn_key": []}
    spawned = np.random.default_rng(np.random.SeedSequence(7, spawn_key=(2, 3)))
    seed = run_filter("pf", SURVEY, MAP, config, rng=spawned).meta["seed"]
    assert seed == {"entropy": 7, "spawn_key": [2, 3]}
    # the recorded seed gives the same track back
    again = run_filter("pf", SURVEY, MAP, config, rng=np.random.default_rng(track.meta["seed"]["entropy"]))
    np.testing.assert_array_equal(again.pose, track.pose)
    unseeded = np.random.default_rng()
    entropy = run_filter("pf", SURVEY, MAP, config, rng=unseeded).meta["seed"]["entropy"]
    assert entropy == unseeded.bit_generator.seed_seq.entropy  # an OS-drawn seed is recorded too


class CountingSeed(np.random.bit_generator.ISeedSequence):
    """A seed source that is not a numpy SeedSequence (no entropy or spawn key to record)."""

    def generate_state(self, n_words, dtype=np.uint32):
        return np.arange(1, n_words + 1, dtype=dtype)


def test_no_seed_is_recorded_for_a_generator_without_a_seed_sequence():
    rng = np.random.Generator(np.random.PCG64(CountingSeed()))
    config = PFConfig(n_particles=20)
    assert run_filter("pf", SURVEY, MAP, config, rng=rng).meta["seed"] is None


@pytest.mark.parametrize("method", ["pf", "ipf", "sjcpf"])
def test_pings_no_particle_explains_do_not_drag_the_cloud(method):
    """Two blocks of 10 pings with every depth 5 m off: with the ping gate they are not weighed
    (the cloud keeps to the dead reckoning through them, and says so); without it they drag it."""
    from tangraph.sim.faults import outlier_blocks

    survey = multibeam_survey(MAP, pings=80, seed=2)
    model = navigation(survey, initial_position_std=10.0, sounding_std=0.5)
    spoiled = outlier_blocks(survey, "depth_bias", 0.25, rng=np.random.default_rng(1), block=10,
                             bias=(5.0, 5.0))
    cls = {"pf": PFConfig, "ipf": IPFConfig, "sjcpf": SJCPFConfig}[method]
    errors = {}
    for gate in (True, False):
        config = cls(n_particles=500, health=FilterHealth(ping_gate=gate))
        track = run_filter(method, spoiled, MAP, config, model=model, rng=np.random.default_rng(3))
        errors[gate] = float(np.sqrt(np.mean(np.sum((track.pose[:, :2] - survey.true_pose[:, :2]) ** 2,
                                                    axis=1))))
        if gate:
            assert track.meta["n_gated"] >= 10
    clean = run_filter(method, survey, MAP, cls(n_particles=500), model=model, rng=np.random.default_rng(3))
    rmse_clean = float(np.sqrt(np.mean(np.sum((clean.pose[:, :2] - survey.true_pose[:, :2]) ** 2, axis=1))))
    assert clean.meta["n_gated"] == 0
    assert errors[True] <= 1.5 * rmse_clean + 1.0 < errors[False]


@pytest.mark.parametrize("method", ["pf", "ipf"])
def test_a_cloud_every_ping_disagrees_with_is_drawn_afresh(method):
    """The DR starts 25 m off while the model says 2 m: every ping is gated, the cloud keeps the
    wrong start; after ``gate_pings`` gated pings in a row it is drawn afresh around its mean
    (spread ``reinit_std``) and finds the vehicle. With no way out it stays off."""
    from tangraph.sim.faults import offset_start

    survey = multibeam_survey(MAP, pings=85, seed=5)
    model = navigation(survey, initial_position_std=2.0, sounding_std=0.5)
    wrong = offset_start(survey, [20.0, -15.0])
    cls = {"pf": PFConfig, "ipf": IPFConfig}[method]
    final = {}
    for gate_pings in (10, 10_000):
        health = FilterHealth(ping_gate=True, gate_pings=gate_pings, reinit_std=40.0)
        config = cls(n_particles=500, health=health)
        track = run_filter(method, wrong, MAP, config, model=model, rng=np.random.default_rng(6))
        final[gate_pings] = float(np.hypot(*(track.pose[-1, :2] - survey.true_pose[-1, :2])))
        assert (track.meta["n_redraws"] >= 1) == (gate_pings == 10)
    assert final[10] < 5.0 < 15.0 < final[10_000]


@pytest.mark.parametrize("method", ["pf", "ipf", "sjcpf", "jbpf", "tercom-pf", "mle", "pmf"])
def test_a_known_calibration_stays_as_given(method):
    """A model whose speed scale and heading bias are known (stds 0) keeps them at their prior
    mean: the filter reports them with no uncertainty."""
    model = MODEL.replace(speed_scale=0.01, heading_bias=0.02, speed_scale_std=0.0, heading_bias_std=0.0)
    config = config_type(method)(n_particles=200) if method not in ("mle", "pmf") else None
    track = run_filter(method, SURVEY, MAP, config, model=model, rng=np.random.default_rng(2))
    c = track.meta["calibration"]
    assert c["speed_scale"] == pytest.approx(0.01) and c["speed_scale_std"] == pytest.approx(0.0, abs=1e-12)
    assert np.all(np.isfinite(track.pose[:, :2])) and np.all(np.isfinite(track.covariance[:, :2, :2]))
