"""Factor graph vs particle filters on the same seeded surveys, against the Cramér-Rao bound.

Every run simulates one survey of a scenario with a fresh seed (by default with the drifting dead
reckoning of the ``demo`` scenario: 3.5 deg heading bias, 3 % speed scale, heading walk) and
navigates it with the online iSAM2 graph, the batch smoother and the particle filters, all on the
survey's one :class:`~tangraph.sensors.NavigationModel` (same DR model, same start uncertainty).
It records each method's RMSE, its ratio to the posterior Cramér-Rao bound of the survey (the
smoother against the smoother bound, every causal estimator against the filter bound; pooled over
the runs as the bound is on the mean squared error: sqrt(mean RMSE^2 / mean PCRB^2)), the final
NEES, the estimated speed scale and heading error against the truth (in their reported sigmas),
and, for the graph, whether each fix it used covers the truth at 95 %.

The summary checks the targets set for the navigation model: smoother RMSE <= 1.25 x its PCRB,
online graph <= 1.0 x the best filter and <= 2 x the filter PCRB, mean final NEES inside the
chi-square band of the runs
(exact: independent chi-square(2) samples, ``tangraph.eval.anees_band(R)``), calibration within
2 sigma of the truth in >= 90 % of runs, fix coverage at 95 % within [0.93, 0.97].

    tangraph experiment graph_vs_filters [--runs 20] [--seed 6] [--quick] [--workers 2]
                                         [--methods ...] [--dr demo|own] [--out DIR]
"""

from __future__ import annotations

import json
import shlex
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SCENARIOS = ("demo", "wang2019", "han2020", "chen2022", "demo-flat", "demo-map-error", "wang2019-map-error",
             "han2020-map-error", "singlebeam", "singlebeam-map-error", "demo-patch-error",
             "singlebeam-patch-error", "demo-compass", "demo-drift", "demo-change")
FILTERS = ("pf", "ipf", "sjcpf", "jbpf", "tercom-pf", "mle", "pmf")
GRAPH = ("isam2", "smoother")


def _survey(config: dict, rng):
    import dataclasses

    from tangraph.maps import load_any
    from tangraph.sim.scenario import load_scenario, simulate_run

    name = config["scenario"]  # NAME-flat: the scenario over a flat seabed (no fix can be made)
    flat = name.endswith("-flat")
    scenario = load_scenario(name.removesuffix("-flat"))
    if config.get("dr", "demo") == "demo":
        scenario = dataclasses.replace(scenario, dead_reckoning=load_scenario("demo").dead_reckoning)
    bathymetry = load_any(scenario.map)
    if flat:  # at the median depth under the track
        from tangraph.sim.scenario import true_trajectory

        _, truth = true_trajectory(scenario, bathymetry)
        depth = float(np.nanmedian(bathymetry.depth_at(truth[:, 0], truth[:, 1])))
        bathymetry = dataclasses.replace(bathymetry, depth=np.full(bathymetry.depth.shape, depth),
                                         name=f"{bathymetry.name}-flat")
    # a NAME-map-error scenario's estimators navigate on the prior map gridded from its seafloor
    return simulate_run(scenario, rng=rng, bathymetry=bathymetry)


def _map_errors(run, refined) -> dict[str, float]:
    """The prior map's and the refined map's RMS error against the simulated seafloor over the
    map cells under the survey's true footprints, and the refined error in its stated stds."""
    out = {"map_rms_prior": np.nan, "map_rms_refined": np.nan, "map_z_refined": np.nan}
    if run.world is None or refined is None:
        return out
    prior = run.bathymetry
    under = prior.cells_under(*run.survey.footprints(run.survey.true_pose))
    truth = run.world.seafloor.depth_at(*np.meshgrid(prior.north, prior.east, indexing="ij"))
    under &= np.isfinite(truth) & np.isfinite(prior.depth)
    if not under.any():
        return out
    error = refined.depth[under] - truth[under]
    return {"map_rms_prior": float(np.sqrt(np.mean((prior.depth[under] - truth[under]) ** 2))),
            "map_rms_refined": float(np.sqrt(np.mean(error**2))),
            "map_z_refined": float(np.sqrt(np.mean((error / refined.depth_std[under]) ** 2)))}


