"""A survey in its map's frame (tangraph.map_frame): shifted or reprojected onto a map in another
CRS (a lat/lon log, another UTM zone, a CRS in feet, the log of a real run), and refused when a
CRS is not understood, when it was simulated on another map or when it does not overlap the
map's data."""

from __future__ import annotations

import logging

import numpy as np
import pyproj
import pytest

from tangraph.cli import main
from tangraph.errors import TangraphError
from tangraph.formats import import_csv_xyz, import_sontek_sum, read_sontek_sum
from tangraph.map_frame import MIN_MAP_OVERLAP, check_overlap, in_map_frame
from tangraph.maps import load, read_map
from tangraph.maps.grid import BathymetryMap
from tangraph.navigation import navigate
from tangraph.survey import Survey, write_survey
from tests.formats.feet_cases import FEET, US_FOOT, texas_line, write_geographic
from tests.formats.latlon_cases import angle_difference, latlon_log, true_to_grid, write_latlon
from tests.recorded_cases import MODEL, model_for, recorded


@pytest.fixture(autouse=True)
def _quiet():
    logging.getLogger("tangraph.formats.sontek").setLevel(logging.ERROR)


def utm_map(crs="EPSG:32633", origin=(5_806_000.0, 395_000.0)):
    return BathymetryMap(north=np.arange(0.0, 3000, 50), east=np.arange(0.0, 3000, 50),
                         depth=np.full((60, 60), 30.0), crs=crs, origin=origin, name="flat")


def utm33_survey(origin=(5_806_000.0, 396_000.0)):
    k = 12
    pose = np.column_stack([np.linspace(0, 900, k), np.linspace(0, 1500, k), np.linspace(0.1, 6.0, k)])
    return Survey(
        time=np.arange(k, dtype=float),
        dr_pose=pose,
        vehicle_depth=np.full(k, 5.0),
        beam_forward=np.zeros((k, 2)),
        beam_starboard=np.tile([-10.0, 10.0], (k, 1)),
        beam_depth=np.full((k, 2), 30.0),
        true_pose=pose + np.array([3.0, -2.0, 0.05]),
        meta={"crs": "EPSG:32633", "origin": list(origin)},
    )


# -- a simulated survey on another map, or off the map's data ----------------------------------
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


# -- reprojection onto a map in another CRS ----------------------------------------------------
def test_latlon_log_reprojected_onto_a_utm_map_lands_where_pyproj_puts_it(tmp_path):
    log = latlon_log()
    local = import_csv_xyz(*write_latlon(tmp_path, log))  # local transverse Mercator
    bathymetry = utm_map()
    survey = in_map_frame(local, bathymetry)
    e, n = pyproj.Transformer.from_crs("EPSG:4326", "EPSG:32633", always_xy=True).transform(
        log["lon"], log["lat"])
    np.testing.assert_allclose(survey.dr_pose[:, 0], n - bathymetry.origin[0], atol=1e-3, rtol=0)
    np.testing.assert_allclose(survey.dr_pose[:, 1], e - bathymetry.origin[1], atol=1e-3, rtol=0)
    grid = true_to_grid("EPSG:32633", log["lat"], log["lon"], log["heading"])
    np.testing.assert_allclose(angle_difference(survey.dr_pose[:, 2], grid), 0.0, atol=1e-6)
    np.testing.assert_array_equal(survey.beam_starboard, local.beam_starboard)
    assert survey.meta["crs"] == "EPSG:32633" and survey.meta["origin"] == list(bathymetry.origin)
    assert survey.meta["reprojected_from"] == {"crs": local.meta["crs"], "origin": [0.0, 0.0]}
    # the same as importing straight into the map's CRS, up to the origins
    direct = import_csv_xyz(tmp_path / "nav.csv", tmp_path / "s.xyz", crs="EPSG:32633")
    shift = np.subtract(direct.meta["origin"], bathymetry.origin)
    np.testing.assert_allclose(survey.dr_pose[:, :2], direct.dr_pose[:, :2] + shift, atol=1e-3, rtol=0)


