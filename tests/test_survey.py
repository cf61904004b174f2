"""Survey (tangraph.survey): validation, footprints, cutting pings, the NetCDF round trip and bad
files; and survey files as CF trajectories: absolute time, latitude/longitude, standard names,
versions."""

from __future__ import annotations

import datetime
import os
import shutil
import subprocess
from pathlib import Path

import netCDF4
import numpy as np
import pyproj
import pytest
import xarray as xr

from tangraph.survey import SCHEMA_VERSION, SurveyError, footprints, read_survey, write_survey
from tests.survey_cases import make_survey


@pytest.mark.parametrize("truth", [True, False])
def test_netcdf_round_trip_is_exact(tmp_path, truth):
    s = make_survey(truth=truth)
    path = write_survey(s, tmp_path / "s.nc")
    back = read_survey(path)
    for name in ("time", "dr_pose", "vehicle_depth", "beam_forward", "beam_starboard", "beam_depth"):
        np.testing.assert_array_equal(getattr(back, name), getattr(s, name))
    if truth:
        np.testing.assert_array_equal(back.true_pose, s.true_pose)
    else:
        assert back.true_pose is None
    assert back.meta == s.meta
    assert back.n_empty_pings == s.n_empty_pings == 1


def test_write_does_not_clobber(tmp_path):
    s = make_survey()
    write_survey(s, tmp_path / "s.nc")
    with pytest.raises(FileExistsError):
        write_survey(s, tmp_path / "s.nc")


def test_footprints_heading_east_puts_starboard_south():
    pose = np.array([[100.0, 200.0, np.pi / 2]])
    north, east = footprints(pose, np.array([[10.0, 0.0]]), np.array([[0.0, 5.0]]))
    np.testing.assert_allclose(north, [[100.0, 95.0]], atol=1e-12)
    np.testing.assert_allclose(east, [[210.0, 200.0]], atol=1e-12)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"time": np.r_[0.0, 2, 1, *np.arange(3, 20)]}, "time is not increasing at ping 2"),
        ({"vehicle_depth": np.ones(19)}, r"vehicle_depth has shape \(19,\), expected \(20,\)"),
        ({"beam_depth": np.full((20, 7), np.nan)}, "no ping has any sounding"),
        ({"beam_forward": np.ones((20, 6))}, "must all be"),
        ({"meta": {"bad": object()}}, "JSON-serialisable"),
    ],
)
def test_invalid_surveys_are_named(change, message):
    with pytest.raises(SurveyError, match=message):
        make_survey().replace(**change)


def test_bad_files_are_named(tmp_path):
    s = make_survey()
    path = write_survey(s, tmp_path / "s.nc")
    ds = xr.open_dataset(path).load()
    ds.drop_vars("dr_east").to_netcdf(tmp_path / "missing.nc")
    with pytest.raises(SurveyError, match=r"missing.nc: missing variables \['dr_east'\]"):
        read_survey(tmp_path / "missing.nc")
    bad = ds.copy()
    bad["time"] = ("ping", ds["time"].values[::-1])
    bad.to_netcdf(tmp_path / "backwards.nc")
    with pytest.raises(SurveyError, match="backwards.nc: survey: time is not increasing"):
        read_survey(tmp_path / "backwards.nc")
    with pytest.raises(FileNotFoundError):
        read_survey(tmp_path / "none.nc")
    (tmp_path / "junk.nc").write_text("junk")
    with pytest.raises(SurveyError, match="junk.nc: not a readable NetCDF"):
        read_survey(tmp_path / "junk.nc")


def test_pings_cuts_every_array_and_names_a_bad_range():
    import numpy as np
    import pytest

    from tangraph.survey import Survey, SurveyError

    k = 5
    survey = Survey(
        time=np.arange(k, dtype=float),
        dr_pose=np.zeros((k, 3)),
        vehicle_depth=np.ones(k),
        beam_forward=np.zeros((k, 2)),
        beam_starboard=np.zeros((k, 2)),
        beam_depth=np.arange(2 * k, dtype=float).reshape(k, 2),
        true_pose=np.ones((k, 3)),
        meta={"map": "m"},
    )
    part = survey.pings(1, 3)
    assert part.n_pings == 2 and part.beam_depth.tolist() == [[2.0, 3.0], [4.0, 5.0]]
    assert part.true_pose.shape == (2, 3) and part.meta == {"map": "m", "pings": [1, 3]}
    for start, stop in ((3, 3), (-1, 2), (0, 6)):
        with pytest.raises(SurveyError, match="not inside 0..4"):
            survey.pings(start, stop)


# -- CF trajectories ---------------------------------------------------------------------------
PLACED = {"crs": "EPSG:32755", "origin": [5_900_000.0, 750_000.0]}


