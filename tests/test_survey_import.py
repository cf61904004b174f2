"""Importing recorded surveys: CSV options (columns, headers, separators, times) and the
reprojection of a survey onto a map in another CRS."""

from __future__ import annotations

import numpy as np
import pyproj
import pytest

from tangraph.cli import main
from tangraph.errors import TangraphError
from tangraph.formats import import_csv_xyz
from tangraph.maps.grid import BathymetryMap
from tangraph.navigation import in_map_frame
from tangraph.survey import Survey, SurveyError, read_survey

LAT0, LON0 = 52.40, 13.40  # near Potsdam: UTM zone 33, 1.3 deg west of its central meridian
OFFSETS = np.array([-20.0, 0.0, 20.0])  # beams to starboard, metres
START = np.datetime64("2024-05-01T10:00:00", "s")  # UTC


def latlon_log(k=30):
    """A curving track in WGS84 with true headings, and three beams per ping placed along the
    true starboard azimuth on the ellipsoid (pyproj.Geod)."""
    t = np.arange(k) * 2.0
    lat = LAT0 + 1e-4 * t + 2e-4 * np.sin(t / 15)
    lon = LON0 + 2e-4 * t
    heading = (40.0 + 3.0 * t) % 360.0
    depth = 5.0 + 0.1 * t
    geod = pyproj.Geod(ellps="WGS84")
    rep = np.repeat
    side = np.tile(OFFSETS, k)
    lon_b, lat_b, _ = geod.fwd(rep(lon, 3), rep(lat, 3), rep(heading, 3) + 90.0 * np.sign(side), np.abs(side))
    lon_b, lat_b = np.asarray(lon_b), np.asarray(lat_b)
    centre = np.tile(OFFSETS, k) == 0
    lon_b[centre], lat_b[centre] = rep(lon, 3)[centre], rep(lat, 3)[centre]
    z = 30.0 + np.tile([1.0, 2.0, 3.0], k)
    return {"t": t, "lat": lat, "lon": lon, "heading": heading, "depth": depth,
            "sounding": np.column_stack([rep(t, 3), lon_b, lat_b, z])}


def write_latlon(tmp_path, log, *, time_text=None, sounding_time_text=None, sep=",", header=True,
                 order=("time", "lat", "lon", "heading", "depth")):
    values = {"time": log["t"], "lat": log["lat"], "lon": log["lon"], "heading": log["heading"],
              "depth": log["depth"]}
    lines = [sep.join(order)] if header else []
    for i in range(log["t"].size):
        fields = [time_text[i] if (key == "time" and time_text is not None) else repr(float(values[key][i]))
                  for key in order]
        lines.append(sep.join(fields))
    nav = tmp_path / "nav.csv"
    nav.write_text("\n".join(lines) + "\n")
    xyz = tmp_path / "s.xyz"
    rows = log["sounding"]
    xyz.write_text("".join(
        f"{sounding_time_text[i] if sounding_time_text is not None else repr(float(r[0]))} "
        + " ".join(repr(float(v)) for v in r[1:]) + "\n" for i, r in enumerate(rows)))
    return nav, xyz


def true_to_grid(crs, lat, lon, heading_deg):
    """Grid heading from the true one with PROJ's meridian convergence (independent of the
    numeric step of the import)."""
    gamma = pyproj.Proj(crs).get_factors(lon, lat).meridian_convergence
    return np.radians(heading_deg - np.asarray(gamma))


def angle_difference(a, b):
    return np.angle(np.exp(1j * (np.asarray(a) - np.asarray(b))))


def utm_map(crs="EPSG:32633", origin=(5_806_000.0, 395_000.0)):
    return BathymetryMap(north=np.arange(0.0, 3000, 50), east=np.arange(0.0, 3000, 50),
                         depth=np.full((60, 60), 30.0), crs=crs, origin=origin, name="flat")


