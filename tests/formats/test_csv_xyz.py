"""Importing a CSV navigation log with XYZ soundings (tangraph.formats.csv_xyz): body footprints
recovered; lat/lon logs into a projected CRS (grid headings, a local transverse Mercator); a CRS
in feet; columns, headers and separators; times and clocks; bad input named by file, line and
column."""

from __future__ import annotations

import numpy as np
import pyproj
import pytest

from tangraph.errors import TangraphError
from tangraph.formats import import_csv_xyz
from tangraph.survey import SurveyError, read_survey
from tests.formats.feet_cases import (
    FEET,
    LENGTH,
    US_FOOT,
    lonlat_back,
    texas_line,
    track_length,
    write_feet,
    write_geographic,
)
from tests.formats.latlon_cases import (
    OFFSETS,
    START,
    angle_difference,
    iso,
    latlon_log,
    true_to_grid,
    write_latlon,
)
from tests.survey_cases import make_survey


def test_import_csv_xyz_recovers_body_footprints(tmp_path):
    s = make_survey(k=12, b=5, truth=False)
    s = s.replace(beam_depth=np.where(np.isnan(s.beam_depth), 50.0, s.beam_depth))  # all returns
    north, east = s.footprints()
    # the log at twice the ping rate: pings at log times, so interpolation is exact
    log_time = np.sort(np.r_[s.time, s.time[:-1] + np.diff(s.time) / 3])
    heading = np.degrees(np.unwrap(s.dr_pose[:, 2]))
    nav = np.column_stack(
        [
            log_time,
            *(
                np.interp(log_time, s.time, v)
                for v in (s.dr_pose[:, 0], s.dr_pose[:, 1], heading, s.vehicle_depth)
            ),
        ]
    )
    np.savetxt(tmp_path / "nav.csv", nav, delimiter=",", header="time,north,east,heading,depth", comments="")
    rows = np.column_stack([np.repeat(s.time, s.n_beams), east.ravel(), north.ravel(), s.beam_depth.ravel()])
    rows = np.vstack([rows, [s.time[-1] + 100, 0, 0, 10]])  # a sounding after the log ends
    np.savetxt(tmp_path / "soundings.xyz", rows[::-1])  # order must not matter
    imported = import_csv_xyz(tmp_path / "nav.csv", tmp_path / "soundings.xyz")
    np.testing.assert_allclose(imported.time, s.time)
    np.testing.assert_allclose(imported.dr_pose[:, :2], s.dr_pose[:, :2], atol=1e-9)
    np.testing.assert_allclose(np.cos(imported.dr_pose[:, 2] - s.dr_pose[:, 2]), 1.0, atol=1e-12)
    # beams within a ping may come in another order: compare sorted by starboard
    for got, want in ((imported.beam_starboard, s.beam_starboard), (imported.beam_forward, s.beam_forward)):
        np.testing.assert_allclose(np.sort(got, axis=1), np.sort(want, axis=1), atol=1e-6)
    assert imported.meta["n_dropped_outside_navigation"] == 1

    from tangraph.cli import main

    out = tmp_path / "imported.nc"
    assert (
        main(["survey", "import", str(tmp_path / "nav.csv"), str(tmp_path / "soundings.xyz"), "-o", str(out)])
        == 0
    )
    np.testing.assert_array_equal(read_survey(out).beam_depth, imported.beam_depth)


def test_import_names_missing_columns(tmp_path):
    (tmp_path / "nav.csv").write_text("time,north,east,depth\n0,0,0,5\n1,1,0,5\n")
    (tmp_path / "s.xyz").write_text("0 0 0 10\n")
    with pytest.raises(SurveyError, match=r"nav.csv: missing columns \['heading'\]"):
        import_csv_xyz(tmp_path / "nav.csv", tmp_path / "s.xyz")


# -- lat/lon logs into a projected CRS ---------------------------------------------------------
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


def test_a_geographic_or_unknown_crs_is_refused_naming_the_option(tmp_path):
    nav, xyz = write_latlon(tmp_path, latlon_log())
    with pytest.raises(SurveyError, match=r"^crs='EPSG:4326' is not a projected CRS.*crs=, CLI: --crs"):
        import_csv_xyz(nav, xyz, crs="EPSG:4326")
    with pytest.raises(SurveyError, match="crs='EPSG:99999' is not understood by pyproj"):
        import_csv_xyz(nav, xyz, crs="EPSG:99999")


def test_soundings_beyond_an_echo_sounders_reach_are_refused(tmp_path):
    log = latlon_log()
    swapped = log["sounding"].copy()
    swapped[:, [1, 2]] = swapped[:, [2, 1]]  # latitude where the longitude belongs
    nav, xyz = write_latlon(tmp_path, {**log, "sounding": swapped})
    with pytest.raises(SurveyError, match=r"s.xyz: 90 soundings lie farther from the vehicle than an "
                                          r"echo sounder reaches \(ping 0: .* m away, 26.0 m below it\): "
                                          "the x and y"):
        import_csv_xyz(nav, xyz, crs="EPSG:25833")