def placed_survey(truth=True, start_time="2024-05-01T10:00:00.25+02:00", **meta):
    s = make_survey(k=12, b=4, truth=truth)
    extra = {"start_time": start_time} if start_time else {}
    return s.replace(meta={**s.meta, **PLACED, **extra, **meta}, attitude=np.full((12, 2), 0.01))


def attrs_of(path):
    with netCDF4.Dataset(path) as ds:
        return ({k: ds.getncattr(k) for k in ds.ncattrs()},
                {v.name: ({k: v.getncattr(k) for k in v.ncattrs()}, v.dtype, v.dimensions)
                 for v in ds.variables.values()})


@pytest.mark.parametrize("truth", [True, False])
def test_a_placed_survey_is_a_cf_trajectory(tmp_path, truth):
    s = placed_survey(truth=truth)
    path = write_survey(s, tmp_path / "run7.nc")
    glob, var = attrs_of(path)
    assert glob["featureType"] == "trajectory" and glob["Conventions"] == "CF-1.8"
    assert glob["tangraph_survey_version"] == SCHEMA_VERSION == 2
    traj_attrs, traj_type, _ = var["trajectory"]
    assert traj_attrs["cf_role"] == "trajectory_id" and traj_type == np.dtype("S1")  # char, not vlen
    time_attrs = var["time"][0]
    assert time_attrs["units"] == "seconds since 2024-05-01 08:00:00.250000"  # UTC
    assert (time_attrs["standard_name"], time_attrs["calendar"], time_attrs["axis"]) == (
        "time", "standard", "T")
    assert var["lat"][0]["standard_name"] == "latitude" and var["lat"][0]["units"] == "degrees_north"
    assert var["lon"][0]["standard_name"] == "longitude" and var["lon"][0]["units"] == "degrees_east"
    assert var["lat"][0]["long_name"].endswith("(true_pose)" if truth else "(dr_pose)")
    assert var["vehicle_depth"][0]["standard_name"] == "depth" and var["vehicle_depth"][0]["axis"] == "Z"
    assert var["beam_depth"][0]["standard_name"] == "sea_floor_depth_below_sea_surface"
    assert var["pitch"][0]["standard_name"] == "platform_pitch_fore_up"
    assert var["roll"][0]["standard_name"] == "platform_roll_starboard_down"
    for name in ("dr_north", "beam_depth", "pitch"):
        coordinates = set(var[name][0]["coordinates"].split())
        assert coordinates == {"time", "lat", "lon", "vehicle_depth", "trajectory"}
    for name in ("time", "lat", "lon"):
        assert "_FillValue" not in var[name][0]  # coordinates have no missing values
    reference = s.true_pose if truth else s.dr_pose
    lon, lat = pyproj.Transformer.from_crs("EPSG:32755", "EPSG:4326", always_xy=True).transform(
        reference[:, 1] + 750_000.0, reference[:, 0] + 5_900_000.0)
    with xr.open_dataset(path) as ds:
        np.testing.assert_allclose(ds["lat"].values, lat, rtol=0, atol=1e-12)
        np.testing.assert_allclose(ds["lon"].values, lon, rtol=0, atol=1e-12)
        assert str(ds["trajectory"].values.item()) == "run7"
        # a CF reader gets absolute times
        assert ds["time"].values[0] == np.datetime64("2024-05-01T08:00:00.25") + np.timedelta64(
            round(s.time[0] * 1e9), "ns")
    back = read_survey(path)
    np.testing.assert_array_equal(back.time, s.time)  # seconds from the start, exactly
    np.testing.assert_array_equal(back.attitude, s.attitude)
    assert back.meta == s.meta


def test_depths_on_another_datum_have_no_standard_name(tmp_path):
    path = write_survey(placed_survey(vertical_datum="chart datum"), tmp_path / "s.nc")
    var = attrs_of(path)[1]
    assert "standard_name" not in var["beam_depth"][0] and "standard_name" not in var["vehicle_depth"][0]
    assert var["vehicle_depth"][0]["axis"] == "Z"


def test_an_unplaced_survey_has_plain_seconds_and_no_lat_lon(tmp_path):
    s = make_survey(k=12, b=4)
    path = write_survey(s, tmp_path / "sim.nc")
    glob, var = attrs_of(path)
    assert glob["featureType"] == "trajectory" and "lat" not in var and "lon" not in var
    assert var["time"][0]["units"] == "s" and "standard_name" not in var["time"][0]
    np.testing.assert_array_equal(read_survey(path).time, s.time)


def test_a_survey_whose_crs_does_not_project_is_written_without_lat_lon(tmp_path, caplog):
    s = placed_survey(crs="not a crs")
    path = write_survey(s, tmp_path / "bad.nc")
    assert "no latitude/longitude written" in caplog.text
    assert "lat" not in attrs_of(path)[1]
    assert read_survey(path).meta["crs"] == "not a crs"


