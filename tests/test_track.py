"""Track (tangraph.track): validation, errors against the truth, poses flagged lost, and its files
for GIS and other tools: CSV (with latitude/longitude and UTC times), TUM (NED and ENU frames),
GeoJSON and GeoPackage, with error ellipses."""

from __future__ import annotations

import json

import numpy as np
import pyproj
import pytest

from tangraph.errors import TangraphError
from tangraph.fix_records import FixRecord, FixStatus
from tangraph.track import (
    Track,
    error_ellipse,
    position_errors,
    utc_times,
    write_track_csv,
    write_track_geojson,
    write_track_gpkg,
    write_track_tum,
)

CRS, ORIGIN = "EPSG:32755", (5.9e6, 7.5e5)
START = "2024-05-01T23:59:58.75Z"


def make_track(k=5):
    time = np.arange(k, dtype=float)
    pose = np.column_stack([10.0 * time, 5.0 * time, np.full(k, np.pi / 2)])
    cov = np.tile(np.diag([4.0, 9.0, 0.01]), (k, 1, 1))
    return Track(time=time, pose=pose, covariance=cov, method="test")


def epoch_track(k: int = 6) -> Track:
    """Epoch-scale, sub-second times; a heading and a covariance that changes along the track."""
    time = 1.7e9 + 0.123456 + 0.25 * np.arange(k)
    pose = np.column_stack([10.0 * np.arange(k), -4.0 * np.arange(k), np.linspace(-0.5, 3.0, k)])
    cov = np.zeros((k, 3, 3))
    cov[:, 0, 0], cov[:, 1, 1], cov[:, 2, 2] = 4.0 + np.arange(k), 1.0, 0.01
    cov[:, 0, 1] = cov[:, 1, 0] = 0.5
    cov[-1] = np.nan  # one pose whose covariance is unknown
    return Track(time=time, pose=pose, covariance=cov, method="isam2")


def lonlat(track: Track) -> tuple[np.ndarray, np.ndarray]:
    t = pyproj.Transformer.from_crs(CRS, "EPSG:4326", always_xy=True)
    return t.transform(track.pose[:, 1] + ORIGIN[1], track.pose[:, 0] + ORIGIN[0])


def test_validation_names_the_problem():
    with pytest.raises(TangraphError, match="strictly increasing"):
        Track(time=[0.0, 0.0], pose=np.zeros((2, 3)))
    with pytest.raises(TangraphError, match=r"pose has shape \(2, 2\)"):
        Track(time=[0.0, 1.0], pose=np.zeros((2, 2)))
    t = Track(time=[0.0, 1.0], pose=np.zeros((2, 3)))
    assert np.all(np.isnan(t.covariance))


def test_fixes_are_a_typed_field_none_for_an_estimator_without_fixes():
    assert make_track().fixes is None
    record = FixRecord.of(2, None, FixStatus.MATCH_FAILED, float("nan"), 50.0, "too few soundings")
    t = Track(time=[0.0, 1.0, 2.0], pose=np.zeros((3, 3)), method="mle", fixes=[record])
    assert t.fixes == (record,)
    assert Track(time=[0.0], pose=np.zeros((1, 3)), fixes=[]).fixes == ()
    with pytest.raises(TangraphError, match="track 'mle': fixes must be FixRecords, got dict"):
        Track(time=[0.0], pose=np.zeros((1, 3)), method="mle", fixes=[{"index": 0}])


def test_position_errors():
    t = make_track()
    truth = t.pose + np.array([3.0, 4.0, 0.0])
    np.testing.assert_allclose(position_errors(t, truth), 5.0)


def test_csv_with_latitude_longitude(tmp_path):
    t = make_track()
    path = write_track_csv(t, tmp_path / "t.csv", crs="EPSG:32755", origin=(5.9e6, 7.5e5))
    data = np.genfromtxt(path, delimiter=",", names=True)
    assert data.dtype.names[:4] == ("time", "lat", "lon", "north")
    np.testing.assert_allclose(data["north"], t.pose[:, 0])
    np.testing.assert_allclose(data["heading_deg"], 90.0)
    np.testing.assert_allclose(data["var_east"], 9.0)
    assert -38 < data["lat"][0] < -36 and 149 < data["lon"][0] < 151  # 250 km east of 147 E
    with pytest.raises(FileExistsError):
        write_track_csv(t, path)


def test_tum_quaternion_is_the_heading(tmp_path):
    t = make_track()
    data = np.loadtxt(write_track_tum(t, tmp_path / "t.tum"))
    assert data.shape == (5, 8)
    qz, qw = data[:, 6], data[:, 7]
    np.testing.assert_allclose(2 * np.arctan2(qz, qw), np.pi / 2)


