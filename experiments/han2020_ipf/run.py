"""Han, Chen & Shen 2020 study: MLE vs TERCOM-PF vs IPF over matching areas of increasing entropy.

Each run simulates one short survey line across one matching area (on the 5 km synthetic chart
``han2020`` or on the real 1 m map ``lidar-dem``), with the scenario's dead-reckoning model and a
start error drawn ``N(0, init_error^2)`` per axis, and runs every method on the same survey (a
paired comparison). A patch is ``beams`` beams x ``pings`` consecutive pings, as in the paper:

- MLE and TERCOM-PF match each non-overlapping window of ``pings`` pings (``window = pings``);
- the IPF takes each patch as one measurement (the pings of a patch merged into one "ping" whose
  soundings are placed by dead reckoning relative to the patch's last ping), with the per-ping
  white noise summed over the patch, so its motion model is the same as the others'.

Every method of a run shares one ``tangraph.sensors.NavigationModel``: the scenario's simulated
dead-reckoning errors (white speed noise as it is; the constant heading bias and speed scale as
priors the filters estimate), the start error's std as ``initial_position_std``, the simulated
sounding noise and an unknown tide (prior std 3 m).

Every method is scored at the patch ends (where each has seen the same soundings): the mean
error over the area's second half of patches, and the error at the area's exit.
Parts: ``areas`` (the paper's Fig. comparing the three methods per area, both maps), ``beams``
(beam sets 40x3 .. 80x7) and ``particles`` (250 .. 4000 particles, the IPF's time per patch).
Configuration: ``config.toml`` beside this file.

    tangraph experiment han2020_ipf [--part areas|beams|particles|all] [--runs N] [--seed S]
                                    [--quick] [--workers W] [--scheduler ADDR] [--out DIR] [--replot]
"""

from __future__ import annotations

import dataclasses
import json
import time
import tomllib
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
PARTS = ("areas", "beams", "particles")
MAPS = {"synthetic": "han2020", "replay": "lidar-dem"}


def load_config() -> dict:
    with open(HERE / "config.toml", "rb") as f:
        return tomllib.load(f)


# -- the matching areas ------------------------------------------------------------------------
def matching_areas(part: str, cfg: dict) -> list[dict]:
    """The areas of one map: name, the survey line crossing it (start, end; map coordinates) and
    the box whose terrain entropy is reported."""
    from tangraph.maps import HAN2020_AREAS

    if part == "synthetic":
        out = []
        for i, ((n_lo, n_hi), (e_lo, e_hi)) in enumerate(HAN2020_AREAS):
            mid = 0.5 * (n_lo + n_hi)
            out.append(
                {
                    "name": f"S{i + 1}",
                    "start": [mid, e_lo],
                    "end": [mid, e_hi],
                    "box": [[n_lo, n_hi], [e_lo, e_hi]],
                }
            )
        return out
    from tangraph.sim import load_scenario

    scenario = load_scenario(cfg["replay"]["scenario"])
    p0, p1 = (np.asarray(p, float) for p in scenario.trajectory["points"])
    unit = (p1 - p0) / np.hypot(*(p1 - p0))
    length = cfg["replay"]["area_length"]
    half = 0.5 * length  # the box: the stretch's own extent plus the swath (about the altitude)
    out = []
    for i in range(cfg["replay"]["n_areas"]):
        a, b = p0 + unit * length * i, p0 + unit * length * (i + 1)
        mid = 0.5 * (a + b)
        out.append(
            {
                "name": f"R{i + 1}",
                "start": a.tolist(),
                "end": b.tolist(),
                "box": [[mid[0] - half, mid[0] + half], [mid[1] - half, mid[1] + half]],
            }
        )
    return out


def area_entropy(bathymetry, box) -> tuple[float, float]:
    """Terrain entropy (nats, Wang et al. 2007, literal) of the box and its deficit ``ln N - H``."""
    from tangraph.maps import region_entropy

    h = region_entropy(bathymetry, north=tuple(box[0]), east=tuple(box[1]))
    n = bathymetry.crop(north=tuple(box[0]), east=tuple(box[1])).depth.size
    return h, float(np.log(n) - h)


# -- one run -----------------------------------------------------------------------------------
_SCENES: dict = {}  # per process: the ray-casting scene of each map, built once


