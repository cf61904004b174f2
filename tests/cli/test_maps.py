"""The ``tangraph maps`` commands (tangraph.cli.maps): list; info of a name or a file (as JSON, a
BAG, the map's error, the uncertainty variable); plot; mesh with its sidecar; grid of x y z
soundings and of surveys (--units, --position-std as the library's, the map's error written and
reported, --check-lines) and check; their one-line refusals."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest
import xarray as xr

from tangraph.cli import main
from tangraph.gridding_surveys import grid_surveys
from tangraph.maps import BathymetryMap, read_map, write_map
from tangraph.survey import read_survey, write_survey
from tests.gridding_cases import SIGMA, nadir_survey, random_soundings, simulated_survey, smooth_map
from tests.maps.mesh_cases import CRS, _ply_vertices, small_map

US_FOOT = 1200.0 / 3937.0


def soundings_in_feet(path, rng):
    """Scattered soundings in Texas South Central (EPSG:2278, US survey feet), z in feet too."""
    x = 3_000_000 + rng.uniform(0, 330, 3000)  # about 100 m
    y = 13_000_000 + rng.uniform(0, 330, 3000)
    z = 100 + 0.05 * (y - 13_000_000) + rng.normal(0, 0.5, 3000)  # feet
    np.savetxt(path, np.column_stack([x, y, z]))
    return path


def test_maps_list(capsys):
    assert main(["maps", "list"]) == 0
    out = capsys.readouterr().out
    assert "merimbula" in out and "Apache-2.0" in out


def test_maps_info_of_a_name_and_of_a_file(capsys, tmp_path):
    assert main(["maps", "info", "lidar-dem"]) == 0
    out = capsys.readouterr().out
    assert "400 x 400 cells of 1 x 1 m" in out and "EPSG:26915" in out
    assert main(["maps", "info", "lidar-dem", "--cell", "4"]) == 0  # a name is resampled
    assert "100 x 100 cells of 4 x 4 m" in capsys.readouterr().out
    assert main(["maps", "info", "lidar-dem", "--sign", "depth"]) == 2  # file options do not apply
    assert "does not apply to the catalogue map 'lidar-dem'" in capsys.readouterr().err
    # a map smaller than the roughness window, with no two neighbouring cells of data: said, no warning
    sparse = tmp_path / "sparse.nc"
    write_map(BathymetryMap(np.arange(3.0), np.arange(3.0), np.array([[30.0, np.nan, 31.0], [np.nan] * 3,
                                                                      [32.0, np.nan, np.nan]])), sparse)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert main(["maps", "info", str(sparse)]) == 0
    out = capsys.readouterr().out
    assert "slope        not told" in out and "roughness    not told (no 5 x 5 cells hold data)" in out


def test_maps_plot_writes_a_png_and_does_not_clobber(tmp_path, capsys):
    out = tmp_path / "dem.png"
    assert main(["maps", "plot", "lidar-dem", "-o", str(out)]) == 0
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    before = out.stat().st_mtime_ns
    assert main(["maps", "plot", "lidar-dem", "-o", str(out)]) == 2
    assert "--force" in capsys.readouterr().err
    assert out.stat().st_mtime_ns == before
    assert main(["maps", "plot", "lidar-dem", "-o", str(out), "--force"]) == 0


def test_maps_mesh_writes_ply(tmp_path):
    out = tmp_path / "dem.ply"
    assert main(["maps", "mesh", "lidar-dem", "-o", str(out)]) == 0
    assert out.read_bytes().startswith(b"ply")


def test_maps_mesh_command_writes_the_sidecar_and_refuses_to_clobber(tmp_path, capsys):
    source = write_map(small_map(), tmp_path / "lake.npz")
    out = tmp_path / "lake.ply"
    assert main(["maps", "mesh", str(source), "-o", str(out), "--z-up"]) == 0
    about = json.loads((tmp_path / "lake.ply.json").read_text())
    assert about["crs"] == CRS and about["axes"] == ["east", "north", "up"]
    vertices, _ = _ply_vertices(out)
    assert np.all(vertices[:, 2] < 0)
    capsys.readouterr()
    # the sidecar alone existing is enough to refuse, and nothing is written
    out2 = tmp_path / "other.ply"
    (tmp_path / "other.ply.json").write_text("keep")
    assert main(["maps", "mesh", str(source), "-o", str(out2)]) == 2
    assert "other.ply.json exists" in capsys.readouterr().err and not out2.exists()
    assert main(["maps", "mesh", str(source), "-o", str(out2), "--force"]) == 0
    assert json.loads((tmp_path / "other.ply.json").read_text())["axes"] == ["north", "east", "down"]
    # a mesh input is never overwritten by its own mesh
    assert main(["maps", "mesh", str(out), "--cell", "3", "-o", str(out), "--force"]) == 2
    assert "over the input map" in capsys.readouterr().err


def test_maps_grid_soundings_to_netcdf(tmp_path, capsys):
    rng = np.random.default_rng(4)
    east, north = rng.uniform(0, 100, (2, 4000))
    depth = 30 + 0.1 * north + rng.normal(0, 0.2, 4000)
    depth[:7] = np.nan
    path = tmp_path / "soundings.xyz"
    np.savetxt(path, np.column_stack([east, north, depth]))
    out = tmp_path / "grid.nc"
    assert main(["maps", "grid", str(path), "--cell", "10", "--sign", "depth", "-o", str(out)]) == 0
    assert "dropped 7" in capsys.readouterr().out
    m = read_map(out)
    assert m.cell_size == (10.0, 10.0)
    nn, _ = np.meshgrid(m.north, m.east, indexing="ij")
    # cell means of a plane plus noise: within 5 sigma of the mean's standard error
    assert np.nanmax(np.abs(m.depth - (30 + 0.1 * nn))) < 0.1 * 10 / 2 + 5 * 0.2 / np.sqrt(20)


def test_maps_grid_position_std_is_the_librarys(tmp_path):
    """``--position-std`` gives the map the error ``grid_surveys(position_std=)`` gives it: the
    slope's share on top of the soundings' own."""
    from tangraph.maps import grid_surveys
    from tangraph.survey import Survey, write_survey

    east = np.arange(0.0, 200.0)
    surveys = []
    for k, line in enumerate((0.0, 20.0, 40.0)):
        pose = np.column_stack([np.full(east.size, line), east, np.full(east.size, np.pi / 2)])
        starboard = np.tile([-3.0, 0.0, 3.0], (east.size, 1))
        depth = 30.0 + 0.1 * (line - starboard) + 0.05 * east[:, None]
        surveys.append(Survey(time=east.copy(), dr_pose=pose, vehicle_depth=np.zeros(east.size),
                              beam_forward=np.zeros((east.size, 3)), beam_starboard=starboard,
                              beam_depth=depth, true_pose=pose))
        write_survey(surveys[-1], tmp_path / f"line{k}.nc")
    paths = [str(tmp_path / f"line{k}.nc") for k in range(3)]
    for std in ("0", "2.5"):
        out = tmp_path / f"grid{std}.nc"
        args = ["maps", "grid", *paths, "--cell", "5", "--fill", "2", "--position-std", std, "-o", str(out)]
        assert main(args) == 0
        expected = grid_surveys(surveys, cell=5.0, fill=2, position_std=float(std)).depth
        np.testing.assert_allclose(read_map(out).depth_std, expected.depth_std, rtol=1e-12)
    placed, exact = read_map(tmp_path / "grid2.5.nc"), read_map(tmp_path / "grid0.nc")
    assert np.nanmean(placed.depth_std) > np.nanmean(exact.depth_std)


def test_unknown_map_and_bad_file_are_clear_errors(tmp_path, capsys):
    assert main(["maps", "info", "atlantis"]) == 2
    assert "neither a catalogue map (merimbula" in capsys.readouterr().err
    bad = tmp_path / "bad.nc"
    bad.write_text("nope")
    assert main(["maps", "info", str(bad)]) == 2
    assert "bad.nc: not a readable NetCDF" in capsys.readouterr().err


def test_grid_asks_for_units_in_feet_and_has_the_option(tmp_path, capsys):
    path = soundings_in_feet(tmp_path / "ft.xyz", np.random.default_rng(1))
    out = tmp_path / "grid.nc"
    base = ["maps", "grid", str(path), "--sign", "depth", "--crs", "EPSG:2278", "--cell", "10",
            "-o", str(out)]
    assert main(base) == 2
    err = capsys.readouterr().err
    assert "pass units=" in err and "(CLI: --units)" in err  # the message names an option that exists
    assert main([*base, "--units", "us-ft"]) == 0
    m = read_map(out)
    assert m.cell_size == (10.0, 10.0)
    assert 100 * US_FOOT - 1 < np.nanmin(m.depth) and np.nanmax(m.depth) < (100 + 0.05 * 330) * US_FOOT + 1
    # the std in metres: the soundings' 0.5 ft noise and the plane's slope within a cell, about
    # 0.14 m (0.45 if the feet were taken as metres)
    assert m.depth_std is not None and 0.05 < np.nanmedian(m.depth_std) < 0.2
    assert main([*base, "--units", "furlong", "--force"]) == 2
    assert "has units 'furlong', which tangraph does not know" in capsys.readouterr().err


def test_grid_writes_and_reports_the_map_error(tmp_path, capsys):
    rng = np.random.default_rng(2)
    east = rng.uniform(0, 200, 20000)
    north = rng.choice([0.0, 100.0, 200.0], east.size) + rng.uniform(-4, 4, east.size)  # three lines
    depth = 30 + 2 * np.sin(north / 30) + rng.normal(0, 0.1, east.size)
    path = tmp_path / "lines.xyz"
    np.savetxt(path, np.column_stack([east, north, depth]))
    out = tmp_path / "grid.nc"
    assert main(["maps", "grid", str(path), "--sign", "depth", "--cell", "5", "--fill", "12",
                 "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "map error: std median" in printed and "correlation length" in printed
    m = read_map(out)
    assert m.correlation_length > 20  # the gaps between lines, not the cell
    between = m.depth_std[np.argmin(np.abs(m.north - 50)), 20]
    on_line = m.depth_std[np.argmin(np.abs(m.north - 100)), 20]
    assert between > 3 * on_line
    assert main(["maps", "info", str(out)]) == 0
    text = capsys.readouterr().out
    assert "map error    depth std median" in text
    assert f"correlation length {m.correlation_length:g} m" in text
    assert main(["maps", "info", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["correlation_length_m"] == pytest.approx(m.correlation_length)
    assert report["depth_std_m"]["max"] == pytest.approx(np.nanmax(m.depth_std))
    assert main(["maps", "info", str(out), "--uncertainty", "none"]) == 0
    assert "map error    not in the map" in capsys.readouterr().out


def test_info_chooses_the_uncertainty_variable(tmp_path, capsys):
    import xarray as xr

    shape = (8, 9)
    ds = xr.Dataset({"depth": (("y", "x"), np.full(shape, 20.0), {"positive": "down"}),
                     "stdev": (("y", "x"), np.full(shape, 0.4)), "error": (("y", "x"), np.full(shape, 0.9))},
                    coords={"y": 5.0 * np.arange(8), "x": 5.0 * np.arange(9)})
    ds.to_netcdf(tmp_path / "two.nc")
    assert main(["maps", "info", str(tmp_path / "two.nc")]) == 2
    assert "several uncertainty variables ['stdev', 'error']" in capsys.readouterr().err
    assert main(["maps", "info", str(tmp_path / "two.nc"), "--uncertainty", "error"]) == 0
    assert "depth std median 0.900 m" in capsys.readouterr().out
    # every command that reads a map takes the option the message names
    assert main(["maps", "plot", str(tmp_path / "two.nc"), "-o", str(tmp_path / "two.png")]) == 2
    assert "--uncertainty" in capsys.readouterr().err
    assert main(["maps", "plot", str(tmp_path / "two.nc"), "--uncertainty", "none",
                 "-o", str(tmp_path / "two.png")]) == 0


def test_grid_refuses_units_for_surveys(tmp_path, capsys):
    from tangraph.survey import Survey, write_survey

    pose = np.column_stack([np.arange(20.0), np.zeros(20), np.zeros(20)])
    survey = Survey(time=np.arange(20.0), dr_pose=pose, vehicle_depth=np.zeros(20),
                    beam_forward=np.zeros((20, 3)), beam_starboard=np.tile([-2.0, 0, 2], (20, 1)),
                    beam_depth=np.full((20, 3), 30.0), true_pose=pose)
    path = write_survey(survey, tmp_path / "s.nc")
    args = ["maps", "grid", str(path), "--cell", "2", "--units", "ft", "-o", str(tmp_path / "g.nc")]
    assert main(args) == 2
    assert "maps grid: --units applies to x y z text" in capsys.readouterr().err


def test_info_of_a_bag(tmp_path, capsys):
    depth = 20 + np.add.outer(np.arange(8.0), np.arange(6.0)) * 0.5  # 20 .. 26 m
    m = BathymetryMap(north=10 * np.arange(8.0), east=10 * np.arange(6.0), depth=depth, crs="EPSG:32633",
                      origin=(6e6, 5e5), depth_std=np.full((8, 6), 0.3), correlation_length=15)
    path = write_map(m, tmp_path / "m.bag")
    assert main(["maps", "info", str(path)]) == 0
    out = capsys.readouterr().out
    assert "depth        20.00 .. 26.00 m" in out and "depth std median 0.300 m" in out
    assert "correlation length 15 m" in out


def test_grid_check_lines_scales_the_error_by_held_out_surveys(tmp_path, capsys):
    from tangraph.survey import Survey, write_survey

    rng = np.random.default_rng(5)
    paths = []
    for day in range(3):  # three days of lines over one plane; the third finds it 0.8 m deeper
        east = np.arange(0.0, 400.0, 1.0)
        pose = np.concatenate([np.column_stack([np.full(east.size, n + day), east, np.zeros(east.size)])
                               for n in np.arange(0.0, 100.0, 5.0)])
        k = pose.shape[0]
        depth = 30.0 + 0.01 * pose[:, 1:2] + 0.05 * rng.standard_normal((k, 3)) + (0.8 if day == 2 else 0.0) \
            * (pose[:, 1:2] > 200)
        survey = Survey(time=np.arange(float(k)), dr_pose=pose, vehicle_depth=np.zeros(k),
                        beam_forward=np.zeros((k, 3)), beam_starboard=np.tile([-2.0, 0, 2], (k, 1)),
                        beam_depth=depth, true_pose=pose)
        paths.append(str(write_survey(survey, tmp_path / f"day{day}.nc")))
    plain, checked, default = tmp_path / "plain.nc", tmp_path / "checked.nc", tmp_path / "default.nc"
    assert main(["maps", "grid", *paths, "--cell", "5", "--no-check-lines", "-o", str(plain)]) == 0
    assert main(["maps", "grid", *paths, "--cell", "5", "--check-lines", "--sounding-std", "0.05",
                 "-o", str(checked)]) == 0
    out = capsys.readouterr().out
    # checked by default: the same map as asked for
    assert main(["maps", "grid", *paths, "--cell", "5", "--sounding-std", "0.05", "-o", str(default)]) == 0
    np.testing.assert_array_equal(read_map(default).depth_std, read_map(checked).depth_std)
    assert read_map(default).error_dof == read_map(checked).error_dof
    capsys.readouterr()
    assert "check lines: " in out and "depth_std scaled by" in out
    scale = float(out.split("depth_std scaled by ")[1].split(",")[0])
    assert scale > 2.0
    ratio = read_map(checked).depth_std / read_map(plain).depth_std
    np.testing.assert_allclose(ratio, np.nanmean(ratio), rtol=1e-9)
    assert np.nanmean(ratio) == pytest.approx(scale, abs=0.006)
    # one day off by 0.8 m over half the area: a tail heavier than a Gaussian's, kept in the file
    dof = float(out.split("Student-t of ")[2].split()[0])
    assert read_map(checked).error_dof == pytest.approx(dof, abs=0.006) and read_map(plain).error_dof is None
    assert out.count("(the gridding's own, not checked)") == 1  # the plain map's line only
    assert f"a Student-t tail of {dof:.3g} degrees of freedom; wrote {checked}" in out
    # the same figures from `maps check`
    assert main(["maps", "check", *paths, "--cell", "5", "--sounding-std", "0.05", "-q"]) == 0
    assert "held out" not in capsys.readouterr().err  # quiet: no progress lines
    assert main(["maps", "check", *paths, "--cell", "5", "--sounding-std", "0.05"]) == 0
    out = capsys.readouterr().out
    assert f"Student-t of scale {scale:.2f}" in out
    assert "soundings one by one: data cells " in out and "; filled cells " in out
    # one survey: its lines against each other (--lines), or a one-line error naming the option
    assert main(["maps", "check", paths[0], "--cell", "5", "--lines", "--fill", "1"]) == 0
    assert f"{paths[0]} line 19," in capsys.readouterr().out
    # lines 5 m apart whose swaths never meet: no window to score, said in one line
    assert main(["maps", "check", paths[0], "--cell", "5", "--lines"]) == 2
    assert "no window of 50 m of a held-out survey lies on the map of the others" in capsys.readouterr().err
    assert main(["maps", "check", paths[0], "--cell", "5"]) == 2
    assert "CLI --lines" in capsys.readouterr().err
    xyz = tmp_path / "s.xyz"
    np.savetxt(xyz, np.column_stack([rng.uniform(0, 50, 100), rng.uniform(0, 50, 100), np.full(100, 30.0)]))
    assert main(["maps", "grid", str(xyz), "--sign", "depth", "--cell", "5", "--check-lines",
                 "-o", str(tmp_path / "x.nc")]) == 2
    assert "--check-lines and --lines need survey files" in capsys.readouterr().err
    assert main(["maps", "grid", str(xyz), "--sign", "depth", "--cell", "5",
                 "-o", str(tmp_path / "x.nc")]) == 0
    assert "check lines: not made (x y z text has no tracks to hold out)" in capsys.readouterr().out
    # one survey whose lines, 5 m apart, do not overlap in the map's cells: nothing to check with
    assert main(["maps", "grid", paths[0], "--cell", "5", "--check-lines", "--lines",
                 "-o", str(tmp_path / "one.nc")]) == 2
    assert "no window of 50 m of a held-out survey lies on the map of the others" in capsys.readouterr().err
    assert not (tmp_path / "one.nc").exists()
    # by default its lines are tried, and the map keeps the gridding's error, saying why
    assert main(["maps", "grid", paths[0], "--cell", "5", "-o", str(tmp_path / "one.nc")]) == 0
    out = capsys.readouterr().out
    assert "check lines: not made (check_map_error: no window of 50 m" in out
    with xr.open_dataset(tmp_path / "one.nc") as ds:
        skipped = json.loads(ds.attrs["tangraph_meta"])["check_lines_skipped"]
    assert "no window of 50 m of a held-out survey" in skipped


def test_cli_grids_surveys_end_to_end(tmp_path, capsys):
    m = smooth_map()
    surveys = [simulated_survey(m, seed=1), simulated_survey(m, seed=2)]
    a = write_survey(surveys[0], tmp_path / "a.nc")
    b = write_survey(surveys[1], tmp_path / "b.nc")
    out = tmp_path / "map.nc"
    assert main(["maps", "grid", str(a), str(b), "--cell", "5", "--fill", "2", "-o", str(out)]) == 0
    check, drift, line = capsys.readouterr().out.strip().split("\n")  # the check lines', the map's
    assert check.startswith("check lines: 50 windows of 50 m")
    assert drift.startswith("check lines: drift: ")
    assert line.startswith("gridded ") and "median" in line and f"wrote {out}" in line
    assert "more filled by --fill 2" in line
    grid = read_map(out)
    assert grid.crs == m.crs and grid.origin == m.origin and grid.cell_size == (5.0, 5.0)
    with xr.open_dataset(out) as ds:
        assert {"depth", "mean", "median", "count", "std", "filled"} <= set(ds.data_vars)
        assert ds["depth"].attrs["cell_methods"] == "area: median"
        meta = json.loads(ds.attrs["tangraph_meta"])
        assert meta["sources"] == [str(a), str(b)] and meta["vertical_datum"] == "water surface"
        assert int(ds["count"].sum()) == sum(s.n_soundings for s in surveys)
        count = ds["count"].values
        measured = count > 0
        np.testing.assert_array_equal(ds["depth"].values[measured], ds["median"].values[measured])
        assert int(ds["filled"].sum()) == int(np.sum(~measured & np.isfinite(ds["depth"].values)))
    nn, ee = np.meshgrid(grid.north, grid.east, indexing="ij")
    ok = count >= 5
    err = (grid.depth - m.depth_at(nn, ee))[ok]
    assert np.median(np.abs(err)) < 1.3 * 0.6745 * 1.2533 * SIGMA * np.median(1 / np.sqrt(count[ok]))
    same = grid_surveys([read_survey(a), read_survey(b)], cell=5.0, fill=2)
    np.testing.assert_array_equal(same.depth.depth, grid.depth)


def test_cli_user_errors_are_one_line_and_status_2(tmp_path, capsys):
    pts = random_soundings(n=300)
    plain = write_survey(nadir_survey(pts, origin=(0, 0)), tmp_path / "plain.nc")
    dr_only = write_survey(nadir_survey(pts, origin=(0, 0), truth=False), tmp_path / "dr.nc")
    level = write_survey(nadir_survey(pts, origin=(0, 0), datum="chart datum", start=1e5),
                         tmp_path / "level.nc")
    xyz = tmp_path / "s.xyz"
    np.savetxt(xyz, pts[:, [1, 0, 2]])
    out = str(tmp_path / "out.nc")
    cases = [
        ([str(dr_only)], "dr.nc: the survey has no reference track"),
        ([str(plain), str(level)], "level.nc 'chart datum'"),
        ([str(plain), "--sign", "depth"], "--sign applies to x y z text"),
        ([str(plain), str(xyz), "--sign", "depth"], "not both"),
        ([str(xyz)], "needs --sign"),
        ([str(xyz), "--sign", "depth", "--use-dr"], "--use-dr applies to survey files"),
    ]
    for inputs, message in cases:
        assert main(["maps", "grid", *inputs, "--cell", "10", "-o", out]) == 2, message
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1
    assert main(["maps", "grid", str(plain), "--cell", "10", "-o", str(plain), "--force"]) == 2
    assert "is one of the inputs" in capsys.readouterr().err
    # a folder named as the output is refused before any work, and left as it was
    (tmp_path / "folder").mkdir()
    with pytest.raises(SystemExit) as exited:
        main(["maps", "grid", str(plain), "--cell", "10", "-o", str(tmp_path / "folder"), "--force"])
    assert exited.value.code == 2 and "folder is a folder; give the file's name" in capsys.readouterr().err
    assert not any((tmp_path / "folder").iterdir())
    assert main(["maps", "grid", str(dr_only), "--cell", "10", "--use-dr", "-o", out]) == 0
    capsys.readouterr()
    out_xyz = str(tmp_path / "xyz.nc")
    assert main(["maps", "grid", str(xyz), "--cell", "10", "--sign", "depth", "--statistic", "mean",
                 "-o", out_xyz]) == 0
    assert "(10 m, mean)" in capsys.readouterr().out
    with xr.open_dataset(out_xyz) as ds:
        np.testing.assert_array_equal(ds["depth"].values, ds["mean"].values)


def test_maps_info_says_the_drift_a_map_states(tmp_path, capsys):
    m = BathymetryMap(north=np.arange(20.0) * 5, east=np.arange(30.0) * 5, depth=np.full((20, 30), 12.0),
                      error_drift=(0.196, 172.0))
    path = write_map(m, tmp_path / "drifting.nc")
    assert main(["maps", "info", str(path)]) == 0
    assert "a track drift of 0.196 m over 172 s" in capsys.readouterr().out
    assert main(["maps", "info", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["error_drift"] == {"std_m": 0.196, "time_s": 172.0}


@pytest.mark.parametrize("drift", [0.0, 0.3])
def test_maps_grid_gives_the_map_the_drift_its_check_lines_find(tmp_path, capsys, drift):
    """Three days of lines over one seafloor whose depths drift along each day's track by a
    Gauss-Markov offset (``drift`` m, forgotten over 150 s): the gridded map states the drift
    when there is one (its size within a third), and none when there is none."""
    from tests.eval.line_cases import line_survey, seafloor

    rng = np.random.default_rng(5)
    paths = []
    for day in range(3):
        survey = line_survey(seafloor, rng, lines=np.arange(10.0, 390.0, 18.0) + 6.0 * day, name=f"day{day}")
        keep = np.exp(-1.0 / 150.0)  # a ping a second
        offset = np.empty(survey.n_pings)
        offset[0] = drift * rng.standard_normal()
        for k in range(1, offset.size):
            offset[k] = keep * offset[k - 1] + drift * np.sqrt(1 - keep**2) * rng.standard_normal()
        survey = survey.replace(beam_depth=survey.beam_depth + offset[:, None])
        paths.append(str(write_survey(survey, tmp_path / f"day{day}.nc")))
    out = tmp_path / "map.nc"
    assert main(["maps", "grid", *paths, "--cell", "5", "--fill", "2", "--sounding-std", "0.1",
                 "-o", str(out)]) == 0
    printed = capsys.readouterr().out
    stated = read_map(out).error_drift
    if drift:
        assert stated is not None and stated[0] == pytest.approx(drift, rel=1 / 3)
        assert f"a drift along a track of {stated[0]:.3g} m" in printed
    else:
        assert stated is None and "a drift along a track" not in printed


def test_maps_change_prints_the_librarys_change_and_the_model_fields(tmp_path, capsys):
    from tangraph.eval.map_change import measure_change
    from tangraph.sensors import NavigationModel
    from tests.eval.line_cases import earlier_map, later_survey

    survey, earlier = later_survey(5, 0.25), earlier_map()
    write_map(earlier, tmp_path / "earlier.nc")
    write_survey(survey, tmp_path / "later.nc")
    assert main(["maps", "change", str(tmp_path / "earlier.nc"), str(tmp_path / "later.nc"),
                 "--sounding-std", "0.1", "--window", "60"]) == 0
    out = capsys.readouterr().out
    found = measure_change([read_survey(tmp_path / "later.nc")], read_map(tmp_path / "earlier.nc"),
                           NavigationModel(sounding_std=0.1), window=60.0)
    assert found.summary() in out
    assert f"map_change_std = {found.model_fields()['map_change_std']:g}\n" in out
    assert f"map_change_length = {found.model_fields()['map_change_length']:g}\n" in out
    assert main(["maps", "change", str(tmp_path / "earlier.nc"), str(tmp_path / "missing.nc")]) == 2
    assert "missing.nc" in capsys.readouterr().err
    # a survey given twice, and a map that states no error, are refused in one line naming them
    later = str(tmp_path / "later.nc")
    assert main(["maps", "change", str(tmp_path / "earlier.nc"), later, later]) == 2
    err = capsys.readouterr().err
    assert f"'{later}' and '{later}' hold the same" in err and err.count("\n") == 1
    write_map(earlier.replace(depth_std=None, correlation_length=None), tmp_path / "bare.nc")
    assert main(["maps", "change", str(tmp_path / "bare.nc"), later]) == 2
    assert "states no error" in capsys.readouterr().err
    assert main(["maps", "change", str(tmp_path / "bare.nc"), later, "--map-std", "0.1"]) == 0
    assert "change since the map: std" in capsys.readouterr().out


def test_maps_change_uses_the_cells_a_gridded_map_measured(tmp_path, capsys):
    from tangraph.eval.map_change import measure_change
    from tangraph.maps.netcdf import measured_cells
    from tangraph.sensors import NavigationModel

    seabed = smooth_map()
    surveys = [simulated_survey(seabed, seed) for seed in (1, 2)]
    grid = grid_surveys(surveys[:1], cell=5.0, fill=3)
    path = tmp_path / "grid.nc"
    from tangraph.maps.io import write_sounding_grid

    write_sounding_grid(grid, path)
    write_survey(surveys[1], tmp_path / "later.nc")
    cells = measured_cells(path, read_map(path))
    np.testing.assert_array_equal(cells, grid.count > 0)
    assert measured_cells(path, read_map(path).crop(north=(0.0, 100.0))) is None  # not the map's grid
    assert main(["maps", "change", str(path), str(tmp_path / "later.nc"), "--position-std", "1"]) == 0
    out = capsys.readouterr().out
    found = measure_change([read_survey(tmp_path / "later.nc")], read_map(path),
                           NavigationModel(sounding_std=0.1), measured=cells, position_std=1.0)
    assert found.cells == "measured" and found.summary() in out
