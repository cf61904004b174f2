"""Wang et al. 2019 study: how often do Xie's, Wang's and our calibrated regions hold the truth?

Each run simulates the wang2019 scenario (a multibeam line, ray-cast soundings) on one terrain
with one sounding-noise model, then makes TAP fixes with windows of 3, 10, 20 and 30 pings
ending every 30 pings, each searched around a prior drawn 10 m (std) from the truth. For every fix
it records the estimated sounding std and tide (the paper's Tables 1 and 2), whether the true
position lies inside each method's region at 1 - alpha = 0.68, 0.95, 0.99 (the criterion is
evaluated exactly at the truth and compared with the region's threshold), the regions' areas, and
the NEES of the region, curvature and CRLB covariances.

Dead reckoning inside a window is exact in the paper's case (its ship had GNSS): the prior error is
what matching corrects. Two more cases lay the patches with the drifting DR of the ``demo``
scenario (3.5 deg heading bias, 3 % speed scale, heading walk) on the real map with Gaussian
noise: ``raw``, the DR as it is, and ``calibrated``, the DR corrected with the speed scale and
heading bias the batch smoother estimates from the same survey (as the graph lays its patches).
Configuration: ``config.toml`` beside this file.

    tangraph experiment wang2019_confidence [--runs N] [--seed S] [--quick] [--scheduler ADDR]
"""

from __future__ import annotations

import dataclasses
import json
import tomllib
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
LEVELS = (0.68, 0.95, 0.99)
METHODS = ("xie", "wang", "calibrated")


def load_config() -> dict:
    with open(HERE / "config.toml", "rb") as f:
        return tomllib.load(f)


_TERRAINS: dict = {}  # per process; a plain dict, as functools.cache cannot travel by value


def terrain(name: str):
    """A catalogue map, or a seeded fractal terrain of graded roughness ("fractal-<relief>")."""
    from tangraph.maps import fractal, load

    if name not in _TERRAINS:
        if name.startswith("fractal-"):
            relief = float(name.split("-")[1])
            _TERRAINS[name] = fractal(
                (420, 420),
                10.0,
                rng=np.random.default_rng(7),
                beta=3.5,
                relief=relief,
                mean_depth=8.0 + 3 * relief,
                name=name,
            )
        else:
            _TERRAINS[name] = load(name)
    return _TERRAINS[name]


def calibrated_dr(survey, bathymetry):
    """The survey with its DR corrected by the speed scale and heading bias the batch smoother
    estimates from it (the DR frame mapped to the world, :mod:`tangraph.graph.calibration`)."""
    from tangraph.graph import GraphConfig, smooth_survey
    from tangraph.graph.calibration import to_world
    from tangraph.sensors import NavigationModel

    track = smooth_survey(survey, bathymetry, GraphConfig().replace(rematch_iterations=0),
                          model=NavigationModel.from_survey(survey))
    c = track.meta["calibration"]
    corrected = to_world(survey.dr_pose, (c["speed_scale"], c["heading_bias"]), survey.dr_pose[0, :2])
    return survey.replace(dr_pose=corrected)