def test_csv_with_a_reference_track_and_its_shape_checked(tmp_path):
    track = Track(time=[0.0, 1.0], pose=[[1.0, 2.0, 0.0], [3.0, 4.0, 0.1]])
    ref = np.array([[1.5, 2.5], [3.5, 4.5]])
    path = write_track_csv(track, tmp_path / "t.csv", reference=ref)
    header = path.read_text().splitlines()[0].split(",")
    rows = np.loadtxt(path, delimiter=",", skiprows=1)
    np.testing.assert_array_equal(rows[:, header.index("ref_north")], [1.5, 3.5])
    np.testing.assert_array_equal(rows[:, header.index("ref_east")], [2.5, 4.5])
    with pytest.raises(TangraphError, match="reference track has shape"):
        write_track_csv(track, tmp_path / "u.csv", reference=ref[:1])


def test_poses_flagged_lost_are_a_column_and_a_property(tmp_path):
    flagged = Track(time=np.arange(5.0), pose=np.zeros((5, 3)), meta={"lost_steps": [1, 2, 7]})
    assert flagged.lost.tolist() == [False, True, True, False, False]  # a step past the end ignored
    path = write_track_csv(flagged, tmp_path / "t.csv")
    data = np.genfromtxt(path, delimiter=",", names=True)
    assert data["lost"].tolist() == [0.0, 1.0, 1.0, 0.0, 0.0]
    plain = write_track_csv(make_track(), tmp_path / "u.csv")  # no record of lost poses: no column
    assert "lost" not in plain.read_text().splitlines()[0].split(",")
    assert not make_track().lost.any()


# -- UTC times and error ellipses --------------------------------------------------------------
def test_utc_times_add_seconds_to_the_start_across_midnight():
    assert utc_times(np.array([0.0, 1.25, 2.000001]), START) == [
        "2024-05-01T23:59:58.750000Z",
        "2024-05-02T00:00:00.000000Z",
        "2024-05-02T00:00:00.750001Z",
    ]
    # a zone other than UTC is converted; no zone is UTC
    assert utc_times(np.array([0.0]), "2024-05-02T01:00:00+02:00") == ["2024-05-01T23:00:00.000000Z"]
    assert utc_times(np.array([0.5]), "2024-05-01T10:00:00") == ["2024-05-01T10:00:00.500000Z"]
    with pytest.raises(TangraphError, match="not ISO 8601"):
        utc_times(np.array([0.0]), "yesterday")


def test_error_ellipse_of_a_rotated_covariance():
    # semi-axes 3 (along azimuth 30 deg, clockwise from north) and 1, at chi2 = 1
    a = np.radians(30.0)
    r = np.array([[np.cos(a), -np.sin(a)], [np.sin(a), np.cos(a)]])  # (north, east) columns
    cov = r @ np.diag([9.0, 1.0]) @ r.T
    major, minor, azimuth = error_ellipse(cov, chi2=1.0)
    np.testing.assert_allclose([major, minor, azimuth], [3.0, 1.0, 30.0], atol=1e-12)
    major95, _, _ = error_ellipse(cov)
    np.testing.assert_allclose(major95, 3.0 * np.sqrt(5.991464547107979), rtol=1e-12)
    assert np.all(np.isnan(error_ellipse(np.full((2, 2), np.nan))))