def _fix_coverage(track, truth) -> tuple[int, int]:
    """Fixes the method used (the graph, TERCOM-PF, MLE), and how many of them hold the truth in
    their 95 % ellipse."""
    used = covered = 0
    for fix in track.fixes or ():
        if not fix.accepted:
            continue
        error = fix.position - truth[fix.index, :2]
        cov = fix.covariance
        used += 1
        covered += int(error @ np.linalg.solve(cov, error) <= 5.991464547107979)
    return used, covered


def one_run(config: dict, *, rng: np.random.Generator) -> list[dict]:
    """One survey of ``config["scenario"]`` navigated by every method: a row per method."""
    import dataclasses

    from tangraph.eval import bound_rmse, posterior_crb, track_metrics
    from tangraph.navigation import dead_reckoning_track, navigate
    from tangraph.sensors import NavigationModel

    run = _survey(config, rng)
    survey, bathymetry = run.survey, run.bathymetry
    model = NavigationModel.from_survey(survey, **config.get("model", {}))
    bound = {kind: bound_rmse(posterior_crb(survey, bathymetry, model, kind=kind))
             for kind in ("smoother", "filter")}
    # the physical limit: the same bound with the soundings' simulated noise (the model's
    # sounding_std has a margin of 1.5 over it, NavigationModel.from_survey)
    noise = dataclasses.replace(model, sounding_std=float(survey.meta["settings"]["sonar"]["depth_noise"]))
    limit = {kind: bound_rmse(posterior_crb(survey, bathymetry, noise, kind=kind))
             for kind in ("smoother", "filter")}
    truth_scale = float(survey.meta["settings"]["dead_reckoning"]["speed_scale"])
    truth_heading = float(survey.dr_pose[-1, 2] - survey.true_pose[-1, 2])
    rows = []
    dr = track_metrics(dead_reckoning_track(survey), survey.true_pose)
    rows.append({"method": "dr", **dr, "ms_per_step": 0.0, "n_fixes_accepted": -1, "n_fixes_rejected": -1,
                 "pcrb": bound["filter"], "pcrb_noise": limit["filter"], **_map_errors(run, None)})
    for method in config["methods"]:
        settings = None
        if method in GRAPH and config.get("graph"):
            from tangraph.experiments.study import graph_settings

            settings = graph_settings(config["graph"])
        if method in FILTERS:
            from tangraph.filters import ParticleConfig, default_config

            settings = default_config(method)
            if method not in ("mle", "pmf"):  # deterministic: no particles
                settings = dataclasses.replace(settings, n_particles=config["n_particles"])
            names = {f.name for f in _setting_fields(settings)}
            changes = {k: v for k, v in config.get("filter", {}).items() if k in names}
            settings = settings.replace(**changes) if isinstance(settings, ParticleConfig) else \
                dataclasses.replace(settings, **changes)
        started = time.perf_counter()
        track = navigate(survey, bathymetry, method, settings, rng=rng, model=model)
        seconds = time.perf_counter() - started
        metrics = track_metrics(track, survey.true_pose)
        kind = "smoother" if method == "smoother" else "filter"
        pcrb = bound[kind]
        calibration = track.meta.get("calibration") or {}
        heading_miss = np.angle(np.exp(1j * (calibration.get("heading_error", np.nan) - truth_heading)))
        used, covered = _fix_coverage(track, survey.true_pose)  # the graph's, TERCOM-PF's and MLE's
        rows.append(
            {
                "method": method,
                **metrics,
                "pcrb": pcrb,
                "pcrb_noise": limit[kind],
                "rmse_over_pcrb": metrics["rmse"] / pcrb,
                "scale_z": (calibration.get("speed_scale", np.nan) - truth_scale)
                / calibration.get("speed_scale_std", np.nan),
                "heading_z": float(heading_miss) / calibration.get("heading_error_std", np.nan),
                "fixes_used": used,
                "fixes_covered": covered,
                "ms_per_step": 1e3 * seconds / survey.n_pings,
                "n_fixes_accepted": int(track.meta.get("n_fixes_accepted", -1)),
                "n_fixes_rejected": int(track.meta.get("n_fixes_rejected", -1)),
                **_map_errors(run, track.meta.get("refined_map")),
            }
        )
    return rows


