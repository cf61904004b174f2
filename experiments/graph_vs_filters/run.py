"""Factor graph vs particle filters on the same seeded surveys of each paper's scenario.

Every run simulates one survey of a scenario with a fresh seed and navigates it with the online
iSAM2 graph, the batch smoother and the particle filters; it records each method's RMSE, final
error, ANEES and time per ping. The summary puts the graph next to the best filter of each
scenario (lowest mean RMSE over the runs) and checks the issue's goals: smoother RMSE at most
0.7x the best filter's, online graph at most 1.0x, and the graph's ANEES over the runs inside
the chi-square 95 % band. The band is exact for the mean over R runs of the final pose's NEES
(independent chi-square(2) samples: ``tangraph.eval.anees_band(R)``); the ANEES over all poses of
a track is reported too, as a guide (its poses are correlated).

    tangraph experiment graph_vs_filters [--runs 50] [--seed 6] [--quick] [--workers 2]
                                         [--scheduler ADDR] [--out DIR]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SCENARIOS = ("wang2019", "han2020", "chen2022")
FILTERS = ("pf", "ipf", "sjcpf", "jbpf", "tercom-pf", "mle")
GRAPH = ("isam2", "smoother")


def one_run(config: dict, *, rng: np.random.Generator) -> list[dict]:
    """One survey of ``config["scenario"]`` navigated by every method: a row per method."""
    import dataclasses

    from tangraph.eval import track_metrics
    from tangraph.filters import default_config
    from tangraph.maps import load_any
    from tangraph.navigation import dead_reckoning_track, navigate
    from tangraph.sim.scenario import load_scenario, simulate

    scenario = load_scenario(config["scenario"])
    bathymetry = load_any(scenario.map)
    survey = simulate(scenario, rng=rng, bathymetry=bathymetry)
    rows = []
    dr = track_metrics(dead_reckoning_track(survey), survey.true_pose)
    rows.append({"method": "dr", **dr, "ms_per_step": 0.0, "n_fixes_accepted": -1, "n_fixes_rejected": -1})
    for method in (*GRAPH, *config["filters"]):
        settings = None
        if method in FILTERS and method != "mle":
            settings = dataclasses.replace(default_config(method), n_particles=config["n_particles"])
        started = time.perf_counter()
        track = navigate(survey, bathymetry, method, settings, rng=rng)
        seconds = time.perf_counter() - started
        rows.append(
            {
                "method": method,
                **track_metrics(track, survey.true_pose),
                "ms_per_step": 1e3 * seconds / survey.n_pings,
                "n_fixes_accepted": int(track.meta.get("n_fixes_accepted", -1)),
                "n_fixes_rejected": int(track.meta.get("n_fixes_rejected", -1)),
            }
        )
    return rows


def summarise(table) -> list[dict]:
    from tangraph.eval import anees_band

    rows = []
    for scenario, group in table.groupby("scenario", sort=False):
        means = group.groupby("method")[["rmse", "final_error", "anees", "final_nees", "ms_per_step"]].mean()
        runs = int(group.groupby("method").size().min())
        filters = [m for m in means.index if m in FILTERS]
        best = means.loc[filters, "rmse"].idxmin()
        lo, hi = anees_band(runs)
        for method in ("dr", *GRAPH, *filters):
            m = means.loc[method]
            ratio = m.rmse / means.loc[best, "rmse"]
            goal = {"smoother": 0.7, "isam2": 1.0}.get(method)
            rows.append(
                {
                    "scenario": scenario,
                    "method": method + (" (best filter)" if method == best else ""),
                    "runs": runs,
                    "RMSE (m)": m.rmse,
                    "final error (m)": m.final_error,
                    "RMSE / best filter": ratio,
                    "RMSE goal": "" if goal is None else f"<= {goal}: {'met' if ratio <= goal else 'missed'}",
                    "ANEES (track)": m.anees,
                    "mean final NEES": m.final_nees,
                    f"final NEES in [{lo:.2f}, {hi:.2f}]": ""
                    if not np.isfinite(m.final_nees)
                    else ("yes" if lo <= m.final_nees <= hi else "no"),
                    "ms per ping": m.ms_per_step,
                }
            )
    return rows


def markdown(rows: list[dict]) -> str:
    from tangraph.eval import format_figure

    keys = list(rows[0])
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    for row in rows:
        lines.append(
            "| " + " | ".join(format_figure(v) for v in row.values()) + " |"
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


def main(argv=None) -> int:
    from tangraph.experiments import run_many

    parser = argparse.ArgumentParser(
        prog="tangraph experiment graph_vs_filters", description=__doc__.splitlines()[0]
    )
    parser.add_argument("--runs", type=int, default=50)
    parser.add_argument("--seed", type=int, default=6)
    parser.add_argument("--particles", type=int, default=1000, help="particles of every filter")
    parser.add_argument("--scheduler", help="Dask scheduler address (default: local processes)")
    parser.add_argument("--workers", type=int, help="local worker processes (default: all cores)")
    parser.add_argument("--quick", action="store_true", help="4 runs of PF, IPF and SJCPF: minutes")
    parser.add_argument("--scenarios", nargs="+", default=list(SCENARIOS), choices=SCENARIOS)
    parser.add_argument("--out", type=Path, default=HERE / "results", help="folder for the tables")
    args = parser.parse_args(argv)
    runs = 4 if args.quick else args.runs
    filters = ("pf", "ipf", "sjcpf") if args.quick else FILTERS
    configs = [
        {"scenario": s, "filters": list(filters), "n_particles": args.particles} for s in args.scenarios
    ]
    table = run_many(one_run, configs, runs, args.seed, scheduler=args.scheduler, workers=args.workers)
    failed = table["error"].notna()
    if failed.any():
        print(f"{int(failed.sum())} runs failed; first error: {table.loc[failed, 'error'].iloc[0]}")
    rows = summarise(table[~failed])
    tag = f"seed{args.seed}_runs{runs}" + ("_quick" if args.quick else "")
    args.out.mkdir(parents=True, exist_ok=True)
    table.to_csv(args.out / f"runs_{tag}.csv", index=False)
    figure(table[~failed], args.out / f"rmse_{tag}.png")
    command = (
        f"tangraph experiment graph_vs_filters --runs {runs} --seed {args.seed} --particles {args.particles}"
        + (" --quick" if args.quick else "")
        + f" --scenarios {' '.join(args.scenarios)}"
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
