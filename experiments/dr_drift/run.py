"""Is the dead-reckoning model honest? Monte Carlo of the final DR error against its prediction.

For each scenario, every run simulates the dead reckoning of the scenario's true trajectory with
a fresh seed. The predicted final error is the deterministic part (heading bias, speed scale:
the same run with the random terms switched off) plus a zero-mean Gaussian whose covariance is
``tangraph.sensors.increment_covariance`` from the first to the last ping, turned into the world
frame. If the model states its covariance honestly, the NEES of the random part has mean 2
(chi-square with 2 degrees of freedom), and over R runs its mean lies in the band
``chi2.ppf([0.025, 0.975], 2R) / R`` with 95 % probability.

    tangraph experiment dr_drift [--runs 200] [--seed 1] [--scheduler ADDR] [--quick] [--out DIR]
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

SCENARIOS = ("wang2019", "han2020", "han2020_1m", "chen2022")
HERE = Path(__file__).resolve().parent


def one_run(config: dict, *, rng: np.random.Generator) -> dict:
    """One seeded run: final DR error, its predicted mean and covariance, and the NEES."""
    from tangraph.maps import load_any
    from tangraph.sensors import increment_covariance, simulate_dead_reckoning
    from tangraph.sim.scenario import load_scenario, true_trajectory

    scenario = load_scenario(config["scenario"])
    time, truth = true_trajectory(scenario, load_any(scenario.map))
    model = scenario.dead_reckoning
    dr = simulate_dead_reckoning(time, truth, model, rng=rng)
    steady = dataclasses.replace(
        model, heading_walk=0.0, heading_noise=0.0, speed_noise=0.0, dropout_rate=0.0, start_position_std=0.0
    )
    mean_dr = simulate_dead_reckoning(time, truth, steady, rng=np.random.default_rng(0))
    error = dr.pose[-1, :2] - truth[-1, :2]
    mean = mean_dr.pose[-1, :2] - truth[-1, :2]
    body = increment_covariance(model, time, dr.pose, 0, time.size - 1, dvl_valid=dr.dvl_valid)[:2, :2]
    psi = dr.pose[0, 2]
    rot = np.array([[np.cos(psi), -np.sin(psi)], [np.sin(psi), np.cos(psi)]])
    cov = rot @ body @ rot.T + model.start_position_std**2 * np.eye(2)  # the start error adds as it is
    e = error - mean
    return {
        "err_north": error[0],
        "err_east": error[1],
        "mean_north": mean[0],
        "mean_east": mean[1],
        "pred_std_north": float(np.sqrt(cov[0, 0])),
        "pred_std_east": float(np.sqrt(cov[1, 1])),
        "nees": float(e @ np.linalg.solve(cov, e)),
        "distance": float(np.sum(np.hypot(*np.diff(truth[:, :2], axis=0).T))),
    }


def summarise(table):
    from scipy import stats

    rows = []
    for name, group in table.groupby("scenario", sort=False):
        r = len(group)
        lo, hi = stats.chi2.ppf([0.025, 0.975], 2 * r) / r
        final = np.hypot(group.err_north, group.err_east)
        spread = np.hypot(group.err_north - group.mean_north, group.err_east - group.mean_east)
        predicted = np.sqrt(group.pred_std_north**2 + group.pred_std_east**2)
        rows.append(
            {
                "scenario": name,
                "runs": r,
                "distance (m)": group.distance.iloc[0],
                "mean final error (m)": final.mean(),
                "RMS random part (m)": np.sqrt(np.mean(spread**2)),
                "predicted RMS random part (m)": np.sqrt(np.mean(predicted**2)),
                "mean NEES": group.nees.mean(),
                "95% band": f"[{lo:.2f}, {hi:.2f}]",
                "honest": bool(lo <= group.nees.mean() <= hi),
            }
        )
    return rows


def markdown(rows) -> str:
    keys = list(rows[0])
    lines = ["| " + " | ".join(keys) + " |", "|" + "---|" * len(keys)]
    for row in rows:
        lines.append(
            "| " + " | ".join(f"{v:.2f}" if isinstance(v, float) else str(v) for v in row.values()) + " |"
        )
    return "\n".join(lines)


def main(argv=None) -> int:
    from tangraph.experiments import run_many
    from tangraph.experiments.study import output_folder, study_parser

    parser = study_parser(HERE, __doc__.splitlines()[0], runs=200, seed=1,
                          quick="40 runs, a minute or less")
    args = parser.parse_args(argv)
    args.out = output_folder(args, HERE)
    runs = 40 if args.quick else args.runs
    configs = [{"scenario": name} for name in SCENARIOS]
    table = run_many(one_run, configs, runs, args.seed, scheduler=args.scheduler, workers=args.workers)
    failed = table["error"].notna().sum()
    if failed:
        print(f"{failed} runs failed; first error: {table.loc[table['error'].notna(), 'error'].iloc[0]}")
    rows = summarise(table[table["error"].isna()])
    table.to_csv(args.out / f"runs_seed{args.seed}_n{runs}.csv", index=False)
    text = markdown(rows)
    (args.out / f"summary_seed{args.seed}_n{runs}.md").write_text(
        f"Command: tangraph experiment dr_drift --runs {runs} --seed {args.seed}\n\n{text}\n"
    )
    (args.out / f"config_seed{args.seed}_n{runs}.json").write_text(
        json.dumps({"runs": runs, "seed": args.seed, "scenarios": list(SCENARIOS)}, indent=2)
    )
    print(text)
    return 0 if all(r["honest"] for r in rows) else 1


if __name__ == "__main__":
    raise SystemExit(main())
