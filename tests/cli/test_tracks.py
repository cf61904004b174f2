"""The ``tangraph navigate`` and ``smooth`` commands (tangraph.cli.tracks): they go through the
library's one door and give its tracks (a recorded survey in another CRS, a single-beam survey),
write latitude/longitude CSV, TUM, GeoJSON, GeoPackage and figures all or none, refuse to
clobber, clashing outputs and GIS without a CRS, take --dr-model and --graph-config, and find the
map a survey was simulated on; and the chain a hydrographer runs on the real Lake Caputh files
(SonTek import, a map gridded from surveys, smoothing scored against the GPS)."""

from __future__ import annotations

import dataclasses
import json
import logging
from types import SimpleNamespace

import numpy as np
import pytest

import tangraph
import tangraph.navigation
import tangraph.track
from tangraph.cli import main
from tangraph.errors import TangraphError
from tangraph.formats import read_sontek_sum
from tangraph.maps import BathymetryMap, load, read_map, write_map
from tangraph.navigation import navigate
from tangraph.sim.scenario import load_scenario, simulate
from tangraph.survey import read_survey, write_survey
from tests.recorded_cases import MODEL, recorded

OPTIONS = ["--format", "sontek-sum", "--crs", "EPSG:25833", "--timezone", "Europe/Berlin"]
CAPUTH_MODEL = """[navigation]
speed_noise = 0.01
heading_noise_deg = 0.3
heading_walk_deg = 0.005
speed_scale_std = 0.05
heading_bias_std_deg = 5.0
initial_position_std = 3.0
sounding_std = 0.1
map_std = 0.2
tide_std = 0.1
map_correlation_length = 10.0
robust_kernel = "cauchy"
"""
GRAPH = """[graph.fixes]
n_pings = 120
fix_spacing = 60
accept_multimodal = false
gate_probability = 0.99

[graph.fixes.tap]
criterion = "msd"
alpha = 0.01
"""
COLUMNS = ["time", "lat", "lon", "north", "east", "heading_deg", "var_north", "cov_north_east", "var_east",
           "var_heading"]


@pytest.fixture(autouse=True)
def _quiet():
    logging.getLogger("tangraph.formats.sontek").setLevel(logging.ERROR)


@pytest.mark.parametrize("command", ["navigate", "smooth"])
def test_the_cli_goes_through_the_same_door(command, monkeypatch, tmp_path):
    import tangraph.cli.tracks as tracks
    from tangraph.cli import main

    calls = []
    survey, bathymetry = SimpleNamespace(name="survey"), SimpleNamespace(name="map", depth_std=None)

    def door(*args, **kwargs):
        calls.append((*args[:2], str(args[2])))
        raise TangraphError("through the door")

    assert tangraph.navigate is tangraph.navigation.navigate
    monkeypatch.setattr(tracks, "_survey_and_map", lambda args: (survey, bathymetry))
    monkeypatch.setattr(tangraph.navigation, "navigate", door)
    assert main([command, "s.nc", "-o", str(tmp_path / "track.csv")]) == 2
    assert calls == [(survey, bathymetry, "isam2" if command == "navigate" else "smoother")]


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


def test_the_cli_gives_the_library_s_track_and_the_right_lat_lon(simulated, merimbula, tmp_path, capsys):
    from tangraph.maps.projection import to_lonlat

    rec = recorded(simulated)
    path, dr_model, out = tmp_path / "rec.nc", tmp_path / "dr.toml", tmp_path / "s.csv"
    write_survey(rec, path)
    dr_model.write_text(MODEL)
    from tangraph.sensors import load_navigation_model

    model = load_navigation_model(dr_model)
    assert main(["smooth", str(path), "--map", "merimbula", "--dr-model", str(dr_model), "-q",
                 "-o", str(out)]) == 0
    from tangraph.survey import read_survey

    track = navigate(read_survey(path), merimbula, "smoother", model=model)
    rows = np.genfromtxt(out, delimiter=",", names=True)
    np.testing.assert_allclose(rows["north"], track.pose[:, 0], atol=1e-6)
    np.testing.assert_allclose(rows["east"], track.pose[:, 1], atol=1e-6)
    lat, lon = to_lonlat(merimbula, track.pose[:, 0], track.pose[:, 1])
    np.testing.assert_allclose(rows["lat"], lat, atol=1e-8)
    np.testing.assert_allclose(rows["lon"], lon, atol=1e-8)
    # the reference written beside it is the survey's in the map's frame
    np.testing.assert_allclose(rows["ref_north"], simulated.true_pose[:, 0], atol=1e-3)
    assert "RMSE" in capsys.readouterr().out


# -- GIS outputs -------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def dated_survey(tmp_path_factory):
    """80 pings of the wang2019 scenario on Merimbula (EPSG:32755), with a start time."""
    bathymetry = load("merimbula")
    survey = simulate(load_scenario("wang2019"), rng=np.random.default_rng(3), bathymetry=bathymetry, seed=3)
    survey = survey.replace(meta={**survey.meta, "start_time": "2023-03-04T05:06:07.5Z"})
    folder = tmp_path_factory.mktemp("gis")
    path = folder / "wang.nc"
    write_survey(survey, path)
    local = write_map(
        BathymetryMap(bathymetry.north, bathymetry.east, bathymetry.depth, name="local"), folder / "local.npz"
    )
    return path, local


