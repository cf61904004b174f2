"""Speed of the map-aware posterior Cramér-Rao bound (what a realistic-map study run pays first).

    ./run bench   (or: python benchmarks/bench_crb.py [--scenarios NAME ...]);
    one thread: NUMBA_NUM_THREADS and OMP_NUM_THREADS default to 1.

Every run of ``experiments/graph_vs_filters`` on a realistic map computes four bounds of its
survey (smoother and filter, with the model's and with the simulated sounding noise), each
with the map's error as a Gaussian-Markov field solved sparsely with the track
(:mod:`tangraph.eval.field_bound`). Measured in one run, as CPU time of this process (one call
after a warm-up call), for one simulated survey of each scenario (seed 1):

- the bound with the map taken as the truth (the prior map without its error: a Kalman filter
  and RTS smoother over the linearised model), the reference;
- the map-aware smoother and filter bounds, on the field's nodes near the footprints
  (:func:`tangraph.eval.map_field.map_error_field` with ``trim=True``, as the bound solves it)
  and on every node of the footprints' bounding box (``trim=False``);
- one PF run of the same survey (1000 particles), to put the bound's cost beside a method's.

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
    parser.add_argument("--scenarios", nargs="+", default=["demo-map-error", "wang2019-map-error"],
                        help="realistic-map scenarios (han2020-map-error takes minutes)")
    args = parser.parse_args(argv)

    for name in args.scenarios:
        _scenario(name)


def _scenario(name: str) -> None:
    import tangraph.eval.map_field as map_field
    from tangraph.eval import posterior_crb
    from tangraph.filters import default_config, run_filter
    from tangraph.sensors import NavigationModel
    from tangraph.sim.scenario import load_scenario, simulate_run

    run = simulate_run(load_scenario(name), rng=np.random.default_rng(1))
    survey, prior = run.survey, run.bathymetry
    model = NavigationModel.from_survey(survey)
    perfect = prior.replace(depth_std=None, correlation_length=None)
    reference = {kind: best_cpu(lambda kind=kind: posterior_crb(survey, perfect, model, kind=kind), 1)
                 for kind in ("smoother", "filter")}
    print(f"{name}: {survey.n_pings} pings x {survey.beam_depth.shape[1]} beams (CPU s, ratio to the "
          "bound with the map as the truth)")
    original = map_field.map_error_field
    for kind in ("smoother", "filter"):
        cells = []
        for trim in (True, False):
            map_field.map_error_field = lambda *a, _trim=trim, **k: original(*a, **{**k, "trim": _trim})
            try:
                seconds = best_cpu(lambda kind=kind: posterior_crb(survey, prior, model, kind=kind), 1)
                nodes = posterior_crb(survey, prior, model, kind=kind).field_nodes
            finally:
                map_field.map_error_field = original
            cells.append(f"{'near the footprints' if trim else 'the whole box'} {seconds:7.2f} s "
                         f"({seconds / reference[kind]:6.0f}x, {nodes} nodes)")
        print(f"   {kind:8s} the map as the truth {reference[kind]:6.3f} s; the map's error: "
              + "; ".join(cells))
    t0 = time.process_time()
    run_filter("pf", survey, prior, default_config("pf"), model=model, rng=np.random.default_rng(3))
    print(f"   one PF run of the survey: {time.process_time() - t0:.1f} s")


if __name__ == "__main__":
    main()