def test_time_is_read_against_any_epoch(tmp_path):
    s = placed_survey()
    path = write_survey(s, tmp_path / "s.nc")
    # another tool rewrites the file with its own time encoding (decoded, then re-encoded)
    with xr.open_dataset(path) as ds:
        ds = ds.load()
    ds["time"].encoding.update(units="hours since 1970-01-01", dtype="float64")
    ds.to_netcdf(tmp_path / "rewritten.nc")
    assert attrs_of(tmp_path / "rewritten.nc")[1]["time"][0]["units"] == "hours since 1970-01-01"
    np.testing.assert_allclose(read_survey(tmp_path / "rewritten.nc").time, s.time, rtol=0, atol=1e-5)
    # without a start time in the metadata, the start is the first ping
    with xr.open_dataset(path, decode_times=False) as ds:
        ds = ds.load()
    ds.attrs["tangraph_meta"] = "{}"
    ds.to_netcdf(tmp_path / "no_start.nc")
    back = read_survey(tmp_path / "no_start.nc")
    np.testing.assert_allclose(back.time, s.time - s.time[0], rtol=0, atol=1e-9)
    start = datetime.datetime.fromisoformat(back.meta["start_time"])
    expected = datetime.datetime(2024, 5, 1, 8, 0, 0, 250000, tzinfo=datetime.UTC) + datetime.timedelta(
        seconds=float(s.time[0]))
    assert abs((start - expected).total_seconds()) < 1e-5


def test_version_1_files_still_read(tmp_path):
    s = placed_survey()
    path = write_survey(s, tmp_path / "s.nc")
    with xr.open_dataset(path, decode_times=False) as ds:
        ds = ds.load()
    old = ds.reset_coords().drop_vars(["lat", "lon", "trajectory"])
    old["time"].attrs = {"units": "s", "long_name": "time from the survey start"}
    old.attrs = {k: v for k, v in ds.attrs.items() if k != "featureType"}
    old.attrs["tangraph_survey_version"] = 1
    for v in old.variables.values():
        v.encoding.pop("coordinates", None)
    old.to_netcdf(tmp_path / "v1.nc")
    back = read_survey(tmp_path / "v1.nc")
    np.testing.assert_array_equal(back.time, s.time)
    np.testing.assert_array_equal(back.true_pose, s.true_pose)
    old.attrs["tangraph_survey_version"] = 3
    old.to_netcdf(tmp_path / "v3.nc")
    with pytest.raises(SurveyError, match="tangraph_survey_version is 3, this tangraph reads 1 and 2"):
        read_survey(tmp_path / "v3.nc")


def test_unknown_time_units_are_named(tmp_path):
    path = write_survey(placed_survey(), tmp_path / "s.nc")
    with netCDF4.Dataset(path, "a") as ds:
        ds["time"].units = "fortnights since 2024-01-01"
    with pytest.raises(SurveyError, match=r"s.nc: time has units 'fortnights since 2024-01-01'"):
        read_survey(path)


# a folder holding the CF tables standard-names.xml, area-types.xml and regions.xml (the checker
# downloads them otherwise)
_TABLES = os.environ.get("TANGRAPH_CF_TABLES")


@pytest.mark.skipif(shutil.which("cfchecks") is None or not _TABLES,
                    reason="the CF checker needs cfchecks and local CF tables (TANGRAPH_CF_TABLES)")
def test_cf_checker_finds_no_error_or_warning(tmp_path):
    tables = Path(_TABLES)
    for s, name in ((placed_survey(), "placed.nc"), (make_survey(k=12, b=4), "plain.nc")):
        path = write_survey(s, tmp_path / name)
        command = ["cfchecks", "-s", str(tables / "standard-names.xml"), "-a", str(tables / "area-types.xml"),
                   "-r", str(tables / "regions.xml"), str(path)]
        out = subprocess.run(command, capture_output=True, text=True, check=False).stdout
        assert "ERRORS detected: 0" in out and "WARNINGS given: 0" in out, out


def test_non_finite_poses_name_the_pings_that_hold_them():
    survey = make_survey(k=6)
    pose = survey.true_pose.copy()
    pose[2, 0], pose[4, 2] = np.nan, np.inf  # one component of two pings
    with pytest.raises(SurveyError, match=r"true_pose holds non-finite values at pings \[2, 4\]"):
        survey.replace(true_pose=pose)
    depth = survey.beam_depth.copy()
    depth[3, 1] = np.inf  # NaN is no return, infinity a broken value
    with pytest.raises(SurveyError, match=r"beam_depth is infinite at pings \[3\]"):
        survey.replace(beam_depth=depth)