def one_run(config: dict, *, rng: np.random.Generator) -> list[dict]:
    """One survey, its fixes: a row per fix."""
    from tangraph.matching import (
        MatchingError,
        RegionMethod,
        TapConfig,
        criterion_at,
        nees,
        region_thresholds,
        tap_fix_patch,
        window_patch,
    )
    from tangraph.sensors import DeadReckoningModel
    from tangraph.sim import load_scenario, simulate

    scenario = load_scenario("wang2019")
    sonar = dataclasses.replace(scenario.sonar, **config["sonar"])
    laid = config.get("dr", "exact")
    dr = DeadReckoningModel.ideal() if laid == "exact" else load_scenario("demo").dead_reckoning
    scenario = dataclasses.replace(scenario, sonar=sonar, dead_reckoning=dr)
    bathymetry = terrain(config["map"])
    survey = simulate(scenario, rng=rng, bathymetry=bathymetry)
    if laid == "calibrated":
        survey = calibrated_dr(survey, bathymetry)
    search = TapConfig(half_width=config["half_width"], step=config["step"])
    rows = []
    for end in range(config["first_end"], survey.n_pings, config["every"]):
        truth = survey.true_pose[end, :2]
        for window in config["windows"]:
            base = {"end": end, "window": window}
            try:
                patch = window_patch(survey, end, window)
                prior = truth + rng.normal(0.0, config["prior_std"], 2)
                fix = tap_fix_patch(patch, bathymetry, search, prior=prior)
            except MatchingError as exc:
                rows.append({**base, "failed": str(exc)})
                continue
            q_truth = float(criterion_at(bathymetry, patch, truth)[0])
            s_truth = float(criterion_at(bathymetry, patch, truth, tide=fix.tide)[0])
            q_min = float(np.nanmin(fix.surface))
            row = {
                **base,
                "failed": "",
                "n": fix.n_soundings,
                "sigma": fix.sigma,
                "tide": fix.tide,
                "fix_error": float(np.hypot(*(fix.position - truth))),
                "accepted": fix.accepted,
                "inflation": fix.variance_inflation,
            }
            for level in LEVELS:
                thresholds = region_thresholds(q_min, fix.n_soundings, 1 - level, fix.variance_inflation)
                for method in METHODS:
                    value = s_truth if method == "wang" else q_truth
                    row[f"in_{method}_{level}"] = bool(value <= thresholds[RegionMethod(method)])
            for method in METHODS:
                row[f"area_{method}_0.95"] = fix.regions[RegionMethod(method)].area
            for name, cov in fix.covariances.items():
                row[f"nees_{name}"] = nees(fix.position - truth, cov) if np.all(np.isfinite(cov)) else np.nan
            rows.append(row)
    return rows