# -- lat/lon logs into a projected CRS ----------------------------------------------------------
def test_latlon_log_into_utm_matches_pyproj_and_turns_headings_to_grid_north(tmp_path):
    log = latlon_log()
    nav, xyz = write_latlon(tmp_path, log)
    survey = import_csv_xyz(nav, xyz, crs="EPSG:32633")
    to_utm = pyproj.Transformer.from_crs("EPSG:4326", "EPSG:32633", always_xy=True)
    e, n = to_utm.transform(log["lon"], log["lat"])
    origin = [np.floor(n.min()), np.floor(e.min())]
    assert survey.meta["crs"] == "EPSG:32633" and survey.meta["origin"] == origin
    np.testing.assert_allclose(survey.time, log["t"])
    np.testing.assert_allclose(survey.dr_pose[:, 0], n - origin[0], atol=1e-3, rtol=0)
    np.testing.assert_allclose(survey.dr_pose[:, 1], e - origin[1], atol=1e-3, rtol=0)
    grid = true_to_grid("EPSG:32633", log["lat"], log["lon"], log["heading"])
    assert np.abs(grid - np.radians(log["heading"])).min() > 0.02  # the convergence matters here
    np.testing.assert_allclose(angle_difference(survey.dr_pose[:, 2], grid), 0.0, atol=1e-6)
    # beams laid on the true starboard azimuth are abeam in the grid too (scale k ~ 0.9997)
    np.testing.assert_allclose(np.sort(survey.beam_forward, axis=1), 0.0, atol=2e-3)
    np.testing.assert_allclose(np.sort(survey.beam_starboard, axis=1), np.tile(OFFSETS, (30, 1)),
                               atol=2e-2)
    np.testing.assert_array_equal(np.sort(survey.beam_depth, axis=1), np.tile([31.0, 32, 33], (30, 1)))


def test_latlon_log_without_crs_goes_into_a_recorded_local_mercator(tmp_path):
    from tangraph.maps import local_crs

    log = latlon_log()
    survey = import_csv_xyz(*write_latlon(tmp_path, log))
    assert survey.meta["crs"] == local_crs(float(log["lat"].mean()), float(log["lon"].mean()))
    assert survey.meta["origin"] == [0.0, 0.0]
    t = pyproj.Transformer.from_crs("EPSG:4326", survey.meta["crs"], always_xy=True)
    e, n = t.transform(log["lon"], log["lat"])
    np.testing.assert_allclose(survey.dr_pose[:, :2], np.column_stack([n, e]), atol=1e-3, rtol=0)


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


def test_a_geographic_or_unknown_crs_is_refused_naming_the_option(tmp_path):
    nav, xyz = write_latlon(tmp_path, latlon_log())
    with pytest.raises(SurveyError, match=r"^crs='EPSG:4326' is not a projected CRS.*crs=, CLI: --crs"):
        import_csv_xyz(nav, xyz, crs="EPSG:4326")
    with pytest.raises(SurveyError, match="crs='EPSG:99999' is not understood by pyproj"):
        import_csv_xyz(nav, xyz, crs="EPSG:99999")


def test_an_impossible_latitude_is_named(tmp_path):
    log = latlon_log()
    log["lat"] = log["lat"].copy()
    log["lat"][4] = 123.0
    nav, xyz = write_latlon(tmp_path, log)
    with pytest.raises(SurveyError, match=r"nav.csv, line 6, column lat: 123.0 is not a latitude"):
        import_csv_xyz(nav, xyz)


# -- reprojection between projected CRSs --------------------------------------------------------
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


# -- columns, headers, separators -----------------------------------------------------------------
@pytest.mark.parametrize("sep", [",", ";", "\t", " "])
def test_headerless_logs_by_position_in_any_separator(tmp_path, sep):
    log = latlon_log()
    order = ("heading", "time", "depth", "lon", "lat")
    nav, xyz = write_latlon(tmp_path, log, sep=sep, header=False, order=order)
    columns = {key: i for i, key in enumerate(order)}
    survey = import_csv_xyz(nav, xyz, header=False, columns=columns, crs="EPSG:32633")
    (tmp_path / "ref").mkdir()
    reference = import_csv_xyz(*write_latlon(tmp_path / "ref", log), crs="EPSG:32633")
    np.testing.assert_array_equal(survey.dr_pose, reference.dr_pose)
    np.testing.assert_array_equal(survey.vehicle_depth, log["depth"])


def test_columns_by_name_and_projected_coordinates_with_elevations(tmp_path):
    nav = tmp_path / "nav.txt"
    nav.write_text("# exported\nT;Northing;Easting;Hdg;Z\n"
                   "0;5806000.5;396000.25;90;4\n10;5806000.5;396010.25;90;6\n")
    xyz = tmp_path / "s.xyz"
    xyz.write_text("time;x;y;z\n5;396005.25;5806000.5;-30\n5;396005.25;5805990.5;-31\n")
    survey = import_csv_xyz(nav, xyz, sign="elevation", crs="EPSG:32633", columns={
        "time": "t", "north": "NORTHING", "east": "easting", "heading": "hdg", "depth": "z"})
    assert survey.meta["origin"] == [5806000.0, 396000.0]
    np.testing.assert_allclose(survey.dr_pose, [[0.5, 5.25, np.pi / 2]])
    np.testing.assert_allclose(survey.vehicle_depth, [5.0])
    np.testing.assert_allclose(survey.beam_starboard, [[0.0, 10.0]], atol=1e-9)
    np.testing.assert_allclose(survey.beam_depth, [[30.0, 31.0]])
    assert "start_time" not in survey.meta  # seconds on the log's own clock
    np.testing.assert_array_equal(survey.time, [5.0])