def test_navigate_writes_geojson_gpkg_and_enu_tum(dated_survey, tmp_path, capsys):
    survey_file, _ = dated_survey
    gj, gpkg, tum, csv = (tmp_path / n for n in ("t.geojson", "t.gpkg", "t.tum", "t.csv"))
    base = ["navigate", str(survey_file), "--method", "pf", "--particles", "200", "-q"]
    assert main([*base, "-o", str(gj), "--tum", str(tum), "--frame", "enu"]) == 0
    doc = json.loads(gj.read_text())
    points = doc["features"][1:]
    assert points[0]["properties"]["utc"] == "2023-03-04T05:06:07.500000Z"
    assert {"ref_north", "ref_east", "var_north", "ellipse95_major"} <= set(points[0]["properties"])
    lon, lat = points[0]["geometry"]["coordinates"]
    assert 149 < lon < 151 and -38 < lat < -36  # Merimbula
    enu = np.loadtxt(tum)
    north_east = np.array([[p["properties"]["north"], p["properties"]["east"]] for p in points])
    np.testing.assert_allclose(enu[:, 1:3], north_east[:, ::-1], atol=1e-6)
    assert main([*base, "-o", str(csv)]) == 0
    assert csv.read_text().splitlines()[0].startswith("time,utc,lat,lon,north")
    pytest.importorskip("pyogrio")
    assert main([*base, "-o", str(gpkg)]) == 0
    import pyogrio

    assert pyogrio.read_info(gpkg, layer="poses")["crs"] == "EPSG:4326"


