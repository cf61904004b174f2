"""One dispatch over every estimator, and the navigate / smooth commands end to end."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.cli import main
from tangraph.errors import TangraphError
from tangraph.maps import load
from tangraph.navigation import Method, dead_reckoning_track, navigate, track_summary
from tangraph.sim.scenario import load_scenario, simulate
from tangraph.survey import write_survey


@pytest.fixture(scope="module")
def wang_survey():
    """The wang2019 scenario on the real Merimbula map: 280 pings over 1.7 km."""
    bathymetry = load("merimbula")
    survey = simulate(load_scenario("wang2019"), rng=np.random.default_rng(3), bathymetry=bathymetry, seed=3)
    return survey, bathymetry


@pytest.fixture(scope="module")
def survey_file(wang_survey, tmp_path_factory):
    path = tmp_path_factory.mktemp("nav") / "wang.nc"
    write_survey(wang_survey[0], path)
    return path


def test_the_cli_methods_are_the_filters_and_the_graph():
    from tangraph.filters import FilterMethod

    assert {m.value for m in Method} == {m.value for m in FilterMethod} | {"isam2", "smoother"}
    assert {m.value for m in Method if m.is_graph} == {"isam2", "smoother"}


def test_unknown_method_and_missing_rng_are_named(wang_survey):
    survey, bathymetry = wang_survey
    with pytest.raises(TangraphError, match="unknown navigation method 'kalman'.*tercom-pf"):
        navigate(survey, bathymetry, "kalman")
    with pytest.raises(TangraphError, match="'pf' is random: pass rng"):
        navigate(survey, bathymetry, "pf")


@pytest.mark.parametrize("method", [m.value for m in Method])
def test_every_method_beats_dead_reckoning_on_a_real_map(wang_survey, method):
    survey, bathymetry = wang_survey
    track = navigate(survey, bathymetry, method, rng=np.random.default_rng(11))
    assert track.method == method and track.n_poses == survey.n_pings
    np.testing.assert_array_equal(track.time, survey.time)
    from tangraph.eval import track_metrics

    got = track_metrics(track, survey.true_pose, skip=30)
    dr = track_metrics(dead_reckoning_track(survey), survey.true_pose, skip=30)
    assert got["rmse"] < dr["rmse"], (got, dr)
    text = track_summary(track, survey)
    assert f"method       {method}" in text and "dead reckoning: RMSE" in text


def test_navigate_command_writes_lat_lon_and_refuses_to_clobber(survey_file, tmp_path, capsys):
    out = tmp_path / "pf.csv"
    args = ["navigate", str(survey_file), "--method", "pf", "--particles", "300", "-q", "-o", str(out)]
    assert main(args) == 0
    header = out.read_text().splitlines()[0].split(",")
    assert header[:4] == ["time", "lat", "lon", "north"]
    assert "RMSE" in capsys.readouterr().out
    before = out.read_bytes()
    assert main(args) == 2 and "--force" in capsys.readouterr().err
    assert out.read_bytes() == before
    assert main(["navigate", str(survey_file), "--method", "isam2", "--particles", "10", "-o", str(out)]) == 2
    assert "--particles does not apply" in capsys.readouterr().err
    assert main(["navigate", str(survey_file), "-o", str(survey_file), "--force", "-q"]) == 2
    assert "over the input survey" in capsys.readouterr().err
    # an existing second output is found before any work, and the first is not written either
    fresh, taken = tmp_path / "fresh.csv", tmp_path / "taken.tum"
    taken.write_text("keep")
    assert main(["navigate", str(survey_file), "-q", "-o", str(fresh), "--tum", str(taken)]) == 2
    assert not fresh.exists() and taken.read_text() == "keep"


def test_smooth_command_writes_csv_tum_and_figure(wang_survey, survey_file, tmp_path, capsys):
    k = wang_survey[0].n_pings
    out, tum, fig = tmp_path / "s.csv", tmp_path / "s.tum", tmp_path / "s.png"
    args = ["smooth", str(survey_file), "-q", "-o", str(out), "--tum", str(tum), "--plot", str(fig)]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert "fixes" in printed and "accepted" in printed
    rows = np.loadtxt(out, delimiter=",", skiprows=1)
    assert rows.shape[0] == k and np.all(np.isfinite(rows[:, :6]))
    # the survey's reference track beside the estimate, in the same frame, and the scores
    header = out.read_text().splitlines()[0].split(",")
    assert header[-2:] == ["ref_north", "ref_east"]
    np.testing.assert_allclose(rows[:, -2:], wang_survey[0].true_pose[:, :2], rtol=1e-9, atol=1e-6)
    north, east = header.index("north"), header.index("east")
    error = np.hypot(rows[:, north] - rows[:, -2], rows[:, east] - rows[:, -1])
    assert f"median {np.median(error):.2f} m" in printed and "against the truth" in printed
    assert np.loadtxt(tum).shape == (k, 8)
    assert fig.read_bytes()[:4] == b"\x89PNG"


def test_a_recorded_survey_is_smoothed_in_the_map_frame_with_its_dr_model(wang_survey, tmp_path, capsys):
    """CSV log + XYZ soundings in UTM -> `survey import` -> `smooth --dr-model`: the imported survey
    has its own local origin, and the smoothed track must land on the truth in the map's frame."""
    survey, bathymetry = wang_survey
    north0, east0 = bathymetry.origin
    dr = survey.dr_pose
    nav, sounds, model = tmp_path / "nav.csv", tmp_path / "s.xyz", tmp_path / "dr.toml"
    np.savetxt(nav, np.column_stack([survey.time, dr[:, 0] + north0, dr[:, 1] + east0,
                                     np.degrees(dr[:, 2]) % 360, survey.vehicle_depth]),
               delimiter=",", header="time,north,east,heading,depth", comments="", fmt="%.3f")
    north, east = survey.footprints()
    has = np.isfinite(survey.beam_depth)
    t = np.broadcast_to(survey.time[:, None], has.shape)
    np.savetxt(sounds, np.column_stack([t[has], east[has] + east0, north[has] + north0,
                                        survey.beam_depth[has]]), fmt="%.3f")
    model.write_text("heading_bias_std_deg = 2.0\nspeed_scale_std = 0.02\nspeed_noise = 0.05\n"
                     "sounding_std = 0.3\n")
    recorded = tmp_path / "rec.nc"
    args = ["survey", "import", str(nav), str(sounds), "--crs", bathymetry.crs, "-o", str(recorded)]
    assert main(args) == 0
    out = tmp_path / "smoothed.csv"
    base = ["smooth", str(recorded), "--map", "merimbula", "-q", "-o", str(out)]
    assert main(base) == 2 and "NavigationModel" in capsys.readouterr().err
    assert main([*base, "--dr-model", str(model)]) == 0
    rows = np.genfromtxt(out, delimiter=",", names=True)
    same = np.searchsorted(survey.time, rows["time"])
    error = np.hypot(rows["north"] - survey.true_pose[same, 0], rows["east"] - survey.true_pose[same, 1])
    dr_error = np.hypot(*(dr[same, :2] - survey.true_pose[same, :2]).T)
    assert np.sqrt(np.mean(error**2)) < 0.25 * np.sqrt(np.mean(dr_error**2))


