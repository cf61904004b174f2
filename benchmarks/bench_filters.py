"""Speed of the particle filters (tangraph.filters).

    ./run bench   (or: python benchmarks/bench_filters.py [--repeat R] [--pings K]);
    one thread: NUMBA_NUM_THREADS and OMP_NUM_THREADS default to 1.

1. One likelihood update of 10^4 particles x 300 soundings on a 1000 x 1000 map (target: at most
   40 ms on one core): the residual sums, the model's update with an uncertain tide (what the
   filters call) and the plain Gaussian log-likelihood (both one compiled pass), against a
   vectorised numpy reference (bilinear depths of all particles x soundings as arrays).
2. SJCPF time per loop at Chen & Che's setting (the chen2022 scenario simulated: polar500 chart,
   one sounding per 100 s, 1000 particles), Pearson, Spearman and Kendall, against the paper's
   140.59, 301.19 and 235.37 ms per loop (target: at least 100x faster for Pearson), and the
   bootstrap PF on the same survey.
3. Per-step times of every filter with its default config on a short multibeam survey (60 beams,
   a ping every 10 m, a 5 m fractal map), with the navigation model of its simulated DR (the
   survey records no settings, so the model is passed).

Parts 2 and 3 give each filter the run's ``NavigationModel`` (part 2: ``from_survey`` of the
simulated chen2022 survey), so the particles also estimate the DVL scale and heading bias.

Best of R runs after a warm-up (benchmarks/_timing.py for wall time); on a shared machine the
process CPU time (``time.process_time``) is printed too, and the ratios use it. Nothing is asserted.
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np
from _timing import best_cpu, best_time

from tangraph.filters import FilterMethod, SJCPFConfig, default_config, run_filter
from tangraph.filters.likelihood import TerrainLikelihood
from tangraph.filters.model import Ping, TerrainModel
from tangraph.maps import BathymetryMap, fractal
from tangraph.sensors import DeadReckoningModel, NavigationModel, simulate_dead_reckoning
from tangraph.sim import trajectories
from tangraph.survey import Survey, footprints

PAPER_MS = {"pearson": 140.59, "spearman": 301.19, "kendall": 235.37}


def numpy_log_likelihood(bathymetry: BathymetryMap, particles, offsets, depths, sigma: float) -> np.ndarray:
    """The Gaussian log-likelihood by plain numpy over (N, B) arrays (the reference)."""
    dn, de = bathymetry.cell_size
    ny, nx = bathymetry.shape
    fy = (particles[:, 0:1] + offsets[:, 0] - bathymetry.north[0]) / dn
    fx = (particles[:, 1:2] + offsets[:, 1] - bathymetry.east[0]) / de
    inside = (fy >= 0) & (fy <= ny - 1) & (fx >= 0) & (fx <= nx - 1)
    i = np.clip(np.floor(fy).astype(np.int64), 0, ny - 2)
    j = np.clip(np.floor(fx).astype(np.int64), 0, nx - 2)
    ty, tx = fy - i, fx - j
    d = bathymetry.depth
    h = ((1 - ty) * ((1 - tx) * d[i, j] + tx * d[i, j + 1])
         + ty * ((1 - tx) * d[i + 1, j] + tx * d[i + 1, j + 1]))  # fmt: skip
    r = np.where(inside, h - depths, np.nan)
    ll = -0.5 * np.sum(r**2, axis=1) / sigma**2
    return np.where(np.isfinite(ll), ll, -np.inf)


def likelihood_case(repeat: int) -> None:
    rng = np.random.default_rng(0)
    m = fractal((1000, 1000), 5.0, rng=rng, beta=3.0, relief=10.0, mean_depth=100.0, name="bench")
    n, b = 10_000, 300
    particles = np.array([2500.0, 2500.0]) + 30.0 * rng.standard_normal((n, 2))
    along = np.repeat(np.arange(5) * 10.0 - 20.0, 60)
    across = np.tile(np.linspace(-60.0, 60.0, 60), 5)
    offsets = np.column_stack([along, across])
    depths = m.depth_at(2500.0 + offsets[:, 0], 2500.0 + offsets[:, 1]) + 0.3 * rng.standard_normal(b)
    like = TerrainLikelihood(m, 0.5)
    model = TerrainModel(m, 0.5, tide_std=3.0)
    ping = Ping(1, np.zeros(2), offsets, depths)
    tide = np.zeros(n)
    want = numpy_log_likelihood(m, particles, offsets, depths, 0.5)
    got = like.log_likelihood(particles, offsets, depths)
    assert np.allclose(got, want, rtol=1e-9), "compiled and numpy likelihoods differ"
    cases = [
        ("residual sums (compiled)", lambda: like.residual_sums(particles, offsets, depths)),
        ("model update, tide estimated", lambda: model.evaluate(particles, tide, 9.0, ping)),
        ("Gaussian log-likelihood", lambda: like.log_likelihood(particles, offsets, depths)),
        ("numpy reference", lambda: numpy_log_likelihood(m, particles, offsets, depths, 0.5)),
    ]
    print(
        f"\n1. one likelihood update, {n} particles x {b} soundings, 1000 x 1000 map "
        f"(target <= 40 ms), best of {repeat}"
    )
    print(f"   {'':<32}{'wall ms':>9}{'cpu ms':>9}{'vs numpy':>10}{'ns/particle/sounding':>22}")
    rows = []
    for label, fn in cases:
        r = max(1, repeat // 3) if label.startswith("numpy") else repeat
        rows.append((label, best_time(fn, r), best_cpu(fn, r)))
    cpu_np = rows[-1][2]
    for label, wall, cpu in rows:
        per = 1e9 * cpu / (n * b)
        print(f"   {label:<32}{1e3 * wall:>9.1f}{1e3 * cpu:>9.1f}{cpu_np / cpu:>9.1f}x{per:>22.2f}")


def chen2022_survey() -> tuple[Survey, BathymetryMap]:
    from tangraph.maps import load
    from tangraph.sim.scenario import load_scenario, simulate

    scenario = load_scenario("chen2022")
    chart = load(scenario.map)
    return simulate(scenario, rng=np.random.default_rng(scenario.seed), bathymetry=chart), chart


def per_loop(
    method, survey, chart, config, repeat: int, model: NavigationModel | None = None
) -> tuple[float, float, float]:
    """Best wall and CPU seconds per ping over ``repeat`` runs (after a warm-up), and the RMSE of
    the last run; ``model`` None: the survey's (``NavigationModel.from_survey``)."""
    wall = cpu = np.inf
    run_filter(method, survey, chart, config, model=model, rng=np.random.default_rng(0))  # warm-up
    for r in range(repeat):
        t0 = time.process_time()
        track = run_filter(method, survey, chart, config, model=model, rng=np.random.default_rng(r))
        cpu = min(cpu, (time.process_time() - t0) / survey.n_pings)
        wall = min(wall, track.timings["per_step"])
    error = np.hypot(*(track.pose[:, :2] - survey.true_pose[:, :2]).T)
    return wall, cpu, float(np.sqrt(np.mean(error**2)))