def summarise(table) -> list[dict]:
    from tangraph.eval import anees_band

    rows = []
    for scenario, group in table.groupby("scenario", sort=False):
        columns = ["rmse", "final_error", "rmse_over_pcrb", "anees", "final_nees", "ms_per_step",
                   "fixes_used", "fixes_covered", "confident_wrong"]
        means = group.groupby("method")[columns].mean()
        # the bound is on the mean squared error: RMSE / PCRB pooled over the runs
        pooled = group.assign(mse=group["rmse"] ** 2, bound=group["pcrb"] ** 2).groupby("method")[
            ["mse", "bound"]].mean()
        means["rmse_over_pcrb"] = np.sqrt(pooled["mse"] / pooled["bound"])
        if "pcrb_noise" in group:  # results made before the column have none
            limit = group.assign(bound=group["pcrb_noise"] ** 2).groupby("method")["bound"].mean()
            means["rmse_over_limit"] = np.sqrt(pooled["mse"] / limit)
        else:
            means["rmse_over_limit"] = np.nan
        sums = group.groupby("method")[["fixes_used", "fixes_covered"]].sum()
        refined = _refined_summary(group)
        within = group.assign(
            ok=(group["scale_z"].abs() <= 2) & (group["heading_z"].abs() <= 2)
        ).groupby("method")["ok"].mean()
        runs = int(group.groupby("method").size().min())
        filters = [m for m in means.index if m in FILTERS]
        best = means.loc[filters, "rmse"].idxmin() if filters else None
        lo, hi = anees_band(runs)
        for method in ("dr", *[m for m in GRAPH if m in means.index], *filters):
            m = means.loc[method]
            ratio = m.rmse / means.loc[best, "rmse"] if best else np.nan
            goal_pcrb = {"smoother": 1.25, "isam2": 2.0}.get(method)
            fixes = int(sums.loc[method, "fixes_used"])
            coverage = sums.loc[method, "fixes_covered"] / fixes if fixes else np.nan
            rows.append(
                {
                    "scenario": scenario,
                    "method": method + (" (best filter)" if method == best else ""),
                    "runs": runs,
                    "RMSE (m)": m.rmse,
                    "RMSE / PCRB": m.rmse_over_pcrb if method != "dr" else np.nan,
                    "RMSE / PCRB (simulated noise)": m.rmse_over_limit if method != "dr" else np.nan,
                    "PCRB goal": "" if goal_pcrb is None
                    else f"<= {goal_pcrb}: {'met' if m.rmse_over_pcrb <= goal_pcrb else 'missed'}",
                    "RMSE / best filter": ratio,
                    "final error (m)": m.final_error,
                    "ANEES (track)": m.anees,
                    "mean final NEES": m.final_nees,
                    f"final NEES in [{lo:.2f}, {hi:.2f}]": ""
                    if not np.isfinite(m.final_nees)
                    else ("yes" if lo <= m.final_nees <= hi else "no"),
                    "poses NEES > 20 not flagged lost": m.confident_wrong if method != "dr" else np.nan,
                    "calibration within 2 sigma": within.get(method, np.nan) if method != "dr" else np.nan,
                    "fixes used": fixes if fixes else np.nan,
                    "fix coverage at 0.95": coverage,
                    "ms per ping": m.ms_per_step,
                    **refined.get(method, {}),
                }
            )
    return rows


