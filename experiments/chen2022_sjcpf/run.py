"""Chen & Che 2022 study: PF vs SJCPF (Pearson, Spearman, Kendall) on low-resolution charts.

Each run simulates the 100 000 s single-beam survey of a scenario (``chen2022`` on the synthetic
500 m chart ``polar500``; ``chen2022_arctic`` on the real ETOPO5 chart of the paper's own region)
and runs every variant named in the configuration on that same survey (a paired comparison). A
variant is a method (``pf`` or ``sjcpf``) with changes to the shared settings of ``config.toml``:
the navigation model's (``[model]``: initial spread, sounding and speed noise, the tide; the
filters estimate the DR's heading bias and speed scale) or the filter config's (``[filter]``:
particles, resampling; the SJCPF's jitter, window, kernel). Scored: the RMSE of the
whole track (the paper's figure), the final error and the time per loop (ms per sounding).

Parts: ``main`` (the paper's RMSE comparison: PF and the three correlations, both charts),
``particles`` (50 / 500 / 1000), ``rates`` (0.05 / 0.01 / 0.001 Hz), ``constants`` (the window,
kernel and jitter the paper leaves out, and ablations: jitter only, correction only, a PF with
too little process noise), ``timing`` (time per loop, each filter run in turn in this process).

    tangraph experiment chen2022_sjcpf [--part main|particles|rates|constants|timing|all] [--runs N]
                                       [--seed S] [--quick] [--workers W] [--scheduler ADDR] [--out DIR]
                                       [--replot]
"""

from __future__ import annotations

import dataclasses
import json
import tomllib
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
PARTS = ("main", "particles", "rates", "constants", "timing")
N_SAMPLES = 51  # errors kept per run, at evenly spaced pings (for the error-vs-distance figure)
PAPER_RMSE = {"pf": 1767.75, "sjcpf-pearson": 1277.31, "sjcpf-spearman": 1386.98, "sjcpf-kendall": 1241.01}
PAPER_MS = {"sjcpf-pearson": 140.59, "sjcpf-spearman": 301.19, "sjcpf-kendall": 235.37}


def load_config() -> dict:
    with open(HERE / "config.toml", "rb") as f:
        return tomllib.load(f)


def variant_config(variant: dict, shared: dict, sjcpf: dict):
    """The filter config of a variant: the method's defaults, the shared settings, the SJCPF's own
    settings (for ``sjcpf``), then the variant's changes that are not navigation model fields
    (those are :func:`model_changes`)."""
    from tangraph.filters import default_config

    changes = {k: v for k, v in variant.items() if k not in _model_fields()}
    method = changes.pop("method")
    base = default_config(method)
    settings = {**shared, **(sjcpf if method == "sjcpf" else {}), **changes}
    return method, dataclasses.replace(base, **settings)


def _model_fields() -> set[str]:
    from tangraph.sensors import NavigationModel

    return {f.name for f in dataclasses.fields(NavigationModel)}


def navigation_model(survey, model: dict, variant: dict):
    """The navigation model of a variant on a survey: the survey's simulated DR errors
    (``NavigationModel.from_survey``) with the study's ``[model]`` fields, then the variant's."""
    from tangraph.sensors import NavigationModel

    fields = _model_fields()
    changes = {**model, **{k: v for k, v in variant.items() if k in fields}}
    return NavigationModel.from_survey(survey).replace(**changes)


