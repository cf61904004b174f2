"""The library puts a recorded survey on its map as the CLI does: in the map's frame (its own CRS
and origin shifted or reprojected), refused when it does not overlap the map's data; the
library and the CLI give the same track, written in the right latitude/longitude."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.cli import main
from tangraph.errors import TangraphError
from tangraph.maps import load
from tangraph.maps.grid import BathymetryMap
from tangraph.navigation import (
    MIN_MAP_OVERLAP,
    check_overlap,
    dead_reckoning_track,
    in_map_frame,
    navigate,
    survey_on_map,
)
from tangraph.sensors import NavigationModel
from tangraph.sim.scenario import load_scenario, simulate
from tangraph.survey import write_survey

MODEL = "heading_bias_std_deg = 2.0\nspeed_scale_std = 0.02\nspeed_noise = 0.05\nsounding_std = 0.3\n"


@pytest.fixture(scope="module")
def merimbula():
    return load("merimbula")


@pytest.fixture(scope="module")
def simulated(merimbula):
    return simulate(load_scenario("wang2019"), rng=np.random.default_rng(3), bathymetry=merimbula, seed=3)


def recorded(survey, crs="EPSG:32756", origin=(5_900_000.0, 230_000.0)):
    """The survey as a recorder would give it: in another CRS (UTM 56S: Merimbula lies 0.1 deg
    west of its edge) with its own origin, and no word of the map it was simulated on."""
    frame = BathymetryMap(north=np.array([0.0, 1.0]), east=np.array([0.0, 1.0]), depth=np.zeros((2, 2)),
                          crs=crs, origin=origin, name="frame")
    moved = in_map_frame(survey, frame)
    meta = {k: v for k, v in moved.meta.items() if k not in ("map", "map_identity", "reprojected_from")}
    return moved.replace(meta=meta)


def model_for(survey):
    return NavigationModel.from_survey(survey)


def horizontal_rmse(pose, truth):
    return float(np.sqrt(np.mean(np.sum((pose[:, :2] - truth[:, :2]) ** 2, axis=1))))


def test_navigate_puts_a_recorded_survey_in_the_map_frame(simulated, merimbula):
    rec = recorded(simulated)
    assert np.abs(rec.dr_pose[:, :2] - simulated.dr_pose[:, :2]).min() > 1000.0  # km apart as numbers
    model = model_for(simulated)
    track = navigate(rec, merimbula, "smoother", model=model)
    dr = horizontal_rmse(simulated.dr_pose, simulated.true_pose)
    assert horizontal_rmse(track.pose, simulated.true_pose) < 0.5 * dr
    on_map = survey_on_map(rec, merimbula)
    np.testing.assert_allclose(on_map.true_pose[:, :2], simulated.true_pose[:, :2], atol=1e-3)
    assert survey_on_map(on_map, merimbula) is on_map  # twice is harmless
    again = navigate(on_map, merimbula, "smoother", model=model)
    np.testing.assert_allclose(again.pose, track.pose, atol=1e-9)
    pf = navigate(rec, merimbula, "pf", model=model, rng=np.random.default_rng(5))
    assert horizontal_rmse(pf.pose, simulated.true_pose) < dr


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


def test_a_survey_that_never_meets_the_map_is_refused(simulated, tmp_path, capsys):
    """A survey recorded in Australia on a Canadian map."""
    rec = recorded(simulated)
    vancouver = load("vancouver")
    with pytest.raises(TangraphError, match=r"^the survey does not overlap map 'vancouver': 0 of its 281 "
                                            r"pings with soundings .*lat -36\.\d+\.\.-36\.\d+, lon 149\.\d+.*"
                                            r"the map's data lat 4\d\.\d+.*; it lies 12,\d{3} km from them "
                                            r"\(its CRS EPSG:32756 .*, the map's '\+proj=tmerc.*"
                                            r"another region\?\); "
                                            r".*--other-map, to run it on this one anyway\)$"):
        navigate(rec, vancouver, "smoother", model=model_for(simulated))
    with pytest.raises(TangraphError, match="does not overlap map 'vancouver'"):
        check_overlap(rec, vancouver)
    path, dr_model, out = tmp_path / "rec.nc", tmp_path / "dr.toml", tmp_path / "x.csv"
    write_survey(rec, path)
    dr_model.write_text(MODEL)
    for command in (["smooth"], ["navigate", "--method", "pf"]):
        assert main([*command, str(path), "--map", "vancouver", "--dr-model", str(dr_model), "-q",
                     "-o", str(out)]) == 2
        err = capsys.readouterr().err
        assert err.startswith("tangraph: error: the survey does not overlap map 'vancouver'")
        assert err.count("\n") == 1 and not out.exists()


def test_a_survey_that_partly_leaves_the_map_runs_and_one_barely_on_it_is_refused(simulated, merimbula):
    rec = recorded(simulated)  # records no map: only the overlap is checked
    north = simulated.footprints()[0]
    model = model_for(simulated)
    rng = np.random.default_rng(2)
    # no data north of the survey's middle: half of it is off the map's data
    cut = float(np.nanmedian(north))
    half = merimbula.replace(depth=np.where(merimbula.north[:, None] > cut, np.nan, merimbula.depth))
    track = navigate(rec, half, "pf", model=model, rng=rng)
    assert track.n_poses == rec.n_pings and np.all(np.isfinite(track.pose))
    # data under the first 3 % of the pings only
    k = int(0.03 * simulated.n_pings)
    edge = float(np.nanmax(north[:k]))
    sliver = merimbula.replace(depth=np.where(merimbula.north[:, None] > edge, np.nan, merimbula.depth))
    assert MIN_MAP_OVERLAP == 0.05
    with pytest.raises(TangraphError, match=r"does not overlap map 'merimbula': \d+ of its 281 pings"):
        navigate(rec, sliver, "pf", model=model, rng=rng)
    # other_map=True runs it anyway: the estimators keep the dead reckoning off the map
    track = navigate(rec, sliver, "pf", model=model, rng=rng, other_map=True)
    assert np.all(np.isfinite(track.pose))


def test_the_dead_reckoning_of_a_recorded_survey_is_written_on_the_map(simulated, merimbula):
    """The baseline in the same frame as the tracks: survey_on_map first."""
    rec = recorded(simulated)
    dr = dead_reckoning_track(survey_on_map(rec, merimbula))
    np.testing.assert_allclose(dr.pose[:, :2], simulated.dr_pose[:, :2], atol=1e-3)
