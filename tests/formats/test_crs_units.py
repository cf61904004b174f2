"""A CRS in feet in every survey importer: coordinates come out in metres, the survey records a
CRS in metres, and writing a track back to latitude/longitude gives the input's positions."""

from __future__ import annotations

import numpy as np
import pyproj
import pytest

from tangraph.cli import main
from tangraph.errors import TangraphError
from tangraph.formats import import_csv_xyz
from tangraph.maps.grid import BathymetryMap
from tangraph.navigation import dead_reckoning_track, in_map_frame
from tangraph.survey import SurveyError, read_survey
from tangraph.track import write_track_csv

FEET = "EPSG:2278"  # NAD83 / Texas South Central, US survey feet
US_FOOT = 1200.0 / 3937.0
LAT0, LON0 = 29.70, -95.40  # Houston
LENGTH = 7000.0  # m


def texas_line(k=351):
    """A 7 km line (WGS84 lat/lon, true heading 60 deg) at 2 m/s, one ping every 10 s, three
    beams: one under the boat and one 15 m to each side."""
    geod = pyproj.Geod(ellps="WGS84")
    t = np.arange(k) * LENGTH / 2.0 / (k - 1)
    lon, lat, back = geod.fwd(np.full(k, LON0), np.full(k, LAT0), np.full(k, 60.0), 2.0 * t)
    heading = (np.asarray(back) + 180.0) % 360.0
    side = np.tile([-15.0, 0.0, 15.0], k)
    rep = np.repeat
    lon_b, lat_b, _ = geod.fwd(rep(lon, 3), rep(lat, 3), rep(heading, 3) + 90.0, side)
    z = 10.0 + np.tile([1.0, 2.0, 3.0], k)
    return {"t": t, "lat": np.asarray(lat), "lon": np.asarray(lon), "heading": heading,
            "lat_b": np.asarray(lat_b), "lon_b": np.asarray(lon_b), "t_b": rep(t, 3), "z": z}


def write_geographic(tmp_path, line):
    nav, xyz = tmp_path / "nav.csv", tmp_path / "s.xyz"
    np.savetxt(nav, np.column_stack([line["t"], line["lat"], line["lon"], line["heading"],
                                     np.zeros_like(line["t"])]),
               delimiter=",", header="time,lat,lon,heading,depth", comments="", fmt="%.10f")
    np.savetxt(xyz, np.column_stack([line["t_b"], line["lon_b"], line["lat_b"], line["z"]]), fmt="%.10f")
    return nav, xyz


def write_feet(tmp_path, line, *, depth_unit=1.0):
    """The same line with north/east in EPSG:2278 (US survey feet), depths divided by
    ``depth_unit`` (metres per unit of the file's depths)."""
    to_feet = pyproj.Transformer.from_crs("EPSG:4326", FEET, always_xy=True)
    e, n = to_feet.transform(line["lon"], line["lat"])
    e_b, n_b = to_feet.transform(line["lon_b"], line["lat_b"])
    convergence = np.asarray(pyproj.Proj(FEET).get_factors(line["lon"], line["lat"]).meridian_convergence)
    nav, xyz = tmp_path / "nav_ft.csv", tmp_path / "s_ft.xyz"
    np.savetxt(nav, np.column_stack([line["t"], n, e, line["heading"] - convergence,
                                     np.full_like(line["t"], 1.0) / depth_unit]),
               delimiter=",", header="time,north,east,heading,depth", comments="", fmt="%.6f")
    np.savetxt(xyz, np.column_stack([line["t_b"], e_b, n_b, line["z"] / depth_unit]), fmt="%.6f")
    return nav, xyz


def track_length(pose):
    return float(np.sum(np.hypot(*np.diff(pose[:, :2], axis=0).T)))


def lonlat_back(survey, tmp_path):
    """Latitude and longitude of the survey's DR track as the track writer puts them."""
    out = tmp_path / "track.csv"
    write_track_csv(dead_reckoning_track(survey), out, crs=survey.meta["crs"],
                    origin=survey.meta["origin"], overwrite=True)
    rows = np.genfromtxt(out, delimiter=",", names=True)
    return rows["lat"], rows["lon"]