def _refined_summary(group) -> dict[str, dict]:
    """Per method that refined the map: its error against the prior map's (mean and worst run),
    the runs where it is smaller, and its RMS in its own stds (results made before these columns,
    or without a refined map, have none)."""
    if "map_rms_refined" not in group or not np.isfinite(group["map_rms_refined"]).any():
        return {}
    out = {}
    for method, runs in group[np.isfinite(group["map_rms_refined"])].groupby("method"):
        ratio = runs["map_rms_refined"] / runs["map_rms_prior"]
        z = float(np.sqrt(np.mean(runs["map_z_refined"] ** 2)))
        spread = f"{ratio.mean():.2f}, {ratio.max():.2f}"
        out[method] = {"refined map RMS / prior map's (mean, worst run)": spread,
                       "refined map better in runs": f"{int((ratio < 1).sum())} of {ratio.size}",
                       "refined map error / its std (RMS)": z}
    return out


def markdown(rows: list[dict]) -> str:
    from tangraph.eval import format_figure

    keys = list(dict.fromkeys(k for row in rows for k in row))  # a refined map's columns: some rows
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    for row in rows:
        lines.append(
            "| " + " | ".join(format_figure(row.get(k, "")) for k in keys) + " |"
        )
    return "\n".join(lines)


def figure(table, path: Path) -> None:
    from matplotlib.figure import Figure

    scenarios = list(dict.fromkeys(table["scenario"]))
    fig = Figure(figsize=(4.2 * len(scenarios), 4.0), layout="constrained")
    for ax, scenario in zip(fig.subplots(1, len(scenarios), squeeze=False)[0], scenarios, strict=True):
        group = table[table["scenario"] == scenario]
        methods = list(dict.fromkeys(group["method"]))
        ax.boxplot([group.loc[group["method"] == m, "rmse"] for m in methods], tick_labels=methods)
        ax.set_yscale("log")
        ax.set_title(scenario)
        ax.set_ylabel("RMSE per run (m)")
        ax.tick_params(axis="x", rotation=60)
    fig.savefig(path, dpi=120)


def _setting_fields(config) -> tuple:
    """The fields a ``--filter`` item may name: the config's own, and its ``health``'s (a
    particle filter's lost test, gate and recovery)."""
    import dataclasses

    from tangraph.filters import FilterHealth, ParticleConfig

    extra = dataclasses.fields(FilterHealth) if isinstance(config, ParticleConfig) else ()
    return (*dataclasses.fields(config), *extra)


def _filter_settings(items, methods) -> dict:
    """``--filter FIELD=VALUE`` items as a mapping; a field that no chosen filter's configuration
    has is refused (it would change nothing)."""

    from tangraph.errors import TangraphError
    from tangraph.experiments.study import field_values
    from tangraph.filters import default_config

    settings = field_values(items, "--filter")
    names = {f.name for m in methods if m in FILTERS for f in _setting_fields(default_config(m))}
    unknown = sorted(set(settings) - names)
    if unknown:
        raise TangraphError(f"--filter {', '.join(unknown)}: no chosen filter has such a setting")
    return settings


def _model_settings(items: dict) -> dict:
    """``--model`` settings with an angle given in degrees (``NAME_deg``) in radians."""
    import math

    return {k.removesuffix("_deg"): math.radians(float(v)) if k.endswith("_deg") else v
            for k, v in items.items()}


def _check_settings(graph: dict, model: dict) -> None:
    """Refuse ``--graph`` and ``--model`` settings that are not fields (or were moved) before any
    run starts."""
    from tangraph.experiments.study import graph_settings
    from tangraph.sensors import NavigationModel

    graph_settings(graph)
    NavigationModel.from_mapping(model, "--model")


