"""The filter family through its public door (tangraph.filters.api): every filter recovers a known
truth from seeded noise, estimates an unknown tide and the DR's speed scale and heading bias, keeps a
known calibration, and its track carries what run_filter promises; run_filter dispatches, checks the
config and takes the model from the survey."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.filters import (
    FilterMethod,
    MLEConfig,
    PFConfig,
    config_type,
    default_config,
    run_filter,
)
from tangraph.sensors import NavigationModel
from tests.filters.calibrated import MAP as CALIBRATED_MAP
from tests.filters.calibrated import calibrated_survey
from tests.filters.synthetic import dr_final_error, final_error, multibeam_survey, navigation, rough_map

MAP = rough_map(0)
SURVEY = multibeam_survey(MAP, seed=1, pings=50)
MODEL = navigation(SURVEY, initial_position_std=20.0, sounding_std=0.5)

#: the run of the known-calibration test (12 pings), and of the model's test (30 pings)
SURVEY_12 = multibeam_survey(MAP, pings=12)
MODEL_12 = navigation(SURVEY_12, initial_position_std=10.0, sounding_std=0.5)
SURVEY_30 = multibeam_survey(MAP, seed=1, pings=30)
MODEL_30 = navigation(SURVEY_30, initial_position_std=20.0, sounding_std=0.5)

MULTIBEAM = {  # 50 pings of 30 beams, 0.3 m noise, a 3 deg heading bias: DR is ~25 m off at the end
    "pf": dict(n_particles=1000),
    "ipf": dict(n_particles=1000),
    "sjcpf": dict(n_particles=1000, jitter_std=1.0),
    "jbpf": dict(n_particles=1000),
    "tercom-pf": dict(n_particles=1000),
    "mle": dict(),
    "pmf": dict(),
}

# Thresholds of the recovery test. Scale: the rms slope at the footprints is 0.28 (0.20 per axis), so
# one ping's 30 soundings of 0.3 m noise bound a position to about 0.3 / sqrt(30) / 0.20 = 0.27 m
# per axis (Cramér-Rao); the particle filters reach about twice that, the fix-based ones (TERCOM-PF,
# MLE) dead-reckon between fixes 5 pings apart, drifting up to 5 x 10 m x sin(3 deg) = 2.6 m.
# Measured (in a one-off study, not run here) over 3 surveys (seeds 1, 11, 21) x 12 filter seeds
# (0-11) of every method: the mean error over pings 25-49 was at most 1.92 m (TERCOM-PF; the
# particle filters 0.75 m, sd <= 0.04 m across filter seeds), the final error at most 2.06 m (JBPF;
# sd <= 0.22 m). The thresholds are 1.5 and 2 times those maxima: a filter that lost the vehicle
# or stayed on dead reckoning (25 m off at the end) fails by far, a seed change does not.
LATE_MEAN_ERROR = 3.0  # m, 1.5 x 1.92
FINAL_ERROR = 4.0  # m, 2 x 2.06


@pytest.mark.parametrize("method", list(FilterMethod))
def test_every_filter_recovers_the_truth_on_a_multibeam_survey(method):
    config = config_type(method)(**MULTIBEAM[method])
    track = run_filter(method, SURVEY, MAP, config, model=MODEL, rng=np.random.default_rng(2))
    assert dr_final_error(SURVEY) > 20
    errors = np.hypot(*(track.pose[:, :2] - SURVEY.true_pose[:, :2]).T)
    assert errors[25:].mean() < LATE_MEAN_ERROR, errors[25:].mean()
    assert final_error(track, SURVEY) < FINAL_ERROR
    assert track.method == FilterMethod(method).value
    assert track.meta["n_divergences"] == 0
    assert track.meta["n_lost"] == 0 and track.meta["lost_steps"] == []


@pytest.mark.parametrize("method", ["pf", "ipf"])
def test_an_unknown_tide_is_estimated(method):
    """Soundings 2.5 m deeper than the map: a filter told the tide is exactly 0 is misled (it
    shifts to where the map is deeper), one that estimates it (tide_std > 0) is not."""
    survey = multibeam_survey(MAP, seed=3, pings=40, tide=2.5)
    config = config_type(method)(**MULTIBEAM[method])
    known = run_filter(
        method, survey, MAP, config, model=MODEL.replace(tide_std=0.0), rng=np.random.default_rng(4)
    )
    estimated = run_filter(
        method, survey, MAP, config, model=MODEL.replace(tide_std=5.0), rng=np.random.default_rng(4)
    )

    def late(track):
        return np.hypot(*(track.pose[20:, :2] - survey.true_pose[20:, :2]).T).mean()

    # Measured over 2 surveys (seeds 3, 13) x 12 filter seeds (0-11), pings 20-39: estimating the
    # tide, a mean error of at most 0.72 m (sd <= 0.05 m); told it is 0, at least 4.99 m (often tens
    # of metres: the 2.5 m offset over slopes of ~0.2 moves the best match by metres, or off the
    # vehicle entirely). 1.5 m is twice the former maximum, 3.0 m 0.6 times the latter minimum.
    assert late(estimated) < 1.5 < 3.0 < late(known), (late(estimated), late(known))


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
    track = run_filter(method, survey, CALIBRATED_MAP, config, model=model, rng=np.random.default_rng(51))
    c = track.meta["calibration"]
    truth_b = survey.dr_pose[-1, 2] - survey.true_pose[-1, 2]
    assert truth_b == pytest.approx(np.radians(3.0))
    assert abs(c["speed_scale"] - 0.03) < 3 * c["speed_scale_std"], c
    assert abs(c["heading_error"] - truth_b) < 3 * c["heading_error_std"], c
    assert c["speed_scale_std"] < 0.2 * model.speed_scale_std  # learnt, not the prior
    assert c["heading_error_std"] < 0.2 * model.heading_bias_std
    assert track.meta["n_lost"] == 0 and track.meta["n_divergences"] == 0
    assert np.hypot(*(track.pose[-1, :2] - survey.true_pose[-1, :2])) < 2.0


@pytest.mark.parametrize("method", ["pf", "ipf", "sjcpf", "jbpf", "tercom-pf", "mle", "pmf"])
def test_a_known_calibration_stays_as_given(method):
    """A model whose speed scale and heading bias are known (stds 0) keeps them at their prior
    mean: the filter reports them with no uncertainty."""
    model = MODEL_12.replace(speed_scale=0.01, heading_bias=0.02, speed_scale_std=0.0, heading_bias_std=0.0)
    config = config_type(method)(n_particles=200) if method not in ("mle", "pmf") else None
    track = run_filter(method, SURVEY_12, MAP, config, model=model, rng=np.random.default_rng(2))
    c = track.meta["calibration"]
    assert c["speed_scale"] == pytest.approx(0.01) and c["speed_scale_std"] == pytest.approx(0.0, abs=1e-12)
    assert np.all(np.isfinite(track.pose[:, :2])) and np.all(np.isfinite(track.covariance[:, :2, :2]))


@pytest.mark.parametrize("method", list(FilterMethod))
def test_the_track_carries_what_the_api_promises(method):
    survey = multibeam_survey(MAP, seed=5, pings=12)
    config = config_type(method)(
        **{k: (200 if k == "n_particles" else v) for k, v in MULTIBEAM[method].items()}
    )
    track = run_filter(FilterMethod(method), survey, MAP, config, model=MODEL, rng=np.random.default_rng(6))
    assert track.method == method and track.pose.shape == (12, 3)
    np.testing.assert_array_equal(track.pose[:, 2], survey.dr_pose[:, 2])
    assert np.all(np.isnan(track.covariance[:, 2, :])) and np.all(np.isnan(track.covariance[:, :, 2]))
    assert np.all(np.linalg.eigvalsh(track.covariance[:, :2, :2]) >= -1e-9)
    for key in ("ess", "n_resampled", "n_divergences", "divergence_steps", "n_lost", "lost_steps", "config"):
        assert key in track.meta, key
    assert set(track.meta["calibration"]) == {
        "speed_scale", "speed_scale_std", "heading_error", "heading_error_std"
    }  # fmt: skip
    assert all(np.isfinite(v) for v in track.meta["calibration"].values())
    assert track.meta["navigation_model"] == MODEL.as_dict()
    assert len(track.meta["ess"]) == 12
    assert set(track.timings) >= {"total", "per_step"} and track.timings["total"] > 0
    assert track.meta["config"] == dataclasses.asdict(config) | {
        k: v.value for k, v in dataclasses.asdict(config).items() if hasattr(v, "value")
    }


def test_run_filter_refuses_another_methods_config_and_unknown_methods():
    with pytest.raises(TangraphError, match="'ipf' takes a IPFConfig.*got PFConfig"):
        run_filter("ipf", SURVEY, MAP, PFConfig(), rng=np.random.default_rng(0))
    with pytest.raises(TangraphError, match="MLEConfig"):
        run_filter("mle", SURVEY, MAP, {"window": 3}, rng=np.random.default_rng(0))
    with pytest.raises(TangraphError, match="unknown filter method 'ukf'"):
        run_filter("ukf", SURVEY, MAP, rng=np.random.default_rng(0))
    with pytest.raises(TangraphError, match="unknown filter method of type Survey; known: pf, ") as caught:
        run_filter(SURVEY, "pf", MAP, rng=np.random.default_rng(0))  # arguments swapped: no repr of a survey
    assert "\n" not in str(caught.value)


def test_default_configs():
    assert [m.value for m in FilterMethod] == ["pf", "ipf", "sjcpf", "jbpf", "tercom-pf", "mle", "pmf"]
    for method in FilterMethod:
        assert type(default_config(method)) is config_type(method)
    sjcpf = default_config("sjcpf")  # Chen & Che's 15 m (variance 225 m^2) at 100 m per sounding
    assert sjcpf.jitter_std is None and sjcpf.jitter_fraction * 100.0 == pytest.approx(15.0)
    assert default_config("ipf").n_particles == 2000  # Han et al.'s replay
    assert isinstance(default_config("mle"), MLEConfig)


def test_the_model_comes_from_the_survey_and_the_map_error_inflates_the_likelihood():
    """No model: ``NavigationModel.from_survey`` (1.5 x the recorded 0.3 m depth noise); a model's
    map error is added in quadrature to its sounding std."""
    track = run_filter("pf", SURVEY_30, MAP, PFConfig(n_particles=100), rng=np.random.default_rng(0))
    assert track.meta["sounding_std"] == pytest.approx(0.45)
    assert track.meta["navigation_model"] == NavigationModel.from_survey(SURVEY_30).as_dict()
    inflated = MODEL_30.replace(sounding_std=0.3, map_std=0.4)
    track = run_filter(
        "pf", SURVEY_30, MAP, PFConfig(n_particles=100), model=inflated, rng=np.random.default_rng(0)
    )
    assert track.meta["sounding_std"] == pytest.approx(0.5)
    recorded = SURVEY_30.replace(meta={})
    with pytest.raises(TangraphError, match="pf: this survey does not record its dead-reckoning error model"):
        run_filter("pf", recorded, MAP, PFConfig(n_particles=100), rng=np.random.default_rng(0))
    with pytest.raises(TangraphError, match="model must be a tangraph.sensors.NavigationModel"):
        run_filter("mle", SURVEY_30, MAP, model={"sounding_std": 0.5}, rng=None)
