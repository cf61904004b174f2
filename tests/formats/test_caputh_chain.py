"""The chain a hydrographer runs on real files: SonTek import -> map gridded from surveys ->
smoothing scored against the GPS; and a lat/lon navigation log of the same run put onto the
UTM map, landing where the SonTek import puts it."""

from __future__ import annotations

import logging

import numpy as np
import pytest

from tangraph.cli import main
from tangraph.formats import import_csv_xyz, import_sontek_sum, read_sontek_sum
from tangraph.maps import read_map
from tangraph.navigation import in_map_frame
from tangraph.survey import read_survey

OPTIONS = ["--format", "sontek-sum", "--crs", "EPSG:25833", "--timezone", "Europe/Berlin"]
MODEL = """[navigation]
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


@pytest.fixture(autouse=True)
def _quiet():
    logging.getLogger("tangraph.formats.sontek").setLevel(logging.ERROR)


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
    model.write_text(MODEL)
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


def test_lat_lon_log_of_a_real_run_lands_on_the_utm_map(caputh, tmp_path):
    """The run's GPS as a lat/lon CSV log and its vertical beam as lon/lat XYZ soundings, imported
    without a CRS (a local transverse Mercator), reprojected onto a map in EPSG:25833: the
    positions must be those of the SonTek import in EPSG:25833 to the millimetre, the headings
    within 1e-6 rad."""
    run = caputh / "20250327143017.sum"
    rec = read_sontek_sum(run)
    direct = import_sontek_sum(run, crs="EPSG:25833", timezone="UTC")
    t = np.arange(rec.n_samples, dtype=float)
    log = tmp_path / "nav.csv"
    heading_true = np.degrees(direct.true_pose[:, 2]) - direct.meta["grid_convergence_deg"]
    np.savetxt(log, np.column_stack([t, rec.lat, rec.lon, heading_true, np.zeros_like(t)]),
               delimiter=",", header="time,lat,lon,heading,depth", comments="", fmt="%.10f")
    xyz = tmp_path / "soundings.xyz"
    np.savetxt(xyz, np.column_stack([t, rec.lon, rec.lat, rec.beam_depth[:, 0]]), fmt="%.10f")
    recorded = import_csv_xyz(log, xyz)
    bathymetry = read_map(_utm_map(tmp_path, direct))
    moved = in_map_frame(recorded, bathymetry)
    shift = np.asarray(direct.meta["origin"]) - np.asarray(bathymetry.origin)
    # the log's positions are the raw GPS samples (the SonTek reference interpolates repeats)
    gps = import_sontek_sum(run, crs="EPSG:25833", timezone="UTC")
    fresh = np.concatenate([[True], (np.diff(rec.lat) != 0) | (np.diff(rec.lon) != 0)])
    np.testing.assert_allclose(moved.dr_pose[fresh, :2], gps.true_pose[fresh, :2] + shift, atol=1e-3)
    assert np.abs(np.angle(np.exp(1j * (moved.dr_pose[:, 2] - direct.true_pose[:, 2])))).max() < 1e-4


def _utm_map(tmp_path, survey):
    from tangraph.maps import grid_surveys
    from tangraph.maps.io import write_sounding_grid

    path = tmp_path / "utm.nc"
    write_sounding_grid(grid_surveys([survey], cell=5.0), path)
    return path