def test_an_impossible_latitude_is_named(tmp_path):
    log = latlon_log()
    log["lat"] = log["lat"].copy()
    log["lat"][4] = 123.0
    nav, xyz = write_latlon(tmp_path, log)
    with pytest.raises(SurveyError, match=r"nav.csv, line 6, column lat: 123.0 is not a latitude"):
        import_csv_xyz(nav, xyz)


# -- a CRS in feet -----------------------------------------------------------------------------
def test_a_lat_lon_log_projected_into_feet_is_in_metres_and_writes_back(tmp_path):
    line = texas_line()
    survey = import_csv_xyz(*write_geographic(tmp_path, line), crs=FEET)
    assert track_length(survey.dr_pose) == pytest.approx(LENGTH, rel=2e-4)  # scale factor of the grid
    assert pyproj.CRS(survey.meta["crs"]).axis_info[0].unit_name == "metre"
    assert survey.meta["crs_given"] == {"crs": FEET, "unit": "US survey foot",
                                        "metres_per_unit": pytest.approx(US_FOOT, rel=1e-12)}
    # the soundings 15 m to the side stay 15 m to the side
    np.testing.assert_allclose(survey.beam_starboard, np.tile([-15.0, 0.0, 15.0], (survey.n_pings, 1)),
                               atol=0.01)
    lat, lon = lonlat_back(survey, tmp_path)
    np.testing.assert_allclose(lat, line["lat"], atol=1e-8, rtol=0)
    np.testing.assert_allclose(lon, line["lon"], atol=1e-8, rtol=0)


def test_north_east_in_feet_are_converted_and_their_depth_unit_must_be_said(tmp_path):
    line = texas_line()
    nav, xyz = write_feet(tmp_path, line, depth_unit=US_FOOT)
    with pytest.raises(SurveyError, match=r"^crs='EPSG:2278' has axes in US survey foot.*"
                                          r"units='m' or units='ft'.*CLI: --units"):
        import_csv_xyz(nav, xyz, crs=FEET)
    survey = import_csv_xyz(nav, xyz, crs=FEET, units="US survey foot")
    assert track_length(survey.dr_pose) == pytest.approx(LENGTH, rel=2e-4)
    np.testing.assert_allclose(survey.vehicle_depth, 1.0, atol=1e-5)
    np.testing.assert_allclose(survey.beam_depth, (10.0 + np.tile([1.0, 2.0, 3.0], (survey.n_pings, 1))),
                               atol=1e-5)
    np.testing.assert_allclose(survey.beam_starboard, np.tile([-15.0, 0.0, 15.0], (survey.n_pings, 1)),
                               atol=0.01)
    lat, lon = lonlat_back(survey, tmp_path)
    np.testing.assert_allclose(lat, line["lat"], atol=1e-8, rtol=0)
    np.testing.assert_allclose(lon, line["lon"], atol=1e-8, rtol=0)
    # the same survey as the lat/lon log projected into EPSG:2278, origins aside
    geographic = import_csv_xyz(*write_geographic(tmp_path, line), crs=FEET)
    shift = np.subtract(survey.meta["origin"], geographic.meta["origin"])
    np.testing.assert_allclose(survey.dr_pose[:, :2] + shift, geographic.dr_pose[:, :2], atol=1e-3)
    np.testing.assert_allclose(survey.dr_pose[:, 2], geographic.dr_pose[:, 2], atol=1e-6)
    # depths in metres beside feet coordinates
    nav, xyz = write_feet(tmp_path, line)
    metres = import_csv_xyz(nav, xyz, crs=FEET, units="m")
    np.testing.assert_allclose(metres.beam_depth, survey.beam_depth, atol=1e-5)
    with pytest.raises(TangraphError, match="furlong"):
        import_csv_xyz(nav, xyz, crs=FEET, units="furlong")


# -- columns, headers, separators --------------------------------------------------------------
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


# -- times -------------------------------------------------------------------------------------
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


def test_soundings_on_another_clock_than_the_log_are_refused(tmp_path):
    nav, xyz = tmp_path / "nav.csv", tmp_path / "s.xyz"
    t = np.arange(0.0, 101.0)
    np.savetxt(nav, np.column_stack([t, 10 * t, 0 * t, 0 * t, 0 * t + 1]), delimiter=",",
               header="time,north,east,heading,depth", comments="")
    ms = np.arange(0.0, 100_001.0, 500.0)  # the soundings' times in milliseconds
    np.savetxt(xyz, np.column_stack([ms, 0 * ms, 0 * ms, 0 * ms + 20]))
    with pytest.raises(SurveyError, match=r"do not fit the log's .* are both in seconds on one clock"):
        import_csv_xyz(nav, xyz)
    np.savetxt(xyz, np.column_stack([ms / 1000, 0 * ms, 10 * ms / 1000, 0 * ms + 20]))  # under the vehicle
    assert import_csv_xyz(nav, xyz).n_pings == ms.size


# -- bad input ---------------------------------------------------------------------------------
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
