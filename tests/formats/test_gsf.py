"""The GSF multibeam reader (tangraph.formats.gsf) against values read with gsfpy from the real file
of ``../shared/data/multibeam``, and its one-line refusal of a truncated file."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.formats import import_gsf
from tangraph.survey import SurveyError
from tests.formats.recorded_files import GSF, GSF_CRS


@pytest.fixture(scope="session")
def gsf_survey(multibeam):
    pytest.importorskip("gsfpy")
    return import_gsf(multibeam / GSF, crs=GSF_CRS)


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
