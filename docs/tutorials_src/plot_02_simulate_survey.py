"""
Simulate a survey and look at it
================================

Before matching soundings against a map we need soundings. This tutorial simulates a survey
from one of the papers' scenarios: a true track, the dead reckoning (DR) that drifts away from
it, and the multibeam soundings ray-cast on the map. Then it looks at the result from a few
sides: the track over the map, the growth of the DR error, the NetCDF file a survey is stored
in, and the beams of one ping. A second, very different scenario closes the tutorial.

Coordinates are local ``(north, east)`` in metres, headings are clockwise from north and
depth is positive down (see :doc:`/conventions`).
"""

# %%
# A scenario
# ----------
#
# A scenario is a TOML file that names a map, a trajectory, a dead-reckoning error model and a
# sonar (see :func:`~tangraph.sim.load_scenario`). ``wang2019`` follows Wang et al. (2019): a
# survey boat runs a straight line due north over the deep western basin of Merimbula Lake, a
# 10 m map, with a 101-beam multibeam. Its heading reference is poor (a constant 1 degree bias)
# and its speed log reads 1 % fast, so its dead reckoning drifts: this is the error terrain
# matching has to correct.

import dataclasses
import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from tangraph.maps import load
from tangraph.plot import plot_survey
from tangraph.sim import list_scenarios, load_scenario, simulate
from tangraph.survey import footprints, read_survey, write_survey

print("shipped scenarios:", ", ".join(list_scenarios()))
scenario = load_scenario("wang2019")
print(scenario.description)
print(f"map            {scenario.map}")
print(f"seed           {scenario.seed}")
print(f"vehicle depth  {scenario.vehicle_depth} m")
print(f"trajectory     {scenario.trajectory}")
dr_model = scenario.dead_reckoning
print(f"dead reckoning heading bias {np.degrees(dr_model.heading_bias):.1f} deg, "
      f"speed scale {dr_model.speed_scale:+.0%}, speed noise {dr_model.speed_noise} m/s, "
      f"start error {dr_model.start_position_std} m (std)")
sonar = scenario.sonar
print(f"sonar          {sonar.n_beams} beams over {np.degrees(sonar.swath):.0f} deg, "
      f"{sonar.ping_rate} Hz, depth noise {sonar.depth_noise} m, "
      f"range noise {sonar.range_noise:.1%} of the range, tide {sonar.tide} m")

# %%
# Simulate
# --------
#
# :func:`~tangraph.sim.simulate` samples the true trajectory at the ping rate, runs the
# dead-reckoning error model along it and ray-casts every beam of every ping on a mesh of the
# map. All the randomness comes from the one generator passed as ``rng``; ``seed`` is only
# written into the survey's metadata, so the survey says how to make it again.

rng = np.random.default_rng(2019)
survey = simulate(scenario, rng=rng, seed=2019)
print(survey.summary())

# %%
# The result is a :class:`~tangraph.survey.Survey`: read-only arrays of ``time (K,)``,
# ``dr_pose (K, 3)`` and ``true_pose (K, 3)`` as ``(north, east, heading)``, and per beam the
# footprint in the vehicle frame (``beam_forward``, ``beam_starboard``) and the measured depth
# (``beam_depth``), each ``(K, B)``.

print(f"time {survey.time.shape}, dr_pose {survey.dr_pose.shape}, "
      f"beam_depth {survey.beam_depth.shape}")
print("metadata keys:", ", ".join(survey.meta))

# %%
# The survey over its map
# -----------------------
#
# :func:`~tangraph.plot.plot_survey` draws the true track, the dead reckoning and the swath
# footprints of every few pings over the hill-shaded map. On the whole lake (left) the line is
# short and the drift of a few tens of metres hardly shows; the right panel crops the map to the
# last 300 m of the line, where the dead reckoning has drifted most. The white bars are the
# footprints of every 7th ping, about 40 m wide across the track.

bathymetry = load(survey.meta["map"])
end = survey.true_pose[-1, :2]
last_part = bathymetry.crop(north=(end[0] - 330, end[0] + 70), east=(end[1] - 200, end[1] + 200))
fig, axes = plt.subplots(1, 2, figsize=(11, 5), layout="constrained")
plot_survey(survey, bathymetry, ax=axes[0], title="wang2019 on the whole lake")
plot_survey(survey, last_part, ax=axes[1], title="the end of the line")
axes[1].set_xlim(last_part.extent[2], last_part.extent[3])
axes[1].set_ylim(last_part.extent[0], last_part.extent[1])
plt.show()

# %%
# How the dead reckoning drifts
# -----------------------------
#
# The DR position error is the distance between ``dr_pose`` and ``true_pose``. The boat heads
# due north, so the north error is the along-track error and the east error the cross-track
# error. Both follow from the error model: the DR starts where it was initialised, a draw of
# ``start_position_std`` (10 m) from the true start; from there the 1 % speed scale makes the
# along-track error grow as ``0.01 v t``, and the 1 degree heading bias turns the track to
# starboard, so the cross-track error grows as ``sin(1 deg) (1.01 v) t``. The white speed noise
# adds a small random walk on top.

