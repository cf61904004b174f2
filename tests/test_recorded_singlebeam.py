"""A single-beam echo sounder survey as a hydrographer records it (one sounding per ping at
2 Hz, a navigation log): written as CSV + XYZ, imported, and navigated with the smoother and
the PF through the library and the CLI, with the settings the user guide gives for single-beam
surveys. The library and the CLI give the same track; accuracy is the studies' business."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tangraph.cli import main
from tangraph.formats import import_csv_xyz
from tangraph.maps import load
from tangraph.navigation import navigate
from tangraph.sim.scenario import load_scenario, simulate
from tangraph.survey import read_survey

SCENARIO = """name = "singlebeam"
description = "a single-beam echo sounder: 2 Hz, one vertical beam, a boat at 2 m/s"
map = "merimbula"
seed = 5
vehicle_depth = 0.3

[trajectory]
kind = "waypoints"
points = [[1300.0, 1150.0], [2100.0, 1150.0], [2100.0, 1250.0], [1300.0, 1250.0]]
speed = 2.0
turn_radius = 20.0

[dead_reckoning]
start_position_std = 10.0
heading_bias_deg = 2.0
speed_scale = 0.02
speed_noise = 0.05

[sonar]
kind = "singlebeam"
ping_rate = 2.0
depth_noise = 0.1
"""
#: the guide's single-beam settings: windows of 100 pings (100 m of profile, ten 10 m cells)
GRAPH = """[graph.fixes]
n_pings = 100
fix_spacing = 50
ramp_pings = 20
"""
MODEL = "heading_bias_std_deg = 2.0\nspeed_scale_std = 0.02\nspeed_noise = 0.05\nsounding_std = 0.2\n"
COLUMNS = ["time", "lat", "lon", "north", "east", "heading_deg", "var_north", "cov_north_east", "var_east",
           "var_heading"]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """The simulated survey written as a recorder would: a log of the (GPS-like) track in the
    map's UTM zone and one ``time x y z`` row per sounding; the graph and model settings."""
    folder = tmp_path_factory.mktemp("singlebeam")
    bathymetry = load("merimbula")
    (folder / "singlebeam.toml").write_text(SCENARIO)
    survey = simulate(load_scenario(folder / "singlebeam.toml"), rng=np.random.default_rng(5),
                      bathymetry=bathymetry)
    assert survey.n_beams == 1
    north0, east0 = bathymetry.origin
    dr = survey.dr_pose
    np.savetxt(folder / "nav.csv",
               np.column_stack([survey.time, dr[:, 0] + north0, dr[:, 1] + east0,
                                np.degrees(dr[:, 2]) % 360, survey.vehicle_depth]),
               delimiter=",", header="time,north,east,heading,depth", comments="", fmt="%.3f")
    north, east = survey.footprints()
    has = np.isfinite(survey.beam_depth)
    t = np.broadcast_to(survey.time[:, None], has.shape)
    np.savetxt(folder / "sounding.xyz", np.column_stack([t[has], east[has] + east0, north[has] + north0,
                                                         survey.beam_depth[has]]), fmt="%.3f")
    (folder / "graph.toml").write_text(GRAPH)
    (folder / "dr.toml").write_text(MODEL)
    imported = folder / "survey.nc"
    assert main(["survey", "import", str(folder / "nav.csv"), str(folder / "sounding.xyz"),
                 "--crs", bathymetry.crs, "-q", "-o", str(imported)]) == 0
    return {"folder": folder, "survey": imported, "n_soundings": int(has.sum()), "map": bathymetry}


def test_the_survey_imports_one_sounding_per_ping(files):
    folder = files["folder"]
    survey = import_csv_xyz(folder / "nav.csv", folder / "sounding.xyz", crs="EPSG:32755")
    assert survey.n_beams == 1 and survey.n_pings == files["n_soundings"] == survey.n_soundings
    from_cli = read_survey(files["survey"])
    np.testing.assert_allclose(from_cli.dr_pose, survey.dr_pose, atol=1e-9)
    np.testing.assert_allclose(from_cli.beam_depth, survey.beam_depth, atol=1e-9)


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
