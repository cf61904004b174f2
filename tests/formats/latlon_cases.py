"""A curving track near Potsdam as a lat/lon navigation log with XYZ soundings (three beams laid
on the true starboard azimuth), written as CSV/XYZ files; the grid heading PROJ's meridian
convergence gives; ISO times. Shared by the CSV/XYZ import, map-frame and ``survey import``
tests."""

from __future__ import annotations

import numpy as np
import pyproj

LAT0, LON0 = 52.40, 13.40  # near Potsdam: UTM zone 33, 1.3 deg west of its central meridian
OFFSETS = np.array([-20.0, 0.0, 20.0])  # beams to starboard, metres
START = np.datetime64("2024-05-01T10:00:00", "s")  # UTC


def latlon_log(k=30):
    """A curving track in WGS84 with true headings, and three beams per ping placed along the
    true starboard azimuth on the ellipsoid (pyproj.Geod)."""
    t = np.arange(k) * 2.0
    lat = LAT0 + 1e-4 * t + 2e-4 * np.sin(t / 15)
    lon = LON0 + 2e-4 * t
    heading = (40.0 + 3.0 * t) % 360.0
    depth = 5.0 + 0.1 * t
    geod = pyproj.Geod(ellps="WGS84")
    rep = np.repeat
    side = np.tile(OFFSETS, k)
    lon_b, lat_b, _ = geod.fwd(rep(lon, 3), rep(lat, 3), rep(heading, 3) + 90.0 * np.sign(side), np.abs(side))
    lon_b, lat_b = np.asarray(lon_b), np.asarray(lat_b)
    centre = np.tile(OFFSETS, k) == 0
    lon_b[centre], lat_b[centre] = rep(lon, 3)[centre], rep(lat, 3)[centre]
    z = 30.0 + np.tile([1.0, 2.0, 3.0], k)
    return {"t": t, "lat": lat, "lon": lon, "heading": heading, "depth": depth,
            "sounding": np.column_stack([rep(t, 3), lon_b, lat_b, z])}


def write_latlon(tmp_path, log, *, time_text=None, sounding_time_text=None, sep=",", header=True,
                 order=("time", "lat", "lon", "heading", "depth")):
    values = {"time": log["t"], "lat": log["lat"], "lon": log["lon"], "heading": log["heading"],
              "depth": log["depth"]}
    lines = [sep.join(order)] if header else []
    for i in range(log["t"].size):
        fields = [time_text[i] if (key == "time" and time_text is not None) else repr(float(values[key][i]))
                  for key in order]
        lines.append(sep.join(fields))
    nav = tmp_path / "nav.csv"
    nav.write_text("\n".join(lines) + "\n")
    xyz = tmp_path / "s.xyz"
    rows = log["sounding"]
    xyz.write_text("".join(
        f"{sounding_time_text[i] if sounding_time_text is not None else repr(float(r[0]))} "
        + " ".join(repr(float(v)) for v in r[1:]) + "\n" for i, r in enumerate(rows)))
    return nav, xyz


def true_to_grid(crs, lat, lon, heading_deg):
    """Grid heading from the true one with PROJ's meridian convergence (independent of the
    numeric step of the import)."""
    gamma = pyproj.Proj(crs).get_factors(lon, lat).meridian_convergence
    return np.radians(heading_deg - np.asarray(gamma))


def angle_difference(a, b):
    return np.angle(np.exp(1j * (np.asarray(a) - np.asarray(b))))


def iso(t, fmt="%Y-%m-%dT%H:%M:%S", suffix="Z"):
    import datetime as dt

    base = dt.datetime(2024, 5, 1, 10, 0, 0)
    return [(base + dt.timedelta(seconds=float(s))).strftime(fmt) + suffix for s in t]