def one_run(config: dict, *, rng: np.random.Generator) -> list[dict]:
    """One survey of the scenario, every variant on it: a row per variant."""
    from tangraph.eval import track_metrics
    from tangraph.filters import run_filter
    from tangraph.maps import load
    from tangraph.navigation import dead_reckoning_track
    from tangraph.sim import load_scenario, simulate
    from tangraph.track import position_errors

    scenario = load_scenario(config["scenario"])
    scenario = dataclasses.replace(
        scenario, sonar=dataclasses.replace(scenario.sonar, ping_rate=config["rate"])
    )
    bathymetry = load(scenario.map)
    survey = simulate(scenario, rng=rng, bathymetry=bathymetry)
    dr_track = dead_reckoning_track(survey)
    dr = track_metrics(dr_track, survey.true_pose)
    dr_err = position_errors(dr_track, survey.true_pose)
    k = survey.n_pings
    samples = np.unique(np.linspace(0, k - 1, N_SAMPLES).round().astype(int))
    distance = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(survey.true_pose[:, :2], axis=0).T))])
    rows = []
    for name in config["variants"]:
        variant = config["variant_settings"][name]
        method, cfg = variant_config(variant, config["shared"], config["sjcpf"])
        if "n_particles" in config:
            cfg = dataclasses.replace(cfg, n_particles=config["n_particles"])
        model = navigation_model(survey, config["model"], variant)
        track = run_filter(method, survey, bathymetry, cfg, model=model, rng=rng)
        calibration = track.meta.get("calibration", {})
        metrics = track_metrics(track, survey.true_pose)
        err = position_errors(track, survey.true_pose)
        row = {
            "variant": name,
            "method": method,
            "rmse": metrics["rmse"],
            "final_error": metrics["final_error"],
            "mean_error": metrics["mean_error"],
            "final_err_north": float(track.pose[-1, 0] - survey.true_pose[-1, 0]),
            "final_err_east": float(track.pose[-1, 1] - survey.true_pose[-1, 1]),
            "dr_rmse": dr["rmse"],
            "dr_final_error": dr["final_error"],
            "ms_per_loop": 1e3 * track.timings["per_step"],
            "seconds": track.timings["total"],
            "n_pings": k,
            "n_divergences": int(track.meta.get("n_divergences", 0)),
            "n_resampled": int(track.meta.get("n_resampled", 0)),
            "n_lost": int(track.meta.get("n_lost", 0)),
            "n_tempered": int(track.meta.get("n_tempered", 0)),
            "heading_error_deg": float(np.degrees(calibration.get("heading_error", np.nan))),
            "speed_scale": float(calibration.get("speed_scale", np.nan)),
            "mean_ess": float(np.nanmean(track.meta["ess"])),
        }
        for i, s in enumerate(samples):
            row[f"err_{i:02d}"] = float(err[s])
            row[f"dist_{i:02d}"] = float(distance[s])
            row[f"drerr_{i:02d}"] = float(dr_err[s])
        rows.append(row)
    return rows


def configurations(part: str, cfg: dict, quick: bool) -> list[dict]:
    base = {
        "part": part,
        "shared": cfg["filter"],
        "model": cfg["model"],
        "sjcpf": cfg["sjcpf"],
        "variant_settings": cfg["variants"],
        "rate": 0.01,
    }
    maps = cfg["maps"][:1] if quick and part == "constants" else cfg["maps"]
    out = []
    for scenario in maps:
        b = {**base, "scenario": scenario}
        if part == "main":
            out.append({**b, "variants": cfg["main"]})
        elif part == "particles":
            out += [
                {**b, "n_particles": n, "variants": cfg["sweeps"]["particle_variants"]}
                for n in cfg["sweeps"]["particles"]
            ]
        elif part == "rates":
            out += [
                {**b, "rate": r, "variants": cfg["sweeps"]["rate_variants"]} for r in cfg["sweeps"]["rates"]
            ]
        else:
            out.append({**b, "variants": cfg["sweeps"]["constants"]})
    return out


# -- tables ------------------------------------------------------------------------------------
def _cell(s, column: str) -> str:
    return f"{s[column].mean():.0f} ± {s[column].sem():.0f}"


