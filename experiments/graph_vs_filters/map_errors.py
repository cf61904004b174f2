"""How the prior map of a realistic-map scenario errs against its simulated seafloor.

    python experiments/graph_vs_filters/map_errors.py demo-map-error wang2019-map-error --runs 2

For the first ``--runs`` surveys of each scenario (the study's seed 6 and its config index),
over the map's cells with data: the RMS error, that in cells the earlier survey measured and in
cells its gap fill gave a depth, each also in the map's stated stds (``z``), and the RMS of the
error's mean along each column of cells (north: the earlier survey's lines run along the
longer side of its area): a part of the error the same all along a line, which a vehicle that
runs along it takes for a position offset.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import run as study  # the study's own surveys, so the maps are the runs' maps

from tangraph.experiments import run_rng


def map_errors(scenario: str, index: int, run: int) -> dict[str, float]:
    """The figures of the module docstring for one run's prior map."""
    world = study._survey({"scenario": scenario, "dr": "demo"}, run_rng(6, index, run))
    prior = world.bathymetry
    error = world.world.map_error()
    z = error / prior.depth_std
    surveyed = world.world.prior_survey
    north, east = (np.ravel(a) for a in surveyed.footprints(surveyed.true_pose))
    measured = np.zeros(prior.shape, bool)
    row = np.round((north - prior.north[0]) / prior.cell_size[0]).astype(int)
    col = np.round((east - prior.east[0]) / prior.cell_size[1]).astype(int)
    inside = (row >= 0) & (row < prior.shape[0]) & (col >= 0) & (col < prior.shape[1])
    measured[row[inside], col[inside]] = True
    ok = np.isfinite(z)
    rms = lambda a: float(np.sqrt(np.mean(a**2)))  # noqa: E731
    with np.errstate(invalid="ignore"):
        along = np.nanmean(np.where(ok, error, np.nan), axis=0)
    return {"rms": rms(error[ok]), "measured": rms(error[ok & measured]),
            "filled": rms(error[ok & ~measured]), "z_measured": rms(z[ok & measured]),
            "z_filled": rms(z[ok & ~measured]), "along_lines": rms(along[np.isfinite(along)])}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("scenarios", nargs="+")
    parser.add_argument("--runs", type=int, default=2)
    args = parser.parse_args()
    print("| scenario | run | RMS error (m) | measured cells | filled cells | z measured | z filled | "
          "along the lines |")
    print("|---|---|---|---|---|---|---|---|")
    for index, scenario in enumerate(args.scenarios):
        for run in range(args.runs):
            e = map_errors(scenario, index, run)
            print(f"| {scenario} | {run} | {e['rms']:.3f} | {e['measured']:.3f} | {e['filled']:.3f} | "
                  f"{e['z_measured']:.2f} | {e['z_filled']:.2f} | {e['along_lines']:.3f} |")


if __name__ == "__main__":
    main()