error = survey.dr_pose[:, :2] - survey.true_pose[:, :2]
speed = scenario.trajectory["speed"]
t = survey.time
fig, ax = plt.subplots(figsize=(8, 4), layout="constrained")
ax.plot(t, np.hypot(error[:, 0], error[:, 1]), "k-", lw=2, label="position error")
ax.plot(t, error[:, 0], "C0-", label="north (along track)")
ax.plot(t, error[:, 1], "C1-", label="east (cross track)")
start = error[0]
ax.plot(t, start[0] + dr_model.speed_scale * speed * t, "C0:", label="start + 0.01 v t")
ax.plot(t, start[1] + np.sin(dr_model.heading_bias) * (1 + dr_model.speed_scale) * speed * t, "C1:",
        label="start + sin(1 deg) 1.01 v t")
ax.set_xlabel("time (s)")
ax.set_ylabel("DR - truth (m)")
ax.set_title("dead-reckoning error of the wang2019 survey")
ax.legend()
plt.show()
print(f"DR error after {t[-1]:.0f} s: {np.hypot(*error[-1]):.1f} m "
      f"({np.hypot(*error[-1]) / (speed * t[-1]):.1%} of the distance run)")

# %%
# Write it to NetCDF and read it back
# -----------------------------------
#
# :func:`~tangraph.survey.write_survey` stores a survey as a CF NetCDF file (the schema is
# described in :doc:`/survey_schema`); :func:`~tangraph.survey.read_survey` reads it and checks
# everything it reads. The metadata, with the scenario's settings, travels in the file. The file
# goes to a temporary folder here.

with tempfile.TemporaryDirectory() as folder:
    path = write_survey(survey, Path(folder) / "wang2019.nc")
    back = read_survey(path)
    print(f"{path.name}: {path.stat().st_size / 1e6:.2f} MB")
same = {name: np.array_equal(getattr(back, name), getattr(survey, name), equal_nan=True)
        for name in ("time", "dr_pose", "true_pose", "beam_forward", "beam_starboard", "beam_depth")}
print("arrays read back unchanged:", same)
print("metadata read back unchanged:", back.meta == survey.meta)

# %%
# One ping
# --------
#
# Each ping gives one depth per beam across the track. ``beam_starboard`` is the footprint's
# offset to starboard of the vehicle (negative: to port) and ``beam_depth`` the measured depth.
# Placing the footprints with the *true* pose (:func:`~tangraph.survey.footprints`) and reading
# the map there shows what the sonar saw. The measured depths lie ``tide`` = 2.5 m below the
# map's: the sea surface is 2.5 m above the map's datum, so **measured depth = map depth +
# tide**, plus the sounding noise. (Terrain matching estimates this offset with the position;
# see the next tutorial.)

ping = 119
pose = survey.true_pose[ping : ping + 1]
north, east = footprints(pose, survey.beam_forward[ping : ping + 1], survey.beam_starboard[ping : ping + 1])
map_depth = bathymetry.depth_at(north[0], east[0])
starboard = survey.beam_starboard[ping]
measured = survey.beam_depth[ping]

fig, ax = plt.subplots(figsize=(8, 4), layout="constrained")
ax.plot(starboard, map_depth, "k-", label="map depth under the true footprints")
ax.plot(starboard, map_depth + sonar.tide, "k--", lw=1, label="map depth + tide")
ax.plot(starboard, measured, "C3.", label="measured depth")
ax.invert_yaxis()
ax.set_xlabel("starboard offset of the footprint (m)")
ax.set_ylabel("depth (m)")
ax.set_title(f"ping {ping} at t = {survey.time[ping]:.0f} s: {np.isfinite(measured).sum()} beams")
ax.legend()
plt.show()

residual = measured - map_depth
print(f"measured - map: mean {np.nanmean(residual):.3f} m (the tide is {sonar.tide} m), "
      f"std {np.nanstd(residual):.3f} m (depth noise {sonar.depth_noise} m plus the range noise)")

# %%
# A very different survey: ``chen2022``
# -------------------------------------
#
# ``chen2022`` follows Chen and Che (2022): an AUV at 1 m/s for 100 000 s (100 km) over a
# synthetic 500 m chart, with a single vertical beam sounding once every 100 s (std 5 m) and a
# 2 degree heading bias. Its DR error reaches kilometres, and it has only one sounding per ping:
# this is the setting of the particle filters, not of batch fixes from a multibeam swath.

chen = load_scenario("chen2022")
print(chen.description)
chen_survey = simulate(chen, rng=np.random.default_rng(chen.seed), seed=chen.seed)
print(chen_survey.summary())

# %%
# :func:`~tangraph.plot.plot_survey` shows the soundings (one per ping, under the vehicle) along
# the 100 km route; the dead reckoning ends about 4 km off.

chen_map = load(chen_survey.meta["map"])
fig, ax = plt.subplots(figsize=(8, 7), layout="constrained")
plot_survey(chen_survey, chen_map, ax=ax, title="chen2022: 100 000 s, one sounding per 100 s")
plt.show()

# %%
# The scenarios are plain frozen dataclasses once loaded, so a variation needs no new file:
# :func:`dataclasses.replace` gives a copy with, say, a longer swath or no DR error at all (the
# next tutorial does that). A changed scenario simulates like any other:

wide = dataclasses.replace(scenario, sonar=dataclasses.replace(sonar, swath=np.radians(150.0)))
wide_survey = simulate(wide, rng=np.random.default_rng(2019), seed=2019)
print(f"swath 140 deg: {np.ptp(survey.beam_starboard[ping]):.1f} m wide; "
      f"150 deg: {np.ptp(wide_survey.beam_starboard[ping]):.1f} m wide")

# sphinx_gallery_thumbnail_number = 1