def test_navigate_refuses_gis_without_crs_and_clashing_outputs(dated_survey, tmp_path, capsys):
    survey_file, local = dated_survey
    base = ["navigate", str(survey_file), "--method", "pf", "--particles", "100", "-q"]
    for name in ("t.geojson", "t.gpkg"):
        out = tmp_path / name
        assert main([*base, "--map", str(local), "-o", str(out)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "--map" in err[0] and "CRS" in err[0]
        assert not out.exists()
    # two outputs on one path, an output over an input
    same = tmp_path / "same.tum"
    assert main([*base, "-o", str(same), "--tum", str(same)]) == 2
    assert "another output" in capsys.readouterr().err and not same.exists()
    assert main([*base, "--map", str(local), "-o", str(local), "--force"]) == 2
    assert "over the input map" in capsys.readouterr().err
    plot = tmp_path / "t.csv"
    assert main([*base, "-o", str(plot), "--plot", str(plot)]) == 2
    assert "another output" in capsys.readouterr().err
    # --frame without a TUM output
    assert main([*base, "-o", str(tmp_path / "x.csv"), "--frame", "enu"]) == 2
    assert "--frame applies to TUM output" in capsys.readouterr().err
    assert not (tmp_path / "x.csv").exists()


# -- outputs written all or none ---------------------------------------------------------------
@pytest.fixture(scope="module")
def small_survey(tmp_path_factory):
    from tangraph.maps import load
    from tangraph.sim.scenario import load_scenario, simulate
    from tangraph.survey import write_survey

    bathymetry = load("merimbula")
    survey = simulate(load_scenario("wang2019"), rng=np.random.default_rng(3), bathymetry=bathymetry, seed=3)
    path = tmp_path_factory.mktemp("outputs") / "wang.nc"
    write_survey(survey.pings(0, 80), path)
    return path


def test_a_failing_tum_leaves_no_track_and_keeps_the_old_figure(small_survey, tmp_path, monkeypatch):
    def full(*args, **kwargs):
        raise TangraphError("no space left for the TUM file")

    out, tum, fig = tmp_path / "t.csv", tmp_path / "t.tum", tmp_path / "t.png"
    fig.write_text("the old figure")
    monkeypatch.setattr(tangraph.track, "write_track_tum", full)
    args = ["navigate", str(small_survey), "--method", "pf", "--particles", "100", "-q",
            "-o", str(out), "--tum", str(tum), "--plot", str(fig), "--force"]
    assert main(args) == 2
    assert not out.exists() and not tum.exists() and fig.read_text() == "the old figure"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.png"]
    monkeypatch.undo()
    assert main(args) == 0
    assert out.read_text().startswith("time,") and np.loadtxt(tum).shape == (80, 8)
    assert fig.read_bytes()[:4] == b"\x89PNG"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.csv", "t.png", "t.tum"]


# -- a single-beam survey ----------------------------------------------------------------------
def read_track(path):
    header = path.read_text().splitlines()[0].split(",")
    return header, np.genfromtxt(path, delimiter=",", names=True)


def check_same(track, path, n_pings):
    header, rows = read_track(path)
    assert header[:len(COLUMNS)] == COLUMNS
    assert rows.shape == (n_pings,) and track.n_poses == n_pings
    assert np.all(np.isfinite(track.pose))
    for name in ("lat", "lon", "north", "east", "heading_deg"):
        assert np.all(np.isfinite(rows[name])), name
    np.testing.assert_allclose(rows["north"], track.pose[:, 0], atol=1e-6)
    np.testing.assert_allclose(rows["east"], track.pose[:, 1], atol=1e-6)


def test_smoother_through_the_library_and_the_cli(files, tmp_path):
    from tangraph.graph import load_graph_config
    from tangraph.sensors import load_navigation_model

    folder, out = files["folder"], tmp_path / "smoothed.csv"
    assert main(["smooth", str(files["survey"]), "--map", "merimbula", "--dr-model", str(folder / "dr.toml"),
                 "--graph-config", str(folder / "graph.toml"), "-q", "-o", str(out)]) == 0
    survey = read_survey(files["survey"])
    track = navigate(survey, files["map"], "smoother", load_graph_config(folder / "graph.toml"),
                     model=load_navigation_model(folder / "dr.toml"))
    check_same(track, out, survey.n_pings)
    assert np.all(np.isfinite(track.covariance[:, :2, :2]))


def test_particle_filter_through_the_library_and_the_cli(files, tmp_path):
    from tangraph.filters import default_config
    from tangraph.sensors import load_navigation_model

    folder, out = files["folder"], tmp_path / "pf.csv"
    assert main(["navigate", str(files["survey"]), "--map", "merimbula", "--method", "pf",
                 "--particles", "500", "--seed", "4", "--dr-model", str(folder / "dr.toml"), "-q",
                 "-o", str(out)]) == 0
    survey = read_survey(files["survey"])
    config = dataclasses.replace(default_config("pf"), n_particles=500)
    track = navigate(survey, files["map"], "pf", config, model=load_navigation_model(folder / "dr.toml"),
                     rng=np.random.default_rng(4))
    check_same(track, out, survey.n_pings)


# -- the Lake Caputh chain ---------------------------------------------------------------------
def test_import_grid_smooth_on_real_runs(caputh, tmp_path, capsys):
    level = ["--water-level", str(caputh / "waterlevel.csv"), "--water-level-interpolate"]
    january = []
    for stem in ("20250130115554", "20250130132742"):  # 30 January: 85 and 24 min
        january.append(tmp_path / f"{stem}.nc")
        assert main(["survey", "import", *OPTIONS, *level, str(caputh / f"{stem}.sum"),
                     "-o", str(january[-1])]) == 0
    grid = tmp_path / "january.nc"
    assert main(["maps", "grid", *map(str, january), "--cell", "5", "--fill", "3", "-o", str(grid)]) == 0
    march = tmp_path / "march.nc"
    assert main(["survey", "import", *OPTIONS, *level, str(caputh / "20250327143017.sum"),
                 "-o", str(march)]) == 0
    capsys.readouterr()
    # check lines: each January run against a map of the other (and March's against both)
    assert main(["maps", "check", *map(str, january), str(march), "--cell", "5", "--fill", "3"]) == 0
    rows = capsys.readouterr().out.splitlines()
    assert rows[0] == "survey,windows,rms,robust,share_beyond_3"
    assert [r.split(",")[0] for r in rows[1:4]] == [*map(str, january), str(march)]
    assert sum(int(r.split(",")[1]) for r in rows[1:4]) > 0 and rows[4].startswith("all: ")
    model, graph = tmp_path / "boat.toml", tmp_path / "graph.toml"
    model.write_text(CAPUTH_MODEL)
    graph.write_text(GRAPH)
    track = tmp_path / "march.csv"
    assert main(["smooth", str(march), "--map", str(grid), "--dr-model", str(model),
                 "--graph-config", str(graph), "-q", "-o", str(track)]) == 0
    printed = capsys.readouterr().out
    assert "against the GPS" in printed

    # the reference columns are the file's GPS in the map's frame: EPSG:25833 less its origin
    import pyproj

    bathymetry = read_map(grid)
    rec = read_sontek_sum(caputh / "20250327143017.sum")
    east, north = pyproj.Transformer.from_crs("EPSG:4326", "EPSG:25833", always_xy=True).transform(
        rec.lon[0], rec.lat[0])
    import pandas as pd

    table = pd.read_csv(track)
    assert table["utc"].iloc[0] == "2025-03-27T13:30:17.000000Z"  # 14:30:17 CET, the first sample
    ref = table[["ref_north", "ref_east"]].to_numpy()
    assert ref[0] + np.asarray(bathymetry.origin) == pytest.approx([north, east], abs=1e-3)
    assert bathymetry.crs == "EPSG:25833" and read_survey(march).meta["vertical_datum"].startswith("zero")
    # on this run the file's boat velocity follows the GPS: the smoothed track must stay near it
    error = np.hypot(*(table[["north", "east"]].to_numpy() - ref).T)
    assert np.median(error) < 10.0, np.median(error)
    assert f"median {np.median(error):.2f} m" in printed