def summarise(table, truth_sigma: dict, truth_tide: float) -> str:
    from scipy import stats

    ok = table[table["failed"] == ""]
    out = [
        "### Estimated sounding std and tide (the paper's Tables 1 and 2)",
        "",
        "| terrain | noise | pings | fixes | sigma: mean | sigma: std | true sigma | tide: mean | tide: std |"
        " true tide |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for (m, noise, w), g in ok[ok["dr"] == "exact"].groupby(["map", "noise", "window"], sort=False):
        out.append(
            f"| {m} | {noise} | {w} | {len(g)} | {g.sigma.mean():.4f} | {g.sigma.std():.4f} | "
            f"{truth_sigma[noise]:.3f} | {g.tide.mean():.4f} | {g.tide.std():.4f} | {truth_tide:.2f} |"
        )
    out += [
        "",
        "### Coverage of the true position (fraction of fixes inside the region) and NEES",
        "",
        "Binomial 95 % band of a coverage estimate at the nominal level over k fixes: "
        "nominal +- 1.96 sqrt(p (1 - p) / k). NEES of an honest 2-D covariance has mean 2.",
        "",
        "Patch laid with: *exact* the true track inside the window (the paper's case), *raw* the "
        "demo's drifting DR, *calibrated* that DR corrected with the smoother's calibration estimate.",
        "",
        "| terrain | noise | patch laid with | pings | fixes | "
        + " | ".join(f"{m} {lv}" for lv in LEVELS for m in METHODS)
        + " | area xie / wang / cal. 0.95 (m²) | NEES region | NEES curvature | NEES CRLB | accepted |",
        "|" + "---|" * (5 + 3 * len(LEVELS) + 5),
    ]
    for (m, noise, laid, w), g in ok.groupby(["map", "noise", "dr", "window"], sort=False):
        cover = " | ".join(f"{g[f'in_{meth}_{lv}'].mean():.3f}" for lv in LEVELS for meth in METHODS)
        areas = " / ".join(f"{g[f'area_{meth}_0.95'].median():.0f}" for meth in METHODS)
        nees_cols = " | ".join(f"{np.nanmean(g[f'nees_{c}']):.2f}" for c in ("region", "curvature", "crlb"))
        out.append(
            f"| {m} | {noise} | {laid} | {w} | {len(g)} | {cover} | {areas} | {nees_cols} | "
            f"{g.accepted.mean():.2f} |"
        )
    k = len(ok[(ok["map"] == ok["map"].iloc[0])]) if len(ok) else 0
    half = 1.96 * np.sqrt(0.95 * 0.05 / max(k, 1))
    out += [
        "",
        f"(For example, over {k} fixes the band at 0.95 is [{0.95 - half:.3f}, {0.95 + half:.3f}]; "
        f"chi-square 95 % band of a mean NEES over 500 fixes: "
        f"[{stats.chi2.ppf(0.025, 1000) / 500:.2f}, {stats.chi2.ppf(0.975, 1000) / 500:.2f}].)",
    ]
    return "\n".join(out)


def figures(table, out: Path, tag: str) -> list[Path]:
    """Coverage at 0.95 against window length per method, and one fix drawn like Wang's figures."""
    from matplotlib.figure import Figure

    from tangraph.matching import TapConfig, tap_fix
    from tangraph.plot import plot_fix
    from tangraph.sensors import DeadReckoningModel
    from tangraph.sim import load_scenario, simulate

    ok = table[(table["error"].isna()) & (table["failed"] == "") & (table["dr"] == "exact")]
    maps, noises = list(dict.fromkeys(ok["map"])), list(dict.fromkeys(ok["noise"]))
    fig = Figure(figsize=(3.6 * len(noises), 3.0 * len(maps)), layout="constrained")
    grid = fig.subplots(len(maps), len(noises), squeeze=False, sharex=True, sharey=True)
    for (m, noise), g in ok.groupby(["map", "noise"], sort=False):
        ax = grid[maps.index(m), noises.index(noise)]
        for method in METHODS:
            cover = g.groupby("window")[f"in_{method}_0.95"].mean()
            ax.plot(cover.index, cover.values, "o-", label=method)
        ax.axhline(0.95, color="k", lw=0.8, ls=":")
        ax.set_ylim(0, 1.02)
        ax.set_xlabel("pings per window")
        ax.set_title(f"{m}, {noise}", fontsize="medium")
    for row in grid:
        row[0].set_ylabel("coverage at 0.95")
    grid[0, 0].legend(fontsize="small")
    paths = [out / f"coverage_{tag}.png"]
    fig.savefig(paths[0], dpi=120)

    scenario = load_scenario("wang2019")
    scenario = dataclasses.replace(scenario, dead_reckoning=DeadReckoningModel.ideal())
    survey = simulate(scenario, rng=np.random.default_rng(5), bathymetry=terrain("merimbula"))
    fix = tap_fix(survey, terrain("merimbula"), 119, 10, TapConfig(half_width=40.0, step=2.0),
                  prior=survey.true_pose[119, :2] + np.array([12.0, -8.0]))
    fig = Figure(figsize=(7, 6), layout="constrained")
    plot_fix(fix, fig.add_subplot(), truth=survey.true_pose[119, :2])
    paths.append(out / f"example_fix_{tag}.png")
    fig.savefig(paths[1], dpi=120)
    return paths


def main(argv=None) -> int:
    from tangraph.experiments import run_many
    from tangraph.experiments.study import output_folder, study_parser

    parser = study_parser(HERE, __doc__.splitlines()[0], runs=None, seed=2019,
                          quick="few runs on the real map only: minutes")
    args = parser.parse_args(argv)
    args.out = output_folder(args, HERE)
    cfg = load_config()
    runs = args.runs or (cfg["quick_runs"] if args.quick else cfg["runs"])
    configs = []
    for m in cfg["maps"][:1] if args.quick else cfg["maps"]:
        for noise, sonar in cfg["noise"].items():
            if args.quick and noise != "gaussian":
                continue
            drifting = cfg["drifting_dr"] if (m, noise) == (cfg["maps"][0], "gaussian") else []
            for laid in ("exact", *drifting):
                configs.append({"map": m, "noise": noise, "dr": laid, "sonar": sonar,
                                "windows": cfg["windows"], **cfg["search"]})
    table = run_many(one_run, configs, runs, args.seed, scheduler=args.scheduler, workers=args.workers)
    if table["error"].notna().all():
        print(f"every run failed; the first: {table['error'].iloc[0]}")
        return 1
    tag = f"seed{args.seed}_runs{runs}{'_quick' if args.quick else ''}"
    table.to_csv(args.out / f"fixes_{tag}.csv", index=False)
    truth_sigma = {k: float(np.hypot(v.get("depth_noise", 0.0), 0.0)) for k, v in cfg["noise"].items()}
    text = summarise(table[table["error"].isna()], truth_sigma, truth_tide=2.5)
    header = (
        f"Command: `tangraph experiment wang2019_confidence --runs {runs} --seed {args.seed}"
        f"{' --quick' if args.quick else ''}`  \nConfig: `config.toml` (recorded in config_{tag}.json)\n\n"
    )
    (args.out / f"summary_{tag}.md").write_text(header + text + "\n")
    for path in figures(table, args.out, tag):
        print(f"wrote {path}")
    (args.out / f"config_{tag}.json").write_text(
        json.dumps({"runs": runs, "seed": args.seed, **cfg}, indent=2)
    )
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
