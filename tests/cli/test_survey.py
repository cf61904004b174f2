"""The ``tangraph survey import`` command (tangraph.cli.survey): a CSV/XYZ log with its options
(columns, no header, time zones, a CRS in feet), the SonTek, XTF and GSF formats, the options of
another format refused, writing over an input refused, a malformed file refused in one line;
and the single-beam survey it imports is the library's."""

from __future__ import annotations

import numpy as np
import pyproj
import pytest

from tangraph.cli import main
from tangraph.formats import import_csv_xyz
from tangraph.survey import read_survey
from tests.formats.feet_cases import FEET, LENGTH, lonlat_back, texas_line, track_length, write_feet
from tests.formats.latlon_cases import iso, latlon_log, write_latlon
from tests.formats.recorded_files import GSF, GSF_CRS, LONG_RUN, XTF, XTF_CRS, _write


def test_cli_imports_a_headerless_latlon_log_with_local_times(tmp_path, capsys):
    log = latlon_log()
    text = iso(log["t"], suffix="")
    order = ("time", "heading", "lat", "lon", "depth")
    nav, xyz = write_latlon(tmp_path, log, time_text=text, sounding_time_text=np.repeat(text, 3),
                            header=False, order=order)
    out = tmp_path / "survey.nc"
    args = ["survey", "import", str(nav), str(xyz), "--crs", "EPSG:25833", "--no-header",
            "--timezone", "UTC", "--columns", "time=0,heading=1,lat=2,lon=3,depth=4", "-o", str(out)]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert "counts       n_dropped_outside_navigation 0" in printed and f"wrote {out}" in printed
    survey = read_survey(out)
    assert survey.meta["crs"] == "EPSG:25833" and survey.meta["start_time"] == "2024-05-01T10:00:00Z"
    e, n = pyproj.Transformer.from_crs("EPSG:4326", "EPSG:25833", always_xy=True).transform(
        log["lon"], log["lat"])
    np.testing.assert_allclose(survey.dr_pose[:, 0] + survey.meta["origin"][0], n, atol=1e-3, rtol=0)
    np.testing.assert_allclose(survey.dr_pose[:, 1] + survey.meta["origin"][1], e, atol=1e-3, rtol=0)
    assert main(args) == 2 and "exists; pass --force" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--draft", "0.2"], "--draft does not apply to --format csv-xyz"),
        (["--water-level-interpolate", "--declination", "3"],
         "--water-level-interpolate, --declination do not apply to --format csv-xyz"),
        (["--format", "sontek-sum", "--columns", "time=0"],
         "--columns does not apply to --format sontek-sum"),
        (["--format", "sontek-sum", "--no-header", "--sign", "depth"],
         "--no-header, --sign do not apply to --format sontek-sum"),
        (["--columns", "time"], "--columns: 'time' is not KEY=COLUMN"),
        (["--crs", "EPSG:4326"], "crs='EPSG:4326' is not a projected CRS"),
    ],
)
def test_cli_refuses_options_of_the_other_format(tmp_path, capsys, extra, message):
    nav, xyz = write_latlon(tmp_path, latlon_log())
    out = tmp_path / "survey.nc"
    assert main(["survey", "import", str(nav), str(xyz), *extra, "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not out.exists()


def test_cli_refuses_writing_over_an_input_and_the_wrong_file_count(tmp_path, capsys):
    nav, xyz = write_latlon(tmp_path, latlon_log())
    before = xyz.read_bytes()
    assert main(["survey", "import", str(nav), str(xyz), "-o", str(xyz), "--force"]) == 2
    assert "refusing to write the survey over the input" in capsys.readouterr().err
    assert xyz.read_bytes() == before
    assert main(["survey", "import", str(nav), "-o", str(tmp_path / "s.nc")]) == 2
    assert "--format csv-xyz takes two files (navigation log, soundings), got 1" in capsys.readouterr().err
    assert main(["survey", "import", str(nav), str(xyz), "-o", str(tmp_path / "s.txt")]) == 2
    assert "a survey is written as NetCDF; name it .nc" in capsys.readouterr().err
    assert not (tmp_path / "s.txt").exists()
    with pytest.raises(SystemExit) as info:
        main(["survey", "import", "--format", "kmall", str(nav), "-o", str(tmp_path / "s.nc")])
    assert info.value.code == 2 and "invalid choice: 'kmall'" in capsys.readouterr().err


def test_cli_hands_sontek_files_and_options_to_the_sontek_import(tmp_path, capsys, monkeypatch):
    import tangraph.formats.sontek as sontek

    log = latlon_log()
    made = import_csv_xyz(*write_latlon(tmp_path, log), crs="EPSG:25833")
    calls = []

    def fake(paths, **kwargs):
        calls.append((paths, kwargs))
        return made.replace(meta={**made.meta, "n_no_depth": 3})

    monkeypatch.setattr(sontek, "import_sontek_sum", fake)
    files = [tmp_path / "a.sum", tmp_path / "b.sum"]
    out = tmp_path / "run.nc"
    args = ["survey", "import", "--format", "sontek-sum", *map(str, files), "--crs", "EPSG:25833",
            "--timezone", "Europe/Berlin", "--water-level", str(tmp_path / "level.csv"),
            "--water-level-interpolate", "--draft", "0.15", "--dr-heading", "compass",
            "--declination", "4.5", "-o", str(out)]
    assert main(args) == 0
    assert calls == [(files, {"crs": "EPSG:25833", "timezone": "Europe/Berlin",
                              "water_level": tmp_path / "level.csv", "water_level_interpolate": True,
                              "draft": 0.15, "dr_heading": "compass", "declination_deg": 4.5})]
    printed = capsys.readouterr().out
    assert "counts       n_dropped_outside_navigation 0, n_no_depth 3" in printed
    assert printed.rstrip().endswith(f"wrote {out}")
    calls.clear()
    assert main(["survey", "import", "--format", "sontek-sum", str(files[0]), "-o",
                 str(tmp_path / "one.nc")]) == 0
    assert calls[0][1] == {"crs": None, "timezone": None, "water_level": None,
                           "water_level_interpolate": False}


def test_cli_imports_feet_with_units(tmp_path, capsys):
    line = texas_line()
    nav, xyz = write_feet(tmp_path, line, depth_unit=0.3048)
    out = tmp_path / "s.nc"
    base = ["survey", "import", str(nav), str(xyz), "--crs", FEET, "-o", str(out)]
    assert main(base) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--units" in err and "US survey foot" in err and not out.exists()
    assert main([*base, "--units", "ft"]) == 0
    survey = read_survey(out)
    assert track_length(survey.dr_pose) == pytest.approx(LENGTH, rel=2e-4)
    np.testing.assert_allclose(survey.vehicle_depth, 1.0, atol=1e-5)
    lat, lon = lonlat_back(survey, tmp_path)
    np.testing.assert_allclose(lat, line["lat"], atol=1e-8, rtol=0)
    np.testing.assert_allclose(lon, line["lon"], atol=1e-8, rtol=0)
    assert main(["survey", "import", "--format", "gsf", str(nav), "--units", "ft", "--crs", FEET,
                 "-o", str(tmp_path / "g.nc")]) == 2
    assert "--units does not apply to --format gsf" in capsys.readouterr().err


def test_cli_refuses_a_malformed_file_in_one_line_and_writes_nothing(tmp_path, caputh, capsys):
    from tangraph.cli import main

    bad = _write(tmp_path, caputh, lambda ls: [*ls[:5], ls[5][:40], *ls[6:]])
    out = tmp_path / "survey.nc"
    args = ["survey", "import", "--format", "sontek-sum", str(bad), "--crs", "EPSG:25833",
            "--timezone", "Europe/Berlin", "-o", str(out)]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "run.sum, line 6: " in err and "Traceback" not in err
    assert not out.exists() and not list(tmp_path.glob(".survey*"))
    with pytest.raises(SystemExit) as exc:
        main(["survey", "import", "--format", "sontek", str(bad), "-o", str(out)])
    assert exc.value.code == 2 and "invalid choice: 'sontek'" in capsys.readouterr().err
    assert main([*args[:4], str(caputh / LONG_RUN), "--crs", "EPSG:32610", "--timezone", "UTC",
                 "-o", str(out)]) == 2
    assert "outside the area of use of EPSG:32610" in capsys.readouterr().err and not out.exists()


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


def test_the_survey_imports_one_sounding_per_ping(files):
    folder = files["folder"]
    survey = import_csv_xyz(folder / "nav.csv", folder / "sounding.xyz", crs="EPSG:32755")
    assert survey.n_beams == 1 and survey.n_pings == files["n_soundings"] == survey.n_soundings
    from_cli = read_survey(files["survey"])
    np.testing.assert_allclose(from_cli.dr_pose, survey.dr_pose, atol=1e-9)
    np.testing.assert_allclose(from_cli.beam_depth, survey.beam_depth, atol=1e-9)
