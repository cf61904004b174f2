"""A 7 km line near Houston as a lat/lon log and as north/east in a CRS in US survey feet
(EPSG:2278), and the checks that a survey imported in feet is the one in metres: shared by the
importers', map-frame and ``survey import`` tests of a CRS in feet."""

from __future__ import annotations

import numpy as np
import pyproj

from tangraph.navigation import dead_reckoning_track
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