# -- times ----------------------------------------------------------------------------------------
def iso(t, fmt="%Y-%m-%dT%H:%M:%S", suffix="Z"):
    import datetime as dt

    base = dt.datetime(2024, 5, 1, 10, 0, 0)
    return [(base + dt.timedelta(seconds=float(s))).strftime(fmt) + suffix for s in t]


def test_iso_times_with_a_zone_count_from_the_first_ping(tmp_path):
    log = latlon_log()
    epoch = (START - np.datetime64("1970-01-01T00:00:00", "s")).astype(float) + log["sounding"][:, 0]
    nav, xyz = write_latlon(tmp_path, log, time_text=iso(log["t"] + 0.5, "%Y-%m-%dT%H:%M:%S.%f", "+00:00"),
                            sounding_time_text=[repr(float(v) + 0.5) for v in epoch])  # soundings: epoch
    survey = import_csv_xyz(nav, xyz)
    assert survey.meta["start_time"] == "2024-05-01T10:00:00.500Z"
    np.testing.assert_allclose(survey.time, log["t"], atol=1e-6)


def test_naive_iso_times_need_a_timezone_and_are_taken_to_utc(tmp_path):
    log = latlon_log()
    text = iso(log["t"], suffix="")
    nav, xyz = write_latlon(tmp_path, log, time_text=text, sounding_time_text=np.repeat(text, 3))
    with pytest.raises(SurveyError, match=r"nav.csv, line 2, column time: '2024-05-01T10:00:00' has no "
                       r"time zone; give the zone of the clock \(timezone=, CLI: --timezone\)"):
        import_csv_xyz(nav, xyz)
    survey = import_csv_xyz(nav, xyz, timezone="Europe/Berlin")  # CEST: UTC+2
    assert survey.meta["start_time"] == "2024-05-01T08:00:00Z"
    np.testing.assert_allclose(survey.time, log["t"], atol=1e-6)
    with pytest.raises(SurveyError, match="timezone='Mars/Olympus' is not a known time zone"):
        import_csv_xyz(nav, xyz, timezone="Mars/Olympus")


def test_epoch_seconds_are_recognised_or_forced(tmp_path):
    log = latlon_log()
    epoch = 1_714_557_600.0  # 2024-05-01T10:00:00Z
    log["t"] = log["t"] + epoch
    log["sounding"][:, 0] += epoch
    nav, xyz = write_latlon(tmp_path, log)
    survey = import_csv_xyz(nav, xyz)
    assert survey.meta["start_time"] == "2024-05-01T10:00:00Z"
    np.testing.assert_allclose(survey.time, log["t"] - epoch)
    small = latlon_log()
    nav, xyz = write_latlon(tmp_path, small)
    forced = import_csv_xyz(nav, xyz, time_format="epoch")
    assert forced.meta["start_time"] == "1970-01-01T00:00:00Z"
    assert "start_time" not in import_csv_xyz(nav, xyz, time_format="seconds").meta