def test_a_lat_lon_log_projected_into_feet_is_in_metres_and_writes_back(tmp_path):
    line = texas_line()
    survey = import_csv_xyz(*write_geographic(tmp_path, line), crs=FEET)
    assert track_length(survey.dr_pose) == pytest.approx(LENGTH, rel=2e-4)  # scale factor of the grid
    assert pyproj.CRS(survey.meta["crs"]).axis_info[0].unit_name == "metre"
    assert survey.meta["crs_given"] == {"crs": FEET, "unit": "US survey foot",
                                        "metres_per_unit": pytest.approx(US_FOOT, rel=1e-12)}
    # the soundings 15 m to the side stay 15 m to the side
    np.testing.assert_allclose(survey.beam_starboard, np.tile([-15.0, 0.0, 15.0], (survey.n_pings, 1)),
                               atol=0.01)
    lat, lon = lonlat_back(survey, tmp_path)
    np.testing.assert_allclose(lat, line["lat"], atol=1e-8, rtol=0)
    np.testing.assert_allclose(lon, line["lon"], atol=1e-8, rtol=0)


def test_north_east_in_feet_are_converted_and_their_depth_unit_must_be_said(tmp_path):
    line = texas_line()
    nav, xyz = write_feet(tmp_path, line, depth_unit=US_FOOT)
    with pytest.raises(SurveyError, match=r"^crs='EPSG:2278' has axes in US survey foot.*"
                                          r"units='m' or units='ft'.*CLI: --units"):
        import_csv_xyz(nav, xyz, crs=FEET)
    survey = import_csv_xyz(nav, xyz, crs=FEET, units="US survey foot")
    assert track_length(survey.dr_pose) == pytest.approx(LENGTH, rel=2e-4)
    np.testing.assert_allclose(survey.vehicle_depth, 1.0, atol=1e-5)
    np.testing.assert_allclose(survey.beam_depth, (10.0 + np.tile([1.0, 2.0, 3.0], (survey.n_pings, 1))),
                               atol=1e-5)
    np.testing.assert_allclose(survey.beam_starboard, np.tile([-15.0, 0.0, 15.0], (survey.n_pings, 1)),
                               atol=0.01)
    lat, lon = lonlat_back(survey, tmp_path)
    np.testing.assert_allclose(lat, line["lat"], atol=1e-8, rtol=0)
    np.testing.assert_allclose(lon, line["lon"], atol=1e-8, rtol=0)
    # the same survey as the lat/lon log projected into EPSG:2278, origins aside
    geographic = import_csv_xyz(*write_geographic(tmp_path, line), crs=FEET)
    shift = np.subtract(survey.meta["origin"], geographic.meta["origin"])
    np.testing.assert_allclose(survey.dr_pose[:, :2] + shift, geographic.dr_pose[:, :2], atol=1e-3)
    np.testing.assert_allclose(survey.dr_pose[:, 2], geographic.dr_pose[:, 2], atol=1e-6)
    # depths in metres beside feet coordinates
    nav, xyz = write_feet(tmp_path, line)
    metres = import_csv_xyz(nav, xyz, crs=FEET, units="m")
    np.testing.assert_allclose(metres.beam_depth, survey.beam_depth, atol=1e-5)
    with pytest.raises(TangraphError, match="furlong"):
        import_csv_xyz(nav, xyz, crs=FEET, units="furlong")


