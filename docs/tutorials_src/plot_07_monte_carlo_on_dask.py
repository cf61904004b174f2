"""
A Monte Carlo study on Dask
===========================

One simulated survey says little about an estimator: its error is one draw of a random
variable. A study repeats the run many times, each with its own seeded generator, and looks at
the distribution. :func:`tangraph.experiments.run_many` does the bookkeeping: it calls a
function ``fn(config, *, rng)`` ``runs`` times for every configuration, on local worker
processes (or a Dask cluster), and gathers the results into one table with a row per run and
the seed of every row.

This tutorial runs a small study of terrain fixes (the fix of :doc:`tutorial 03
<plot_03_first_terrain_fix>`): how the fix error and the honesty of its covariance depend on
the window length and on the sounding noise. The studies in ``experiments/`` (see
:doc:`/studies/index`) are built the same way, only larger.
"""

# %%
# The run function
# ----------------
#
# A run function takes one configuration and a generator, and returns a flat dict of scalars
# (or a list of such dicts, for several rows). It must draw *all* its randomness from ``rng``:
# that is what makes every row reproducible. Here one run simulates the first 240 s of the
# ``wang2019`` line with an exact dead reckoning (as in tutorial 03), draws a prior position
# 10 m (standard deviation) from the truth, makes one fix of the window ending at ping 119 and
# reports its error, the NEES of its covariance, whether the calibrated 95 % region holds the
# truth and whether the quality flags accepted it.
#
# The configuration is a frozen dataclass; its fields become columns of the table. Worker
# processes receive the function and the configs by value (cloudpickle), so a function defined
# at the top level of a script, as here, works; a lambda or a nested function does not.

import dataclasses

import matplotlib.pyplot as plt
import numpy as np

from tangraph.experiments import rerun, run_many
from tangraph.maps import load
from tangraph.matching import RegionMethod, TapConfig, criterion_at, nees, tap_fix_patch, window_patch
from tangraph.sensors import DeadReckoningModel
from tangraph.sim import load_scenario, simulate


@dataclasses.dataclass(frozen=True)
class FixStudy:
    """One configuration of the study."""

    n_pings: int  # window length
    depth_noise: float  # sounding noise (m, standard deviation)
    prior_std: float = 10.0  # error of the prior position the search starts from (m)
    end: int = 119  # the ping the window ends at


def fix_run(config: FixStudy, *, rng: np.random.Generator) -> dict:
    """One seeded run: simulate, fix, compare with the truth."""
    scenario = load_scenario("wang2019")
    scenario = dataclasses.replace(
        scenario,
        trajectory={**scenario.trajectory, "duration": 240.0},
        dead_reckoning=DeadReckoningModel.ideal(),
        sonar=dataclasses.replace(scenario.sonar, depth_noise=config.depth_noise),
    )
    bathymetry = load(scenario.map)
    survey = simulate(scenario, rng=rng, bathymetry=bathymetry)
    truth = survey.true_pose[config.end, :2]
    patch = window_patch(survey, config.end, config.n_pings)
    prior = truth + rng.normal(0.0, config.prior_std, 2)
    fix = tap_fix_patch(patch, bathymetry, TapConfig(half_width=40.0, step=2.0), prior=prior)
    calibrated = fix.regions[RegionMethod.CALIBRATED]
    return {
        "error_m": float(np.hypot(*(fix.position - truth))),
        "nees": float(nees(fix.position - truth, fix.covariance)),
        "in_region_95": bool(criterion_at(bathymetry, patch, truth)[0] <= calibrated.threshold),
        "accepted": bool(fix.accepted),
        "refused_as": fix.quality.reasons[0].split(":")[0] if fix.quality.reasons else "",
        "sigma_m": float(fix.sigma),
        "n_soundings": int(fix.n_soundings),
    }


# %%
# Before sending anything to workers, call the function once in this process: a bug shows its
# traceback here instead of as an ``error`` cell of the table.

print(fix_run(FixStudy(n_pings=10, depth_noise=0.15), rng=np.random.default_rng(0)))

# %%
# Run the study on two local workers
# ----------------------------------
#
# Three window lengths times two noise levels make six configurations; 12 runs of each is 72
# fixes. ``scheduler=None`` (the default) starts a local cluster of ``workers``
# single-threaded processes, sends the runs in batches and closes the cluster at the end; the
# cluster takes a few seconds to start. On a real machine you would give ``workers`` the number
# of cores, or pass a scheduler address to use a cluster (below).

configs = [FixStudy(n_pings=n, depth_noise=noise) for noise in (0.15, 0.5) for n in (3, 10, 20)]
table = run_many(fix_run, configs, runs=12, seed=2026, workers=2, progress=False)
print(f"{len(table)} rows, {table['error'].notna().sum()} failed runs")
print(table.head(8).to_string(index=False))

