"""
Re-navigating a recorded survey
===============================

A hydrographer has the files of a finished survey: the vehicle's navigation log and its
soundings, both georeferenced with the vehicle's own, drifting, dead reckoning. Re-navigating
the survey means estimating where the vehicle really was, from the soundings and a prior map,
and writing the corrected track. This tutorial does it end to end: it writes the two files a
recording system would (from a simulated survey, so that the truth is known), imports them
with :func:`tangraph.formats.import_csv_xyz`, smooths the track with the factor graph and
writes it in latitude and longitude.
"""

# %%
# The files of a survey
# ---------------------
#
# The ``demo`` scenario is a multibeam lawnmower over the western basin of Merimbula Lake, whose
# map comes in UTM zone 55 south (EPSG:32755): 1256 pings over 42 minutes, with a dead
# reckoning that drifts by tens of metres (a 3.5 degree heading bias, a 3 % speed error and a
# heading random walk). Where a real survey would start from its files, we make them: a
# navigation log (CSV, one row per ping: time, northing and easting in the map's CRS, heading
# in degrees, vehicle depth) and the soundings (``time easting northing depth``, one row per
# beam, placed with the dead-reckoned pose, as the recording system placed them). The files go
# to a temporary folder.

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np
import pyproj

from tangraph.graph import smooth_survey
from tangraph.maps import load
from tangraph.navigation import dead_reckoning_track, track_summary
from tangraph.plot import plot_tracks
from tangraph.sim import load_scenario, simulate
from tangraph.formats import import_csv_xyz
from tangraph.track import position_errors, write_track_csv

scenario = load_scenario("demo")
bathymetry = load(scenario.map)
print(bathymetry)
print(f"crs {bathymetry.crs}, local origin (northing, easting) {bathymetry.origin}")
simulated = simulate(scenario, rng=np.random.default_rng(7), bathymetry=bathymetry, seed=7)
print(simulated.summary())

folder = Path(tempfile.mkdtemp(prefix="tangraph-tutorial-"))
north0, east0 = bathymetry.origin  # local (0, 0) in the map's CRS
dr = simulated.dr_pose
navigation_file = folder / "navigation.csv"
np.savetxt(
    navigation_file,
    np.column_stack([simulated.time, dr[:, 0] + north0, dr[:, 1] + east0,
                     np.degrees(dr[:, 2]) % 360.0, simulated.vehicle_depth]),
    delimiter=",", header="time,north,east,heading,depth", comments="", fmt="%.3f",
)
north, east = simulated.footprints()  # every beam, placed with the dead reckoning
has = np.isfinite(simulated.beam_depth)
ping_time = np.broadcast_to(simulated.time[:, None], has.shape)
soundings_file = folder / "soundings.xyz"
np.savetxt(
    soundings_file,
    np.column_stack([ping_time[has], east[has] + east0, north[has] + north0, simulated.beam_depth[has]]),
    header="time x y z", fmt="%.3f",
)
for path in (navigation_file, soundings_file):
    print(f"--- {path.name}: {path.stat().st_size / 1e6:.1f} MB")
    print("".join(path.open().readlines()[:4]), end="")

# %%
# Import
# ------
#
# :func:`~tangraph.formats.import_csv_xyz` reads the log and the soundings, makes one ping per
# distinct sounding time, interpolates the log at those times (the heading on the circle) and
# turns every sounding into body coordinates relative to its ping's pose. ``crs`` names the
# projected CRS of the log; the survey's local frame then starts at the whole metres below the
# log's smallest northing and easting, which the survey records in ``meta["origin"]``. Pings
# without any return leave no row in the soundings file, so they are not in the imported
# survey.

recorded = import_csv_xyz(navigation_file, soundings_file, crs=bathymetry.crs)
print(recorded.summary())
print({k: recorded.meta[k] for k in ("crs", "origin", "n_dropped_outside_navigation")})

# %%
# The survey's frame and the map's differ only by their origins (both are UTM 55S), so one shift
# puts the survey on the map: :func:`~tangraph.navigation.in_map_frame` makes it (a survey in
# another projected CRS it reprojects, turning headings by the grid convergence). Then the import
# can be checked against what was written: the poses at
# the same times must agree to the millimetres of the files.

from tangraph.navigation import in_map_frame

recorded = in_map_frame(recorded, bathymetry)
same = np.searchsorted(simulated.time, recorded.time)  # the simulated ping of each imported one
assert np.allclose(simulated.time[same], recorded.time)
difference = np.abs(recorded.dr_pose[:, :2] - simulated.dr_pose[same, :2]).max()
print(f"{recorded.n_pings} of {simulated.n_pings} pings imported; largest position difference "
      f"{difference * 1e3:.1f} mm; soundings {recorded.n_soundings} of {simulated.n_soundings}")

