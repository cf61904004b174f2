"""The XTF multibeam reader (tangraph.formats.xtf) against values read by hand from the raw bytes
of the real file of ``../shared/data/multibeam``, its one-line refusals, and a CRS in feet (the
GSF reader's too)."""

from __future__ import annotations

import struct

import numpy as np
import pytest

from tangraph.formats import import_xtf
from tangraph.survey import SurveyError
from tests.formats.feet_cases import same_track, utm_in
from tests.formats.recorded_files import XTF, XTF_CRS


@pytest.fixture(scope="session")
def xtf_survey(multibeam):
    pytest.importorskip("pyxtf")
    return import_xtf(multibeam / XTF, crs=XTF_CRS)


def _first_r2sonic_packet(data: bytes) -> bytes:
    """The bytes of the first type-65 packet, found by walking the packet chain by hand."""
    offset = 1024  # file header; one bathymetry channel: its CHANINFO is inside the header
    while True:
        magic, kind = struct.unpack_from("<HB", data, offset)
        size = struct.unpack_from("<I", data, offset + 10)[0]
        assert magic == 0xFACE
        if kind == 65:
            return data[offset:offset + size]
        offset += size


def test_xtf_pings_beams_and_times(xtf_survey):
    s = xtf_survey
    assert (s.n_pings, s.n_beams) == (923, 256)
    assert s.meta["start_time"] == "2015-07-08T23:52:15.920Z"
    assert s.time[0] == 0.0 and s.time[-1] == pytest.approx(48.10, abs=0.01)
    assert s.meta["packet_counts"] == {"3": 1203, "65": 923, "107": 1204}
    assert s.meta["n_pings"] == 923 and s.meta["n_beams_without_return"] == 0  # every Q0 flag passed
    assert s.n_soundings == 923 * 256


def test_xtf_sounding_from_the_bytes(multibeam, xtf_survey):
    raw = _first_r2sonic_packet((multibeam / XTF).read_bytes())
    # XTF ping header (little endian): SensorPitch, SensorRoll (degrees), Heave (m) at byte 204
    pitch_deg, roll_deg, _, heave = struct.unpack_from("<ffff", raw, 204)
    pitch, roll = np.radians([pitch_deg, roll_deg])
    assert xtf_survey.vehicle_depth[0] == pytest.approx(-heave, abs=1e-12)  # draft 0, heave up
    bth = raw[256:]
    assert bth[:4] == b"BTH0"
    # sections (big endian) in the order of this file: H0 (116 bytes), R0, A2, ...
    assert bth[12:14] == b"H0" and bth[128:130] == b"R0"
    sound_speed = struct.unpack_from(">f", bth, 12 + 44)[0]
    scale, count = struct.unpack_from(">fH", bth, 128 + 4)
    a2 = 128 + struct.unpack_from(">H", bth, 130)[0]
    assert bth[a2:a2 + 2] == b"A2"
    first, step = struct.unpack_from(">ff", bth, a2 + 4)
    angle = first + struct.unpack_from(">H", bth, a2 + 36)[0] * step
    assert (count, round(sound_speed, 3)) == (8069, 1514.962)
    r = 0.5 * sound_speed * count * scale
    # beam 0 (port outer), turned by roll (starboard down) then pitch (bow up)
    assert xtf_survey.beam_starboard[0, 0] == pytest.approx(r * np.sin(angle - roll), abs=1e-9)
    assert xtf_survey.beam_depth[0, 0] == pytest.approx(
        r * np.cos(angle - roll) * np.cos(pitch) + xtf_survey.vehicle_depth[0], abs=1e-9)
    assert xtf_survey.beam_forward[0, 0] == pytest.approx(r * np.cos(angle - roll) * np.sin(pitch), abs=1e-9)
    assert xtf_survey.beam_depth[0, 0] == pytest.approx(11.103, abs=0.001)
    assert xtf_survey.beam_starboard[0, 0] < 0 < xtf_survey.beam_starboard[0, -1]  # port first