@pytest.mark.parametrize(
    ("nav_text", "xyz_text", "kwargs", "message"),
    [
        ("time,north,east,depth\n0,0,0,5\n", "0 0 0 10\n", {}, r"nav.csv: missing columns \['heading'\]"),
        ("time,north,east,heading,depth\n0,0,0,9,5\n1,1,0,x9,5\n", "0 0 0 10\n", {},
         r"^\S*nav.csv, line 3, column heading: 'x9' is not a number$"),
        ("0,0,0,9,5\n1,1,0,9\n", "0 0 0 10\n",
         {"header": False, "columns": {"time": 0, "north": 1, "east": 2, "heading": 3, "depth": 4}},
         r"nav.csv, line 2: column 4 \(depth\) is field 5 \(0-based 4\) but the line has 4 fields"),
        ("0,0,0,9,5\n", "0 0 0 10\n", {"header": False},
         r"nav.csv: without a header row, give the 0-based position of every column"),
        ("time,north,east,heading,depth\n2024-05-01T10:00Z,0,0,9,5\n2024-05-01 noon,1,0,9,5\n",
         "0 0 0 10\n", {}, r"nav.csv, line 3, column time: '2024-05-01 noon' is not a time"),
        ("time,north,east,heading,depth\n2024-02-30T10:00:00Z,0,0,9,5\n", "0 0 0 10\n", {},
         r"nav.csv, line 2, column time: '2024-02-30T10:00:00Z' is not a valid time$"),
        ("time,north,east,heading,depth\n2024-03-31T02:30:00,0,0,9,5\n", "0 0 0 10\n",
         {"timezone": "Europe/Berlin"}, r"line 2, column time: .* skipped there: a daylight-saving"),
        ("time,north,east,heading,depth\n2024-05-01T10:00:00Z,0,0,9,5\n", "0 0 0 10\n", {},
         r"nav.csv: times are absolute .* but \S*s.xyz: times are seconds on their own clock"),
        ("time,north,east,heading,depth\n0,0,0,9,5\n", "0 0 0 10\n", {"timezone": "UTC"},
         r"timezone='UTC' applies to ISO 8601 times without a zone"),
        ("time,north,east,heading,depth\n0,0,0,9,5\n", "0 0 0 10\n", {"columns": {"speed": 3}},
         r"columns: unknown keys \['speed'\]"),
        ("time,north,east,heading,depth\n0,0,0,9,5\n", "0 0 0 10\n", {"columns": {"lat": 1, "north": 2}},
         r"columns: give lat/lon or north/east, not both"),
        ("time,north,east,heading,depth\n0,0,0,9,5\n", "0 0 0 10\n", {"time_format": "iso"},
         r"nav.csv, line 2, column time: '0' is not a time"),
        ("time,north,east,heading,depth\n0,0,0,9,5\n1,0,0,9,5\n", "0 0 0\n", {},
         r"s.xyz, line 1: expected columns time x y z, got 3 columns"),
        ("time,north,east,heading,depth\n0,0,0,9,5\n1,0,0,9,5\n", "time x y z\n0 0 oops 10\n", {},
         r"s.xyz, line 2, column 2 \(y\): 'oops' is not a number$"),
        ("time,north,east,heading,depth\n0,0,0,9,5\n1,0,0,9,5\n", "0 0 0 10\n0 nan 0 10\n", {},
         r"s.xyz, line 2, column 1 \(x\): 'nan' is not a finite number$"),
    ],
)
def test_bad_input_is_one_line_naming_file_line_and_column(tmp_path, nav_text, xyz_text, kwargs, message):
    (tmp_path / "nav.csv").write_text(nav_text)
    (tmp_path / "s.xyz").write_text(xyz_text)
    with pytest.raises(SurveyError, match=message) as info:
        import_csv_xyz(tmp_path / "nav.csv", tmp_path / "s.xyz", **kwargs)
    assert "\n" not in str(info.value)