def sjcpf_case(repeat: int) -> None:
    survey, chart = chen2022_survey()
    dr_error = np.hypot(*(survey.dr_pose[:, :2] - survey.true_pose[:, :2]).T)
    print(
        f"\n2. SJCPF per loop, chen2022 ({survey.n_pings} pings, {survey.n_soundings} soundings, "
        f"polar500), 1000 particles, best of {repeat} runs; DR RMSE {np.sqrt(np.mean(dr_error**2)):.0f} m"
    )
    print(f"   {'':<20}{'wall ms':>9}{'cpu ms':>9}{'paper ms':>10}{'speed-up (cpu)':>16}{'RMSE m':>9}")
    for kind in ("pearson", "spearman", "kendall"):
        wall, cpu, rmse = per_loop("sjcpf", survey, chart, SJCPFConfig(correlation=kind), repeat)
        print(
            f"   {'sjcpf ' + kind:<20}{1e3 * wall:>9.3f}{1e3 * cpu:>9.3f}{PAPER_MS[kind]:>10.2f}"
            f"{PAPER_MS[kind] / (1e3 * cpu):>15.0f}x{rmse:>9.0f}"
        )
    wall, cpu, rmse = per_loop("pf", survey, chart, default_config("pf"), repeat)
    print(f"   {'pf (same survey)':<20}{1e3 * wall:>9.3f}{1e3 * cpu:>9.3f}{'':>10}{'':>16}{rmse:>9.0f}")


def multibeam_survey(pings: int) -> tuple[Survey, BathymetryMap, NavigationModel]:
    rng = np.random.default_rng(1)
    m = fractal((600, 600), 5.0, rng=rng, beta=3.0, relief=8.0, mean_depth=80.0, name="bench")
    time, truth = trajectories.straight_line((300.0, 300.0), np.radians(45.0), 2.0, (pings - 1) * 5.0, 0.2)
    model = DeadReckoningModel(heading_bias=np.radians(1.0), speed_scale=0.01, speed_noise=0.05)
    dr = simulate_dead_reckoning(time, truth, model, rng=rng).pose
    forward = np.zeros((time.size, 60))
    starboard = np.tile(np.linspace(-60.0, 60.0, 60), (time.size, 1))
    north, east = footprints(truth, forward, starboard)
    depth = m.depth_at(north, east) + 0.3 * rng.standard_normal(north.shape)
    survey = Survey(time, dr, np.full(time.size, 20.0), forward, starboard, depth, true_pose=truth)
    # the DR starts at the truth; the soundings' 0.3 m noise with from_survey's 1.5 margin
    navigation = NavigationModel.from_dead_reckoning(model, initial_position_std=10.0, sounding_std=0.45)
    return survey, m, navigation


def filters_case(pings: int, repeat: int) -> None:
    survey, m, navigation = multibeam_survey(pings)
    dr_error = np.hypot(*(survey.dr_pose[:, :2] - survey.true_pose[:, :2]).T)
    print(
        f"\n3. every filter, default config, {pings} pings x 60 beams on a 600 x 600 map (5 m), "
        f"best of {repeat}; DR RMSE {np.sqrt(np.mean(dr_error**2)):.1f} m"
    )
    print(f"   {'method':<12}{'particles':>10}{'wall ms':>9}{'cpu ms':>9}{'RMSE m':>8}")
    for method in FilterMethod:
        config = default_config(method)
        wall, cpu, rmse = per_loop(method, survey, m, config, repeat, navigation)
        n = getattr(config, "n_particles", "-")
        print(f"   {method.value:<12}{n:>10}{1e3 * wall:>9.2f}{1e3 * cpu:>9.2f}{rmse:>8.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--pings", type=int, default=100, help="pings of the multibeam survey of part 3")
    args = parser.parse_args()
    print(f"tangraph.filters, NUMBA_NUM_THREADS={os.environ['NUMBA_NUM_THREADS']}, pid {os.getpid()}")
    likelihood_case(args.repeat)
    sjcpf_case(args.repeat)
    filters_case(args.pings, max(1, args.repeat // 2))


if __name__ == "__main__":
    main()
