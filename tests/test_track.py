"""Track: validation, errors against the truth, CSV (with lat/lon) and TUM files."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.fix_records import FixRecord, FixStatus
from tangraph.track import Track, position_errors, write_track_csv, write_track_tum


def make_track(k=5):
    time = np.arange(k, dtype=float)
    pose = np.column_stack([10.0 * time, 5.0 * time, np.full(k, np.pi / 2)])
    cov = np.tile(np.diag([4.0, 9.0, 0.01]), (k, 1, 1))
    return Track(time=time, pose=pose, covariance=cov, method="test")


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


def test_the_summary_says_which_poses_are_lost():
    from tangraph.navigation import track_summary
    from tangraph.survey import Survey

    survey = Survey(time=np.arange(5.0), dr_pose=np.zeros((5, 3)), vehicle_depth=np.zeros(5),
                    beam_forward=np.zeros((5, 1)), beam_starboard=np.zeros((5, 1)),
                    beam_depth=np.full((5, 1), 10.0))
    track = Track(time=np.arange(5.0), pose=np.zeros((5, 3)),
                  meta={"lost_steps": [1, 2], "lost_episodes": [{"start": 1}], "n_off_map": 3,
                        "start_prior": "outlier"})
    text = track_summary(track, survey)
    assert "2 pings flagged lost in 1 episodes" in text and "3 pings: dead reckoning only" in text
    assert "start position prior disagreed" in text
