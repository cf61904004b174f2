"""The tangraph command: each subcommand end to end, and its errors."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.cli import main
from tangraph.maps import read_map


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


def test_no_subcommand_is_a_usage_error():
    with pytest.raises(SystemExit) as exc:
        main([])
    assert exc.value.code == 2


def test_json_figures_and_options_after_the_subcommand(capsys, tmp_path):
    import json

    from tangraph.cli import build_parser

    assert main(["maps", "info", "merimbula", "--json", "-v"]) == 0
    figures = json.loads(capsys.readouterr().out)
    assert figures["name"] == "merimbula" and figures["crs"] == "EPSG:32755"
    assert figures["shape"] == [413, 509] and 0 < figures["valid_fraction"] < 1
    args = build_parser().parse_args(["maps", "info", "merimbula", "-q"])
    assert args.quiet is True and args.verbose is False
    assert build_parser().parse_args(["-q", "maps", "list"]).quiet is True
    commands = next(a for a in build_parser()._actions if a.dest == "command")
    demo_help = commands.choices["demo"].format_help()
    assert "(default: 7)" in demo_help and "(default: None)" not in demo_help


def test_survey_import_is_the_library_s_import_survey(tmp_path):
    from tangraph.errors import TangraphError
    from tangraph.formats import SURVEY_FORMATS, import_survey

    assert list(SURVEY_FORMATS) == ["csv-xyz", "sontek-sum", "xtf", "gsf"]
    with pytest.raises(TangraphError, match="format 'xtf' takes no timezone"):
        import_survey("xtf", [tmp_path / "a.xtf"], crs="EPSG:32610", timezone="UTC")
    with pytest.raises(TangraphError, match=r"format 'csv-xyz' takes two files \(navigation log, "):
        import_survey("csv-xyz", [tmp_path / "nav.csv"])
    with pytest.raises(TangraphError, match="unknown survey format 'kmall'"):
        import_survey("kmall", [tmp_path / "a.kmall"])


def test_the_package_runs_as_a_module_and_keeps_its_modules_small():
    import ast
    import subprocess
    import sys
    from pathlib import Path

    import tangraph.cli

    done = subprocess.run([sys.executable, "-m", "tangraph.cli", "--version"], capture_output=True,
                          text=True, timeout=120)
    assert done.returncode == 0 and done.stdout.startswith("tangraph ")
    for path in Path(tangraph.cli.__file__).parent.glob("*.py"):  # one role each, short handlers
        text = path.read_text()
        assert text.count("\n") <= 500, path
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.FunctionDef):
                assert node.end_lineno - node.lineno < 80, f"{path.name}: {node.name}"
