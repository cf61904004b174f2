"""TERCOM-PF and MLE (batch fixes inside a filter), JBPF's jitter, the progress bar."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.filters import (
    FilterModel,
    JBPFConfig,
    MLEConfig,
    PFConfig,
    TercomPFConfig,
    fixes,
    initial_belief,
    jbpf_step,
    pf_step,
    run_filter,
    run_particle_filter,
    survey_pings,
    tercom_pf_step,
)
from tangraph.filters.fixes import fix_due, fix_window
from tangraph.filters.steps import predict
from tangraph.sensors import NavigationModel
from tests.filters.synthetic import multibeam_survey, navigation, rough_map

MAP = rough_map(0)
SURVEY = multibeam_survey(MAP, seed=1, pings=30)
MODEL = navigation(SURVEY, initial_position_std=20.0, sounding_std=0.5)


def tercom_steps(config, belief, upto):
    model = FilterModel.from_model(MODEL, MAP, config)
    step = functools.partial(tercom_pf_step, survey=SURVEY, bathymetry=MAP)
    rng = np.random.default_rng(0)
    results = []
    for ping in survey_pings(SURVEY)[:upto]:
        results.append(step(belief, ping, model, config, rng=rng))
        belief = results[-1].belief
    return results


def test_tercom_pf_first_fix_initialises_the_cloud_then_fixes_reweight_it():
    config = TercomPFConfig(n_particles=500, window=5)
    belief = initial_belief(SURVEY.dr_pose[0, :2], 20.0, 500, rng=np.random.default_rng(1))
    results = tercom_steps(config, belief, 15)
    fixes = [r.fixes for r in results]
    assert [i for i, f in enumerate(fixes) if f] == [4, 9, 14]  # non-overlapping windows of 5
    first = fixes[4][0]
    assert first["accepted"] and first["action"] == "initialise"
    cloud = results[4].belief.particles
    np.testing.assert_allclose(
        cloud.mean(axis=0), first["position"], atol=4 * np.sqrt(np.max(first["covariance"]))
    )
    assert np.hypot(*(results[4].mean - SURVEY.true_pose[4, :2])) < 5.0
    assert fixes[9][0]["action"] == "reweight" and fixes[14][0]["action"] == "reweight"
    assert results[0].belief.n_fixes == 0 and results[14].belief.n_fixes == 3


def test_tercom_pf_recentres_on_a_fix_far_from_the_cloud():
    config = TercomPFConfig(n_particles=500, window=5, gate=13.8, min_half_width=100.0)
    belief = initial_belief(SURVEY.dr_pose[0, :2], 20.0, 500, rng=np.random.default_rng(1))
    results = tercom_steps(config, belief, 5)
    # move the cloud 40 m away after the first fix: the next fix is far outside its gate
    shifted = results[4].belief.replace(particles=results[4].belief.particles + np.array([40.0, 0.0]))
    model = FilterModel.from_model(MODEL, MAP, config)
    step = functools.partial(tercom_pf_step, survey=SURVEY, bathymetry=MAP)
    rng = np.random.default_rng(2)
    belief = shifted
    for ping in survey_pings(SURVEY)[5:10]:
        result = step(belief, ping, model, config, rng=rng)
        belief = result.belief
    record = result.fixes[0]
    assert record["accepted"] and record["action"] == "recentre" and record["mahalanobis2"] > 13.8
    assert result.counts["n_recentred"] == 1
    assert np.hypot(*(result.mean - SURVEY.true_pose[9, :2])) < 5.0


@pytest.mark.parametrize("criterion", ["mle", "msd"])
def test_tercom_pf_records_its_fixes(criterion):
    track = run_filter(
        "tercom-pf",
        SURVEY,
        MAP,
        TercomPFConfig(n_particles=300, criterion=criterion),
        model=MODEL,
        rng=np.random.default_rng(3),
    )
    meta = track.meta
    assert len(meta["fixes"]) == 6 == meta["n_fixes_accepted"] + meta["n_fixes_rejected"]
    assert meta["n_fixes_accepted"] >= 4
    assert np.hypot(*(track.pose[-1, :2] - SURVEY.true_pose[-1, :2])) < 5.0


def test_mle_jumps_to_each_fix_with_its_covariance_and_dead_reckons_between():
    track = run_filter(
        "mle", SURVEY, MAP, MLEConfig(require_accepted=False), model=MODEL, rng=np.random.default_rng(0)
    )
    fixes = track.meta["fixes"]
    assert [f["index"] for f in fixes] == [4, 9, 14, 19, 24, 29]
    for f in fixes:
        k = f["index"]
        np.testing.assert_allclose(track.pose[k, :2], f["position"])
        np.testing.assert_allclose(track.covariance[k, :2, :2], f["covariance"])
        if k + 1 < SURVEY.n_pings:  # then dead reckoning, with a growing covariance
            step = SURVEY.dr_pose[k + 1, :2] - SURVEY.dr_pose[k, :2]
            np.testing.assert_allclose(track.pose[k + 1, :2] - track.pose[k, :2], step)
            assert np.all(np.diag(track.covariance[k + 1, :2, :2]) > np.diag(track.covariance[k, :2, :2]))
    np.testing.assert_allclose(track.pose[:4, :2], SURVEY.dr_pose[:4, :2])  # before the first fix
    assert np.isnan(track.meta["ess"]).all() and track.meta["n_divergences"] == 0


def test_fix_windows_and_schedule():
    assert fix_window(MLEConfig(), SURVEY) == 5  # 30 beams per ping
    single = SURVEY.replace(
        beam_forward=SURVEY.beam_forward[:, :1],
        beam_starboard=SURVEY.beam_starboard[:, :1],
        beam_depth=SURVEY.beam_depth[:, :1],
    )
    assert fix_window(MLEConfig(), single) == 30  # about 30 soundings
    assert fix_window(MLEConfig(window=7), single) == 7
    assert [k for k in range(20) if fix_due(MLEConfig(fix_interval=3), k, 5)] == [4, 7, 10, 13, 16, 19]


def test_the_model_comes_from_the_survey_and_the_map_error_inflates_the_likelihood():
    """No model: ``NavigationModel.from_survey`` (1.5 x the recorded 0.3 m depth noise); a model's
    map error is added in quadrature to its sounding std."""
    track = run_filter("pf", SURVEY, MAP, PFConfig(n_particles=100), rng=np.random.default_rng(0))
    assert track.meta["sounding_std"] == pytest.approx(0.45)
    assert track.meta["navigation_model"] == NavigationModel.from_survey(SURVEY).as_dict()
    inflated = MODEL.replace(sounding_std=0.3, map_std=0.4)
    track = run_filter(
        "pf", SURVEY, MAP, PFConfig(n_particles=100), model=inflated, rng=np.random.default_rng(0)
    )
    assert track.meta["sounding_std"] == pytest.approx(0.5)
    recorded = SURVEY.replace(meta={})
    with pytest.raises(TangraphError, match="pf: this survey does not record its dead-reckoning error model"):
        run_filter("pf", recorded, MAP, PFConfig(n_particles=100), rng=np.random.default_rng(0))
    with pytest.raises(TangraphError, match="model must be a tangraph.sensors.NavigationModel"):
        run_filter("mle", SURVEY, MAP, model={"sounding_std": 0.5}, rng=None)


def test_jbpf_jitters_only_the_pings_it_resamples():
    model = FilterModel.from_model(MODEL, MAP)
    ping = survey_pings(SURVEY)[1]
    belief = initial_belief(SURVEY.dr_pose[0, :2], 10.0, 300, rng=np.random.default_rng(0))
    kept = jbpf_step(
        belief, ping, model, JBPFConfig(n_particles=300, ess_threshold=0.0, tempering=False),
        rng=np.random.default_rng(1),
    )  # fmt: skip
    moved = predict(belief, ping, model, rng=np.random.default_rng(1)).particles
    assert not kept.resampled
    np.testing.assert_array_equal(kept.belief.particles, moved)
    config = JBPFConfig(n_particles=300, ess_threshold=1.0, jitter_std=2.0)
    jittered = jbpf_step(belief, ping, model, config, rng=np.random.default_rng(1))
    assert jittered.resampled
    assert np.unique(jittered.belief.particles, axis=0).shape[0] == 300  # copies pulled apart
    # exactly the bootstrap step, then N(0, jitter_std^2) on its resampled particles
    rng = np.random.default_rng(1)
    plain = pf_step(belief, ping, model, config, rng=rng)
    np.testing.assert_array_equal(jittered.belief.log_weights, plain.belief.log_weights)
    np.testing.assert_array_equal(jittered.mean, plain.mean)
    assert jittered.ess == plain.ess
    np.testing.assert_allclose(
        jittered.belief.particles, plain.belief.particles + 2.0 * rng.standard_normal((300, 2))
    )


def test_the_default_fix_window_is_computed_once_per_survey(monkeypatch):
    """A TERCOM-PF step without ``window`` asks fix_window at every ping: the survey's soundings
    are scanned the first time only."""
    survey = SURVEY.replace(meta={"copy": True})  # a survey not seen yet
    config = TercomPFConfig(n_particles=200)
    assert fix_window(config, survey) == 5

    def no_scan(*args, **kwargs):
        raise AssertionError("fix_window scanned the survey again")

    monkeypatch.setattr(fixes.np, "isfinite", no_scan)
    assert fix_window(config, survey) == 5
    monkeypatch.undo()
    step = functools.partial(tercom_pf_step, survey=survey, bathymetry=MAP)  # no window passed
    track = run_particle_filter(
        survey, MAP, config, step, method="tercom-pf", rng=np.random.default_rng(3), model=MODEL,
        count_keys=COUNTS,
    )  # fmt: skip
    reference = run_filter("tercom-pf", survey, MAP, config, model=MODEL, rng=np.random.default_rng(3))
    np.testing.assert_array_equal(track.pose, reference.pose)
    assert track.meta["n_fixes_accepted"] == reference.meta["n_fixes_accepted"] > 0


COUNTS = ("n_fixes_accepted", "n_fixes_rejected", "n_recentred")


def test_progress_bar(capsys):
    config = PFConfig(n_particles=50)
    run_filter("pf", SURVEY, MAP, config, model=MODEL, rng=np.random.default_rng(0), progress=True)
    assert "pf" in capsys.readouterr().err
