"""The particle filters' runner (tangraph.filters.runner): its recovery policy on a step that diverges
or finds no map at chosen pings, a cloud off the map, the ping gate and a cloud drawn afresh, the
lost test, the arguments it checks, the seed it records and its progress bar."""

from __future__ import annotations

import re

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.filters import (
    FilterDivergence,
    FilterHealth,
    IPFConfig,
    JBPFConfig,
    MLEConfig,
    OffMap,
    PFConfig,
    SJCPFConfig,
    run_filter,
)
from tangraph.filters.pf import pf_step
from tangraph.filters.runner import run_particle_filter
from tests.filters.calibrated import MAP as CALIBRATED_MAP
from tests.filters.calibrated import calibrated_survey
from tests.filters.synthetic import multibeam_survey, navigation, rough_map

MAP = rough_map(0)
SURVEY = multibeam_survey(MAP, pings=12)
MODEL = navigation(SURVEY, initial_position_std=10.0, sounding_std=0.5)

#: the divergence test's run, on a map of 100 x 100 cells (its diagonal caps the fresh cloud's spread)
SMALL_MAP = rough_map(0, shape=(100, 100))
SMALL_SURVEY = multibeam_survey(SMALL_MAP, pings=12)
SMALL_MODEL = navigation(SMALL_SURVEY, initial_position_std=10.0, sounding_std=0.5)
#: the progress bar's run
SURVEY_30 = multibeam_survey(MAP, seed=1, pings=30)
MODEL_30 = navigation(SURVEY_30, initial_position_std=20.0, sounding_std=0.5)


def failing_at(diverged, off_map):
    def step(belief, ping, model, config, *, rng):
        if ping.index in diverged:
            raise FilterDivergence(f"ping {ping.index}: made to diverge")
        if ping.index in off_map:
            raise OffMap(f"ping {ping.index}: made off the map")
        return pf_step(belief, ping, model, config, rng=rng)

    return step


def test_divergences_in_a_row_widen_the_fresh_cloud_up_to_the_map_and_off_map_pings_only_predict(caplog):
    config = PFConfig(n_particles=200, health=FilterHealth(reinit_std=40.0, reinit_growth=4.0))
    step = failing_at(diverged=(2, 3, 4, 5, 8), off_map=(6, 10))
    with caplog.at_level("WARNING", logger="tangraph.filters.runner"):
        track = run_particle_filter(SMALL_SURVEY, SMALL_MAP, config, step, method="pf", model=SMALL_MODEL,
                                    rng=np.random.default_rng(3))
    pattern = re.compile(r"re-initialised around dead reckoning, spread ([0-9.]+) m")
    spreads = [float(m.group(1)) for r in caplog.records if (m := pattern.search(r.getMessage()))]
    n_min, n_max, e_min, e_max = SMALL_MAP.extent
    diagonal = float(np.hypot(n_max - n_min, e_max - e_min))
    # 40, 160, 640, then the cap; an off-map ping does not end the run of divergences, a step does
    assert spreads == [40.0, 160.0, 640.0, round(diagonal, 1), 40.0]
    assert track.meta["divergence_steps"] == [2, 3, 4, 5, 8]
    assert track.meta["off_map_steps"] == [6, 10]
    assert track.meta["n_divergences"] == 5 and track.meta["n_off_map"] == 2
    assert any("2 pings off the map (first 6)" in r.getMessage() for r in caplog.records)
    assert np.all(np.isfinite(track.pose)) and np.all(np.isfinite(track.covariance[:, :2, :2]))
    assert list(track.meta)[:10] == [
        "ess", "n_resampled", "n_divergences", "divergence_steps", "n_lost", "lost_steps", "n_off_map",
        "off_map_steps", "n_redraws", "redraw_steps",
    ]


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


def test_a_vehicle_never_on_the_map_follows_dead_reckoning_and_says_so(caplog):
    survey = SURVEY.replace(dr_pose=SURVEY.dr_pose + np.array([1e5, 0.0, 0.0]))
    config = PFConfig(n_particles=200)
    with caplog.at_level("WARNING", logger="tangraph.filters.runner"):
        track = run_filter("pf", survey, MAP, config, model=MODEL, rng=np.random.default_rng(6))
    assert track.meta["off_map_steps"] == list(range(survey.n_pings))
    assert track.meta["divergence_steps"] == []
    assert np.all(np.isfinite(track.pose)) and np.all(np.isfinite(track.covariance[:, :2, :2]))
    assert any("off the map" in r.getMessage() for r in caplog.records)


@pytest.mark.parametrize("method", ["pf", "ipf", "sjcpf"])
def test_pings_no_particle_explains_do_not_drag_the_cloud(method):
    """Two blocks of 10 pings with every depth 5 m off: with the ping gate they are not weighed
    (the cloud keeps to the dead reckoning through them, and says so); without it they drag it
    (the stated errors trusted: a misfit scale learns the blocks' misfit and weighs them less)."""
    from tangraph.sim.faults import outlier_blocks

    survey = multibeam_survey(MAP, pings=80, seed=2)
    model = navigation(survey, initial_position_std=10.0, sounding_std=0.5, misfit_dof=0.0)
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


def test_a_dead_reckoning_500_m_off_the_truth_reports_itself_lost():
    """The DR (and so the cloud) 500 m north of the truth, still on the map: no particle is ever
    off the map (no divergence), but no particle explains the soundings either: after the first
    lost_pings inconsistent pings, every ping is lost. The same survey unshifted is never lost."""
    survey = calibrated_survey(3, pings=40)
    model = navigation(survey)
    config = PFConfig(n_particles=500)
    good = run_filter("pf", survey, CALIBRATED_MAP, config, model=model, rng=np.random.default_rng(5))
    assert good.meta["n_lost"] == 0 and good.meta["lost_steps"] == []
    shifted = survey.replace(dr_pose=survey.dr_pose + np.array([500.0, 0.0, 0.0]))
    lost = run_filter("pf", shifted, CALIBRATED_MAP, config, model=model, rng=np.random.default_rng(5))
    assert lost.meta["n_divergences"] == 0
    steps = lost.meta["lost_steps"]
    assert lost.meta["n_lost"] == len(steps) >= survey.n_pings - 5
    assert steps[0] == config.health.lost_pings - 1  # the third inconsistent ping in a row
    assert steps == sorted(steps)


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


def test_progress_bar(capsys):
    config = PFConfig(n_particles=50)
    run_filter("pf", SURVEY_30, MAP, config, model=MODEL_30, rng=np.random.default_rng(0), progress=True)
    assert "pf" in capsys.readouterr().err
