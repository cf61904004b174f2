"""Robustness: bad ping blocks, a wrong start and leaving the map, against the same survey clean.

Every run simulates one `demo` survey (multibeam lawnmower on the real Merimbula map, drifting
dead reckoning) with a fresh seed and navigates it, clean and spoiled in each of these ways
(:mod:`tangraph.sim.faults`), with the same methods and the same navigation model:

- ``shift-F``: F % of the pings, in blocks of 20, have every swath footprint moved 30 m in one
  direction per block (the soundings measured in one place and recorded in another);
- ``bias-F``: F % of the pings, in blocks of 20, have every depth off by 3-10 m (one value and
  sign per block);
- ``start-200``: the whole dead-reckoned track starts 200 m from the truth (a random direction)
  while the navigation model says 10 m;
- ``half-map``: the map holds no depth east of 1100 m, so the survey leaves it about halfway;
- ``off-map``: the map holds no depth within 1 km of the survey (a map of another part of the
  lake): no sounding can be matched anywhere.

Per run and method it records the RMSE, final error, ANEES, final NEES, the share of poses
flagged lost and the share of *confident wrong* poses (NEES above 20 and not flagged lost),
and for ``half-map`` the RMSE and ANEES of the poses off the map. The summary pools the RMSE
over runs (sqrt of the mean squared RMSE), gives its ratio to the clean survey's for the same
method, and checks the goals: every outlier case <= 1.5 x the clean RMSE with the mean final
NEES inside its chi-square band; no confident wrong pose after a wrong start; honest NEES off
the map; a particle filter entirely off the map no worse than the dead reckoning and as honest.

    tangraph experiment robustness [--runs 12] [--seed 13] [--workers 2] [--cases ...]
                                   [--methods isam2 smoother pf] [--graph FIELD=VALUE ...]
                                   [--quick] [--out DIR]
"""

from __future__ import annotations

import json
import shlex
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
CASES = ("clean", "shift-10", "shift-20", "shift-30", "bias-10", "bias-20", "bias-30", "start-200",
         "half-map", "off-map")
METHODS = ("isam2", "smoother", "pf")
HALF_MAP_EAST = 1100.0  # m: the map's east limit in "half-map"
OFF_MAP_EAST = 2500.0  # m: the map's west limit in "off-map" (the survey lies 1 km west of it)


def _case(name: str, survey, bathymetry, rng):
    """The survey and map of one case."""
    import dataclasses

    from tangraph.sim.faults import offset_start, outlier_blocks

    if name == "clean":
        return survey, bathymetry
    if name.startswith(("shift-", "bias-")):
        kind, percent = name.split("-")
        kind = {"shift": "footprint_shift", "bias": "depth_bias"}[kind]
        return outlier_blocks(survey, kind, int(percent) / 100.0, rng=rng), bathymetry
    if name == "start-200":
        angle = rng.uniform(0.0, 2.0 * np.pi)
        return offset_start(survey, 200.0 * np.array([np.cos(angle), np.sin(angle)])), bathymetry
    depth = np.array(bathymetry.depth)
    if name == "half-map":
        depth[:, bathymetry.east > HALF_MAP_EAST] = np.nan
    elif name == "off-map":
        depth[:, bathymetry.east < OFF_MAP_EAST] = np.nan
    else:
        raise ValueError(f"unknown case {name!r}")
    return survey, dataclasses.replace(bathymetry, depth=depth, name=f"{bathymetry.name}-{name}")


