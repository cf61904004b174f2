"""
The factor graph: online iSAM2 with terrain fixes
=================================================

The factor graph keeps the vehicle's trajectory as a chain of key poses tied together by the
dead reckoning's increments, and ties some of them to the map with terrain-aided position
fixes (TAP, :doc:`tutorial 3 <plot_03_first_terrain_fix>`). This tutorial runs the online
navigator (iSAM2) on the ``wang2019`` survey, looks at which fixes it used and which it
refused and why, then injects a wrong fix to see the two defences at work: the gate, which
refuses a fix that disagrees with the prediction, and the robust noise model, which
down-weights one that got through. The ideas are in :doc:`/guide`.
"""

# %%
# The survey and the settings
# ---------------------------
#
# ``wang2019`` is a 1.7 km multibeam line over Merimbula Lake (see :doc:`tutorial 2
# <plot_02_simulate_survey>`); its dead reckoning has a 1 degree heading bias and reads the
# speed 1 % fast, so it drifts by about 35 m by the end. The graph's settings are a
# :class:`~tangraph.graph.GraphConfig`; its defaults (printed below) make a fix every
# ``fix_spacing`` pings from a window of the last ``n_pings`` pings, put a key pose at least
# every ``key_interval`` seconds and at the end of every window, gate fixes at a quantile of
# ``chi2(2)`` and give the fixes a Huber noise model.

import dataclasses

import matplotlib.pyplot as plt
import numpy as np

from tangraph.eval import track_metrics
from tangraph.graph import GraphConfig, GraphNavigator, navigate_online, search_half_width
from tangraph.graph.fixes import make_fix
from tangraph.maps import load
from tangraph.navigation import dead_reckoning_track, track_summary
from tangraph.plot import plot_errors, plot_tracks
from tangraph.sensors import NavigationModel
from tangraph.sim import load_scenario, simulate
from tangraph.track import position_errors

scenario = load_scenario("wang2019")
bathymetry = load(scenario.map)
survey = simulate(scenario, rng=np.random.default_rng(7), bathymetry=bathymetry, seed=7)
print(survey.summary())

config = GraphConfig()
model = NavigationModel.from_survey(survey)  # the fixes' error model is the navigation model's
print(f"fix every {config.spacing} pings ({config.fixes.n_pings}-ping windows), key pose every "
      f"{config.key_interval:.0f} s at least; gate at p = {config.fixes.gate_probability}; "
      f"robust kernel {model.robust_kernel} at {model.robust_parameter}")

# %%
# Online navigation
# -----------------
#
# :func:`~tangraph.graph.navigate_online` steps through the pings. At each window end it
# predicts the position (the latest key estimate composed with the DR increment), searches a
# TAP fix around it over a half-width of four predicted standard deviations (but at least
# ``min_half_width_cells`` steps of the search grid, whose step is a fraction of a map cell),
# judges the fix
# and, if it is accepted, adds it as a translation prior; iSAM2 is updated with the new factors
# only. The key poses live in the dead reckoning's own frame and the graph holds one more
# variable, the DR's calibration (speed scale factor and heading bias): every fix measures a
# world position through it, so the graph estimates the constant errors with the poses and every
# pose it reports carries their remaining uncertainty (``track.meta["calibration"]``). The
# :class:`~tangraph.sensors.NavigationModel` comes from the survey (a simulated survey records
# its settings; for a recorded one it is passed as ``model``, see :doc:`tutorial 6
# <plot_06_renavigate_recorded_survey>`).

online = navigate_online(survey, bathymetry, config)
print(track_summary(online, survey))
calibration = online.meta["calibration"]
print(f"speed scale {calibration['speed_scale']:+.2%} +- {calibration['speed_scale_std']:.2%}, "
      f"heading bias {np.degrees(calibration['heading_bias']):+.2f} +- "
      f"{np.degrees(calibration['heading_bias_std']):.2f} deg")