def table(part: str, t) -> str:
    out = []
    for scenario, g in t.groupby("scenario", sort=False):
        runs = int(g.groupby(["config_index", "variant"]).size().min())
        out += [f"#### {scenario}: {runs} runs per row, mean ± standard error over runs", ""]
        if part == "main":
            pf = g[g.variant == "pf"].set_index("run").rmse
            out += [
                "| variant | RMSE (m) | paper RMSE (m) | change vs PF, paired (ours) | paper change | "
                "final error (m) | ms per loop | paper ms per loop | DR RMSE (m) |",
                "|---|---|---|---|---|---|---|---|---|",
            ]
            for v, s in g.groupby("variant", sort=False):
                paired = (s.set_index("run").rmse / pf - 1.0) * 100
                paper = PAPER_RMSE.get(v, float("nan"))
                paper_change = (paper / PAPER_RMSE["pf"] - 1.0) * 100
                out.append(
                    f"| {v} | {_cell(s, 'rmse')} | {paper:.2f} | "
                    f"{paired.mean():+.1f} % (median {paired.median():+.1f} %) "
                    f"| {paper_change:+.1f} % | {_cell(s, 'final_error')} | {s.ms_per_loop.median():.2f} | "
                    f"{PAPER_MS.get(v, float('nan')):.2f} | {_cell(s, 'dr_rmse')} |"
                )
        elif part == "particles":
            out += [
                "| particles | variant | RMSE (m) | final error (m) | ms per loop | RMSE std over runs |",
                "|---|---|---|---|---|---|",
            ]
            for (n, v), s in g.groupby(["n_particles", "variant"], sort=True):
                out.append(
                    f"| {n} | {v} | {_cell(s, 'rmse')} | {_cell(s, 'final_error')} | "
                    f"{s.ms_per_loop.median():.2f} | {s.rmse.std():.0f} |"
                )
        elif part == "rates":
            out += [
                "| rate (Hz) | spacing (m) | soundings | variant | RMSE (m) | final error (m) "
                "| ms per loop |",
                "|---|---|---|---|---|---|---|",
            ]
            for (r, v), s in g.groupby(["rate", "variant"], sort=False):
                out.append(
                    f"| {r} | {1.0 / r:.0f} | {int(s.n_pings.iloc[0])} | {v} | {_cell(s, 'rmse')} | "
                    f"{_cell(s, 'final_error')} | {s.ms_per_loop.median():.2f} |"
                )
        else:
            pf = g[g.variant == "pf"].set_index("run").rmse
            out += [
                "| variant | settings changed | RMSE (m) | change vs PF, paired | final error (m) "
                "| ms per loop |",
                "|---|---|---|---|---|---|",
            ]
            settings = load_config()["variants"]
            for v, s in g.groupby("variant", sort=False):
                paired = (s.set_index("run").rmse / pf - 1.0) * 100
                changed = ", ".join(f"{k}={x}" for k, x in settings.get(v, {}).items() if k != "method")
                out.append(
                    f"| {v} | {changed} | {_cell(s, 'rmse')} | {paired.mean():+.1f} % | "
                    f"{_cell(s, 'final_error')} | {s.ms_per_loop.median():.2f} |"
                )
        out.append("")
    return "\n".join(out)


# -- figures -----------------------------------------------------------------------------------
COLOURS = {
    "pf": "tab:red",
    "sjcpf-pearson": "tab:blue",
    "sjcpf-spearman": "tab:green",
    "sjcpf-kendall": "tab:purple",
}


def figure_error_vs_distance(t, path: Path) -> Path:
    from matplotlib.figure import Figure

    scenarios = list(dict.fromkeys(t.scenario))
    fig = Figure(figsize=(6 * len(scenarios), 4), layout="constrained")
    axes = fig.subplots(1, len(scenarios), squeeze=False)[0]
    for ax, scenario in zip(axes, scenarios, strict=True):
        g = t[t.scenario == scenario]
        cols = sorted(c for c in g.columns if c.startswith("err_"))  # err_00 .. err_50
        dist = g[[c.replace("err_", "dist_") for c in cols]].iloc[0].to_numpy() / 1e3
        for v, s in g.groupby("variant", sort=False):
            ax.plot(dist, s[cols].mean().to_numpy(), color=COLOURS.get(v), label=v)
        dr_cols = [c.replace("err_", "drerr_") for c in cols]
        if all(c in g.columns for c in dr_cols):
            dr = g.drop_duplicates(["config_index", "run"])
            ax.plot(dist, dr[dr_cols].mean().to_numpy(), "k:", lw=1.0, label="dead reckoning")
        ax.set_xlabel("distance travelled (km)")
        ax.set_ylabel("mean error over runs (m)")
        ax.set_title(scenario, fontsize="medium")
        ax.grid(alpha=0.3)
        ax.legend(fontsize="small")
    fig.savefig(path, dpi=120)
    return path