# -- the CLI --------------------------------------------------------------------------------------
def test_cli_imports_a_headerless_latlon_log_with_local_times(tmp_path, capsys):
    log = latlon_log()
    text = iso(log["t"], suffix="")
    order = ("time", "heading", "lat", "lon", "depth")
    nav, xyz = write_latlon(tmp_path, log, time_text=text, sounding_time_text=np.repeat(text, 3),
                            header=False, order=order)
    out = tmp_path / "survey.nc"
    args = ["survey", "import", str(nav), str(xyz), "--crs", "EPSG:25833", "--no-header",
            "--timezone", "UTC", "--columns", "time=0,heading=1,lat=2,lon=3,depth=4", "-o", str(out)]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert "counts       n_dropped_outside_navigation 0" in printed and f"wrote {out}" in printed
    survey = read_survey(out)
    assert survey.meta["crs"] == "EPSG:25833" and survey.meta["start_time"] == "2024-05-01T10:00:00Z"
    e, n = pyproj.Transformer.from_crs("EPSG:4326", "EPSG:25833", always_xy=True).transform(
        log["lon"], log["lat"])
    np.testing.assert_allclose(survey.dr_pose[:, 0] + survey.meta["origin"][0], n, atol=1e-3, rtol=0)
    np.testing.assert_allclose(survey.dr_pose[:, 1] + survey.meta["origin"][1], e, atol=1e-3, rtol=0)
    assert main(args) == 2 and "exists; pass --force" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--draft", "0.2"], "--draft does not apply to --format csv-xyz"),
        (["--water-level-interpolate", "--declination", "3"],
         "--water-level-interpolate, --declination do not apply to --format csv-xyz"),
        (["--format", "sontek-sum", "--columns", "time=0"],
         "--columns does not apply to --format sontek-sum"),
        (["--format", "sontek-sum", "--no-header", "--sign", "depth"],
         "--no-header, --sign do not apply to --format sontek-sum"),
        (["--columns", "time"], "--columns: 'time' is not KEY=COLUMN"),
        (["--crs", "EPSG:4326"], "crs='EPSG:4326' is not a projected CRS"),
    ],
)
def test_cli_refuses_options_of_the_other_format(tmp_path, capsys, extra, message):
    nav, xyz = write_latlon(tmp_path, latlon_log())
    out = tmp_path / "survey.nc"
    assert main(["survey", "import", str(nav), str(xyz), *extra, "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not out.exists()


def test_cli_refuses_writing_over_an_input_and_the_wrong_file_count(tmp_path, capsys):
    nav, xyz = write_latlon(tmp_path, latlon_log())
    before = xyz.read_bytes()
    assert main(["survey", "import", str(nav), str(xyz), "-o", str(xyz), "--force"]) == 2
    assert "refusing to write the survey over the input" in capsys.readouterr().err
    assert xyz.read_bytes() == before
    assert main(["survey", "import", str(nav), "-o", str(tmp_path / "s.nc")]) == 2
    assert "--format csv-xyz takes two files (navigation log, soundings), got 1" in capsys.readouterr().err
    with pytest.raises(SystemExit) as info:
        main(["survey", "import", "--format", "kmall", str(nav), "-o", str(tmp_path / "s.nc")])
    assert info.value.code == 2 and "invalid choice: 'kmall'" in capsys.readouterr().err


def test_cli_hands_sontek_files_and_options_to_the_sontek_import(tmp_path, capsys, monkeypatch):
    import tangraph.formats.sontek as sontek

    log = latlon_log()
    made = import_csv_xyz(*write_latlon(tmp_path, log), crs="EPSG:25833")
    calls = []

    def fake(paths, **kwargs):
        calls.append((paths, kwargs))
        return made.replace(meta={**made.meta, "n_no_depth": 3})

    monkeypatch.setattr(sontek, "import_sontek_sum", fake)
    files = [tmp_path / "a.sum", tmp_path / "b.sum"]
    out = tmp_path / "run.nc"
    args = ["survey", "import", "--format", "sontek-sum", *map(str, files), "--crs", "EPSG:25833",
            "--timezone", "Europe/Berlin", "--water-level", str(tmp_path / "level.csv"),
            "--water-level-interpolate", "--draft", "0.15", "--dr-heading", "compass",
            "--declination", "4.5", "-o", str(out)]
    assert main(args) == 0
    assert calls == [(files, {"crs": "EPSG:25833", "timezone": "Europe/Berlin",
                              "water_level": tmp_path / "level.csv", "water_level_interpolate": True,
                              "draft": 0.15, "dr_heading": "compass", "declination_deg": 4.5})]
    printed = capsys.readouterr().out
    assert "counts       n_dropped_outside_navigation 0, n_no_depth 3" in printed
    assert printed.rstrip().endswith(f"wrote {out}")
    calls.clear()
    assert main(["survey", "import", "--format", "sontek-sum", str(files[0]), "-o",
                 str(tmp_path / "one.nc")]) == 0
    assert calls[0][1] == {"crs": None, "timezone": None, "water_level": None,
                           "water_level_interpolate": False}


def test_soundings_on_another_clock_than_the_log_are_refused(tmp_path):
    nav, xyz = tmp_path / "nav.csv", tmp_path / "s.xyz"
    t = np.arange(0.0, 101.0)
    np.savetxt(nav, np.column_stack([t, 10 * t, 0 * t, 0 * t, 0 * t + 1]), delimiter=",",
               header="time,north,east,heading,depth", comments="")
    ms = np.arange(0.0, 100_001.0, 500.0)  # the soundings' times in milliseconds
    np.savetxt(xyz, np.column_stack([ms, 0 * ms, 0 * ms, 0 * ms + 20]))
    with pytest.raises(SurveyError, match=r"do not fit the log's .* are both in seconds on one clock"):
        import_csv_xyz(nav, xyz)
    np.savetxt(xyz, np.column_stack([ms / 1000, 0 * ms, 0 * ms, 0 * ms + 20]))
    assert import_csv_xyz(nav, xyz).n_pings == ms.size