def simulate_line(scenario, bathymetry, start, end, *, rng: np.random.Generator):
    """``tangraph.sim.simulate`` of the scenario on the straight line ``start -> end`` (map
    coordinates), with the map's ray-casting scene kept between runs."""
    from tangraph.maps.mesh import raycasting_scene
    from tangraph.sensors import simulate_dead_reckoning, simulate_pings
    from tangraph.sim.scenario import true_trajectory
    from tangraph.survey import Survey

    corner = np.array([bathymetry.north[0], bathymetry.east[0]])
    points = [list(np.asarray(start) - corner), list(np.asarray(end) - corner)]
    scenario = dataclasses.replace(
        scenario, trajectory={"kind": "waypoints", "points": points, "speed": scenario.trajectory["speed"]}
    )
    if bathymetry.name not in _SCENES:
        _SCENES[bathymetry.name] = raycasting_scene(bathymetry)
    t, truth = true_trajectory(scenario, bathymetry)
    # the DR starts at the true start: the study adds its own start error (init_error)
    dr = simulate_dead_reckoning(t, truth, scenario.dead_reckoning, rng=rng, start_pose=truth[0])
    depth = np.full(t.size, scenario.vehicle_depth)
    pings = simulate_pings(_SCENES[bathymetry.name], truth, depth, scenario.sonar, rng=rng)
    return Survey(
        time=t,
        dr_pose=dr.pose,
        vehicle_depth=depth,
        beam_forward=pings.beam_forward,
        beam_starboard=pings.beam_starboard,
        beam_depth=pings.beam_depth,
        true_pose=truth,
        meta={"map": bathymetry.name, "scenario": scenario.name},
    )


def patch_survey(survey, pings: int):
    """The survey with each non-overlapping run of ``pings`` pings merged into one ping at the
    run's last ping: its soundings placed by dead reckoning in that ping's body frame."""
    from tangraph.survey import Survey, to_body

    ends = np.arange(pings - 1, survey.n_pings, pings)
    north, east = survey.footprints()
    fwd, stb, dep = [], [], []
    for k in ends:
        rows = slice(k - pings + 1, k + 1)
        pose = np.repeat(survey.dr_pose[k : k + 1], pings, axis=0)
        f, s = to_body(pose, north[rows], east[rows])
        fwd.append(f.ravel())
        stb.append(s.ravel())
        dep.append(survey.beam_depth[rows].ravel())
    return Survey(
        time=survey.time[ends],
        dr_pose=survey.dr_pose[ends],
        vehicle_depth=survey.vehicle_depth[ends],
        beam_forward=np.array(fwd),
        beam_starboard=np.array(stb),
        beam_depth=np.array(dep),
        true_pose=survey.true_pose[ends],
        meta=survey.meta,
    ), ends


def navigation_model(scenario, run: dict):
    """The navigation model of a run, shared by every method: the scenario's DR errors (white ones
    as simulated, constant ones as priors of mean zero), the start error's std and the map's
    sounding std; the tide is unknown (the model's prior, std 3 m)."""
    from tangraph.sensors import NavigationModel

    return NavigationModel.from_dead_reckoning(
        scenario.dead_reckoning,
        initial_position_std=run["init_error"],
        sounding_std=run["sounding_std"],
    )


def patch_model(model, pings: int):
    """The model of a patched survey (:func:`patch_survey`): the white per-ping errors summed over
    the ``P`` pings of a patch. A patch's ``dt`` and displacement are ``P`` times a ping's, and
    the model's noise std grows linearly with them (``speed_noise dt``, ``heading_noise |u|``),
    whereas ``P`` independent per-ping errors grow as ``sqrt(P)``: both are divided by
    ``sqrt(P)`` (the heading walk is per ``sqrt(s)`` and needs nothing)."""
    root = float(np.sqrt(pings))
    return model.replace(speed_noise=model.speed_noise / root, heading_noise=model.heading_noise / root)


