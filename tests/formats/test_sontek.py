"""The SonTek RiverSurveyor reader (tangraph.formats.sontek) against hand-checked rows of the real
Lake Caputh files, its refusals of bad input (each one line naming file, line and column), and a
CRS in feet."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.formats import import_sontek_sum, read_sontek_sum
from tangraph.formats.sontek import _footprints
from tangraph.survey import SurveyError
from tests.formats.feet_cases import same_track, utm_in
from tests.formats.recorded_files import LONG_RUN, _write

OPTIONS = {"crs": "EPSG:25833", "timezone": "Europe/Berlin"}


def _dms(d, m, s):
    return d + m / 60 + s / 3600


def test_first_and_last_sample_as_read_by_hand(caputh):
    rec = read_sontek_sum(caputh / LONG_RUN)
    assert rec.n_samples == 5839
    # line 2: 1,3/27/2025 11:01:04 AM,1MHz,HD,3.83, 52° 20' 35.27", 12° 59' 42.97",207.2,-0.2,2.0,
    #         3.81,3.83,3.92,3.96,3.75,3.70,0.20,0.20,0.018,0.204,190.0,202.5
    assert rec.sample[0] == 1 and rec.local_time[0] == np.datetime64("2025-03-27T11:01:04")
    assert rec.lat[0] == pytest.approx(_dms(52, 20, 35.27), abs=1e-12)
    assert rec.lon[0] == pytest.approx(_dms(12, 59, 42.97), abs=1e-12)
    assert (rec.heading[0], rec.pitch[0], rec.roll[0]) == (207.2, -0.2, 2.0)
    np.testing.assert_array_equal(rec.beam_depth[0], [3.83, 3.92, 3.96, 3.75, 3.70])
    assert (rec.boat_speed[0], rec.boat_direction[0]) == (0.204, 202.5)
    # last line: 5839,3/27/2025 12:38:22 PM,3MHz,IC,4.57, 52° 20' 12.15", 13°  0' 2.82",338.0,...
    assert rec.sample[-1] == 5839 and rec.local_time[-1] == np.datetime64("2025-03-27T12:38:22")
    assert rec.lat[-1] == pytest.approx(_dms(52, 20, 12.15), abs=1e-12)
    assert rec.lon[-1] == pytest.approx(_dms(13, 0, 2.82), abs=1e-12)
    assert rec.heading[-1] == 338.0


def test_seconds_rounded_to_60_by_the_exporter(caputh):
    # line 29 of this run writes a longitude of 12° 59' 60.00" (59.996 rounded without a carry)
    rec = read_sontek_sum(caputh / "20250122142802.sum")
    assert rec.lon[27] == pytest.approx(13.0, abs=1e-12)


def test_survey_of_the_long_run(caputh):
    import pyproj

    s = import_sontek_sum(caputh / LONG_RUN, water_level=caputh / "waterlevel.csv", **OPTIONS)
    assert s.n_pings == 5839 and s.n_beams == 5
    # CET (UTC+1) on 27 March 2025: daylight saving starts on 30 March
    assert s.meta["start_time"] == "2025-03-27T10:01:04Z"
    assert s.time[-1] == 5838.0
    # the reference track is the GPS projected into EPSG:25833, in the survey's local frame
    east, north = pyproj.Transformer.from_crs("EPSG:4326", "EPSG:25833", always_xy=True).transform(
        _dms(12, 59, 42.97), _dms(52, 20, 35.27))
    origin = s.meta["origin"]
    assert s.true_pose[0, 0] + origin[0] == pytest.approx(north, abs=1e-6)
    assert s.true_pose[0, 1] + origin[1] == pytest.approx(east, abs=1e-6)
    assert s.dr_pose[0, :2] == pytest.approx(s.true_pose[0, :2])  # the DR starts at the GPS
    # DR: the boat velocity of sample 2 (0.173 m/s towards 201.1 deg) over one second
    step = s.dr_pose[1, :2] - s.dr_pose[0, :2]
    assert step == pytest.approx(0.173 * np.array([np.cos(np.radians(201.1)), np.sin(np.radians(201.1))]))
    # the compass heading turned from true to grid north: PROJ's convergence is grid from true
    factors = pyproj.Proj("EPSG:25833").get_factors(_dms(12, 59, 42.97), _dms(52, 20, 35.27))
    convergence = factors.meridian_convergence
    assert s.dr_pose[0, 2] == pytest.approx(np.radians(207.2 - convergence))
    assert s.meta["grid_convergence_deg"] == pytest.approx(-convergence, abs=0.01)
    # depths below the water-level table's zero: 0.72 m on 27.03.2025
    np.testing.assert_allclose(s.beam_depth[0], np.array([3.83, 3.92, 3.96, 3.75, 3.70]) - 0.72)
    assert s.meta["water_level"] == {"2025-03-27": 0.72}
    assert s.vehicle_depth[0] == pytest.approx(-0.72)
    assert s.attitude[0] == pytest.approx(np.radians([-0.2, 2.0]))
    # this export's boat velocity is GPS-referenced: it follows the GPS within decimetres
    assert s.meta["dr_drift_300s_m"] < 0.5
    assert s.meta["n_no_boat_velocity"] == 0 and s.meta["n_beams_without_return"] == 1


def test_slant_beam_footprint_by_hand(caputh):
    s = import_sontek_sum(caputh / LONG_RUN, **OPTIONS)
    # beam 1 of sample 1: 3.92 m deep, 25 deg from vertical at azimuth 315 (port, forward);
    # turned by roll 2.0 deg (starboard down) and pitch -0.2 deg (bow down)
    a, tilt = np.radians(315.0), np.radians(25.0)
    p, r = np.radians(-0.2), np.radians(2.0)
    beam = np.array([np.sin(tilt) * np.cos(a), np.sin(tilt) * np.sin(a), np.cos(tilt)])
    roll = np.array([[1, 0, 0], [0, np.cos(r), -np.sin(r)], [0, np.sin(r), np.cos(r)]])
    pitch = np.array([[np.cos(p), 0, np.sin(p)], [0, 1, 0], [-np.sin(p), 0, np.cos(p)]])
    level = pitch @ roll @ beam
    expected = 3.92 * level[:2] / level[2]
    assert (s.beam_forward[0, 1], s.beam_starboard[0, 1]) == pytest.approx(tuple(expected), abs=1e-9)
    # level: about depth x tan(25 deg) = 1.83 m from the transducer
    flat_f, flat_s = _footprints(np.full((1, 5), 3.92), np.zeros((1, 2)), np.radians([315, 225, 135, 45.0]))
    assert np.hypot(flat_f[0, 1:], flat_s[0, 1:]) == pytest.approx(3.92 * np.tan(tilt))
    assert (flat_f[0, 0], flat_s[0, 0]) == (0.0, 0.0)


def test_missing_velocity_is_held_and_counted(caputh):
    # the first January run has 47 samples with boat speed 0.000 (no velocity)
    s = import_sontek_sum(caputh / "20250117160335.sum", **OPTIONS)
    rec = read_sontek_sum(caputh / "20250117160335.sum")
    assert s.meta["n_no_boat_velocity"] == int((rec.boat_speed == 0).sum()) == 47
    i = int(np.flatnonzero(rec.boat_speed == 0)[0])  # sample 124: the velocity of 123 is kept
    step = s.dr_pose[i, :2] - s.dr_pose[i - 1, :2]
    v = rec.boat_speed[i - 1] * np.array([np.cos(np.radians(rec.boat_direction[i - 1])),
                                          np.sin(np.radians(rec.boat_direction[i - 1]))])
    assert step == pytest.approx(v)


def test_compass_dead_reckoning_and_declination(caputh):
    s = import_sontek_sum(caputh / LONG_RUN, dr_heading="compass", declination_deg=4.5, **OPTIONS)
    import pyproj

    rec = read_sontek_sum(caputh / LONG_RUN)
    convergence = pyproj.Proj("EPSG:25833").get_factors(rec.lon[1], rec.lat[1]).meridian_convergence
    psi = np.radians(rec.heading[1] + 4.5 - convergence)
    step = s.dr_pose[1, :2] - s.dr_pose[0, :2]
    assert step == pytest.approx(rec.boat_speed[1] * np.array([np.cos(psi), np.sin(psi)]))
    assert s.dr_pose[1, 2] == pytest.approx(psi)


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda ls: [*ls[:5], ls[5][:40], *ls[6:]], r"run.sum, line 6: \d+ fields, the header has 22"),
        (lambda ls: [ls[0].replace("Heading (deg)", "Hdg"), *ls[1:]], "no column 'Heading'"),
        (lambda ls: [*ls[:2], ls[2].replace(",207.0,", ",2O7.0,", 1), *ls[3:]],
         r"line 3, column 'Heading \(deg\)': '2O7.0' is not a number"),
        (lambda ls: [*ls[:4], ls[4].replace("52° 20'", "52d 20'"), *ls[5:]],
         "line 5, column 'Latitude \\(deg\\)': .* is not a degree-minute-second angle"),
        (lambda ls: [*ls[:2], ls[2].replace("3/27/2025", "27.3.2025"), *ls[3:]],
         "line 3, column 'Date/Time': '27.3.2025 11:01:05 AM' is not a time"),
    ],
)
def test_malformed_files_name_file_line_and_column(tmp_path, caputh, edit, message):
    path = _write(tmp_path, caputh, edit)
    with pytest.raises(SurveyError, match=message):
        import_sontek_sum(path, **OPTIONS)


def test_refusals_of_the_options(tmp_path, caputh):
    path = caputh / LONG_RUN
    with pytest.raises(SurveyError, match="local time; give its zone .*--timezone"):
        import_sontek_sum(path, crs="EPSG:25833", timezone=None)
    with pytest.raises(SurveyError, match="--crs"):
        import_sontek_sum(path, crs=None, timezone="UTC")
    with pytest.raises(SurveyError, match="not a projected CRS"):
        import_sontek_sum(path, crs="EPSG:4326", timezone="UTC")
    with pytest.raises(SurveyError, match="outside the area of use of EPSG:32610"):
        import_sontek_sum(path, crs="EPSG:32610", timezone="UTC")  # UTM zone 10 N: California
    with pytest.raises(SurveyError, match="timezone=.Europe/Potsdam. is not a known time zone"):
        import_sontek_sum(path, crs="EPSG:25833", timezone="Europe/Potsdam")
    with pytest.raises(SurveyError, match="--water-level-interpolate.*give it .*--water-level"):
        import_sontek_sum(path, water_level_interpolate=True, **OPTIONS)
    for bad in (float("nan"), float("inf"), 400.0, "east"):
        with pytest.raises(SurveyError, match=r"declination_deg \(--declination\) must be between -180"):
            import_sontek_sum(path, declination_deg=bad, **OPTIONS)
    # the table has 16.01. and 18.01.2025 but not the survey's 17.01.
    with pytest.raises(SurveyError, match="no water level for 2025-01-17; pass .*--water-level-interpolate"):
        import_sontek_sum(caputh / "20250117160335.sum", water_level=caputh / "waterlevel.csv", **OPTIONS)
    s = import_sontek_sum(caputh / "20250117160335.sum", water_level=caputh / "waterlevel.csv",
                          water_level_interpolate=True, **OPTIONS)
    assert s.meta["water_level"] == {"2025-01-17": pytest.approx(0.7625)}
    late = tmp_path / "level.csv"
    late.write_text("date;waterlevel\n01.04.2025;0.7\n02.04.2025;0.71\n")
    with pytest.raises(SurveyError, match="no water level for 2025-03-27; the table runs from 2025-04-01"):
        import_sontek_sum(path, water_level=late, water_level_interpolate=True, **OPTIONS)


def test_consecutive_files_form_one_run_and_others_are_refused(caputh):
    # 17.01. 16:44:16-16:44:49 and 16:44:53-: four seconds apart, one run
    a, b = caputh / "20250117164416.sum", caputh / "20250117164453.sum"
    joined = import_sontek_sum([b, a], **OPTIONS)
    assert joined.n_pings == read_sontek_sum(a).n_samples + read_sontek_sum(b).n_samples
    assert joined.time[34] - joined.time[33] == 4.0
    with pytest.raises(SurveyError, match="import the files one by one"):
        import_sontek_sum([caputh / "20250117160335.sum", caputh / "20250117164453.sum"], **OPTIONS)


def test_daylight_saving_change_is_refused(tmp_path, caputh):
    # 30 March 2025, 02:30 does not exist in Europe/Berlin
    first = ("3/27/2025 11:01:04 AM", "3/30/2025 2:30:00 AM")
    path = _write(tmp_path, caputh, lambda ls: [ls[0], ls[1].replace(*first)])
    with pytest.raises(SurveyError, match="skipped in Europe/Berlin"):
        import_sontek_sum(path, **OPTIONS)
    assert import_sontek_sum(path, crs="EPSG:25833", timezone="Etc/GMT-1").meta["start_time"] == \
        "2025-03-30T01:30:00Z"


def test_sontek_in_feet(caputh):
    import logging

    from tangraph.formats import import_sontek_sum

    logging.getLogger("tangraph.formats.sontek").setLevel(logging.ERROR)
    run = caputh / "20250327110103.sum"
    metres = import_sontek_sum(run, crs="EPSG:25833", timezone="Europe/Berlin")
    feet = import_sontek_sum(run, crs=utm_in("us-ft", 33, "+ellps=GRS80"), timezone="Europe/Berlin")
    same_track(feet, metres)