# %%
# What became of every fix
# ------------------------
#
# ``Track.fixes`` holds one :class:`~tangraph.graph.FixRecord` per window: the ping it
# ends at, the fix and the covariance given to the graph, its :class:`~tangraph.graph.FixStatus`
# (accepted, or why not), its NIS (normalised innovation squared
# against the prediction; the gate is its 0.999 quantile, 13.8) and the search half-width.
# Refused fixes are *multimodal* (the calibrated region has several parts: two places fit),
# *uninformative* (the region reaches the edge of the search or is too large), *gate* (the
# fix disagrees with the prediction), or the match failed.

truth = survey.true_pose
print(" ping  accepted  reason          NIS   half-width  fix error")
for record in online.fixes:
    k = record.index
    error = np.hypot(*(record.position - truth[k, :2]))
    print(f"{k:5d}  {record.accepted!s:>8}  {record.status.value:<13} {record.nis:7.1f}  "
          f"{record.half_width:8.1f} m  {error:7.1f} m")

# %%
# The error against time, with the navigator's 2-sigma band and the fixes marked: the error of
# the dead reckoning grows steadily; the graph's falls at each accepted fix and grows with the
# DR between them.

fixes = online.fixes
fig, ax = plt.subplots(figsize=(9, 4.5), layout="constrained")
plot_errors({"dead reckoning": dead_reckoning_track(survey), "isam2": online}, truth, ax, bound="isam2")
for accepted, marker, colour in ((True, "v", "tab:green"), (False, "x", "tab:red")):
    times = [survey.time[f.index] for f in fixes if f.accepted is accepted]
    ax.plot(times, np.zeros(len(times)) + 0.5, marker, color=colour, ls="",
            label="accepted fixes" if accepted else "refused fixes")
ax.legend(loc="upper left", fontsize="small")
ax.set_title("online iSAM2 on wang2019")
plt.show()

# %%
# An outlier fix
# --------------
#
# A real fix can be wrong and confident: the patch locks onto a place that fits as well as the
# true one, and the flags do not see it. We make such a fix by hand. :class:`~tangraph.graph.GraphNavigator`
# runs one ping per :meth:`~tangraph.graph.GraphNavigator.step`, and ``step`` takes a fix to use
# instead of the one it would make. We take the window end in the middle of the accepted fixes,
# run the default navigator up to it, make the genuine fix as the navigator would
# (``tangraph.graph.fixes.make_fix``, around its prediction), then move
# the fix 30 m north and 20 m west and keep its covariance and its flags: a fix about 36 m off
# that claims an accuracy of a few metres and passes the quality flags.

