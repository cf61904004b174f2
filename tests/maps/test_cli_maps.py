"""`tangraph maps grid` and `maps info` with the map's error: --units, the error layer written
and reported, --uncertainty."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tangraph.cli import main
from tangraph.maps import BathymetryMap, read_map, write_map

US_FOOT = 1200.0 / 3937.0


def soundings_in_feet(path, rng):
    """Scattered soundings in Texas South Central (EPSG:2278, US survey feet), z in feet too."""
    x = 3_000_000 + rng.uniform(0, 330, 3000)  # about 100 m
    y = 13_000_000 + rng.uniform(0, 330, 3000)
    z = 100 + 0.05 * (y - 13_000_000) + rng.normal(0, 0.5, 3000)  # feet
    np.savetxt(path, np.column_stack([x, y, z]))
    return path


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
    plain, checked = tmp_path / "plain.nc", tmp_path / "checked.nc"
    assert main(["maps", "grid", *paths, "--cell", "5", "-o", str(plain)]) == 0
    assert main(["maps", "grid", *paths, "--cell", "5", "--check-lines", "--sounding-std", "0.05",
                 "-o", str(checked)]) == 0
    out = capsys.readouterr().out
    assert "check lines: " in out and "depth_std scaled by" in out
    scale = float(out.split("depth_std scaled by ")[1].split()[0])
    assert scale > 2.0
    ratio = read_map(checked).depth_std / read_map(plain).depth_std
    np.testing.assert_allclose(ratio, np.nanmean(ratio), rtol=1e-9)
    assert np.nanmean(ratio) == pytest.approx(scale, abs=0.006)
    # the same figures from `maps check`
    assert main(["maps", "check", *paths, "--cell", "5", "--sounding-std", "0.05"]) == 0
    assert f"RMS {scale:.2f}" in capsys.readouterr().out
    # one survey: its lines against each other (--lines), or a one-line error naming the option
    assert main(["maps", "check", paths[0], "--cell", "5", "--lines"]) == 0
    assert f"{paths[0]} line 19," in capsys.readouterr().out
    assert main(["maps", "check", paths[0], "--cell", "5"]) == 2
    assert "CLI --lines" in capsys.readouterr().err
    xyz = tmp_path / "s.xyz"
    np.savetxt(xyz, np.column_stack([rng.uniform(0, 50, 100), rng.uniform(0, 50, 100), np.full(100, 30.0)]))
    assert main(["maps", "grid", str(xyz), "--sign", "depth", "--cell", "5", "--check-lines",
                 "-o", str(tmp_path / "x.nc")]) == 2
    assert "--check-lines and --lines need survey files" in capsys.readouterr().err
    # one survey whose lines, 5 m apart, do not overlap in the map's cells: nothing to check with
    assert main(["maps", "grid", paths[0], "--cell", "5", "--check-lines", "--lines",
                 "-o", str(tmp_path / "one.nc")]) == 2
    assert "the check lines scored 0 windows" in capsys.readouterr().err
    assert not (tmp_path / "one.nc").exists()