# %%
# The table has a row per run: ``config_index`` and ``run`` say which run it is, then the
# config's fields, then the result's keys, ``error`` (``None`` where the run succeeded; a run
# that raises becomes a row holding ``"Type: message"`` instead of stopping the study), and the
# seed of the row: ``seed_entropy`` and ``spawn_key``. What the runner did is in
# ``table.attrs["tangraph"]`` (and in a JSON file beside the table when ``output=`` is given):

meta = table.attrs["tangraph"]
for key in ("seed", "runs", "n_configs", "scheduler", "n_workers", "batch_size", "wall_time_s"):
    print(f"{key:<12} {meta[key]}")
print(f"seed scheme  {meta['seed_scheme']}")

# %%
# The summary
# -----------
#
# Group the rows by configuration. An honest covariance has mean NEES 2 (a chi-square of two
# degrees of freedom); an honest 95 % region holds the truth in 95 % of fixes. With 12 runs per
# configuration these are rough figures: the binomial standard error of a coverage of 0.95 over
# 12 fixes is 0.06.

summary = (
    table.groupby(["depth_noise", "n_pings"])
    .agg(
        fixes=("error_m", "size"),
        median_error_m=("error_m", "median"),
        p90_error_m=("error_m", lambda e: e.quantile(0.9)),
        mean_nees=("nees", "mean"),
        coverage_95=("in_region_95", "mean"),
        accepted=("accepted", "mean"),
        sigma_m=("sigma_m", "mean"),
    )
    .round(3)
)
print(summary.to_string())

# %%
# More pings give the match more terrain to hold on to: the error falls with the window length
# and rises with the sounding noise. ``sigma_m``, the fix's estimate of the sounding noise,
# recovers the simulated 0.15 m and 0.5 m. ``accepted`` is the share of fixes the quality flags
# pass (a navigator uses only those); the column ``refused_as`` says why the others were
# flagged. Counted over the whole table:

print(table["refused_as"].replace("", "(accepted)").value_counts().to_string())

# %%
# A 3-ping window is a strip of seabed about 12 m long: its calibrated region is long and
# reaches the edge of the search grid, so the fix is flagged *uninformative*. A precise
# 20-ping fix has a calibrated region of a few tens of square metres, which on the 2 m search
# grid can fall apart into two pieces and be flagged *multimodal*: a finer search step (or a
# region traced below the grid step) would keep more of them. A study like this one is how
# such a limitation is found. The figure shows every fix's error by configuration.

fig, ax = plt.subplots(figsize=(8, 4.2), layout="constrained")
labels = []
for k, ((noise, n_pings), group) in enumerate(table.groupby(["depth_noise", "n_pings"])):
    x = k + np.random.default_rng(k).uniform(-0.15, 0.15, len(group))  # jitter for the eye only
    ax.plot(x, group["error_m"], "o", color="C0" if noise < 0.3 else "C3", alpha=0.7)
    ax.plot([k - 0.3, k + 0.3], [group["error_m"].median()] * 2, "k-", lw=2)
    labels.append(f"{n_pings} pings\n{noise} m")
ax.set_xticks(range(len(labels)), labels)
ax.set_yscale("log")
ax.set_ylabel("fix error (m)")
ax.set_title(f"{len(table)} seeded fixes: window length and sounding noise (bar: median)")
plt.show()

# %%
# Every row can be made again
# ---------------------------
#
# A run's generator depends only on ``(seed, config_index, run)``: not on the number of workers,
# the batches or the order in which the runs finished. :func:`~tangraph.experiments.rerun`
# re-creates one run in this process, which is how a strange row is debugged:

row = table.loc[table["error_m"].idxmax()]
again = rerun(fix_run, configs[row.config_index], seed=2026, config_index=row.config_index, run=row.run)
print(f"worst fix: config {row.config_index}, run {row.run}: error {row.error_m:.3f} m; "
      f"rerun here: {again['error_m']:.3f} m")

# %%
# For the same reason the study extended to more runs keeps its first rows, and a run in this
# process (``scheduler="synchronous"``, handy with a debugger) gives the same numbers as one on
# the workers. Check it on the first configuration:

serial = run_many(fix_run, configs[:1], runs=3, seed=2026, scheduler="synchronous", progress=False)
print("same errors serially:", np.allclose(serial["error_m"], table["error_m"].iloc[:3]))

# %%
# On a cluster
# ------------
#
# Nothing changes but the ``scheduler``: a ``dask scheduler`` started on one machine and
# ``dask worker tcp://HOST:8786`` on the others (with tangraph installed on each), then::
#
#     table = run_many(fix_run, configs, runs=1000, seed=2026,
#                      scheduler="tcp://HOST:8786", output="fixes.csv")
#
# ``output=`` writes the table (CSV or Parquet) and its metadata atomically. The studies of the
# papers wrap this in a ``run.py`` and run as ``tangraph experiment NAME --workers N`` (see
# :doc:`/cli`).

# sphinx_gallery_thumbnail_number = 1