def test_xtf_roll_is_not_applied_by_the_sonar(xtf_survey):
    # the across-track slope of the swath would follow the roll if the angles were stabilised
    # (or the roll applied with the wrong sign); turned by the roll, it does not
    s = xtf_survey
    slope = np.array([np.polyfit(s.beam_starboard[k], s.beam_depth[k], 1)[0] for k in range(s.n_pings)])
    assert abs(np.corrcoef(slope, s.attitude[:, 1])[0, 1]) < 0.2
    assert np.std(slope) < 0.01


def test_xtf_navigation_and_attitude(xtf_survey):
    import pyproj

    s = xtf_survey
    # first raw navigation packet: 37.75684982829624 N, -122.377451444202 E at 23:52:15.009080
    e, n = pyproj.Transformer.from_crs("EPSG:4326", XTF_CRS, always_xy=True).transform(
        -122.377451444202, 37.75684982829624)
    north0 = s.true_pose[0, 0] + s.meta["origin"][0]
    east0 = s.true_pose[0, 1] + s.meta["origin"][1]
    assert np.hypot(north0 - n, east0 - e) < 1.0  # the ping is 0.9 s later, at about 0.7 m/s
    np.testing.assert_array_equal(s.dr_pose, s.true_pose)
    assert s.meta["reference"] == "GNSS"
    track = np.sum(np.hypot(*np.diff(s.true_pose[:, :2], axis=0).T))
    assert 30.0 < track < 35.0
    heading = np.degrees(s.true_pose[:, 2])
    assert 242.0 < heading.min() and heading.max() < 275.0
    pitch, roll = np.degrees(s.attitude).T
    assert -3.0 < pitch.min() and pitch.max() < 1.5
    assert -4.2 < roll.min() and roll.max() < 3.7
    assert roll[0] == pytest.approx(0.21708619594573975, abs=1e-6)  # ping header, deg
    assert 8.0 < np.nanmin(s.beam_depth) and np.nanmax(s.beam_depth) < 12.0


def test_xtf_truncated_file_is_refused_in_one_line(multibeam, tmp_path):
    pytest.importorskip("pyxtf")
    data = (multibeam / XTF).read_bytes()
    cut = tmp_path / "cut.xtf"
    cut.write_bytes(data[: len(data) // 2 + 100])
    with pytest.raises(SurveyError) as info:
        import_xtf(cut, crs=XTF_CRS)
    message = str(info.value)
    assert str(cut) in message and "truncated file" in message and "byte " in message
    assert "\n" not in message


def test_xtf_refusals(multibeam, tmp_path):
    with pytest.raises(SurveyError, match="give the projected CRS"):
        import_xtf(multibeam / XTF, crs=None)
    with pytest.raises(SurveyError, match="not a projected CRS"):
        import_xtf(multibeam / XTF, crs="EPSG:4326")
    other = tmp_path / "x.xtf"
    other.write_bytes(b"\x00" * 2000)
    with pytest.raises(SurveyError, match="not an XTF file"):
        import_xtf(other, crs=XTF_CRS)


def test_xtf_and_gsf_in_feet():
    from tests.formats.recorded_files import GSF, SHARED_DATA, XTF

    folder = SHARED_DATA / "multibeam"
    if not (folder / XTF).is_file():
        pytest.skip(f"real data folder {folder} is absent (it sits beside the checkout as ../shared)")
    pytest.importorskip("pyxtf")
    pytest.importorskip("gsfpy")
    from tangraph.formats import import_gsf, import_xtf

    same_track(import_xtf(folder / XTF, crs=utm_in("us-ft", 10)), import_xtf(folder / XTF, crs="EPSG:32610"))
    same_track(import_gsf(folder / GSF, crs=utm_in("ft", 58)), import_gsf(folder / GSF, crs="EPSG:32658"))