def main(argv=None) -> int:
    from tangraph.experiments import run_many
    from tangraph.experiments.study import field_values, output_folder, study_parser

    parser = study_parser(HERE, __doc__.splitlines()[0], runs=20, seed=6,
                          quick="4 runs of PF, IPF and SJCPF: minutes")
    parser.add_argument("--particles", type=int, default=1000, help="particles of every filter")
    parser.add_argument("--scenarios", nargs="+", default=["demo", "wang2019", "han2020"], choices=SCENARIOS,
                        help="NAME-flat: over a flat seabed; NAME-map-error: a seafloor that is not the map, "
                        "navigated on a prior map gridded from a simulated earlier survey")
    parser.add_argument("--methods", nargs="+", choices=[*GRAPH, *FILTERS],
                        help="methods to run (default: the graph and every filter)")
    parser.add_argument("--graph", nargs="+", default=[], metavar="FIELD=VALUE",
                        help="GraphConfig settings of the graph's runs (values as Python literals)")
    parser.add_argument("--model", nargs="+", default=[], metavar="FIELD=VALUE",
                        help="NavigationModel settings of every method (values as Python literals)")
    parser.add_argument("--filter", nargs="+", default=[], metavar="FIELD=VALUE",
                        help="settings of every filter whose configuration has the field (values as "
                        "Python literals)")
    parser.add_argument("--dr", choices=["demo", "own"], default="demo",
                        help="the demo's drifting DR in every scenario, or each scenario's own")
    args = parser.parse_args(argv)
    methods = args.methods or [*GRAPH, *(("pf", "ipf", "sjcpf") if args.quick else FILTERS)]
    graph = field_values(args.graph)
    model = _model_settings(field_values(args.model, "--model"))
    _check_settings(graph, model)  # bad settings refused before the output folder is made
    filter_settings = _filter_settings(args.filter, methods)
    args.out = output_folder(args, HERE)
    runs = 4 if args.quick else args.runs
    configs = [
        {"scenario": s, "methods": list(methods), "n_particles": args.particles, "dr": args.dr,
         "graph": graph, "filter": filter_settings, "model": model}
        for s in args.scenarios
    ]
    table = run_many(one_run, configs, runs, args.seed, scheduler=args.scheduler, workers=args.workers)
    failed = table["error"].notna()
    if failed.any():
        print(f"{int(failed.sum())} runs failed; first error: {table.loc[failed, 'error'].iloc[0]}")
    if failed.all():
        return 1
    rows = summarise(table[~failed])
    default_scenarios = ["demo", "wang2019", "han2020"]
    tag = f"seed{args.seed}_runs{runs}" + ("_quick" if args.quick else "") + \
        ("" if args.scenarios == default_scenarios else "_" + "-".join(args.scenarios)) + \
        ("" if args.methods is None else "_" + "-".join(args.methods)) + \
        "".join(f"_{item}".replace('"', "").replace("'", "")  # no quotes in names
                for item in [*args.graph, *args.model, *args.filter])
    table.to_csv(args.out / f"runs_{tag}.csv", index=False)
    figure(table[~failed], args.out / f"rmse_{tag}.png")
    command = (
        f"tangraph experiment graph_vs_filters --runs {runs} --seed {args.seed} --particles {args.particles}"
        + (" --quick" if args.quick else "")
        + f" --scenarios {' '.join(args.scenarios)} --dr {args.dr}"
        + ("" if args.methods is None else f" --methods {' '.join(args.methods)}")
        + ("" if not args.graph else f" --graph {' '.join(shlex.quote(item) for item in args.graph)}")
        + ("" if not args.model else f" --model {' '.join(shlex.quote(item) for item in args.model)}")
        + ("" if not args.filter else f" --filter {' '.join(shlex.quote(item) for item in args.filter)}")
    )
    text = markdown(rows)
    (args.out / f"summary_{tag}.md").write_text(f"Command: `{command}`\n\n{text}\n")
    (args.out / f"config_{tag}.json").write_text(
        json.dumps({"command": command, "configs": configs}, indent=2)
    )
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
