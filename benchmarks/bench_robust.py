"""What robustness costs: the ping jackknife of a TAP fix, and the batch smoother's robust solve.

    python benchmarks/bench_robust.py [--repeat R] [--seed S]

One ``demo`` survey (1256 pings of a 101-beam multibeam on the Merimbula map) is simulated with
seed S. Fix: every TAP window of the survey made around the truth (20 pings, half-width 50 m,
half-cell steps) with ``TapConfig(jackknife=True)`` and without, best of R. Smoother:
:func:`tangraph.graph.smooth_survey` with ``robust_solve="gnc"`` and ``"none"`` (each with the
same forward pass), best of R, with its RMSE against the truth. Times in seconds and their
ratios in the same run, on one thread. Nothing is asserted.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

from tangraph.eval import track_metrics
from tangraph.graph import GraphConfig, smooth_survey
from tangraph.graph.fixes import make_fix
from tangraph.graph.keyposes import fix_windows
from tangraph.maps import load_any
from tangraph.matching import MatchingError, TapConfig
from tangraph.sensors import NavigationModel
from tangraph.sim.scenario import load_scenario, simulate


def best(fn, repeat: int) -> tuple[float, object]:
    times, out = [], None
    for _ in range(repeat):
        started = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - started)
    return min(times), out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--seed", type=int, default=1)
    args = parser.parse_args(argv)
    scenario = load_scenario("demo")
    bathymetry = load_any(scenario.map)
    survey = simulate(scenario, rng=np.random.default_rng(args.seed), bathymetry=bathymetry)
    model = NavigationModel.from_survey(survey)
    firsts, ends, _ = fix_windows(survey.n_pings, 20, 10, None)

    def fixes(jackknife: bool) -> int:
        config = GraphConfig().replace(tap=TapConfig(jackknife=jackknife))
        made = 0
        for first, end in zip(firsts, ends, strict=True):
            try:
                make_fix(survey, bathymetry, int(end), config, survey.true_pose[end, :2], 50.0,
                         poses=survey.true_pose[first : end + 1], first=int(first))
                made += 1
            except MatchingError:
                pass
        return made

    plain, made = best(lambda: fixes(False), args.repeat)
    jack, _ = best(lambda: fixes(True), args.repeat)
    print(f"TAP fixes ({made} windows): {plain:.2f} s plain, {jack:.2f} s with the ping jackknife "
          f"({jack / plain:.2f} x)")
    rows = {}
    for solve in ("none", "gnc"):
        config = GraphConfig().replace(robust_solve=solve)
        seconds, track = best(lambda c=config: smooth_survey(survey, bathymetry, c, model=model), args.repeat)
        rows[solve] = seconds
        forward = track.timings["forward_pass"]
        rmse = track_metrics(track, survey.true_pose)["rmse"]
        print(f"smoother, robust_solve={solve!r}: {seconds:.2f} s ({forward:.2f} s forward pass), "
              f"RMSE {rmse:.2f} m")
    print(f"GNC smoother / plain smoother: {rows['gnc'] / rows['none']:.2f} x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