def test_a_survey_in_feet_lands_on_maps_in_metres_and_in_feet(tmp_path):
    line = texas_line()
    survey = import_csv_xyz(*write_geographic(tmp_path, line), crs=FEET)
    to_utm = pyproj.Transformer.from_crs("EPSG:4326", "EPSG:32615", always_xy=True)
    e, n = to_utm.transform(line["lon"], line["lat"])
    origin = (float(np.floor(n.min())) - 500.0, float(np.floor(e.min())) - 500.0)
    utm = BathymetryMap(north=np.arange(0.0, 7000, 50), east=np.arange(0.0, 7000, 50),
                        depth=np.full((140, 140), 12.0), crs="EPSG:32615", origin=origin, name="utm")
    moved = in_map_frame(survey, utm)
    np.testing.assert_allclose(moved.dr_pose[:, 0], n - origin[0], atol=1e-3)
    np.testing.assert_allclose(moved.dr_pose[:, 1], e - origin[1], atol=1e-3)
    # a map read from a file in feet records the same metric CRS: only the origins differ
    from tangraph.maps.io import metric_crs

    feet_map = utm.replace(crs=metric_crs(FEET, "test")[0],
                           origin=(13_000_000.0 * US_FOOT, 3_000_000.0 * US_FOOT))
    shifted = in_map_frame(survey, feet_map)
    assert "reprojected_from" not in shifted.meta
    np.testing.assert_allclose(shifted.dr_pose[:, :2] + feet_map.origin,
                               survey.dr_pose[:, :2] + survey.meta["origin"], atol=1e-6)


def test_a_survey_that_records_a_crs_in_feet_is_refused_on_a_map(tmp_path):
    """A survey file written before the conversion (positions of unknown unit in a feet CRS)."""
    survey = import_csv_xyz(*write_geographic(tmp_path, texas_line()), crs=FEET)
    old = survey.replace(meta={**survey.meta, "crs": FEET})
    utm = BathymetryMap(north=np.arange(0.0, 500, 50), east=np.arange(0.0, 500, 50),
                        depth=np.full((10, 10), 12.0), crs="EPSG:32615", origin=(3_280_000.0, 270_000.0),
                        name="utm")
    with pytest.raises(TangraphError, match=r"^the survey's CRS 'EPSG:2278' has axes in US survey foot.*"
                                            r"import the survey again"):
        in_map_frame(old, utm)


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


# -- the instrument formats: latitude/longitude into a CRS in feet ---------------------------------
def utm_in(unit: str, zone: int, datum: str = "+datum=WGS84") -> str:
    return f"+proj=utm +zone={zone} {datum} +units={unit} +no_defs +type=crs"


def same_track(feet, metres):
    """The survey imported in a UTM zone in feet matches the one in the same zone in metres."""
    assert pyproj.CRS(feet.meta["crs"]).axis_info[0].unit_name == "metre"
    assert feet.meta["crs_given"]["unit"] in ("US survey foot", "foot")
    a = feet.dr_pose[:, :2] + feet.meta["origin"]
    b = metres.dr_pose[:, :2] + metres.meta["origin"]
    np.testing.assert_allclose(a, b, atol=2e-3, rtol=0)
    np.testing.assert_allclose(feet.dr_pose[:, 2], metres.dr_pose[:, 2], atol=1e-6)
    if metres.true_pose is not None:
        np.testing.assert_allclose(feet.true_pose[:, :2] + feet.meta["origin"],
                                   metres.true_pose[:, :2] + metres.meta["origin"], atol=2e-3, rtol=0)
    np.testing.assert_array_equal(feet.beam_depth, metres.beam_depth)


def test_sontek_in_feet(caputh):
    import logging

    from tangraph.formats import import_sontek_sum

    logging.getLogger("tangraph.formats.sontek").setLevel(logging.ERROR)
    run = caputh / "20250327110103.sum"
    metres = import_sontek_sum(run, crs="EPSG:25833", timezone="Europe/Berlin")
    feet = import_sontek_sum(run, crs=utm_in("us-ft", 33, "+ellps=GRS80"), timezone="Europe/Berlin")
    same_track(feet, metres)


def test_xtf_and_gsf_in_feet():
    from tests.formats.test_multibeam import GSF, SHARED_DATA, XTF

    folder = SHARED_DATA / "multibeam"
    if not (folder / XTF).is_file():
        pytest.skip(f"real data folder {folder} is absent (it sits beside the checkout as ../shared)")
    pytest.importorskip("pyxtf")
    pytest.importorskip("gsfpy")
    from tangraph.formats import import_gsf, import_xtf

    same_track(import_xtf(folder / XTF, crs=utm_in("us-ft", 10)), import_xtf(folder / XTF, crs="EPSG:32610"))
    same_track(import_gsf(folder / GSF, crs=utm_in("ft", 58)), import_gsf(folder / GSF, crs="EPSG:32658"))
