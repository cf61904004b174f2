"""The shared loop pieces: pure steps, moments, empty pings, NaN soundings, divergence recovery,
bad configuration."""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.filters import (
    Belief,
    FilterModel,
    IPFConfig,
    JBPFConfig,
    MLEConfig,
    PFConfig,
    Ping,
    SJCPFConfig,
    TercomPFConfig,
    initial_belief,
    ipf_step,
    jbpf_step,
    pf_step,
    run_filter,
    sjcpf_step,
    survey_pings,
    tercom_pf_step,
    weighted_moments,
)
from tests.filters.synthetic import multibeam_survey, rough_map

MAP = rough_map(0)
SURVEY = multibeam_survey(MAP, pings=12)


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
    "pf": (pf_step, PFConfig(n_particles=200, init_std=10.0, sounding_std=0.5)),
    "ipf": (ipf_step, IPFConfig(n_particles=200, init_std=10.0, sounding_std=0.5, ess_threshold=1.0)),
    "sjcpf": (sjcpf_step, SJCPFConfig(n_particles=200, init_std=10.0, sounding_std=0.5, window=3)),
    "jbpf": (jbpf_step, JBPFConfig(n_particles=200, init_std=10.0, sounding_std=0.5, ess_threshold=1.0)),
    "tercom-pf": (
        functools.partial(tercom_pf_step, survey=SURVEY, bathymetry=MAP),
        TercomPFConfig(n_particles=200, init_std=10.0, window=3),
    ),
}


@pytest.mark.parametrize("name", list(STEPS))
def test_steps_return_a_new_belief_and_leave_their_inputs_alone(name):
    step, config = STEPS[name]
    model = FilterModel.from_config(config, MAP)
    pings = survey_pings(SURVEY)
    rng = np.random.default_rng(1)
    window = getattr(config, "window", 0) if name == "sjcpf" else 0
    belief = initial_belief(SURVEY.dr_pose[0, :2], 10.0, 200, rng=rng, history_length=window)
    for ping in pings[:4]:
        before = {f.name: np.copy(getattr(belief, f.name)) for f in dataclasses.fields(belief)}
        result = step(belief, ping, model, config, rng=rng)  # read-only inputs: writing would raise
        for key, value in before.items():
            np.testing.assert_array_equal(getattr(belief, key), value, err_msg=key)
        assert result.belief is not belief
        assert np.isclose(np.exp(result.belief.log_weights).sum(), 1.0)
        belief = result.belief


def test_a_ping_without_soundings_only_predicts():
    config = PFConfig(n_particles=50, ess_threshold=0.0)
    model = FilterModel.from_config(config, MAP)
    belief = initial_belief([300.0, 300.0], 5.0, 50, rng=np.random.default_rng(2))
    belief = belief.replace(log_weights=np.log(np.linspace(1, 2, 50) / np.linspace(1, 2, 50).sum()))
    empty = Ping(3, np.array([10.0, 0.0]), np.zeros((0, 2)), np.zeros(0))
    result = pf_step(belief, empty, model, config, rng=np.random.default_rng(3))
    np.testing.assert_array_equal(result.belief.log_weights, belief.log_weights)
    assert np.all(
        np.abs(result.belief.particles - belief.particles - [10.0, 0.0])
        < 6 * model.motion.noise_std([10.0, 0])
    )


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
    config = PFConfig(n_particles=300, init_std=10.0, sounding_std=0.5)
    a = run_filter("pf", with_nan, MAP, config, rng=np.random.default_rng(4))
    b = run_filter("pf", cut, MAP, config, rng=np.random.default_rng(4))
    assert np.all(np.isfinite(a.pose))
    np.testing.assert_array_equal(a.pose, b.pose)


@pytest.mark.parametrize("method", ["pf", "ipf", "sjcpf", "jbpf"])
def test_all_particles_off_the_map_is_a_divergence_not_an_error(method):
    """Dead reckoning starts 400 m south of the map (the truth is on it): every particle is off
    the map, so the filter re-initialises with a growing spread until it finds the map again."""
    shift = np.array([-400.0, 0.0, 0.0])
    survey = SURVEY.replace(dr_pose=SURVEY.dr_pose + shift)
    config = {"pf": PFConfig, "ipf": IPFConfig, "sjcpf": SJCPFConfig, "jbpf": JBPFConfig}[method](
        n_particles=2000, init_std=10.0, sounding_std=0.5, reinit_std=40.0, reinit_growth=2.0
    )
    track = run_filter(method, survey, MAP, config, rng=np.random.default_rng(5))
    steps = track.meta["divergence_steps"]
    assert track.meta["n_divergences"] == len(steps) >= 1
    assert steps == list(range(len(steps)))  # consecutive from ping 0, then the map is found
    assert len(steps) < survey.n_pings
    assert np.all(np.isfinite(track.pose))
    assert np.hypot(*(track.pose[-1, :2] - survey.dr_pose[-1, :2])) > 100  # it left dead reckoning


@pytest.mark.parametrize("value", [0, -5, 2.5, True, "10"])
def test_bad_particle_count_is_named(value):
    for cls in (PFConfig, IPFConfig, SJCPFConfig, JBPFConfig, TercomPFConfig):
        with pytest.raises(TangraphError, match=f"{cls.__name__}: n_particles"):
            cls(n_particles=value)


@pytest.mark.parametrize(
    ("cls", "field", "value"),
    [
        (PFConfig, "sounding_std", 0.0),
        (PFConfig, "init_std", -1.0),
        (PFConfig, "process_std", np.nan),
        (PFConfig, "ess_threshold", 1.5),
        (PFConfig, "resampler", "bogus"),
        (PFConfig, "reinit_std", 0.0),
        (PFConfig, "reinit_growth", 0.5),
        (PFConfig, "tide_std", -1.0),
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
    with pytest.raises(TangraphError, match=f"{cls.__name__}: {field}"):
        cls(**{field: value})


def test_a_vehicle_never_on_the_map_diverges_at_every_ping_with_a_capped_spread(caplog):
    survey = SURVEY.replace(dr_pose=SURVEY.dr_pose + np.array([1e5, 0.0, 0.0]))
    config = PFConfig(n_particles=200, init_std=10.0, reinit_growth=10.0)
    with caplog.at_level("WARNING", logger="tangraph.filters.core"):
        track = run_filter("pf", survey, MAP, config, rng=np.random.default_rng(6))
    assert track.meta["divergence_steps"] == list(range(survey.n_pings))
    assert np.all(np.isfinite(track.pose))
    spreads = [float(r.getMessage().rsplit("spread ", 1)[1].split()[0]) for r in caplog.records]
    diagonal = np.hypot(MAP.north[-1] - MAP.north[0], MAP.east[-1] - MAP.east[0])
    assert diagonal < 3000.0  # so the third spread (3 init_std x 10^2) is capped
    assert spreads[:2] == [30.0, 300.0]
    np.testing.assert_allclose(spreads[2:], diagonal, atol=0.1)
