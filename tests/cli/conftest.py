"""A single-beam echo sounder survey as a hydrographer records it (one sounding per ping at 2 Hz, a
navigation log), written as CSV + XYZ and imported by ``tangraph survey import``, with the
settings the user guide gives for single-beam surveys: the ``survey import``, ``smooth`` and
``navigate`` tests check that the library and the CLI give the same survey and tracks."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.cli import main
from tangraph.maps import load
from tangraph.sim.scenario import load_scenario, simulate

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
