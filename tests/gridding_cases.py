"""Surveys to grid, shared by the gridding tests (tangraph.gridding_surveys, gridding_files and
maps.gridding_error) and the ``maps grid`` command's: a smooth map and lawnmower surveys
simulated on it, single-beam surveys whose soundings lie at their poses, scattered soundings
of a plane, and lines placed by reference tracks off the truth."""

from __future__ import annotations

import dataclasses

import numpy as np

from tangraph.maps import BathymetryMap
from tangraph.sim.scenario import load_scenario, simulate
from tangraph.survey import Survey

SIGMA = 0.5  # sounding noise (m) of the simulated surveys
CRS = "EPSG:32633"


def smooth_map(cell=5.0) -> BathymetryMap:
    north = east = np.arange(0, 600.0, cell)
    nn, ee = np.meshgrid(north, east, indexing="ij")
    depth = 40 + 2 * np.sin(2 * np.pi * nn / 400) * np.cos(2 * np.pi * ee / 500)
    return BathymetryMap(north, east, depth, crs=CRS, origin=(5.8e6, 4.0e5), name="smooth")


def simulated_survey(bathymetry: BathymetryMap, seed=1, **sonar) -> Survey:
    scenario = load_scenario("han2020")
    quiet = dataclasses.replace(scenario.sonar, ping_rate=1.0, depth_noise=SIGMA, range_noise=0.0,
                                tide=0.0, **sonar)
    scenario = dataclasses.replace(
        scenario, sonar=quiet, vehicle_depth=20.0,
        trajectory={"kind": "lawnmower", "origin": [100.0, 100.0], "heading_deg": 0.0,
                    "line_length": 300.0, "line_spacing": 30.0, "n_lines": 4, "speed": 2.0},
    )
    return simulate(scenario, rng=np.random.default_rng(seed), bathymetry=bathymetry, seed=seed)


def nadir_survey(points, *, origin, crs=CRS, truth=True, datum=None, start=0.0) -> Survey:
    """A single-beam survey whose soundings lie exactly at its poses, a ping a second from
    ``start`` (s: another survey of the same points is another time)."""
    k = len(points)
    pose = np.column_stack([points[:, 0], points[:, 1], np.zeros(k)])
    meta = {"crs": crs, "origin": list(origin)}
    if datum is not None:
        meta["vertical_datum"] = datum
    return Survey(time=start + np.arange(k, dtype=float), dr_pose=pose + 3.0, vehicle_depth=np.zeros(k),
                  beam_forward=np.zeros((k, 1)), beam_starboard=np.zeros((k, 1)),
                  beam_depth=points[:, 2:3], true_pose=pose if truth else None, meta=meta)


def random_soundings(seed=0, n=3000):
    rng = np.random.default_rng(seed)
    north, east = rng.uniform(0, 200, (2, n))
    return np.column_stack([north, east, 30 + 0.05 * north + rng.normal(0, 0.1, n)])


def _plane_survey(offset_std: float, seed: int = 0, n_lines: int = 12, north_slope: float = 0.1):
    """Lines 10 m apart running east over the plane ``30 + north_slope n + 0.05 e``, each placed
    by a reference track off the truth by its own constant offset of std ``offset_std`` per axis."""
    from tangraph.survey import Survey

    rng = np.random.default_rng(seed)
    east = np.arange(0.0, 200.0, 1.0)
    surveys = []
    for line in range(n_lines):
        truth = np.column_stack([np.full(east.size, 10.0 * line), east, np.full(east.size, np.pi / 2)])
        placed = truth.copy()
        placed[:, :2] += offset_std * rng.standard_normal(2)
        starboard = np.tile([-2.0, 0.0, 2.0], (east.size, 1))
        n_true = truth[:, :1] - starboard  # heading east: starboard is south
        depth = 30.0 + north_slope * n_true + 0.05 * truth[:, 1:2]
        surveys.append(Survey(time=1000.0 * line + east, dr_pose=placed, vehicle_depth=np.zeros(east.size),
                              beam_forward=np.zeros((east.size, 3)), beam_starboard=starboard,
                              beam_depth=depth, true_pose=placed))
    return surveys
