"""The XTF and GSF multibeam readers against values read by hand from the real files of
``../shared/data/multibeam`` (raw bytes for XTF, gsfpy for GSF), and their one-line refusals."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest

from tangraph.cli import main
from tangraph.formats import import_gsf, import_xtf
from tangraph.survey import SurveyError, read_survey

#: ``../shared/data`` beside the checkout, as in tests/conftest.py
SHARED_DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"
XTF = "r2sonic_2026_qinsy.xtf"
GSF = "GSF3_08_test_file.gsf"
XTF_CRS = "EPSG:32610"  # UTM 10N: San Francisco Bay
GSF_CRS = "EPSG:32658"  # UTM 58N: 8.7 N, 167.5 E (Kwajalein, Marshall Islands)


@pytest.fixture(scope="session")
def multibeam() -> Path:
    """The real multibeam files; the test is skipped when the folder is absent."""
    folder = SHARED_DATA / "multibeam"
    if not ((folder / XTF).is_file() and (folder / GSF).is_file()):
        pytest.skip(f"real data folder {folder} is absent (it sits beside the checkout as ../shared)")
    return folder


@pytest.fixture(scope="session")
def xtf_survey(multibeam):
    pytest.importorskip("pyxtf")
    return import_xtf(multibeam / XTF, crs=XTF_CRS)


@pytest.fixture(scope="session")
def gsf_survey(multibeam):
    pytest.importorskip("gsfpy")
    return import_gsf(multibeam / GSF, crs=GSF_CRS)


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


# -- XTF ---------------------------------------------------------------------------------------
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


# -- GSF ---------------------------------------------------------------------------------------
def test_gsf_pings_beams_and_times(gsf_survey):
    s = gsf_survey
    assert (s.n_pings, s.n_beams) == (8, 432)
    assert s.meta["start_time"] == "2016-03-23T18:55:53.856Z"  # 1458759353.855999946 s Unix
    assert s.time[-1] == pytest.approx(64.477, abs=1e-3)
    assert s.meta["record_counts"]["GSF_RECORD_SWATH_BATHYMETRY_PING"] == 8
    assert s.meta["n_beams_without_return"] == s.meta["n_beams_flagged"] == 1087
    assert s.n_soundings == 8 * 432 - 1087


def test_gsf_sounding_as_gsfpy_reads_it(multibeam, gsf_survey):
    from gsfpy import open_gsf
    from gsfpy.enums import RecordType

    with open_gsf(multibeam / GSF) as f:
        _, records = f.read(RecordType.GSF_RECORD_SWATH_BATHYMETRY_PING)
    ping = records.mb_ping
    n = ping.number_beams
    flags = np.ctypeslib.as_array(ping.beam_flags, (n,))
    depth = np.ctypeslib.as_array(ping.depth, (n,))
    # beam 148: the first without GSF_IGNORE_BEAM; beam 0 is flagged (1)
    assert int(np.argmax(flags == 0)) == 148 and flags[0] == 1
    assert depth[148] == gsf_survey.beam_depth[0, 148] == 4088.09
    assert gsf_survey.beam_starboard[0, 148] == -1044.6  # across track, port negative
    assert gsf_survey.beam_forward[0, 148] == -239.25
    assert np.isnan(gsf_survey.beam_depth[0, 0]) and np.isnan(gsf_survey.beam_starboard[0, 0])
    assert gsf_survey.beam_depth[0, 216] == 4075.51  # near the centre beam (217)
    across = np.ctypeslib.as_array(ping.across_track, (n,))
    assert (across[0], across[-1]) == (-3960.0, 4064.6)  # beam 0 portmost: starboard positive


def test_gsf_navigation_and_attitude(gsf_survey):
    import pyproj

    s = gsf_survey
    # first ping: 8.7115166 N, 167.475991 E (gsfpy 2.0.0 names them the other way round)
    e, n = pyproj.Transformer.from_crs("EPSG:4326", GSF_CRS, always_xy=True).transform(167.475991, 8.7115166)
    assert s.true_pose[0, 0] + s.meta["origin"][0] == pytest.approx(n, abs=1e-6)
    assert s.true_pose[0, 1] + s.meta["origin"][1] == pytest.approx(e, abs=1e-6)
    np.testing.assert_array_equal(s.dr_pose, s.true_pose)
    # heading 349.95 deg true, plus the grid convergence (-0.38 deg here)
    assert np.degrees(s.true_pose[0, 2]) == pytest.approx(349.95 + s.meta["grid_convergence_deg"], abs=0.01)
    assert np.degrees(s.attitude[0]) == pytest.approx([-0.46, -1.86], abs=1e-9)
    # 7.1 kn over 64.5 s
    track = np.sum(np.hypot(*np.diff(s.true_pose[:, :2], axis=0).T))
    assert 200.0 < track < 240.0
    assert 3800.0 < np.nanmin(s.beam_depth) and np.nanmax(s.beam_depth) < 4350.0


def test_gsf_truncated_file_is_refused_in_one_line(multibeam, tmp_path):
    pytest.importorskip("gsfpy")
    data = (multibeam / GSF).read_bytes()
    cut = tmp_path / "cut.gsf"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(SurveyError) as info:
        import_gsf(cut, crs=GSF_CRS)
    message = str(info.value)
    assert str(cut) in message and "record " in message and "truncated" in message
    assert "\n" not in message


# -- CLI ---------------------------------------------------------------------------------------
@pytest.mark.parametrize(("fmt", "name", "crs"), [("xtf", XTF, XTF_CRS), ("gsf", GSF, GSF_CRS)])
def test_cli_imports_multibeam(multibeam, tmp_path, capsys, fmt, name, crs):
    pytest.importorskip({"xtf": "pyxtf", "gsf": "gsfpy"}[fmt])
    out = tmp_path / "s.nc"
    assert main(["survey", "import", "--format", fmt, str(multibeam / name), "--crs", crs,
                 "-o", str(out)]) == 0
    assert capsys.readouterr().out.rstrip().endswith(f"wrote {out}")
    survey = read_survey(out)
    assert survey.meta["format"] == fmt and survey.attitude is not None


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--draft", "0.2"], "--draft does not apply to --format xtf"),
        (["--timezone", "UTC"], "--timezone does not apply to --format xtf"),
        (["--columns", "time=0", "--water-level-interpolate"],
         "--columns, --water-level-interpolate do not apply to --format xtf"),
    ],
)
def test_cli_refuses_other_formats_options(tmp_path, capsys, extra, message):
    out = tmp_path / "s.nc"
    assert main(["survey", "import", "--format", "xtf", str(tmp_path / "a.xtf"), *extra,
                 "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert main(["survey", "import", "--format", "gsf", "a.gsf", "b.gsf", "-o", str(out)]) == 2
    assert "--format gsf takes one file, got 2" in capsys.readouterr().err
    assert not out.exists()
