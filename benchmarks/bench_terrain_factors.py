"""Speed of the batch smoother with every sounding as a terrain factor, against the TAP-fix smoother.

    python benchmarks/bench_terrain_factors.py [--sizes 10000 100000] [--beams 10] [--field]

A lawnmower of N pings (one per second at 2 m/s, lines 60 m apart) over a fractal map, 10
soundings per ping across a 60 m swath with 0.2 m noise, a drifting DR (+2 % speed, 2 deg
heading, white noise): :func:`tangraph.graph.smooth_survey` with ``smoother_terrain="fixes"``
(TAP fixes, the default) and ``"soundings"`` (the fixes' solve, then every sounding), timed in
the same run; prints both times, their ratio (target: at most 3 at 10^5 pings), the time of
the terrain solve alone and both RMSEs. With ``--field`` the map states an error (0.2 m over
30 m; the soundings see the map itself) and ``"field"`` (the map's error estimated with the
track) is timed too, against the same fixes' smoother. Nothing is asserted.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

from tangraph.graph import GraphConfig, smooth_survey
from tangraph.maps import fractal
from tangraph.sensors import DeadReckoningModel, NavigationModel, simulate_dead_reckoning
from tangraph.survey import Survey


def survey_of(n: int, beams: int, rng: np.random.Generator):
    line = 500  # pings per line: 1 km
    lines = int(np.ceil(n / line))
    side = max(1200.0, 60.0 * lines + 200.0)
    bathymetry = fractal((int(side / 5) + 1, int(side / 5) + 1), 5.0, rng=rng, relief=20.0, mean_depth=80.0)
    k = np.arange(n)
    leg, step = k // line, k % line
    east = 100.0 + np.where(leg % 2 == 0, step, line - 1 - step) * 2.0
    north = 100.0 + 60.0 * leg
    heading = np.where(leg % 2 == 0, np.pi / 2, -np.pi / 2)
    truth = np.column_stack([north, east, heading])
    time_s = k.astype(float)
    dr_model = DeadReckoningModel(speed_scale=0.02, heading_bias=np.deg2rad(2.0), speed_noise=0.02,
                                  heading_noise=np.deg2rad(0.05))
    dr = simulate_dead_reckoning(time_s, truth, dr_model, rng=rng)
    starboard = np.tile(np.linspace(-30.0, 30.0, beams), (n, 1))
    survey = Survey(time=time_s, dr_pose=dr.pose, vehicle_depth=np.zeros(n),
                    beam_forward=np.zeros((n, beams)), beam_starboard=starboard,
                    beam_depth=np.zeros((n, beams)), true_pose=truth)
    north_b, east_b = survey.footprints(truth)
    depth = bathymetry.depth_at(north_b, east_b) + 0.2 * rng.standard_normal((n, beams))
    model = NavigationModel.from_dead_reckoning(dr_model, sounding_std=0.3, tide_std=1.0,
                                                initial_position_std=10.0)
    return survey.replace(beam_depth=depth), bathymetry, model


def rmse(track, truth) -> float:
    return float(np.sqrt(np.mean(np.sum((track.pose[:, :2] - truth[:, :2]) ** 2, axis=1))))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[10_000])
    parser.add_argument("--beams", type=int, default=10)
    parser.add_argument("--field", action="store_true", help="a map that states its error; time 'field' too")
    args = parser.parse_args()
    for n in args.sizes:
        survey, bathymetry, model = survey_of(n, args.beams, np.random.default_rng(n))
        if args.field:
            bathymetry = bathymetry.replace(depth_std=np.full(bathymetry.shape, 0.2), correlation_length=30.0)
        out = {}
        for terrain in ("fixes", "soundings", *(("field",) if args.field else ())):
            t0 = time.perf_counter()
            config = GraphConfig().replace(smoother_terrain=terrain)
            track = smooth_survey(survey, bathymetry, config, model=model)
            out[terrain] = (time.perf_counter() - t0, rmse(track, survey.true_pose), track)
        fixes, soundings = out["fixes"], out["soundings"]
        solve = soundings[2].timings.get("solve", float("nan"))
        print(f"{n} pings x {args.beams} beams: fixes {fixes[0]:.1f} s (RMSE {fixes[1]:.2f} m), "
              f"soundings {soundings[0]:.1f} s (RMSE {soundings[1]:.2f} m; its last solve {solve:.1f} s), "
              f"ratio {soundings[0] / fixes[0]:.2f}")
        if args.field:
            seconds, error, track = out["field"]
            print(f"    field {seconds:.1f} s (RMSE {error:.2f} m; its last solve "
                  f"{track.timings.get('solve', float('nan')):.1f} s, marginals "
                  f"{track.timings.get('marginals', float('nan')):.1f} s), ratio {seconds / fixes[0]:.2f}")


if __name__ == "__main__":
    main()