# -- GeoJSON -----------------------------------------------------------------------------------
def test_geojson_is_rfc7946_lon_lat_with_the_pose_properties(tmp_path):
    track = epoch_track()
    ref = track.pose[:, :2] + [1.5, -2.5]
    path = write_track_geojson(track, tmp_path / "t.geojson", crs=CRS, origin=ORIGIN, reference=ref,
                               start_time=START)
    doc = json.loads(path.read_text())  # strict JSON: NaN would not parse as null
    assert doc["type"] == "FeatureCollection" and "crs" not in doc
    line, *points = doc["features"]
    lon, lat = lonlat(track)
    assert line["geometry"]["type"] == "LineString"
    np.testing.assert_allclose(np.array(line["geometry"]["coordinates"]), np.column_stack([lon, lat]),
                               rtol=0, atol=1e-9)
    assert line["properties"]["method"] == "isam2" and line["properties"]["n_poses"] == track.n_poses
    assert line["properties"]["start_utc"] == utc_times(track.time[:1], START)[0]
    assert len(points) == track.n_poses
    coords = np.array([p["geometry"]["coordinates"] for p in points])
    np.testing.assert_allclose(coords[:, 0], lon, rtol=0, atol=1e-9)
    np.testing.assert_allclose(coords[:, 1], lat, rtol=0, atol=1e-9)
    assert -38 < coords[0, 1] < -36 and 149 < coords[0, 0] < 151  # latitude second: south of the equator
    props = [p["properties"] for p in points]
    np.testing.assert_allclose([p["time"] for p in props], track.time, rtol=0, atol=1e-9)
    assert [p["utc"] for p in props] == utc_times(track.time, START)
    np.testing.assert_allclose([p["heading_deg"] for p in props],
                               np.degrees(np.mod(track.pose[:, 2], 2 * np.pi)))
    np.testing.assert_allclose([p["var_north"] for p in props[:-1]], track.covariance[:-1, 0, 0])
    np.testing.assert_allclose([p["cov_north_east"] for p in props[:-1]], 0.5)
    np.testing.assert_allclose([p["var_east"] for p in props[:-1]], 1.0)
    np.testing.assert_allclose([p["var_heading"] for p in props[:-1]], 0.01)
    major, minor, azimuth = error_ellipse(track.covariance[:-1])
    np.testing.assert_allclose([p["ellipse95_major"] for p in props[:-1]], major)
    np.testing.assert_allclose([p["ellipse95_minor"] for p in props[:-1]], minor)
    np.testing.assert_allclose([p["ellipse95_azimuth_deg"] for p in props[:-1]], azimuth)
    assert props[-1]["var_north"] is None and props[-1]["ellipse95_major"] is None
    np.testing.assert_allclose([[p["ref_north"], p["ref_east"]] for p in props], ref)
    # no start time: no utc; the line is still there
    plain = json.loads(write_track_geojson(track, tmp_path / "p.geojson", crs=CRS, origin=ORIGIN).read_text())
    assert "utc" not in plain["features"][1]["properties"]
    assert "start_utc" not in plain["features"][0]["properties"]


def test_geojson_read_by_shapely(tmp_path):
    shapely = pytest.importorskip("shapely.geometry")
    track = epoch_track()
    doc = json.loads(write_track_geojson(track, tmp_path / "t.geojson", crs=CRS, origin=ORIGIN).read_text())
    line = shapely.shape(doc["features"][0]["geometry"])
    lon, lat = lonlat(track)
    np.testing.assert_allclose(np.array(line.coords), np.column_stack([lon, lat]), rtol=0, atol=1e-9)


def test_gis_writers_refuse_a_track_without_crs_and_write_nothing(tmp_path):
    track = epoch_track()
    for writer, name in ((write_track_geojson, "t.geojson"), (write_track_gpkg, "t.gpkg")):
        with pytest.raises(TangraphError, match="needs the map's CRS"):
            writer(track, tmp_path / name, crs=None)
        assert not (tmp_path / name).exists()


# -- GeoPackage --------------------------------------------------------------------------------
def test_gpkg_read_back_with_pyogrio(tmp_path):
    pyogrio = pytest.importorskip("pyogrio")
    raw = pytest.importorskip("pyogrio.raw")

    track = epoch_track()
    ref = track.pose[:, :2] + 1.0
    path = write_track_gpkg(track, tmp_path / "t.gpkg", crs=CRS, origin=ORIGIN, reference=ref,
                            start_time=START)
    layers = dict(pyogrio.list_layers(path))
    assert layers == {"track": "LineString", "poses": "Point"}
    lon, lat = lonlat(track)
    info = pyogrio.read_info(path, layer="poses")
    assert info["crs"] == "EPSG:4326" and info["features"] == track.n_poses
    meta, _, geometry, fields = raw.read(path, layer="poses")
    xy = np.array([np.frombuffer(g[-16:], "<f8") for g in geometry])  # WKB point: x, y last
    np.testing.assert_allclose(xy[:, 0], lon, rtol=0, atol=1e-9)
    np.testing.assert_allclose(xy[:, 1], lat, rtol=0, atol=1e-9)
    columns = dict(zip(meta["fields"], fields, strict=True))
    np.testing.assert_allclose(columns["time"], track.time, rtol=0, atol=1e-6)
    assert list(columns["utc"]) == utc_times(track.time, START)
    np.testing.assert_allclose(columns["var_north"][:-1], track.covariance[:-1, 0, 0])
    assert np.isnan(columns["var_north"][-1])  # NULL where unknown
    np.testing.assert_allclose(columns["ref_east"], ref[:, 1])
    assert {"ellipse95_major", "ellipse95_minor", "ellipse95_azimuth_deg", "heading_deg"} <= set(columns)
    line_meta, _, line_geometry, line_fields = raw.read(path, layer="track")
    assert pyogrio.read_info(path, layer="track")["crs"] == "EPSG:4326"
    coords = np.frombuffer(line_geometry[0][9:], "<f8").reshape(-1, 2)  # WKB: order, type, count
    np.testing.assert_allclose(coords, np.column_stack([lon, lat]), rtol=0, atol=1e-9)
    assert dict(zip(line_meta["fields"], line_fields, strict=True))["method"][0] == "isam2"
    with pytest.raises(FileExistsError):
        write_track_gpkg(track, path, crs=CRS, origin=ORIGIN)
    write_track_gpkg(track, path, crs=CRS, origin=ORIGIN, overwrite=True)  # replaced, not appended
    assert pyogrio.read_info(path, layer="poses")["features"] == track.n_poses