def figure_final_on_map(t, path: Path) -> Path:
    """Every run's final estimate per variant on the chart, with the route and its end."""
    from matplotlib.figure import Figure

    from tangraph.maps import load
    from tangraph.plot import plot_map
    from tangraph.sim import load_scenario
    from tangraph.sim.scenario import true_trajectory

    scenarios = list(dict.fromkeys(t.scenario))
    fig = Figure(figsize=(6.5 * len(scenarios), 5.5), layout="constrained")
    axes = fig.subplots(1, len(scenarios), squeeze=False)[0]
    for ax, scenario in zip(axes, scenarios, strict=True):
        sc = load_scenario(scenario)
        bathymetry = load(sc.map)
        _, truth = true_trajectory(sc, bathymetry)
        end = truth[-1, :2]
        g = t[t.scenario == scenario]
        radius = np.hypot(g.final_err_north, g.final_err_east)
        half = float(max(3000.0, 1.2 * np.quantile(radius, 0.95)))
        lo, hi = end - half, end + half
        cell = max(bathymetry.cell_size)
        plot_map(
            bathymetry.crop(north=(lo[0] - cell, hi[0] + cell), east=(lo[1] - cell, hi[1] + cell)),
            ax,
            title=f"{scenario}: final estimates around the true end",
            colorbar=False,
        )
        ax.plot(truth[:, 1], truth[:, 0], "w-", lw=1.0, label="true route")
        for v, s in g.groupby("variant", sort=False):
            ax.plot(
                end[1] + s.final_err_east,
                end[0] + s.final_err_north,
                ".",
                ms=5,
                alpha=0.6,
                color=COLOURS.get(v),
                label=f"{v}: final estimates",
            )
        ax.plot(end[1], end[0], "k+", ms=12, mew=2, label="true end")
        ax.set_xlim(lo[1], hi[1])
        ax.set_ylim(lo[0], hi[0])
        ax.legend(fontsize="x-small", loc="best")
    fig.savefig(path, dpi=120)
    return path


def figure_example(cfg: dict, scenario: str, seed: int, path: Path) -> Path:
    """One run (seeded) of the PF and the Pearson SJCPF: tracks on the chart."""
    from matplotlib.figure import Figure

    from tangraph.filters import run_filter
    from tangraph.maps import load
    from tangraph.navigation import dead_reckoning_track
    from tangraph.plot import plot_tracks
    from tangraph.sim import load_scenario, simulate

    sc = load_scenario(scenario)
    bathymetry = load(sc.map)
    rng = np.random.default_rng(seed)
    survey = simulate(sc, rng=rng, bathymetry=bathymetry)
    tracks = {"dead reckoning": dead_reckoning_track(survey)}
    for name in ("pf", "sjcpf-pearson"):
        method, fc = variant_config(cfg["variants"][name], cfg["filter"], cfg["sjcpf"])
        model = navigation_model(survey, cfg["model"], cfg["variants"][name])
        tracks[name] = run_filter(method, survey, bathymetry, fc, model=model, rng=rng)
    fig = Figure(figsize=(8, 7), layout="constrained")
    plot_tracks(
        tracks,
        bathymetry,
        fig.add_subplot(),
        truth=survey.true_pose,
        ellipses="sjcpf-pearson",
        title=f"{scenario}, one run (seed {seed})",
    )
    fig.savefig(path, dpi=120)
    return path


def timing(cfg: dict, seed: int, repeat: int) -> str:
    """Time per loop of the main variants on one chen2022 survey, run ``repeat`` times in this
    process one after another (no Monte Carlo in parallel): the least and the median of the runs."""
    import functools
    import time

    from tangraph.filters import run_filter
    from tangraph.maps import load
    from tangraph.sim import load_scenario, simulate

    sc = load_scenario("chen2022")
    bathymetry = load(sc.map)
    survey = simulate(sc, rng=np.random.default_rng(seed), bathymetry=bathymetry)
    lines = [
        f"#### Time per loop (ms per sounding), chen2022, {survey.n_pings} soundings, {repeat} repeats",
        "",
        "| particles | variant | least ms per loop | median ms per loop | paper ms per loop |",
        "|---|---|---|---|---|",
    ]
    for n in cfg["sweeps"]["particles"]:
        for name in cfg["main"]:
            method, fc = variant_config(cfg["variants"][name], cfg["filter"], cfg["sjcpf"])
            fc = dataclasses.replace(fc, n_particles=n)
            model = navigation_model(survey, cfg["model"], cfg["variants"][name])
            run = functools.partial(run_filter, method, survey, bathymetry, fc, model=model)
            run(rng=np.random.default_rng(0))  # compile, warm caches
            per = []
            for r in range(repeat):
                started = time.perf_counter()
                run(rng=np.random.default_rng(r))
                per.append(1e3 * (time.perf_counter() - started) / survey.n_pings)
            lines.append(
                f"| {n} | {name} | {min(per):.3f} | {np.median(per):.3f} | "
                f"{PAPER_MS.get(name, float('nan')):.2f} |"
            )
    return "\n".join(lines)


