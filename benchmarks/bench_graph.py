"""Speed of the factor graph (tangraph.graph): online iSAM2 per key pose, batch smoother on long chains.

    python benchmarks/bench_graph.py [--online-only | --batch-only] [--sizes 100000 300000] [--long 100000]
    python benchmarks/bench_graph.py --tracking [--seeds 7 8 9] [--tide-drift 0.2 170]

Online: the chen2022 scenario (100 000 s at 1 m/s, a single-beam sounding every 100 s, on the
500 m polar chart), navigated by :func:`tangraph.graph.navigate_online`; prints the mean and p99
time of an iSAM2 key-pose update (update plus the latest key's marginal), the same for whole
steps (TAP included), and the ratio of the mean update time over the last 10 % of the key poses
to the first 10 % (targets: p99 <= 10 ms, ratio <= 2). Batch: a synthetic chain of N poses (1 m
steps with a slight turn, odometry plus a position prior every 100 poses) solved by
:func:`tangraph.graph.smooth_pose_graph` (LM, METIS), with and without the marginal covariance of
every pose (target: 100 000 poses in <= 15 s; 300 000 without a crash). ``--long N``: the
navigator over N key poses with a given fix every 10 (no TAP), to show the update time stays
flat as the chain grows, and a plain GTSAM ``IncrementalFixedLagSmoother`` loop on the same
chain with the fixes the navigator used, in the same run (target: tangraph's mean update at most
2 x the plain loop's). ``--tracking``: the online graph that tracks on every sounding after a
point-mass acquisition (``terrain = "soundings"``, ``acquire = "pmf"``) on ``demo`` surveys, per
ping (mean, p99, max of a whole step, before and after the hand-over), against the point-mass
filter and the TAP graph on the same surveys, and its iSAM2 updates against the plain loop on
its key chain, all in the same run (targets: p99 step <= 10 ms, mean update <= 2 x the plain
loop's); with ``--tide-drift STD TIME`` the surveys' depths drift (m, s) and every estimator's
model says so, the tracking graph then holding a tide per key pose
(:mod:`tangraph.graph.online_tide`). Nothing is asserted.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time
from types import SimpleNamespace

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np

from tangraph.graph import GraphConfig, GraphNavigator, PoseGraph, smooth_pose_graph
from tangraph.maps import load_any
from tangraph.sensors import NavigationModel
from tangraph.sim.scenario import load_scenario, simulate


def online() -> None:
    scenario = load_scenario("chen2022")
    bathymetry = load_any(scenario.map)
    t0 = time.perf_counter()
    survey = simulate(scenario, rng=np.random.default_rng(scenario.seed), bathymetry=bathymetry,
                      seed=scenario.seed)
    print(f"chen2022: {survey.n_pings} pings over {survey.time[-1]:.0f} s, simulated in "
          f"{time.perf_counter() - t0:.1f} s")
    config = GraphConfig().replace(n_pings=10, key_interval=60.0)
    nav = GraphNavigator(survey, bathymetry, config).run()
    track = nav.track()
    updates = np.asarray(nav.update_times) * 1e3
    tenth = max(updates.size // 10, 1)
    ratio = updates[-tenth:].mean() / updates[:tenth].mean()
    err = np.hypot(*(track.pose[:, :2] - survey.true_pose[:, :2]).T)
    dr = np.hypot(*(survey.dr_pose[:, :2] - survey.true_pose[:, :2]).T)
    print(f"online isam2: {len(nav.graph.keys)} key poses, {track.meta['n_fixes_accepted']} fixes accepted, "
          f"{track.meta['n_fixes_rejected']} refused")
    print(f"  key-pose update   mean {updates.mean():.2f} ms   p99 {np.percentile(updates, 99):.2f} ms   "
          f"last 10 % / first 10 % = {ratio:.2f}")
    timings = track.timings
    print(f"  whole step        mean {1e3 * timings['per_step']:.2f} ms   "
          f"p99 {1e3 * timings['per_step_p99']:.2f} ms   (TAP {timings['tap_total']:.1f} s in all)")
    print(f"  RMSE  DR {np.sqrt(np.mean(dr**2)):.0f} m   isam2 {np.sqrt(np.mean(err**2)):.0f} m")


def long_online(n: int) -> None:
    """GraphNavigator over ``n`` pings at 1 Hz, every ping a key pose, a fix every 10 pings: the
    TAP is left out (each fix is the truth plus noise, made from one real fix as a template), so
    the figures are those of the graph alone."""
    import dataclasses

    from tangraph.maps import fractal
    from tangraph.matching import TapConfig, tap_fix
    from tangraph.sensors import DeadReckoningModel, simulate_dead_reckoning
    from tangraph.survey import Survey

    rng = np.random.default_rng(2)
    t = np.arange(n, dtype=float)
    psi = 0.3 + 0.2 * np.sin(t / 2000.0)
    step = np.column_stack([np.cos(psi), np.sin(psi)])
    truth = np.column_stack([200.0 + np.cumsum(step, axis=0) - step[0], psi])
    model = DeadReckoningModel(heading_bias=float(np.deg2rad(1.0)), speed_noise=0.05, heading_walk=1e-5)
    dr = simulate_dead_reckoning(t, truth, model, rng=rng)
    beams = np.linspace(-30.0, 30.0, 20)[None, :].repeat(n, axis=0)
    bathymetry = fractal((200, 200), 5.0, rng=rng, relief=15.0)
    depth = np.full((n, 20), 60.0)
    survey = Survey(time=t, dr_pose=dr.pose, vehicle_depth=np.zeros(n), beam_forward=0 * beams,
                    beam_starboard=beams, beam_depth=depth, true_pose=truth)
    window = slice(0, 10)
    north, east = survey.footprints(truth)
    measured = bathymetry.depth_at(north[window], east[window]) + rng.normal(0.0, 0.1, (10, 20))
    first = Survey(time=t[window], dr_pose=truth[window], vehicle_depth=np.zeros(10),
                   beam_forward=0 * beams[window], beam_starboard=beams[window], beam_depth=measured)
    template = tap_fix(first, bathymetry, 9, 10, TapConfig(half_width=20.0), prior=truth[9, :2])
    assert template.accepted, template.quality.reasons
    config = GraphConfig().replace(key_interval=1.0, n_pings=10)
    nav = GraphNavigator(survey, bathymetry, config, model=NavigationModel.from_dead_reckoning(model))
    cov = np.diag([4.0, 4.0])
    t0 = time.perf_counter()
    for k in range(n):
        fix = None
        if k % 10 == 9:
            fix = dataclasses.replace(template, index=k, first=k - 9, covariance=cov,
                                      position=truth[k, :2] + rng.normal(0.0, 2.0, 2))
        nav.step(fix=fix)
    total = time.perf_counter() - t0
    updates = np.asarray(nav.update_times) * 1e3
    tenth = updates.size // 10
    accepted = sum(f.accepted for f in nav.fixes)
    print(f"online, {n} key poses, {accepted} fixes (graph only): {total:.1f} s; "
          f"update mean {updates.mean():.2f} ms, p99 {np.percentile(updates, 99):.2f} ms, "
          f"last 10 % / first 10 % = {updates[-tenth:].mean() / updates[:tenth].mean():.2f}")
    used = {f.index: (f.position, f.covariance) for f in nav.fixes if f.accepted}
    # the navigator keeps between isam_window and twice as many key poses: the plain loop 1.5 times
    plain = plain_loop(survey, used, lag=1.5 * (config.online.isam_window or n))
    print(f"  plain IncrementalFixedLagSmoother loop on the same chain and fixes: update mean "
          f"{plain.mean():.2f} ms, p99 {np.percentile(plain, 99):.2f} ms; tangraph / plain: mean "
          f"{updates.mean() / plain.mean():.2f}, p99 "
          f"{np.percentile(updates, 99) / np.percentile(plain, 99):.2f}")


def tracking(seeds: list[int], drift: list[float] | None = None) -> None:
    """Per-ping times of the tracking graph against the point-mass filter, the TAP graph and the
    plain iSAM2 loop (see the module docstring), on one ``demo`` survey per seed (``drift``: the
    tide's drift std and time, m and s)."""
    from tangraph.filters.pmf import point_mass_filter

    scenario = load_scenario("demo")
    if drift:
        scenario = dataclasses.replace(scenario, sonar=dataclasses.replace(
            scenario.sonar, tide_drift_std=drift[0], tide_drift_time=drift[1]))
    bathymetry = load_any(scenario.map)
    config = GraphConfig().replace(terrain="soundings", acquire="pmf")
    rows = []
    for seed in seeds:
        survey = simulate(scenario, rng=np.random.default_rng(seed), bathymetry=bathymetry)
        model = NavigationModel.from_survey(survey)
        nav = GraphNavigator(survey, bathymetry, config, model=model).run()
        steps = np.asarray(nav.step_times) * 1e3
        handover = nav.acquisition.handover if nav.acquisition.handover is not None else survey.n_pings
        updates = np.asarray(nav.update_times) * 1e3
        keys = np.asarray(nav.graph.keys)
        chain = SimpleNamespace(time=survey.time[keys], dr_pose=survey.dr_pose[keys], n_pings=keys.size)
        plain = plain_loop(chain, {}, lag=float(nav._lag()))
        t0 = time.perf_counter()
        filtered = point_mass_filter(survey, bathymetry, model=model)
        pmf_ms = (time.perf_counter() - t0) * 1e3 / survey.n_pings
        t0 = time.perf_counter()
        tap = GraphNavigator(survey, bathymetry, GraphConfig(), model=model).run()
        tap_ms = (time.perf_counter() - t0) * 1e3 / survey.n_pings
        error = {name: float(np.sqrt(np.mean(np.sum((t.pose[:, :2] - survey.true_pose[:, :2]) ** 2, 1))))
                 for name, t in (("tracking", nav.track()), ("pmf", filtered), ("tap", tap.track()))}
        rows.append((steps, handover, updates, plain, pmf_ms, tap_ms, error))
        print(f"demo seed {seed}: {survey.n_pings} pings, hand-over at {handover}, {keys.size} key poses")
        print(f"  tracking graph  step mean {steps.mean():.2f} ms  p99 {np.percentile(steps, 99):.2f} ms  "
              f"max {steps.max():.1f} ms  (acquiring: mean {steps[:handover].mean():.2f} ms, p99 "
              f"{np.percentile(steps[:handover], 99):.2f}; tracking: mean {steps[handover:].mean():.2f} ms, "
              f"p99 {np.percentile(steps[handover:], 99):.2f})")
        print(f"  per ping: point-mass filter {pmf_ms:.2f} ms, TAP graph {tap_ms:.2f} ms; "
              f"tracking / pmf {steps.mean() / pmf_ms:.2f}, / TAP {steps.mean() / tap_ms:.2f}")
        print(f"  iSAM2 update mean {updates.mean():.2f} ms (plain loop on its keys {plain.mean():.2f} ms: "
              f"ratio {updates.mean() / plain.mean():.2f}); RMSE tracking {error['tracking']:.2f} m, "
              f"pmf {error['pmf']:.2f} m, TAP {error['tap']:.2f} m")
    steps = np.concatenate([r[0] for r in rows])
    print(f"all seeds: step mean {steps.mean():.2f} ms, p99 {np.percentile(steps, 99):.2f} ms; "
          f"tracking / pmf {np.mean([r[0].mean() / r[4] for r in rows]):.2f}; update / plain loop "
          f"{np.mean([r[2].mean() / r[3].mean() for r in rows]):.2f}")


def plain_loop(survey, fixes: dict, lag: float) -> np.ndarray:
    """GTSAM's ``IncrementalFixedLagSmoother`` on its own (ms per key pose): the survey's DR
    increments as ``BetweenFactorPose2``, the fixes the navigator used as translation priors, the
    key poses of the last ``lag`` seconds kept, every update followed by the newest pose's estimate and
    marginal covariance, as a navigator reports them (no calibration variable, no robust kernel,
    no fix policy: what tangraph's online graph adds is what the ratio measures)."""
    import gtsam

    params = gtsam.ISAM2Params()
    params.setRelinearizeThreshold(0.005)
    smoother = gtsam.IncrementalFixedLagSmoother(float(lag), params)
    pose = survey.dr_pose
    odometry = gtsam.noiseModel.Diagonal.Sigmas(np.array([0.05, 0.05, 1e-3]))
    times = []
    for k in range(survey.n_pings):
        factors, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
        stamps = gtsam.FixedLagSmootherKeyTimestampMap()
        here = gtsam.Pose2(*pose[k])
        values.insert(k, here)
        stamps.insert((k, float(survey.time[k])))
        if k == 0:
            start = gtsam.noiseModel.Diagonal.Sigmas(np.array([5.0, 5.0, 0.1]))
            factors.add(gtsam.PriorFactorPose2(0, here, start))
        else:
            step = gtsam.Pose2(*pose[k - 1]).between(here)
            factors.add(gtsam.BetweenFactorPose2(k - 1, k, step, odometry))
        if k in fixes:
            position, cov = fixes[k]
            factors.add(gtsam.PoseTranslationPrior2D(k, np.asarray(position, float),
                                                     gtsam.noiseModel.Gaussian.Covariance(np.asarray(cov))))
        t0 = time.perf_counter()
        smoother.update(factors, values, stamps)
        isam = smoother.getISAM2()
        isam.calculateEstimatePose2(k)
        isam.marginalCovariance(k)
        times.append(time.perf_counter() - t0)
    return np.asarray(times) * 1e3


def chain(n: int, prior_every: int = 100, calibrated: bool = False) -> PoseGraph:
    """A synthetic chain: 1 m steps turning 0.0001 rad each, position priors every ``prior_every``;
    ``calibrated``: with the DR's calibration variable (scale and heading bias) joined to every fix."""
    graph = PoseGraph(calibration_std=np.array([0.02, 0.035]) if calibrated else None)
    step = np.array([1.0, 0.0, 1e-4])
    odo_cov = np.diag([0.01, 0.01, 1e-6])
    pose = np.zeros(3)
    graph.add_pose(0, 0.0, pose)
    graph.add_start(0, pose, 1.0, 0.1)
    rng = np.random.default_rng(1)
    for k in range(1, n):
        c, s = np.cos(pose[2]), np.sin(pose[2])
        pose = pose + np.array([c * step[0], s * step[0], step[2]])
        graph.add_pose(k, float(k), pose + np.array([0.5, -0.5, 0.0]))
        graph.add_odometry(k - 1, k, step, odo_cov)
        if k % prior_every == 0:
            graph.add_position_fix(k, pose[:2] + rng.normal(0.0, 2.0, 2), np.eye(2) * 4.0)
    return graph


def batch(sizes: list[int]) -> None:
    """Each size without and with the calibration variable, in the same run: the ratio is the
    calibration's cost."""
    for n in sizes:
        totals = {}
        for calibrated in (False, True):
            t0 = time.perf_counter()
            graph = chain(n, calibrated=calibrated)
            built = time.perf_counter() - t0
            for covariance in ("none", "all"):
                t0 = time.perf_counter()
                solution = smooth_pose_graph(graph, GraphConfig().replace(smoother_covariance=covariance))
                total = totals[calibrated, covariance] = time.perf_counter() - t0
                parts = solution.timings
                print(f"batch {n:>7} poses, calibration {'yes' if calibrated else 'no ':<3}, covariance "
                      f"{covariance:<4}: {total:6.1f} s (solve {parts['solve']:.1f} s, marginals "
                      f"{parts['marginals']:.1f} s, {solution.iterations} Gauss-Newton steps; graph "
                      f"built in {built:.1f} s)")
        for covariance in ("none", "all"):
            print(f"batch {n:>7} poses, covariance {covariance:<4}: with / without calibration = "
                  f"{totals[True, covariance] / totals[False, covariance]:.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--online-only", action="store_true")
    parser.add_argument("--batch-only", action="store_true")
    parser.add_argument("--sizes", type=int, nargs="+", default=[100_000, 300_000])
    parser.add_argument("--long", type=int, default=0,
                        help="also a graph-only online run of this many key poses")
    parser.add_argument("--tracking", action="store_true",
                        help="only the tracking graph with point-mass acquisition on demo surveys")
    parser.add_argument("--seeds", type=int, nargs="+", default=[7, 8, 9])
    parser.add_argument("--tide-drift", type=float, nargs=2, metavar=("STD", "TIME"),
                        help="with --tracking: the surveys' depths drift by STD m over TIME s")
    args = parser.parse_args()
    print(f"pid {os.getpid()}")
    if args.tracking:
        tracking(args.seeds, args.tide_drift)
        return
    if not args.batch_only:
        online()
        if args.long:
            long_online(args.long)
    if not args.online_only:
        batch(args.sizes)


if __name__ == "__main__":
    main()