def one_run(config: dict, *, rng: np.random.Generator) -> list[dict]:
    """One survey, every case and method: a row per (case, method), and the dead reckoning's.
    The particle and point-mass filters run with ``ping_gate=True``, their defence against bad
    pings."""

    from tangraph.eval import position_nees, track_metrics
    from tangraph.maps import load_any
    from tangraph.navigation import dead_reckoning_track, navigate
    from tangraph.sensors import NavigationModel
    from tangraph.sim.scenario import load_scenario, simulate
    from tangraph.track import position_errors

    scenario = load_scenario("demo")
    bathymetry = load_any(scenario.map)
    streams = rng.spawn(1 + 2 * len(CASES))
    survey = simulate(scenario, rng=streams[0], bathymetry=bathymetry)
    model = NavigationModel.from_survey(survey)
    rows = []
    for n, case in enumerate(CASES):
        if case not in config["cases"]:
            continue
        spoiled, chart = _case(case, survey, bathymetry, streams[1 + 2 * n])
        on_map = np.isfinite(chart.depth_at(survey.true_pose[:, 0], survey.true_pose[:, 1]))
        tracks = {"dr": dead_reckoning_track(spoiled)}
        seconds = {"dr": 0.0}
        for method in config["methods"]:
            settings = None
            if method in ("isam2", "smoother") and config.get("graph"):
                from tangraph.experiments.study import graph_settings

                settings = graph_settings(config["graph"])
            if method in ("pf", "ipf", "sjcpf", "pmf"):  # with its defence against bad pings
                from tangraph.filters import PMFConfig, default_config

                settings = PMFConfig(ping_gate=True) if method == "pmf" else \
                    default_config(method).replace(ping_gate=True)
            started = time.perf_counter()
            tracks[method] = navigate(spoiled, chart, method, rng=streams[2 + 2 * n], model=model,
                                      config=settings, other_map=case in ("half-map", "off-map"))
            seconds[method] = time.perf_counter() - started
        for method, track in tracks.items():
            metrics = track_metrics(track, spoiled.true_pose)
            errors = position_errors(track, spoiled.true_pose)
            nees = position_nees(track, spoiled.true_pose)
            off = ~on_map
            meta = track.meta
            rows.append({
                "case": case, "method": method, **metrics,
                "rmse_off_map": float(np.sqrt(np.mean(errors[off] ** 2))) if off.any() else np.nan,
                "anees_off_map": float(np.nanmean(nees[off])) if off.any() and method != "dr" else np.nan,
                "fixes_accepted": int(meta.get("n_fixes_accepted", -1)),
                "fixes_outlier": sum(f.status.value == "outlier" for f in track.fixes or ()),
                "lost_episodes": len(meta.get("lost_episodes", [])),
                "start_prior": meta.get("start_prior", ""),
                "n_off_map": int(meta.get("n_off_map", 0)),
                "seconds": seconds[method],
            })
    return rows


def summarise(table) -> list[dict]:
    """One row per (case, method): pooled RMSE, its ratio to the clean survey's, consistency and
    the goal each case is held to."""
    from tangraph.eval import anees_band

    rows = []
    pooled = table.assign(mse=table["rmse"] ** 2).groupby(["case", "method"])["mse"].mean() ** 0.5
    for (case, method), group in table.groupby(["case", "method"], sort=False):
        runs = len(group)
        lo, hi = anees_band(runs)
        rmse = float(pooled[(case, method)])
        clean = float(pooled.get(("clean", method), np.nan))
        final_nees = float(group["final_nees"].mean())
        honest = lo <= final_nees <= hi if np.isfinite(final_nees) else False
        ratio = rmse / clean if case != "clean" else np.nan
        wrong = float(group["confident_wrong"].max())
        goal = ""
        if method != "dr":
            if case.startswith(("shift", "bias")) and method in ("isam2", "smoother"):
                goal = f"<= 1.5x clean, NEES honest: {'met' if ratio <= 1.5 and honest else 'missed'}"
            elif case == "start-200":
                goal = f"no confident wrong pose: {'met' if wrong == 0 else 'missed'}"
            elif case == "half-map":
                off = float(group["anees_off_map"].mean())
                goal = f"honest off the map (ANEES {off:.2f}): {'met' if off <= hi and honest else 'missed'}"
            elif case == "off-map":
                dr = float(pooled[(case, "dr")])
                goal = f"<= 1.1x DR, NEES honest: {'met' if rmse <= 1.1 * dr and honest else 'missed'}"
        rows.append({
            "case": case, "method": method, "runs": runs, "RMSE (m)": rmse,
            "RMSE / clean": ratio,
            "worst run / its clean": float(np.nan) if case == "clean" else np.nan,
            "final error (m)": float(group["final_error"].mean()),
            "ANEES (track)": float(group["anees"].mean()),
            f"mean final NEES (band {lo:.2f}-{hi:.2f})": final_nees,
            "poses flagged lost": float(group["lost_fraction"].mean()),
            "confident wrong (max over runs)": wrong,
            "fixes used": float(group["fixes_accepted"].mean()) if method in ("isam2", "smoother")
            else np.nan,
            "goal": goal,
        })
    per_run = table.set_index(["run", "method", "case"])["rmse"] if "run" in table else None
    if per_run is not None:
        for row in rows:
            if row["case"] == "clean":
                continue
            try:
                mine = per_run.xs((row["method"], row["case"]), level=("method", "case"))
                clean = per_run.xs((row["method"], "clean"), level=("method", "case"))
                row["worst run / its clean"] = float((mine / clean).max())
            except KeyError:
                pass
    return rows


