"""Speed of the point-mass filter against the 1000-particle bootstrap PF, at their accuracy.

    ./run bench   (or: python benchmarks/bench_pmf.py [--repeat R] [--scenario NAME] [--seed S]);
    one thread: NUMBA_NUM_THREADS and OMP_NUM_THREADS default to 1.

One survey of a scenario (default ``demo``: 1256 pings of 101 soundings) navigated by the PF with
1000 particles (the reference, seeded) and by the PMF at its default (41 x 41 points, the calibration per
point), at 31 x 31, and with its calibration bank (3 x 3 nodes of a grid each) at 31 x 31 and
coarser grids. Printed: CPU ms per ping (best of R after a warm-up, this process), its
ratio to the PF's measured in the same run, and each run's RMSE and final NEES (the goal: the
PMF's time per ping at most the PF's at equal or better RMSE).

2. Relocalisation: one ping of 101 soundings weighed on the global grid (201 x 201 points) over a
   5 x 5 km fractal map of 10 m cells (the goal: under 1 s), against one ping of the default
   grid. Nothing is asserted.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
from pathlib import Path

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np
from _timing import best_cpu

from tangraph.eval import track_metrics
from tangraph.filters import PFConfig, PMFConfig, run_filter
from tangraph.sensors import NavigationModel, slope_moment

CONFIGS = {
    "pmf 41 x 41, per point": PMFConfig(),
    "pmf 31 x 31, per point": PMFConfig(grid_points=31),
    "pmf 31 x 31, 3 x 3 nodes": PMFConfig(grid_points=31, calibration="bank"),
    "pmf 21 x 21, 3 x 3 nodes": PMFConfig(grid_points=21, calibration="bank"),
    "pmf 15 x 15, 3 x 3 nodes": PMFConfig(grid_points=15, calibration="bank"),
}


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--scenario", default="demo")
    parser.add_argument("--seed", type=int, default=7)
    args = parser.parse_args(argv)
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "experiments" / "graph_vs_filters"))
    from run import _survey  # the study's scenario with the demo's drifting DR

    run = _survey({"scenario": args.scenario, "dr": "demo"}, np.random.default_rng(args.seed))
    survey, bathymetry = run.survey, run.bathymetry
    model = NavigationModel.from_survey(survey)
    b = survey.beam_depth.shape[1]
    print(f"PMF vs PF on {args.scenario} (seed {args.seed}): {survey.n_pings} pings of {b} soundings; "
          f"CPU ms per ping, best of {args.repeat}")
    tracks = {}

    def run(name, method, config):
        def go():
            tracks[name] = run_filter(method, survey, bathymetry, config, model=model,
                                      rng=np.random.default_rng(1))
        return 1e3 * best_cpu(go, args.repeat) / survey.n_pings

    reference = run("pf 1000 particles", "pf", PFConfig(n_particles=1000))
    rows = [("pf 1000 particles", reference)]
    rows += [(name, run(name, "pmf", config)) for name, config in CONFIGS.items()]
    print(f"   {'':28s} {'ms/ping':>8s} {'ratio':>6s} {'RMSE m':>7s} {'final NEES':>10s}")
    for name, ms in rows:
        m = track_metrics(tracks[name], survey.true_pose)
        print(f"   {name:28s} {ms:8.2f} {ms / reference:6.2f} {m['rmse']:7.2f} {m['final_nees']:10.2f}")
    relocalisation(args.repeat)


def relocalisation(repeat: int) -> None:
    from tangraph.filters import pmf
    from tangraph.filters.model import FilterModel, Ping
    from tangraph.maps import fractal

    chart = fractal((501, 501), 10.0, rng=np.random.default_rng(0), relief=10.0, mean_depth=60.0)
    model = NavigationModel(sounding_std=0.3)
    filter_model = FilterModel.from_model(model, chart)
    config = PMFConfig()
    grid = pmf._Grid(config, config.min_spacing)
    across = np.linspace(-40.0, 40.0, 101)
    ping = Ping(1, np.array([2.0, 0.0]), np.column_stack([np.zeros(101), across]),
                chart.depth_at(np.full(101, 2500.0), 2500.0 + across), dt=1.0)
    slope = slope_moment(chart)
    start = pmf._start(model, np.array([2500.0, 2500.0]), grid, config)

    def weigh(state):
        return lambda: pmf._update(dataclasses.replace(state), ping, filter_model, slope)

    def global_grid():
        state = pmf._relocalised(start, chart, model, config, np.array([2500.0, 2500.0]))
        weigh(state)()

    small = best_cpu(weigh(start), repeat)
    large = best_cpu(global_grid, repeat)
    print(f"2. one ping of 101 soundings on a 5 x 5 km map (CPU ms, best of {repeat})")
    name = f"default grid ({config.grid_points} x {config.grid_points} points)"
    print(f"   {name:41s} {1e3 * small:8.1f} ms  1.00")
    print(f"   global grid (201 x 201 points, built too) {1e3 * large:8.1f} ms  {large / small:.1f}")


if __name__ == "__main__":
    main()