def method_config(method: str, run: dict):
    """The config of ``method`` in a run: the defaults with the study's settings (config.toml)."""
    from tangraph.filters import default_config

    base = default_config(method)
    changes: dict = {}
    if method == "ipf":
        # a per-ping floor summed over a patch of P pings: sqrt(P) times the floor
        changes |= {
            "n_particles": run["n_particles"],
            "process_floor": run["process_floor"] * np.sqrt(run["pings"]),
        }
    elif method == "tercom-pf":
        changes |= {
            "n_particles": run["n_particles"],
            "window": run["pings"],
            "process_floor": run["process_floor"],
        }
    elif method == "mle":
        changes |= {"window": run["pings"]}
    return dataclasses.replace(base, **changes)


def one_run(config: dict, *, rng: np.random.Generator) -> list[dict]:
    """One line across one area, every method on it: a row per method."""
    from tangraph.filters import run_filter
    from tangraph.maps import load
    from tangraph.sim import load_scenario
    from tangraph.track import position_errors

    bathymetry = load(config["map"])
    scenario = load_scenario(config["scenario"])
    scenario = dataclasses.replace(
        scenario, sonar=dataclasses.replace(scenario.sonar, n_beams=config["beams"])
    )
    survey = simulate_line(scenario, bathymetry, config["start"], config["end"], rng=rng)
    offset = rng.normal(0.0, config["init_error"], 2)
    survey = survey.replace(dr_pose=survey.dr_pose + np.array([*offset, 0.0]))
    patched, ends = patch_survey(survey, config["pings"])
    truth = survey.true_pose[ends]
    n = ends.size
    distance = np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(survey.true_pose[:, :2], axis=0).T))])
    model = navigation_model(scenario, config)
    rows = []
    for method in config["methods"]:
        cfg = method_config(method, config)
        started = time.perf_counter()
        if method == "ipf":
            track = run_filter(
                method, patched, bathymetry, cfg, model=patch_model(model, config["pings"]), rng=rng
            )
        else:
            track = run_filter(method, survey, bathymetry, cfg, model=model, rng=rng)
        seconds = time.perf_counter() - started
        pose = track.pose[:, :2] if method == "ipf" else track.pose[ends, :2]
        err = np.hypot(*(pose - truth[:, :2]).T)
        row = {
            "method": method,
            "n_patches": n,
            "start_error": float(np.hypot(*offset)),
            "dr_exit_error": float(np.hypot(*(survey.dr_pose[-1, :2] - survey.true_pose[-1, :2]))),
            "mean_error": float(np.mean(err[n // 2 :])),
            "exit_error": float(err[-1]),
            "exit_err_north": float(pose[-1, 0] - truth[-1, 0]),
            "exit_err_east": float(pose[-1, 1] - truth[-1, 1]),
            "all_patch_mean_error": float(np.mean(err)),
            "seconds": seconds,
            "ms_per_patch": 1e3 * seconds / n,
            "n_divergences": int(track.meta.get("n_divergences", 0)),
            "n_lost": int(track.meta.get("n_lost", 0)),
            "n_tempered": int(track.meta.get("n_tempered", 0)),
            "exit_distance": float(distance[-1]),
        }
        for i in range(n):
            row[f"err_{i:02d}"] = float(err[i])
            row[f"dist_{i:02d}"] = float(distance[ends[i]])
        if method != "ipf":  # the per-ping track, for the record
            row["ping_mean_error"] = float(np.mean(position_errors(track, survey.true_pose)))
        rows.append(row)
    return rows


# -- configurations ----------------------------------------------------------------------------
def configurations(part: str, cfg: dict, quick: bool) -> list[dict]:
    """The run configurations of a part of the study."""
    from tangraph.maps import load

    maps = ["synthetic", "replay"] if part == "areas" else cfg["sweeps"]["maps"]
    out = []
    for which in maps:
        shared = {
            "part": part,
            "map_kind": which,
            "map": MAPS[which],
            "scenario": cfg[which]["scenario"],
            "sounding_std": cfg[which]["sounding_std"],
            "init_error": cfg[which].get("init_error", cfg["init_error"]),
            "process_floor": cfg[which]["process_floor"],
        }
        bathymetry = load(MAPS[which])
        for area in matching_areas(which, cfg):
            h, deficit = area_entropy(bathymetry, area["box"])
            base = {
                **shared,
                "area": area["name"],
                "entropy": h,
                "entropy_deficit": deficit,
                "start": area["start"],
                "end": area["end"],
            }
            if part == "areas":
                out.append(
                    {
                        **base,
                        "beams": cfg["beams"],
                        "pings": cfg["pings"],
                        "n_particles": cfg["n_particles"],
                        "methods": cfg["methods"],
                    }
                )
            elif part == "beams":
                for beams, pings in cfg["sweeps"]["beam_sets"]:
                    out.append(
                        {
                            **base,
                            "beams": beams,
                            "pings": pings,
                            "n_particles": cfg["n_particles"],
                            "methods": cfg["methods"],
                        }
                    )
            else:
                for n in cfg["sweeps"]["particles"]:
                    out.append(
                        {
                            **base,
                            "beams": cfg["beams"],
                            "pings": cfg["pings"],
                            "n_particles": n,
                            "methods": ["tercom-pf", "ipf"],
                        }
                    )
    return out


# -- tables ------------------------------------------------------------------------------------
PAPER_AREAS = {  # Han et al. 2020: entropy of the five synthetic areas and the eight replay areas
    "synthetic": [2.12, 2.25, 3.19, 3.77, 4.09],
    "replay": [2.43, 2.32, 2.24, 1.25, 2.19, 3.32, 3.77, 4.46],
}


def _fmt(x: float) -> str:
    return f"{x:.2f}" if abs(x) < 100 else f"{x:.0f}"


def table_areas(table) -> str:
    out = []
    for which, g in table.groupby("map_kind", sort=False):
        methods = list(dict.fromkeys(g["method"]))
        out += [
            f"#### {which} ({g['map'].iloc[0]}): mean error (m) over the area's second half of patches, "
            f"{g['beams'].iloc[0]} beams x {g['pings'].iloc[0]} pings, {g['n_particles'].iloc[0]} particles",
            "",
            "| area | paper entropy | our entropy H (nats) | ln N - H | runs | DR exit error | "
            + " | ".join(f"{m} mean" for m in methods)
            + " | "
            + " | ".join(f"{m} exit" for m in methods)
            + " | "
            + " | ".join(f"{m} median" for m in methods)
            + " |",
            "|" + "---|" * (6 + 3 * len(methods)),
        ]
        for i, (area, a) in enumerate(g.groupby("area", sort=False)):
            paper = PAPER_AREAS[which][i] if i < len(PAPER_AREAS[which]) else float("nan")
            by = {m: a[a["method"] == m] for m in methods}
            runs = len(by[methods[0]])
            cells = [f"{by[m].mean_error.mean():.2f} ± {by[m].mean_error.sem():.2f}" for m in methods]
            cells += [f"{by[m].exit_error.mean():.2f}" for m in methods]
            cells += [f"{by[m].mean_error.median():.2f}" for m in methods]
            out.append(
                f"| {area} | {paper:.2f} | {a.entropy.iloc[0]:.5f} | {a.entropy_deficit.iloc[0]:.2e} | "
                f"{runs} | "
                f"{by[methods[0]].dr_exit_error.mean():.2f} | " + " | ".join(cells) + " |"
            )
        out.append("")
    return "\n".join(out)


def table_beams(table) -> str:
    out = []
    for which, g in table.groupby("map_kind", sort=False):
        methods = list(dict.fromkeys(g["method"]))
        out += [
            f"#### {which} ({g['map'].iloc[0]}): error (m) over all areas by beam set, "
            "mean and median over runs",
            "",
            "| beams x pings | soundings per patch | runs per area | "
            + " | ".join(f"{m} mean | {m} median" for m in methods)
            + " |",
            "|" + "---|" * (3 + 2 * len(methods)),
        ]
        for (b, p), s in g.groupby(["beams", "pings"], sort=False):
            cells = [
                f"{s[s.method == m].mean_error.mean():.2f} | {s[s.method == m].mean_error.median():.2f}"
                for m in methods
            ]
            runs = len(s[(s.method == methods[0]) & (s.area == s.area.iloc[0])])
            out.append(f"| {b}x{p} | {b * p} | {runs} | " + " | ".join(cells) + " |")
        out.append("")
    return "\n".join(out)


def table_particles(table) -> str:
    out = []
    for which, g in table.groupby("map_kind", sort=False):
        methods = list(dict.fromkeys(g["method"]))
        out += [
            f"#### {which} ({g['map'].iloc[0]}): mean error (m) over all areas and time per patch (ms)",
            "",
            "| particles | runs per area | "
            + " | ".join(f"{m} error | {m} ms/patch" for m in methods)
            + " |",
            "|" + "---|" * (2 + 2 * len(methods)),
        ]
        for n, s in g.groupby("n_particles", sort=True):
            cells = []
            for m in methods:
                sm = s[s.method == m]
                cells += [f"{sm.mean_error.mean():.2f}", f"{sm.ms_per_patch.median():.2f}"]
            runs = len(s[(s.method == methods[0]) & (s.area == s.area.iloc[0])])
            out.append(f"| {n} | {runs} | " + " | ".join(cells) + " |")
        out.append("")
    return "\n".join(out)


TABLES = {"areas": table_areas, "beams": table_beams, "particles": table_particles}


# -- figures -----------------------------------------------------------------------------------
def figure_error_vs_distance(table, path: Path) -> Path:
    """Mean error (over runs) at each patch end against distance along the path, per method."""
    from matplotlib.figure import Figure

    kinds = list(dict.fromkeys(table["map_kind"]))
    fig = Figure(figsize=(11, 3.4 * len(kinds)), layout="constrained")
    axes = fig.subplots(len(kinds), 1, squeeze=False)[:, 0]
    colours = {"mle": "tab:red", "tercom-pf": "tab:orange", "ipf": "tab:blue"}
    for ax, which in zip(axes, kinds, strict=True):
        g = table[table.map_kind == which]
        for j, (area, a) in enumerate(g.groupby("area", sort=False)):
            for method, m in a.groupby("method", sort=False):
                n = int(m.n_patches.iloc[0])
                err = m[[f"err_{i:02d}" for i in range(n)]].mean().to_numpy()
                offset = j * float(m.exit_distance.iloc[0])
                dist = offset + m[[f"dist_{i:02d}" for i in range(n)]].iloc[0].to_numpy()
                ax.plot(
                    dist, err, "o-", ms=3, color=colours.get(method, "k"), label=method if j == 0 else None
                )
            ax.axvline(offset, color="0.7", lw=0.6)
            ax.text(
                offset + 5,
                0.98,
                f"{area}  H-def {a.entropy_deficit.iloc[0]:.1e}",
                fontsize="x-small",
                transform=ax.get_xaxis_transform(),
                va="top",
            )
        ax.set_yscale("log")
        ax.set_xlabel("distance along the areas' lines, laid end to end (m)")
        ax.set_ylabel("mean error (m)")
        ax.set_title(
            f"{which} ({g['map'].iloc[0]}): error at each patch end, mean over runs", fontsize="medium"
        )
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize="small")
    fig.savefig(path, dpi=120)
    return path


def figure_estimates_on_map(table, path: Path) -> Path:
    """Each run's estimate at the area's exit, per method, on the hill-shaded map around the exit."""
    from matplotlib.figure import Figure

    from tangraph.maps import load
    from tangraph.plot import plot_map

    kinds = list(dict.fromkeys(table["map_kind"]))
    n_cols = max(table[table.map_kind == k]["area"].nunique() for k in kinds)
    fig = Figure(figsize=(2.6 * n_cols, 2.9 * len(kinds)), layout="constrained")
    axes = fig.subplots(len(kinds), n_cols, squeeze=False)
    colours = {"mle": "tab:red", "tercom-pf": "tab:orange", "ipf": "tab:blue"}
    for row, which in enumerate(kinds):
        g = table[table.map_kind == which]
        bathymetry = load(g["map"].iloc[0])
        for col, (area, a) in enumerate(g.groupby("area", sort=False)):
            ax = axes[row, col]
            exit_ = np.array(json.loads(a.end.iloc[0]) if isinstance(a.end.iloc[0], str) else a.end.iloc[0])
            radius = np.hypot(a.exit_err_north, a.exit_err_east)
            half = float(np.clip(1.3 * np.quantile(radius, 0.9), 1.5, 4.0 * float(a.init_error.iloc[0])))
            outside = {m: int((r > half).sum()) for m, r in radius.groupby(a["method"], sort=False)}
            pad = half + 3.0 * max(bathymetry.cell_size)
            crop = bathymetry.crop(
                north=(exit_[0] - pad, exit_[0] + pad), east=(exit_[1] - pad, exit_[1] + pad)
            )
            off = ", ".join(f"{m} {k}" for m, k in outside.items() if k)
            title = f"{which} {area}" + (f"\noutside: {off}" if off else "")
            plot_map(crop, ax, title=title, colorbar=False)
            ax.title.set_fontsize("small")
            for method, m in a.groupby("method", sort=False):
                ax.plot(
                    exit_[1] + m.exit_err_east,
                    exit_[0] + m.exit_err_north,
                    ".",
                    ms=5,
                    alpha=0.6,
                    color=colours.get(method, "k"),
                    label=method,
                )
            ax.plot(exit_[1], exit_[0], "k+", ms=10, mew=1.5, label="truth")
            ax.set_xlim(exit_[1] - half, exit_[1] + half)
            ax.set_ylim(exit_[0] - half, exit_[0] + half)
            ax.tick_params(labelsize="x-small")
            ax.set_xlabel("")
            ax.set_ylabel("")
        for col in range(g["area"].nunique(), n_cols):
            axes[row, col].set_axis_off()
    axes[0, 0].legend(fontsize="x-small", loc="lower left")
    fig.savefig(path, dpi=110)
    return path


def _read_runs(csv: Path, config_json: Path):
    """A saved runs table, with the runner's metadata of its config file."""
    import pandas as pd

    table = pd.read_csv(csv)
    table.attrs["tangraph"] = json.loads(config_json.read_text()).get("runner") or {}
    return table


CHECKED = (
    "mean_error",
    "exit_error",
    "ms_per_patch",
)  # every run must give finite values (the smoke test `--quick --runs 2`)


def _runs_path(out: Path, tag: str) -> Path:
    """The saved runs table of a tag (gzipped CSV; plain CSV from earlier versions)."""
    gz = out / f"runs_{tag}.csv.gz"
    return gz if gz.exists() else out / f"runs_{tag}.csv"


# -- main --------------------------------------------------------------------------------------
def main(argv=None) -> int:
    from tangraph.experiments import run_many
    from tangraph.experiments.study import output_folder, study_parser

    parser = study_parser(HERE, __doc__.splitlines()[0], runs=None, seed=2020,
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
    parts = PARTS if args.part == "all" else (args.part,)
    status = 0
    for part in parts:
        default = cfg["runs"] if part == "areas" else cfg["sweep_runs"]
        if args.quick:
            default = cfg["quick_runs"] if part == "areas" else cfg["quick_sweep_runs"]
        runs = args.runs or default
        configs = configurations(part, cfg, args.quick)
        tag = f"{part}_seed{args.seed}_runs{runs}{'_quick' if args.quick else ''}"
        if args.replot:
            table = _read_runs(_runs_path(args.out, tag), args.out / f"config_{tag}.json")
        else:
            table = run_many(
                one_run, configs, runs, args.seed, scheduler=args.scheduler, workers=args.workers
            )
        failed = table["error"].notna()
        if failed.all():
            print(f"{part}: every run failed; the first: {table['error'].iloc[0]}")
            status = 1
            continue
        bad = ~np.isfinite(table.loc[~failed, list(CHECKED)].to_numpy(float)).all(axis=1)
        if bad.any():
            print(f"{part}: {int(bad.sum())} result rows hold non-finite {CHECKED}")
            status = 1
        if failed.any():
            print(f"{part}: {int(failed.sum())} runs failed; the first: {table.loc[failed, 'error'].iloc[0]}")
            status = 1
        if not args.replot:
            table.to_csv(args.out / f"runs_{tag}.csv.gz", index=False)
        ok = table[~failed]
        text = TABLES[part](ok)
        command = (
            f"tangraph experiment han2020_ipf --part {part} --runs {runs} --seed {args.seed}"
            f"{' --quick' if args.quick else ''}"
        )
        wall = table.attrs.get("tangraph", {}).get("wall_time_s", float("nan"))
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
                    "runner": table.attrs.get("tangraph"),
                    **cfg,
                },
                indent=2,
                default=str,
            )
        )
        if part == "areas":
            for fig in (
                figure_error_vs_distance(ok, args.out / f"error_vs_distance_{tag}.png"),
                figure_estimates_on_map(ok, args.out / f"exit_estimates_{tag}.png"),
            ):
                print(f"wrote {fig}")
        print(header + text)
    return status


if __name__ == "__main__":
    raise SystemExit(main())