def markdown(rows: list[dict]) -> str:
    from tangraph.eval import format_figure

    keys = list(rows[0])
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    lines += ["| " + " | ".join(format_figure(v) for v in row.values()) + " |" for row in rows]
    return "\n".join(lines)


def figure(table, path: Path) -> None:
    """RMSE per run and case, one panel per method, log scale."""
    from matplotlib.figure import Figure

    methods = [m for m in dict.fromkeys(table["method"]) if m != "dr"]
    cases = list(dict.fromkeys(table["case"]))
    fig = Figure(figsize=(4.6 * len(methods), 4.2), layout="constrained")
    for ax, method in zip(fig.subplots(1, len(methods), squeeze=False)[0], methods, strict=True):
        group = table[table["method"] == method]
        ax.boxplot([group.loc[group["case"] == c, "rmse"] for c in cases], tick_labels=cases)
        ax.set_yscale("log")
        ax.set_title(method)
        ax.set_ylabel("RMSE per run (m)")
        ax.tick_params(axis="x", rotation=60)
    fig.savefig(path, dpi=120)


def main(argv=None) -> int:
    from tangraph.experiments import run_many
    from tangraph.experiments.study import field_values, graph_settings, output_folder, study_parser

    parser = study_parser(HERE, __doc__.splitlines()[0], runs=12, seed=13,
                          quick="3 runs of the graph on clean, shift-30 and start-200")
    parser.add_argument("--cases", nargs="+", default=list(CASES), choices=CASES)
    parser.add_argument("--methods", nargs="+", default=list(METHODS),
                        choices=["isam2", "smoother", "pf", "ipf", "sjcpf", "pmf"])
    parser.add_argument("--graph", nargs="+", default=[], metavar="FIELD=VALUE",
                        help="GraphConfig settings of the graph's runs (values as Python literals)")
    args = parser.parse_args(argv)
    graph = field_values(args.graph)
    graph_settings(graph)  # a bad field refused before any run, and before the output folder
    args.out = output_folder(args, HERE)
    runs = 3 if args.quick else args.runs
    cases = ["clean", "shift-30", "start-200"] if args.quick else args.cases
    methods = ["isam2", "smoother"] if args.quick else args.methods
    config = {"cases": cases, "methods": methods, "graph": graph}
    table = run_many(one_run, [config], runs, args.seed, scheduler=args.scheduler, workers=args.workers)
    failed = table["error"].notna()
    if failed.any():
        print(f"{int(failed.sum())} runs failed; first error: {table.loc[failed, 'error'].iloc[0]}")
    if failed.all():
        return 1
    table = table[~failed]
    rows = summarise(table)
    tag = (f"seed{args.seed}_runs{runs}" + ("_quick" if args.quick else "")
           + "".join(f"_{item}".replace('"', "").replace("'", "") for item in args.graph))  # no quotes
    command = (f"tangraph experiment robustness --runs {runs} --seed {args.seed}"
               + (" --quick" if args.quick else f" --cases {' '.join(cases)} --methods {' '.join(methods)}")
               + ("" if not args.graph else f" --graph {' '.join(shlex.quote(item) for item in args.graph)}"))
    table.to_csv(args.out / f"runs_{tag}.csv", index=False)
    figure(table, args.out / f"rmse_{tag}.png")
    text = markdown(rows)
    (args.out / f"summary_{tag}.md").write_text(f"Command: `{command}`\n\n{text}\n")
    (args.out / f"config_{tag}.json").write_text(json.dumps({"command": command, **config}, indent=2))
    print(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