good = [f.index for f in fixes if f.accepted]
bad_ping = good[len(good) // 2]
offset = np.array([30.0, -20.0])

nav = GraphNavigator(survey, bathymetry, config)
for _ in range(bad_ping):
    nav.step()
pose, cov = nav.predicted(bad_ping)
half_width = search_half_width(config, bathymetry, cov[:2, :2])
genuine = make_fix(survey, bathymetry, bad_ping, config, pose[:2], half_width)  # as the navigator would
outlier = dataclasses.replace(genuine, position=genuine.position + offset)
std = np.sqrt(np.diag(outlier.covariance))
print(f"outlier at ping {bad_ping} (t = {survey.time[bad_ping]:.0f} s): "
      f"{np.hypot(*(outlier.position - truth[bad_ping, :2])):.1f} m from the truth, "
      f"claimed std {std[0]:.1f} m north, {std[1]:.1f} m east; accepted by the flags: {outlier.accepted}")


def run_with(fix, config: GraphConfig, model: NavigationModel) -> GraphNavigator:
    """The whole survey, with ``fix`` used at its ping instead of the fix the navigator makes."""
    nav = GraphNavigator(survey, bathymetry, config, model=model)
    for k in range(survey.n_pings):
        nav.step(fix=fix if k == fix.index else None)
    return nav


# %%
# Three navigators meet it: the default one (the gate, the hold of a surprising fix until a
# later one agrees, the lost test and Huber), one with Huber only, and one with none of them.

alone = {"gate_probability": None, "confirm_probability": None, "lost_windows": None}
variants = {
    "default": (config, model),
    "huber only": (config.replace(**alone), model),
    "no defence": (config.replace(**alone), model.replace(robust_kernel="none")),
}
results = {}
after = slice(bad_ping, bad_ping + 20)
for label, (variant, variant_model) in variants.items():
    track = run_with(outlier, variant, variant_model).track()
    record = next(f for f in track.fixes if f.index == bad_ping)
    results[label] = track
    print(f"{label:<26} outlier {'accepted' if record.accepted else 'refused'} "
          f"({record.status.value}, NIS {record.nis:.0f}); largest error over the "
          f"next 20 pings {position_errors(track, truth)[after].max():5.1f} m; RMSE "
          f"{track_metrics(track, truth)['rmse']:.2f} m")

# %%
# The gate refuses the fix outright: its NIS, the squared distance between fix and prediction
# in units of their combined covariance, is far beyond the gate's 13.8 (a fix between the
# 0.9 quantile, 4.6, and the gate would be held until the next fix agreed with it). Without
# these the fix enters the graph, and what it does depends on its noise model. The Huber model treats a
# whitened error up to 2.45 as Gaussian and beyond that grows only linearly, so the weight of a
# fix falls with its disagreement with the odometry and the other fixes: the outlier moves the
# track by little. A plain Gaussian prior has no such defence, and the track is dragged towards
# the outlier until the next fixes pull it back. (Without the gate a navigator also accepts any
# genuine fix the gate would have refused: a gate at p = 0.999 refuses a good fix now and then,
# the price of its safety; the table of fixes above shows whether it did on this line.) The
# errors around the outlier:

fig, ax = plt.subplots(figsize=(9, 4.5), layout="constrained")
for (label, track), colour in zip(results.items(), ("tab:green", "tab:orange", "tab:red"), strict=True):
    ax.plot(track.time, position_errors(track, truth), color=colour, label=label)
ax.axvline(survey.time[bad_ping], color="0.5", ls=":", label="outlier fix")
ax.set_xlabel("time (s)")
ax.set_ylabel("horizontal error (m)")
ax.set_ylim(bottom=0)
ax.legend(fontsize="small")
ax.set_xlim(survey.time[bad_ping] - 60, survey.time[bad_ping] + 120)
ax.set_title("an outlier fix met by three navigators")
plt.show()

# %%
# The online track is causal: each pose uses only the pings before it, as a vehicle under way
# has them. After the survey, the batch smoother uses every fix for every pose, so the poses
# before a fix are corrected too. The line runs due north, so the east error is the
# cross-track error; the 1 degree heading bias drives the dead reckoning's off to starboard:

from tangraph.graph import smooth_survey  # noqa: E402

smoothed = smooth_survey(survey, bathymetry, config)
print(track_summary(smoothed, survey))
tracks = {"dead reckoning": dead_reckoning_track(survey), "isam2": online, "smoother": smoothed}
fig, axes = plt.subplots(1, 2, figsize=(10, 6.5), layout="constrained", width_ratios=(1, 2))
plot_tracks(tracks, bathymetry, axes[0], truth=truth, title="the line over the map")
for label, colour in (("dead reckoning", "tab:red"), ("isam2", "tab:cyan"), ("smoother", "tab:blue")):
    track = tracks[label]
    axes[1].plot(track.pose[:, 1] - truth[:, 1], truth[:, 0], color=colour, label=label)
band = 2 * np.sqrt(smoothed.covariance[:, 1, 1])
axes[1].fill_betweenx(truth[:, 0], -band, band, color="tab:blue", alpha=0.15, label="smoother: 2-sigma (east)")
axes[1].axvline(0, color="k", lw=0.8)
axes[1].set_xlim(-15, 40)
axes[1].set_xlabel("east error: estimate - truth (m)")
axes[1].set_ylabel("north (m)")
axes[1].legend(loc="lower right", fontsize="small")
axes[1].set_title("the cross-track error along the line")
plt.show()

# %%
# The smoother's lower RMSE and its ANEES closer to 2 are what hindsight buys: between two
# fixes its poses are pinned from both sides. :doc:`The next tutorial
# <plot_06_renavigate_recorded_survey>` smooths a recorded survey from its files.

# sphinx_gallery_thumbnail_number = 1
