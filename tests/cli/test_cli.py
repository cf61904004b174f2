"""The ``tangraph`` command as a whole (tangraph.cli and its ``__main__``): the parser (no
subcommand, options after the subcommand, defaults in the help), ``python -m tangraph.cli``,
its modules' size, and the error contract of ``main``: one line, exit status 2 for usage errors
and bad input, 1 for runtime errors, no traceback unless --debug; a closed pipe ends quietly."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from tangraph.cli import main


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


# -- the error contract ------------------------------------------------------------------------
def test_a_folder_that_cannot_be_written_is_a_runtime_error_in_one_line(tmp_path, capsys):
    # sysfs refuses new files even to root (a chmod'ed folder would not stop root)
    if not os.path.isdir("/sys/kernel"):
        pytest.skip("needs Linux sysfs")
    status = main(["maps", "plot", "merimbula", "-o", "/sys/tangraph-test.png"])
    err = capsys.readouterr().err
    assert status == 1 and err.count("\n") == 1 and "PermissionError" in err


def test_an_unforeseen_error_is_one_line_and_debug_shows_it(monkeypatch, capsys):
    import tangraph.maps.statistics

    def broken(*args, **kwargs):
        raise RuntimeError("something deep\nwent wrong")

    monkeypatch.setattr(tangraph.maps.statistics, "describe", broken)
    assert main(["maps", "info", "merimbula"]) == 1
    err = capsys.readouterr().err
    assert err == "tangraph: error: RuntimeError: something deep went wrong (--debug shows where)\n"
    with pytest.raises(RuntimeError, match="something deep"):
        main(["--debug", "maps", "info", "merimbula"])


def test_a_closed_pipe_ends_quietly():
    # the reader closes the pipe before the command writes (as head does after its lines)
    script = ("import sys, time; from tangraph.cli import main; time.sleep(1.0); "
              "sys.exit(main(['maps', 'info', 'merimbula', '--json']))")
    with subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE,
                          stderr=subprocess.PIPE) as p:
        p.stdout.close()
        err = p.stderr.read().decode()
        status = p.wait(timeout=60)
    assert "Traceback" not in err and "BrokenPipe" not in err, err
    assert status == 141


def test_an_unknown_crs_is_bad_input(tmp_path, capsys):
    xyz = tmp_path / "a.xyz"
    xyz.write_text("0 0 10\n10 0 11\n0 10 12\n10 10 13\n")
    args = ["maps", "grid", str(xyz), "--sign", "depth", "--cell", "5", "--crs", "EPSG:999999",
            "-o", str(tmp_path / "g.nc")]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "the CRS is not understood by pyproj" in err and "EPSG:999999" in err
    assert not (tmp_path / "g.nc").exists()


def test_status_values_are_documented():
    doc = main.__doc__
    assert all(str(code) in doc for code in (0, 1, 2, 130, 141))


def test_a_grid_larger_than_free_memory_is_refused_before_reading(tmp_path, capsys):
    """A NetCDF file of a few MB that declares 200000 x 200000 cells: refused with its size, as
    a runtime error (status 1), without trying to allocate it."""
    netCDF4 = pytest.importorskip("netCDF4")
    path = tmp_path / "huge.nc"
    with netCDF4.Dataset(path, "w", format="NETCDF4") as ds:
        for name in ("y", "x"):
            ds.createDimension(name, 200_000)
            ds.createVariable(name, "f8", (name,))[:] = 10.0 * np.arange(200_000)
        ds.createVariable("z", "f4", ("y", "x"), chunksizes=(1000, 1000)).units = "m"
    assert main(["maps", "info", str(path), "--sign", "depth"]) == 1
    err = capsys.readouterr().err
    assert "200000 x 200000 cells" in err and "TiB of memory" in err and "gmt grdcut" in err
    assert err.count("\n") == 1 and "Traceback" not in err