# %%
# Smooth
# ------
#
# A recorded survey does not say how good its dead reckoning was: the graph needs a
# :class:`~tangraph.sensors.NavigationModel`, the vehicle's INS/DVL white errors (speed noise,
# heading random walk) and the prior uncertainty of its constant errors (speed scale factor,
# heading bias), which for a real vehicle come from its specification; the graph estimates the
# constant errors themselves. Here the white errors are those the survey was simulated with and
# the priors the defaults (2 % scale, 2 deg bias); ``tangraph smooth --dr-model FILE.toml`` reads
# the same fields from a file. :func:`~tangraph.graph.smooth_survey` makes TAP fixes along the
# track (every ``fix_spacing`` pings, each of the last ``n_pings`` pings), gates them, and solves
# every key pose at once; ``rematch_iterations``
# then re-searches the fixes around the smoothed track (their patches laid with the smoothed
# poses) and solves again, until the fixes stop moving.

from tangraph.graph import GraphConfig  # noqa: E402
from tangraph.sensors import NavigationModel  # noqa: E402

model = NavigationModel.from_dead_reckoning(scenario.dead_reckoning)
config = GraphConfig().replace(rematch_iterations=2)
smoothed = smooth_survey(recorded, bathymetry, config, model=model)
print(track_summary(smoothed, recorded))
calibration = smoothed.meta["calibration"]
print(f"estimated speed scale {calibration['speed_scale']:+.2%} +- {calibration['speed_scale_std']:.2%}, "
      f"heading bias {np.degrees(calibration['heading_bias']):+.2f} +- "
      f"{np.degrees(calibration['heading_bias_std']):.2f} deg "
      f"(simulated: {scenario.dead_reckoning.speed_scale:+.2%}, "
      f"{np.degrees(scenario.dead_reckoning.heading_bias):+.2f} deg)")

# %%
# The imported survey has no truth (a real one would not), so the summary gives no errors. The
# simulation does have one: compare at the imported pings.

truth = simulated.true_pose[same]
for label, track in (("dead reckoning", dead_reckoning_track(recorded)), ("smoothed", smoothed)):
    error = position_errors(track, truth)
    print(f"{label:<15} error: RMSE {np.sqrt(np.mean(error**2)):5.1f} m, "
          f"95th percentile {np.percentile(error, 95):5.1f} m, max {error.max():5.1f} m")

fig, ax = plt.subplots(figsize=(9, 7), layout="constrained")
plot_tracks({"dead reckoning": dead_reckoning_track(recorded), "smoother": smoothed}, bathymetry, ax,
            truth=truth, ellipses="smoother", title="the re-navigated demo survey")
plt.show()

# %%
# Write the track in latitude and longitude
# -----------------------------------------
#
# :func:`~tangraph.track.write_track_csv` writes time, latitude and longitude (when given the
# map's CRS and origin), the local north and east, the heading and the covariance terms of
# every ping. Other tools read the TUM format (:func:`~tangraph.track.write_track_tum`).

track_file = write_track_csv(smoothed, folder / "smoothed.csv", crs=bathymetry.crs, origin=bathymetry.origin)
print("".join(track_file.open().readlines()[:4]), end="")

# %%
# A check of the file against the truth, in geographic coordinates only: the truth is converted
# to latitude and longitude, and the distance between the two on the WGS 84 ellipsoid is the
# error printed above.

table = np.genfromtxt(track_file, delimiter=",", names=True)
to_lonlat = pyproj.Transformer.from_crs(bathymetry.crs, "EPSG:4326", always_xy=True)
true_lon, true_lat = to_lonlat.transform(truth[:, 1] + bathymetry.origin[1], truth[:, 0] + bathymetry.origin[0])
_, _, distance = pyproj.Geod(ellps="WGS84").inv(table["lon"], table["lat"], true_lon, true_lat)
print(f"from the file's lat/lon: RMSE {np.sqrt(np.mean(distance**2)):.1f} m over {len(table)} pings; "
      f"first pose at {table['lat'][0]:.6f}, {table['lon'][0]:.6f}")

fig, ax = plt.subplots(figsize=(7, 6), layout="constrained")
ax.plot(true_lon, true_lat, "k-", lw=2, label="truth")
ax.plot(table["lon"], table["lat"], "C2-", lw=1, label="smoothed (from the file)")
dr_lon, dr_lat = to_lonlat.transform(recorded.dr_pose[:, 1] + bathymetry.origin[1],
                                     recorded.dr_pose[:, 0] + bathymetry.origin[0])
ax.plot(dr_lon, dr_lat, "C1--", lw=1, label="dead reckoning")
ax.set_xlabel("longitude (deg)")
ax.set_ylabel("latitude (deg)")
ax.set_aspect(1 / np.cos(np.radians(np.mean(true_lat))))
ax.legend()
ax.set_title("the written track, in geographic coordinates")
plt.show()

# %%
# On the command line the import is ``tangraph survey import navigation.csv soundings.xyz
# --crs EPSG:32755 -o survey.nc`` (see :doc:`/cli`); the smoothing of a simulated survey file is
# ``tangraph smooth survey.nc --map merimbula --dr-model ins.toml -o track.csv``: the command shifts
# the survey into the map's frame itself, and ``--dr-model`` gives the error model of the vehicle's
# dead reckoning (a scenario's ``[dead_reckoning]`` keys, e.g. ``heading_bias_deg = 0.5``), which
# a survey file from another system does not carry.

# sphinx_gallery_thumbnail_number = 1
