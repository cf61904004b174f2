"""Scenarios and simulated surveys (tangraph.sim.scenario): the shipped scenarios, bad ones named,
surveys on a flat map, and the ``simulate`` command that runs them."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tangraph.cli import main
from tangraph.errors import TangraphError
from tangraph.maps import BathymetryMap
from tangraph.sim.scenario import ScenarioError, list_scenarios, load_scenario, simulate
from tangraph.survey import read_survey


def test_shipped_scenarios_load_with_the_papers_settings():
    assert set(list_scenarios()) >= {"wang2019", "han2020", "han2020_1m", "chen2022"}
    chen = load_scenario("chen2022")
    assert chen.sonar.ping_rate == 0.01
    assert chen.sonar.depth_noise == pytest.approx(5.0)  # variance 25 m^2
    assert chen.dead_reckoning.heading_bias == pytest.approx(np.radians(2.0))
    assert chen.dead_reckoning.speed_noise == pytest.approx(0.1)
    wang = load_scenario("wang2019")
    assert wang.study["windows"] == [10, 20, 30]
    assert wang.sonar.swath == pytest.approx(np.radians(140.0))


def test_a_folder_named_as_a_scenario_does_not_hide_it(tmp_path, monkeypatch):
    """An output folder called ``demo`` where the command runs is not the scenario ``demo``."""
    (tmp_path / "demo").mkdir()
    monkeypatch.chdir(tmp_path)
    assert load_scenario("demo").name == "demo"


@pytest.mark.parametrize(
    ("text", "message"),
    [
        (
            'map = "m"\nvehicle_depth = 1\ncolour = "red"\n[trajectory]\nkind = "line"\n[sonar]\n',
            "unknown keys",
        ),
        ('map = "m"\nvehicle_depth = -1\n[trajectory]\nkind = "line"\n[sonar]\n', "vehicle_depth must be"),
        ('map = "m"\nvehicle_depth = 1\n[trajectory]\nkind = "spiral"\n[sonar]\n', "kind must be one of"),
        ('map = "m"\nvehicle_depth = 1\n[trajectory]\nkind = "line"\n[sonar]\nn_beams = -3\n', r"\[sonar\]"),
        ('map = "m"\nvehicle_depth = 1\n[trajectory]\nkind = "line"\n[sonar]\nbeams = 3\n', "unknown keys"),
        (
            'map = "m"\nvehicle_depth = 1\n[trajectory]\nkind = "line"\n[sonar]\npreset = "x"\n',
            "unknown preset",
        ),
        ("map = [", "not valid TOML"),
    ],
)
def test_bad_scenarios_are_named(tmp_path, text, message):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(ScenarioError, match=message):
        load_scenario(path)


def flat_map(depth=40.0):
    return BathymetryMap(
        north=np.arange(0, 2000.0, 10),
        east=np.arange(0, 2000.0, 10),
        depth=np.full((200, 200), depth),
        name="flat",
    )


def test_simulated_survey_on_a_flat_map_is_exact_without_noise():
    scenario = load_scenario("han2020")
    quiet = dataclasses.replace(scenario.sonar, depth_noise=0.0, range_noise=0.0, tide=0.0)
    scenario = dataclasses.replace(
        scenario,
        sonar=quiet,
        trajectory={
            "kind": "line",
            "start": [1000.0, 100.0],
            "heading_deg": 90.0,
            "speed": 2.0,
            "duration": 500.0,
        },
    )
    s = simulate(scenario, rng=np.random.default_rng(0), bathymetry=flat_map(), seed=0)
    assert s.n_soundings == s.beam_depth.size
    np.testing.assert_allclose(s.beam_depth, 40.0, atol=1e-6)
    np.testing.assert_allclose(
        np.abs(s.beam_starboard).max(), 10.0 * np.tan(scenario.sonar.swath / 2), rtol=1e-6
    )
    assert s.meta["map"] == "flat" and s.meta["settings"]["sonar"]["kind"] == "multibeam"


def test_leaving_the_map_gives_counted_missing_returns():
    scenario = load_scenario("han2020")
    scenario = dataclasses.replace(
        scenario,
        trajectory={
            "kind": "line",
            "start": [1000.0, 1500.0],
            "heading_deg": 90.0,
            "speed": 2.0,
            "duration": 500.0,
        },
    )
    s = simulate(scenario, rng=np.random.default_rng(0), bathymetry=flat_map(), seed=0)
    assert s.n_empty_pings > 0
    assert s.meta["sonar_counts"]["off_map"] == int(np.isnan(s.beam_depth).sum())


def test_simulate_cli_same_seed_same_survey(tmp_path, capsys):
    a, b = tmp_path / "a.nc", tmp_path / "b.nc"
    assert main(["simulate", "han2020_1m", "--seed", "7", "-o", str(a)]) == 0
    assert main(["simulate", "han2020_1m", "--seed", "7", "-o", str(b)]) == 0
    sa, sb = read_survey(a), read_survey(b)
    np.testing.assert_array_equal(sa.beam_depth, sb.beam_depth)
    np.testing.assert_array_equal(sa.dr_pose, sb.dr_pose)
    assert sa.meta["seed"] == 7
    assert main(["survey", "info", str(a)]) == 0
    assert "lidar-dem" in capsys.readouterr().out
    assert main(["survey", "plot", str(a), "-o", str(tmp_path / "a.png")]) == 0
    assert (tmp_path / "a.png").read_bytes()[:4] == b"\x89PNG"


def test_simulate_cli_writes_the_prior_map_of_a_seafloor_that_is_not_the_map(tmp_path, capsys):
    from tangraph.maps import load_any
    from tangraph.navigation import survey_on_map

    out = tmp_path / "s.nc"
    assert main(["simulate", "demo-map-error", "-o", str(out)]) == 0
    prior = tmp_path / "s_prior_map.nc"
    assert "s_prior_map.nc" in capsys.readouterr().out
    survey = read_survey(out)
    assert survey.meta["map"] == str(prior.resolve())
    bathymetry = load_any(survey.meta["map"])
    assert bathymetry.depth_std is not None  # the gridded map's error travels with it
    survey_on_map(survey, bathymetry)  # the map its estimators navigate on: accepted
    assert main(["simulate", "demo-map-error", "-o", str(out)]) == 2
    assert "--force" in capsys.readouterr().err


def test_a_drifting_tide_moves_every_sounding_of_a_ping_alike_and_nothing_else():
    scenario = load_scenario("han2020")
    line = {"kind": "line", "start": [1000.0, 100.0], "heading_deg": 90.0, "speed": 2.0, "duration": 900.0}
    still = dataclasses.replace(scenario, trajectory=line)
    std, forget = 0.3, 50.0
    drifting = dataclasses.replace(still, sonar=dataclasses.replace(still.sonar, tide_drift_std=std,
                                                                    tide_drift_time=forget))
    a = simulate(still, rng=np.random.default_rng(3), bathymetry=flat_map(), seed=3)
    b = simulate(drifting, rng=np.random.default_rng(3), bathymetry=flat_map(), seed=3)
    np.testing.assert_array_equal(a.dr_pose, b.dr_pose)  # the drift is drawn last
    drift = (b.beam_depth - a.beam_depth)
    np.testing.assert_allclose(drift, np.broadcast_to(drift[:, :1], drift.shape), atol=1e-9)  # one per ping
    d = drift[:, 0]
    keep = np.exp(-np.diff(b.time) / forget)
    innovations = (d[1:] - keep * d[:-1]) / (std * np.sqrt(1.0 - keep**2))
    n = innovations.size  # standardised innovations of the Gauss-Markov process: chi-square(n) / n
    assert abs(np.mean(innovations**2) - 1.0) < 4.0 * np.sqrt(2.0 / n)
    assert abs(np.mean(innovations)) < 4.0 / np.sqrt(n)
    from tangraph.sensors import NavigationModel

    model = NavigationModel.from_survey(b)
    assert (model.tide_drift_std, model.tide_drift_time) == (std, forget)
    assert NavigationModel.from_survey(a).tide_drift is None
    with pytest.raises(TangraphError, match="tide_drift_time must be > 0 s with tide_drift_std = 0.3 m"):
        dataclasses.replace(still.sonar, tide_drift_std=std)


def test_a_seafloor_that_changed_since_the_prior_survey_states_the_change():
    """``demo-change``: the survey sees the seafloor plus a change of 0.3 m drawn after the prior
    map (the same map as without it, the same seed), which the survey's metadata and so the
    navigation model of the simulated survey state."""
    from tangraph.sensors import NavigationModel
    from tangraph.sim.scenario import simulate_run

    line = {"kind": "line", "start": [1750.0, 850.0], "heading_deg": 80.0, "speed": 2.0, "duration": 300.0}
    changed = dataclasses.replace(load_scenario("demo-change"), trajectory=line)
    unchanged = dataclasses.replace(changed, seafloor=dataclasses.replace(changed.seafloor, change_std=0.0))
    residuals, maps, surveys = [], [], []
    for scenario in (unchanged, changed):
        run = simulate_run(scenario, rng=np.random.default_rng(5), seed=5)
        north, east = run.survey.footprints(run.survey.true_pose)
        r = (run.survey.beam_depth - run.bathymetry.depth_at(north, east)).ravel()
        residuals.append(r[np.isfinite(r)])
        maps.append(run.bathymetry.depth)
        surveys.append(run.survey)
    without, survey = surveys
    np.testing.assert_array_equal(*maps)  # the change is drawn after the prior map
    added = residuals[1].var() - residuals[0].var()
    assert 0.03 < added < 0.3  # 0.09 m^2 expected: 0.3 m over a 600 m line, a few dozen ranges of 30 m
    stated = survey.meta["seafloor"]
    assert (stated["map_change_std"], stated["map_change_length"]) == (0.3, 30.0)
    model = NavigationModel.from_survey(survey)
    assert (model.map_change_std, model.map_change_length) == (0.3, 30.0)
    assert without.meta["seafloor"]["map_change_std"] == 0.0
    assert NavigationModel.from_survey(without).map_change_std == 0.0