def test_graph_config_option(survey_file, tmp_path, capsys):
    graph = tmp_path / "graph.toml"
    graph.write_text("[graph.fixes]\nn_pings = 30\nfix_spacing = 15\n")
    out = tmp_path / "s.csv"
    assert main(["smooth", str(survey_file), "-q", "--graph-config", str(graph), "-o", str(out)]) == 0
    assert main(["navigate", str(survey_file), "--method", "pf", "-q", "--graph-config", str(graph),
                 "-o", str(tmp_path / "pf.csv")]) == 2
    assert "--graph-config does not apply to method 'pf'" in capsys.readouterr().err
    graph.write_text("[graph.fixes]\nn_ping = 30\n")
    args = ["smooth", str(survey_file), "-q", "--graph-config", str(graph), "-o", str(out), "--force"]
    assert main(args) == 2
    assert "unknown FixConfig field 'n_ping'" in capsys.readouterr().err
    graph.write_text("[graph]\nn_pings = 30\n")  # a file of the flat layout: where the key went
    assert main(args) == 2
    assert "GraphConfig.n_pings is now in the fixes part ([graph.fixes] in a file)" in capsys.readouterr().err


def test_a_survey_simulated_on_a_map_file_finds_it_again(tmp_path, capsys):
    from tangraph.maps import write_map

    grid = tmp_path / "merimbula.nc"
    write_map(load("merimbula"), grid)
    survey = tmp_path / "wang.nc"
    assert main(["simulate", "wang2019", "--map", str(grid), "--seed", "3", "-o", str(survey)]) == 0
    from tangraph.survey import read_survey

    assert read_survey(survey).meta["map"] == str(grid.resolve())
    out = tmp_path / "s.csv"
    assert main(["smooth", str(survey), "-q", "-o", str(out)]) == 0  # no --map: the file it was made on
    assert "RMSE" in capsys.readouterr().out
    # and the map-read options exist on the commands that take --map
    assert main(["smooth", str(survey), "-q", "--map", str(grid), "--nodata", "-99999", "-o",
                 str(tmp_path / "t.csv")]) == 0


def test_a_survey_is_refused_on_a_map_it_was_not_made_on(wang_survey, survey_file, tmp_path, capsys):
    from tangraph.navigation import check_map, map_identity

    survey, bathymetry = wang_survey
    assert survey.meta["map_identity"] == map_identity(bathymetry)
    check_map(survey, bathymetry)  # its own map
    other = load("lidar-dem")
    with pytest.raises(TangraphError, match="simulated on map 'merimbula', not on 'lidar-dem'.*--other-map"):
        navigate(survey, other, "smoother")
    shifted = bathymetry.replace(depth=bathymetry.depth + 0.5)  # same frame, other depths
    with pytest.raises(TangraphError, match=r"differ in depths"):
        check_map(survey, shifted)
    out = tmp_path / "x.csv"
    assert main(["smooth", str(survey_file), "--map", "lidar-dem", "-q", "-o", str(out)]) == 2
    assert "--other-map" in capsys.readouterr().err and not out.exists()
    recorded = survey.replace(meta={k: v for k, v in survey.meta.items() if k != "map_identity"})
    check_map(recorded, other)  # a recorded survey records no map: nothing to check