CHECKED = (
    "rmse",
    "final_error",
    "ms_per_loop",
)  # every run must give finite values (the smoke test `--quick --runs 2`)


def _runs_path(out: Path, tag: str) -> Path:
    """The saved runs table of a tag (gzipped CSV; plain CSV from earlier versions)."""
    gz = out / f"runs_{tag}.csv.gz"
    return gz if gz.exists() else out / f"runs_{tag}.csv"


# -- main --------------------------------------------------------------------------------------
def main(argv=None) -> int:
    from tangraph.experiments import run_many
    from tangraph.experiments.study import output_folder, study_parser

    parser = study_parser(HERE, __doc__.splitlines()[0], runs=None, seed=2022,
                          quick="a few runs per configuration: minutes")
    parser.add_argument("--part", choices=[*PARTS, "all"], default="all")
    parser.add_argument(
        "--replot",
        action="store_true",
        help="remake the tables and figures from the runs CSV of these options",
    )
    args = parser.parse_args(argv)
    args.out = output_folder(args, HERE)
    cfg = load_config()
    status = 0
    for part in PARTS if args.part == "all" else (args.part,):
        if part == "timing":
            repeat = 1 if args.quick else 5
            text = timing(cfg, args.seed, repeat)
            command = f"tangraph experiment chen2022_sjcpf --part timing --seed {args.seed}"
            command += " --quick" if args.quick else ""
            tag = f"timing_seed{args.seed}_repeat{repeat}"
            (args.out / f"summary_{tag}.md").write_text(f"Command: `{command}`\n\n{text}\n")
            print(text)
            continue
        if args.quick:
            default = cfg["quick_runs"] if part == "main" else cfg["quick_sweep_runs"]
        else:
            default = cfg["runs"] if part == "main" else cfg["sweep_runs"]
        runs = args.runs or default
        tag = f"{part}_seed{args.seed}_runs{runs}{'_quick' if args.quick else ''}"
        configs = configurations(part, cfg, args.quick)
        if args.replot:
            import pandas as pd

            t = pd.read_csv(_runs_path(args.out, tag))
            t.attrs["tangraph"] = (
                json.loads((args.out / f"config_{tag}.json").read_text()).get("runner") or {}
            )
        else:
            t = run_many(one_run, configs, runs, args.seed, scheduler=args.scheduler, workers=args.workers)
        failed = t["error"].notna()
        if failed.all():
            print(f"{part}: every run failed; the first: {t['error'].iloc[0]}")
            status = 1
            continue
        bad = ~np.isfinite(t.loc[~failed, list(CHECKED)].to_numpy(float)).all(axis=1)
        if bad.any():
            print(f"{part}: {int(bad.sum())} result rows hold non-finite {CHECKED}")
            status = 1
        if failed.any():
            print(f"{part}: {int(failed.sum())} runs failed; the first: {t.loc[failed, 'error'].iloc[0]}")
            status = 1
        if not args.replot:
            t.to_csv(args.out / f"runs_{tag}.csv.gz", index=False)
        ok = t[~failed]
        text = table(part, ok)
        command = (
            f"tangraph experiment chen2022_sjcpf --part {part} --runs {runs} --seed {args.seed}"
            f"{' --quick' if args.quick else ''}"
        )
        wall = t.attrs.get("tangraph", {}).get("wall_time_s", float("nan"))
        header = (
            f"Command: `{command}` (wall time {wall:.0f} s)  \n"
            f"Config: `config.toml`, recorded in config_{tag}.json\n\n"
        )
        (args.out / f"summary_{tag}.md").write_text(header + text + "\n")
        (args.out / f"config_{tag}.json").write_text(
            json.dumps(
                {
                    "command": command,
                    "runs": runs,
                    "seed": args.seed,
                    "runner": t.attrs.get("tangraph"),
                    **cfg,
                },
                indent=2,
                default=str,
            )
        )
        if part == "main":
            paths = [
                figure_error_vs_distance(ok, args.out / f"error_vs_distance_{tag}.png"),
                figure_final_on_map(ok, args.out / f"final_estimates_{tag}.png"),
            ]
            paths += [
                figure_example(cfg, s, args.seed, args.out / f"example_{s}_seed{args.seed}.png")
                for s in cfg["maps"]
            ]
            for p in paths:
                print(f"wrote {p}")
        print(header + text)
    return status


if __name__ == "__main__":
    raise SystemExit(main())