@pytest.mark.parametrize("target", ["EPSG:25833", "EPSG:32632"])
def test_a_survey_in_one_utm_crs_is_reprojected_onto_a_map_in_another(target):
    survey = utm33_survey()
    origin = (5_805_000.0, 395_000.0) if target == "EPSG:25833" else (5_820_000.0, 800_000.0)
    bathymetry = utm_map(target, origin)
    moved = in_map_frame(survey, bathymetry)
    transformer = pyproj.Transformer.from_crs("EPSG:32633", target, always_xy=True)
    to_geo = pyproj.Transformer.from_crs("EPSG:32633", "EPSG:4326", always_xy=True)
    for before, after in ((survey.dr_pose, moved.dr_pose), (survey.true_pose, moved.true_pose)):
        e, n = transformer.transform(before[:, 1] + 396_000.0, before[:, 0] + 5_806_000.0)
        np.testing.assert_allclose(after[:, 0], n - origin[0], atol=1e-3, rtol=0)
        np.testing.assert_allclose(after[:, 1], e - origin[1], atol=1e-3, rtol=0)
        lon, lat = to_geo.transform(before[:, 1] + 396_000.0, before[:, 0] + 5_806_000.0)
        gamma_s = pyproj.Proj("EPSG:32633").get_factors(lon, lat).meridian_convergence
        gamma_t = pyproj.Proj(target).get_factors(lon, lat).meridian_convergence
        turn = np.radians(np.asarray(gamma_s) - np.asarray(gamma_t))
        np.testing.assert_allclose(after[:, 2] - before[:, 2], turn, atol=1e-6)
        if target == "EPSG:32632":
            assert np.abs(turn).min() > np.radians(4)  # three degrees of longitude apart
    np.testing.assert_array_equal(moved.beam_starboard, survey.beam_starboard)
    np.testing.assert_array_equal(moved.beam_forward, survey.beam_forward)
    assert moved.meta["crs"] == target and moved.meta["origin"] == list(origin)
    assert moved.meta["reprojected_from"] == {"crs": "EPSG:32633", "origin": [5_806_000.0, 396_000.0]}


def test_the_same_crs_is_only_shifted_and_no_crs_is_left_alone():
    survey = utm33_survey()
    moved = in_map_frame(survey, utm_map("EPSG:32633", (5_805_000.0, 395_500.0)))
    np.testing.assert_array_equal(moved.dr_pose, survey.dr_pose + np.array([1000.0, 500.0, 0.0]))
    assert "reprojected_from" not in moved.meta
    assert in_map_frame(survey, utm_map(None)) is survey
    bare = survey.replace(meta={})
    assert in_map_frame(bare, utm_map()) is bare


@pytest.mark.parametrize(
    ("crs", "where", "message"),
    [
        ("EPSG:99999", "survey", r"^the survey's CRS 'EPSG:99999' is not understood by pyproj$"),
        ("EPSG:4326", "survey", r"^the survey's CRS 'EPSG:4326' is not projected"),
        ("+proj=nonsense", "map", r"^map 'flat''s CRS '\+proj=nonsense' is not understood by pyproj$"),
    ],
)
def test_a_crs_pyproj_does_not_understand_is_named(crs, where, message):
    survey = utm33_survey()
    if where == "survey":
        survey, bathymetry = survey.replace(meta={**survey.meta, "crs": crs}), utm_map()
    else:
        bathymetry = utm_map(crs)
    with pytest.raises(TangraphError, match=message):
        in_map_frame(survey, bathymetry)


def test_a_survey_in_feet_lands_on_maps_in_metres_and_in_feet(tmp_path):
    line = texas_line()
    survey = import_csv_xyz(*write_geographic(tmp_path, line), crs=FEET)
    to_utm = pyproj.Transformer.from_crs("EPSG:4326", "EPSG:32615", always_xy=True)
    e, n = to_utm.transform(line["lon"], line["lat"])
    origin = (float(np.floor(n.min())) - 500.0, float(np.floor(e.min())) - 500.0)
    utm = BathymetryMap(north=np.arange(0.0, 7000, 50), east=np.arange(0.0, 7000, 50),
                        depth=np.full((140, 140), 12.0), crs="EPSG:32615", origin=origin, name="utm")
    moved = in_map_frame(survey, utm)
    np.testing.assert_allclose(moved.dr_pose[:, 0], n - origin[0], atol=1e-3)
    np.testing.assert_allclose(moved.dr_pose[:, 1], e - origin[1], atol=1e-3)
    # a map read from a file in feet records the same metric CRS: only the origins differ
    from tangraph.maps.io import metric_crs

    feet_map = utm.replace(crs=metric_crs(FEET, "test")[0],
                           origin=(13_000_000.0 * US_FOOT, 3_000_000.0 * US_FOOT))
    shifted = in_map_frame(survey, feet_map)
    assert "reprojected_from" not in shifted.meta
    np.testing.assert_allclose(shifted.dr_pose[:, :2] + feet_map.origin,
                               survey.dr_pose[:, :2] + survey.meta["origin"], atol=1e-6)


def test_a_survey_that_records_a_crs_in_feet_is_refused_on_a_map(tmp_path):
    """A survey file written before the conversion (positions of unknown unit in a feet CRS)."""
    survey = import_csv_xyz(*write_geographic(tmp_path, texas_line()), crs=FEET)
    old = survey.replace(meta={**survey.meta, "crs": FEET})
    utm = BathymetryMap(north=np.arange(0.0, 500, 50), east=np.arange(0.0, 500, 50),
                        depth=np.full((10, 10), 12.0), crs="EPSG:32615", origin=(3_280_000.0, 270_000.0),
                        name="utm")
    with pytest.raises(TangraphError, match=r"^the survey's CRS 'EPSG:2278' has axes in US survey foot.*"
                                            r"import the survey again"):
        in_map_frame(old, utm)


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
