"""Speed of the map-aware terrain measurement (the map's error in the likelihood and in TAP).

    ./run bench   (or: python benchmarks/bench_map_error.py [--repeat R]);
    one thread: NUMBA_NUM_THREADS and OMP_NUM_THREADS default to 1.

The goal: the map-aware likelihood and TAP at most 1.5 x the time per ping of the
likelihood and TAP that took the map as the truth. Measured in one run, as CPU time of this
process (best of R after a warm-up), as ratios:

1. One ping's likelihood for 1000 particles x 101 soundings on the merimbula map (a filter's
   step): the one compiled pass of residual sums the filters' update used to be (the reference),
   the update now with a perfect map (per particle residuals, the sub-cloud means, the exponents
   all one), and with the map's error (per-sounding variances, map variances, exponents from the
   weighted cloud) read at the dead-reckoned footprints and, as the filters do, where the cloud
   puts each sounding (:func:`tangraph.sensors.sounding_map_counts`), and with the local misfit
   scale integrated out on top (the Student-t of
   :mod:`tangraph.sensors.misfit`, through the filters' terrain model, and the scale's update).
2. One TAP fix of a 10-ping window (the demo's multibeam) on the demo-map-error scenario's prior
   map: without and with the map error its soundings share (among themselves for its regions,
   with the survey for its covariance), both with the ping jackknife as the graph calls it.
3. What a run computes once of the whole survey: the per-sounding variances
   (:func:`tangraph.sensors.sounding_variances`) and the map error's counts the filters and the
   graph read where their estimate puts the soundings
   (:func:`tangraph.sensors.sounding_map_counts`), against one PF run of the same survey.

Nothing is asserted.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np
from _timing import best_cpu


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=20)
    args = parser.parse_args(argv)

    from tangraph.filters.belief import model_belief
    from tangraph.filters.likelihood import TerrainLikelihood
    from tangraph.filters.model import FilterModel, survey_pings
    from tangraph.matching import TapConfig, tap_fix, window_patch
    from tangraph.sensors import (
        NavigationModel,
        map_error,
        shared_map_variances,
        sounding_map_counts,
        sounding_variances,
    )
    from tangraph.sim.scenario import load_scenario, simulate_run

    run = simulate_run(load_scenario("demo-map-error"), rng=np.random.default_rng(1))
    survey, prior = run.survey, run.bathymetry
    model = NavigationModel.from_survey(survey)
    perfect_model = model  # the prior map carries its own error; a map without it is the truth
    perfect = prior.replace(depth_std=None, correlation_length=None)

    k = survey.n_pings // 2
    fm = FilterModel.from_model(model, prior)
    belief = model_belief(survey.dr_pose[k, :2], fm, 1000, rng=np.random.default_rng(2))
    ping_error = survey_pings(survey, prior, model)[k]
    ping_plain = survey_pings(survey, perfect, perfect_model)[k]
    like = TerrainLikelihood(prior, model.measurement_std)
    turn = -belief.calibration[:, 1]
    reference = best_cpu(lambda: like.residual_sums(belief.particles, ping_plain.offsets, ping_plain.depths,
                                                    turn=turn), args.repeat)
    plain = best_cpu(lambda: like.ping_update(belief.particles, ping_plain.offsets, ping_plain.depths,
                                              belief.tide, belief.tide_var, turn=turn,
                                              weights=belief.weights, variance=ping_plain.variance,
                                              map_variance=ping_plain.map_variance), args.repeat)
    aware = best_cpu(lambda: like.ping_update(belief.particles, ping_error.offsets, ping_error.depths,
                                              belief.tide, belief.tide_var, turn=turn,
                                              weights=belief.weights, variance=ping_error.variance,
                                              map_variance=ping_error.map_variance), args.repeat)
    heading = belief.calibration[:, 1]
    placed = best_cpu(lambda: fm.terrain.evaluate(belief.particles, belief.tide, belief.tide_var, ping_error,
                                                  heading, weights=belief.weights), args.repeat)
    scaled_model = model.replace(misfit_dof=2.0)
    fm_scaled = FilterModel.from_model(scaled_model, prior)
    scale = fm_scaled.misfit_prior()
    misfit = best_cpu(lambda: fm_scaled.terrain.evaluate(
        belief.particles, belief.tide, belief.tide_var, ping_error, belief.calibration[:, 1],
        weights=belief.weights, scale=scale).scale_after(belief.weights), args.repeat)
    b = ping_error.n_soundings
    print(f"1. one ping, 1000 particles x {b} soundings (CPU ms, ratio to the one-pass residual sums)")
    print(f"   residual sums (the old update's pass) {1e3 * reference:8.3f} ms  1.00")
    print(f"   update, perfect map                  {1e3 * plain:8.3f} ms  {plain / reference:.2f}")
    print(f"   update, the map's error at the DR     {1e3 * aware:8.3f} ms  {aware / reference:.2f}")
    print(f"   update, the map's error where the cloud puts the soundings (the filters') "
          f"{1e3 * placed:8.3f} ms  {placed / reference:.2f}")
    print(f"   update, the map's error, misfit scale {1e3 * misfit:8.3f} ms  {misfit / reference:.2f} "
          f"({misfit / placed:.2f} x the map's error alone)")

    shared, error = shared_map_variances(survey, prior, model), map_error(prior, model)
    config = TapConfig(half_width=30.0)
    end = k
    centre = survey.true_pose[end, :2]
    few = max(3, args.repeat // 4)
    tap_plain = best_cpu(lambda: tap_fix(survey, perfect, end, 10, config, prior=centre), few)
    tap_error = best_cpu(lambda: tap_fix(survey, prior, end, 10, config, prior=centre, shared=shared,
                                         error=error), few)
    n = window_patch(survey, end, 10).n_soundings
    print(f"2. one TAP fix, 10 pings ({n} soundings), +-30 m (the patch laid, searched, judged)")
    print(f"   the map as the truth  {1e3 * tap_plain:8.2f} ms  1.00")
    print(f"   the map's error       {1e3 * tap_error:8.2f} ms  {tap_error / tap_plain:.2f}")

    variances = best_cpu(lambda: sounding_variances(survey, prior, model), 3)
    counted = best_cpu(lambda: sounding_map_counts(survey, prior, model), 3)
    from tangraph.filters import default_config, run_filter

    t0 = time.process_time()
    run_filter("pf", survey, prior, default_config("pf"), model=model, rng=np.random.default_rng(3))
    pf = time.process_time() - t0
    print(f"3. the survey's per-sounding variances ({survey.n_pings} pings): {variances:.2f} s, "
          f"{variances / pf:.2f} of one PF run ({pf:.1f} s); its map error counts: {counted:.2f} s, "
          f"{counted / pf:.2f}")


if __name__ == "__main__":
    main()
