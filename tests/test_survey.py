"""Survey: validation, the NetCDF round trip, and importing a CSV log with XYZ soundings."""

from __future__ import annotations

import numpy as np
import pytest
import xarray as xr

from tangraph.formats import import_csv_xyz
from tangraph.survey import Survey, SurveyError, footprints, read_survey, write_survey


def make_survey(k=20, b=7, seed=0, truth=True):
    rng = np.random.default_rng(seed)
    time = np.cumsum(rng.uniform(0.5, 1.5, k))
    pose = np.column_stack(
        [np.cumsum(rng.normal(1, 0.1, k)), np.cumsum(rng.normal(0.5, 0.1, k)), rng.uniform(0, 2 * np.pi, k)]
    )
    depth = rng.uniform(40, 60, (k, b))
    depth[rng.random((k, b)) < 0.1] = np.nan
    depth[3] = np.nan  # an empty ping
    return Survey(
        time=time,
        dr_pose=pose,
        vehicle_depth=rng.uniform(5, 10, k),
        beam_forward=rng.normal(0, 1, (k, b)),
        beam_starboard=np.tile(np.linspace(-30, 30, b), (k, 1)),
        beam_depth=depth,
        true_pose=pose + rng.normal(0, 1, (k, 3)) if truth else None,
        meta={"map": "merimbula", "seed": seed, "sonar": {"n_beams": b}},
    )


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