# -- CSV with UTC times ------------------------------------------------------------------------
def test_csv_keeps_sub_second_epoch_times_and_writes_utc(tmp_path):
    track = epoch_track()
    path = write_track_csv(track, tmp_path / "t.csv", crs=CRS, origin=ORIGIN, start_time=START)
    header = path.read_text().splitlines()[0].split(",")
    assert header[:4] == ["time", "utc", "lat", "lon"]
    rows = [line.split(",") for line in path.read_text().splitlines()[1:]]
    np.testing.assert_allclose([float(r[0]) for r in rows], track.time, rtol=0, atol=1e-6)
    assert [r[1] for r in rows] == utc_times(track.time, START)
    lon, lat = lonlat(track)
    np.testing.assert_allclose([float(r[2]) for r in rows], lat, rtol=0, atol=1e-9)
    np.testing.assert_allclose([float(r[3]) for r in rows], lon, rtol=0, atol=1e-9)
    # without a start time: no utc column, the times still whole
    data = np.genfromtxt(write_track_csv(track, tmp_path / "u.csv"), delimiter=",", names=True)
    assert "utc" not in data.dtype.names
    np.testing.assert_allclose(data["time"], track.time, rtol=0, atol=1e-6)


def test_csv_utc_of_survey_seconds(tmp_path):
    track = Track(time=[0.0, 1.25, 61.000001], pose=np.zeros((3, 3)))
    path = write_track_csv(track, tmp_path / "t.csv", start_time=START)
    rows = [line.split(",") for line in path.read_text().splitlines()[1:]]
    assert [r[0] for r in rows] == ["0.000000", "1.250000", "61.000001"]
    assert [r[1] for r in rows] == [
        "2024-05-01T23:59:58.750000Z", "2024-05-02T00:00:00.000000Z", "2024-05-02T00:00:59.750001Z"
    ]


# -- TUM frames --------------------------------------------------------------------------------
def _heading_vector(q: np.ndarray) -> np.ndarray:
    """The body x axis (forward) rotated by quaternions (K, 4: qx qy qz qw) about z only."""
    yaw = 2 * np.arctan2(q[:, 2], q[:, 3])
    return np.column_stack([np.cos(yaw), np.sin(yaw)])


def test_tum_enu_swaps_the_axes_and_turns_the_heading(tmp_path):
    track = epoch_track()
    ned = np.loadtxt(write_track_tum(track, tmp_path / "ned.tum"))
    enu = np.loadtxt(write_track_tum(track, tmp_path / "enu.tum", frame="enu"))
    np.testing.assert_allclose(ned[:, 0], track.time, rtol=0, atol=1e-6)
    np.testing.assert_allclose(ned[:, 1:3], track.pose[:, :2], atol=1e-9)
    np.testing.assert_allclose(enu[:, 1], track.pose[:, 1], atol=1e-9)  # x = east
    np.testing.assert_allclose(enu[:, 2], track.pose[:, 0], atol=1e-9)  # y = north
    np.testing.assert_allclose(np.linalg.norm(enu[:, 4:], axis=1), 1.0, atol=1e-8)
    # forward in NED is (cos psi, sin psi) in (north, east); in ENU the same direction in (east, north)
    psi = track.pose[:, 2]
    np.testing.assert_allclose(_heading_vector(ned[:, 4:]), np.column_stack([np.cos(psi), np.sin(psi)]),
                               atol=1e-8)
    np.testing.assert_allclose(_heading_vector(enu[:, 4:]), _heading_vector(ned[:, 4:])[:, ::-1], atol=1e-8)
    # heading 0 (north) is yaw 90 deg in ENU
    north = Track(time=[0.0], pose=[[0.0, 0.0, 0.0]])
    q = np.loadtxt(write_track_tum(north, tmp_path / "n.tum", frame="enu"))[4:]
    np.testing.assert_allclose(q, [0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)], atol=1e-9)
    with pytest.raises(TangraphError, match="'ned' or 'enu'"):
        write_track_tum(track, tmp_path / "x.tum", frame="nwu")
