"""``tangraph demo``: the whole idea on one real map, in a few minutes.

Simulate a multibeam survey whose dead reckoning drifts, navigate it with the online iSAM2
graph (with TAP fixes, and found by a point-mass filter then tracking on every sounding), the
batch smoother, three particle filters (PF, IPF, SJCPF) and the point-mass filter,
and write a report with figures: the tracks over the hill-shaded map, the position error against
time with the graph's 2-sigma bound, one terrain fix close up with its Xie, Wang and calibrated
regions, and a table of RMSE, final error, NEES, time per step and fixes used.

The report folder is built beside the destination and renamed into place only when complete,
so an interrupted demo (Ctrl-C or SIGTERM) leaves no half-written report, and an existing folder
is replaced only when asked (``force``). The hidden folder is ``.NAME.partial-PID``; one left by a
process that was killed outright (SIGKILL, a power cut) is removed by the next demo writing to the
same place, never one whose process still runs.
"""

from __future__ import annotations

import dataclasses
import datetime
import json
import logging
import os
import shutil
import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from tangraph.errors import TangraphError
from tangraph.outputs import Terminated, deferred_signals, remove_stale_partials, sigterm_exits
from tangraph.track import Track

if TYPE_CHECKING:
    from tangraph.maps.grid import BathymetryMap
    from tangraph.survey import Survey

__all__ = ["DEMO_SCENARIOS", "DemoResult", "run_demo"]

# Which scenario the demo simulates on each map (the trajectory is laid out for that map).
DEMO_SCENARIOS = {
    "merimbula": "demo",
    "lidar-dem": "han2020_1m",
    "han2020": "han2020",
    "polar500": "chen2022",
}
FILTERS = ("pf", "ipf", "sjcpf", "pmf")
PARTICLE_FILTERS = ("pf", "ipf", "sjcpf")
# the online graph found by a point-mass filter, then tracking on every sounding (its row's label)
TRACKING = "isam2 tracking"
GRAPHS = ("isam2", TRACKING, "smoother")

log = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True)
class DemoResult:
    """What the demo wrote and measured."""

    out: Path
    report: Path
    rows: list[dict]  # one per method: method, rmse, final_error, max_error, anees, ms_per_step, fixes
    figures: dict[str, Path]
    seconds: float


def _scenario_for(map_name: str, map_error: bool = False) -> str:
    from tangraph.maps import catalogue
    from tangraph.sim.scenario import list_scenarios

    if map_name in DEMO_SCENARIOS:
        name = DEMO_SCENARIOS[map_name]
        if not map_error:
            return name
        if f"{name}-map-error" not in list_scenarios():
            known = list_scenarios()
            with_error = ", ".join(m for m, s in DEMO_SCENARIOS.items() if f"{s}-map-error" in known)
            raise TangraphError(f"the demo on map {map_name!r} has no variant whose seafloor is not the map; "
                                f"--map-error runs on: {with_error}")
        return f"{name}-map-error"
    runs_on = ", ".join(DEMO_SCENARIOS)
    if map_name in catalogue():
        raise TangraphError(
            f"the demo has no survey laid out on map {map_name!r}; it runs on: {runs_on} "
            f"(`tangraph simulate` with a scenario of your own works on any map)"
        )
    raise TangraphError(f"unknown map {map_name!r}; the demo runs on: {runs_on}")


def _row(label: str, track: Track, survey, bounds: dict) -> dict:
    """One line of the table; ``bounds`` holds the survey's smoother and filter PCRB: the smoother
    is held to the smoother bound, every causal estimator to the filter bound."""
    from tangraph.eval import bound_rmse, track_metrics

    m = track_metrics(track, survey.true_pose)
    bound = bounds["smoother"] if label == "smoother" else bounds["filter"]
    calibration = track.meta.get("calibration") or {}
    fixes = (
        f"{track.meta['n_fixes_accepted']} / {track.meta['n_fixes_rejected']}"
        if "n_fixes_accepted" in track.meta
        else ""
    )
    return {
        "method": label,
        "rmse": m["rmse"],
        "final_error": m["final_error"],
        "max_error": m["max_error"],
        "anees": m["anees"],
        "final_nees": m["final_nees"],
        "rmse_over_pcrb": m["rmse"] / bound_rmse(bound) if label != "dead reckoning" else float("nan"),
        "speed_scale": calibration.get("speed_scale", float("nan")),
        "speed_scale_std": calibration.get("speed_scale_std", float("nan")),
        "heading_error_deg": float(np.degrees(calibration.get("heading_error", float("nan")))),
        "heading_error_std_deg": float(np.degrees(calibration.get("heading_error_std", float("nan")))),
        "ms_per_step": 1e3 * track.timings.get("per_step", float("nan")),
        "fixes": fixes,
    }


def format_table(rows: list[dict]) -> str:
    """The demo's table as Markdown (also readable on a terminal)."""
    from tangraph.eval import format_figure

    head = (
        "| method | RMSE (m) | RMSE / PCRB | final error (m) | max error (m) | ANEES | final NEES "
        "| speed scale (%) | heading error (deg) | ms per ping | fixes used / refused |"
    )
    lines = [head, "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|"]

    def pm(value, std, scale=1.0):
        return "" if not np.isfinite(value) else f"{scale * value:+.2f} +- {scale * std:.2f}"

    for r in rows:
        cells = [r["method"], *(format_figure(r[k]) for k in ("rmse", "rmse_over_pcrb", "final_error",
                                                               "max_error", "anees", "final_nees")),
                 pm(r["speed_scale"], r["speed_scale_std"], 100.0),
                 pm(r["heading_error_deg"], r["heading_error_std_deg"]),
                 format_figure(r["ms_per_step"]), r["fixes"]]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _fix_close_up(survey, bathymetry, smoother: Track, path: Path) -> None:
    """One accepted fix of the smoother, searched again on a finer grid around it (the patch laid
    with the smoothed track, as the smoother's re-matching lays it: the calibrated DR) to show its
    three regions."""
    from matplotlib.figure import Figure

    from tangraph.matching import MatchingError, TapConfig, tap_fix_patch, window_patch
    from tangraph.plot import plot_fix

    fixes = [f for f in smoother.fixes or () if f.accepted]
    fixes = fixes or [f for f in smoother.fixes or () if np.isfinite(f.north)]
    if not fixes:
        raise TangraphError("the demo's smoother made no terrain fix to show")
    chosen = fixes[len(fixes) // 2]
    end = int(chosen.index)
    n_pings = int(smoother.meta["config"]["fixes"]["n_pings"])
    centre = chosen.position
    try:  # a finer grid than the navigator's, centred on its fix, to show the regions' shapes
        patch = window_patch(survey, end, n_pings, poses=smoother.pose[end - n_pings + 1 : end + 1])
        fix = tap_fix_patch(patch, bathymetry, TapConfig(half_width=40.0, step=2.0), prior=centre)
    except MatchingError as exc:
        raise TangraphError(f"the demo could not redo the fix at ping {end}: {exc}") from None
    fig = Figure(figsize=(7.5, 6.5), layout="constrained")
    plot_fix(fix, fig.add_subplot(), truth=survey.true_pose[end, :2])
    fig.savefig(path, dpi=120)


def _figures(folder: Path, survey, bathymetry, tracks: dict[str, Track]) -> dict[str, Path]:
    from matplotlib.figure import Figure

    from tangraph.plot import plot_errors, plot_tracks

    paths = {"tracks": folder / "tracks.png", "errors": folder / "errors.png", "fix": folder / "fix.png"}
    fig = Figure(figsize=(9, 8.5), layout="constrained")
    plot_tracks(
        tracks,
        bathymetry,
        fig.add_subplot(),
        truth=survey.true_pose,
        ellipses="smoother",
        title=f"{survey.meta.get('scenario')} on {bathymetry.name}: estimated tracks",
    )
    fig.savefig(paths["tracks"], dpi=110)
    fig = Figure(figsize=(10, 4.8), layout="constrained")
    plot_errors(tracks, survey.true_pose, fig.add_subplot(), bound="isam2", title="Horizontal position error")
    fig.savefig(paths["errors"], dpi=110)
    _fix_close_up(survey, bathymetry, tracks["smoother"], paths["fix"])
    return paths


def _report(folder: Path, survey, bathymetry, rows, settings: dict, seconds: float) -> Path:
    by = {r["method"]: r for r in rows}
    dr, best_filter = by["dead reckoning"], min((by[f] for f in FILTERS), key=lambda r: r["rmse"])
    smoother, online, tracking = by["smoother"], by["isam2"], by[TRACKING]
    quick = " --quick" if settings["quick"] else ""
    error_option = " --map-error" if settings.get("map_error") else ""
    world = ""
    if settings.get("map_error"):
        world = (f"\nThe seafloor is not the map: the soundings see the map plus relief it never had, and "
                 f"every estimator navigates on `prior_map.nc`, gridded from a simulated earlier survey of "
                 f"that seafloor (its true error: RMS {survey.meta['seafloor']['map_error_rms']:.2f} m), "
                 "with the map's own error std and correlation length in its terrain model.\n")
    dr_settings = survey.meta["settings"]["dead_reckoning"]
    truth_heading = float(np.degrees(survey.dr_pose[-1, 2] - survey.true_pose[-1, 2]))
    bias_deg = float(np.degrees(dr_settings["heading_bias"]))
    text = f"""# tangraph demo: terrain-aided navigation on {bathymetry.name}

A simulated survey ({survey.meta.get("scenario")}: {survey.n_pings} pings of {survey.n_beams} beams
over {survey.time[-1] - survey.time[0]:.0f} s) with drifting dead reckoning, navigated by the
online factor graph (iSAM2 with terrain-aided position fixes as priors), the batch smoother and
three particle filters and the point-mass filter on the same soundings.
{world}
- Dead reckoning drifts up to {dr["max_error"]:.1f} m from the truth (final {dr["final_error"]:.1f} m,
  RMSE {dr["rmse"]:.1f} m).
- The batch smoother: RMSE {smoother["rmse"]:.2f} m ({smoother["rmse"] / best_filter["rmse"]:.2f} x the best
  filter, {best_filter["method"]}, at {best_filter["rmse"]:.2f} m); the online graph:
  RMSE {online["rmse"]:.2f} m ({online["rmse"] / best_filter["rmse"]:.2f} x); the online graph found by the
  point-mass filter and tracking on every sounding (`{TRACKING}`: `GraphConfig` `terrain = "soundings"`,
  `acquire = "pmf"`, for clean data on a map that errs as it states):
  RMSE {tracking["rmse"]:.2f} m ({tracking["rmse"] / best_filter["rmse"]:.2f} x).
- The graph and the filters estimate the dead reckoning's constant errors (the simulated DVL reads
  {100 * dr_settings["speed_scale"]:+.1f} % fast, the compass is {bias_deg:+.1f} deg off; the true
  heading error at the last ping, bias and walk, is {truth_heading:+.2f} deg).
- RMSE / PCRB: the RMSE over the posterior Cramér-Rao bound of this survey (the smoother against
  the smoother bound, every causal estimator against the filter bound): 1 is the physical limit
  on average over runs. One run can fall below it where the start uncertainty (10 m) dominates
  the bound, as the start error drawn in this run may be smaller; the graph_vs_filters study
  averages 20 runs.
- ANEES near 2 means the covariance is honest (a 2-D error normalised by its covariance; over
  the correlated poses of one track it is a guide, not a test).

{format_table(rows)}

![tracks](tracks.png)

*Tracks over the hill-shaded map; thin rings: the smoother's 95 % ellipses.*

![errors](errors.png)

*Horizontal error against time; the band is the online graph's 2-sigma radius.*

![fix](fix.png)

*One of the smoother's terrain-aided fixes, re-made on a finer grid around it (patch laid with the
smoothed track: the calibrated dead reckoning): the criterion surface, the Xie, Wang and
calibrated 95 % regions, the fix's covariance ellipse and the truth.*

Made by `tangraph demo --map {settings["map"]} --seed {settings["seed"]}{quick}{error_option}` in
{seconds:.0f} s ({datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M UTC")}); settings in
`settings.json`, the survey in `survey.nc`, every track in `tracks/` (CSV with latitude/longitude
where the map has a CRS).
"""
    path = folder / "report.md"
    path.write_text(text)
    return path


def _stages(progress: bool):
    from tqdm.auto import tqdm

    names = ["simulate", *GRAPHS, *FILTERS, "figures"]
    return tqdm(total=len(names), desc="demo", unit="stage", disable=not progress, leave=False), names


def run_demo(
    out: str | os.PathLike = "demo",
    *,
    map_name: str = "merimbula",
    seed: int = 7,
    quick: bool = False,
    force: bool = False,
    progress: bool = True,
    map_error: bool = False,
) -> DemoResult:
    """Run the demo and write ``out/report.md`` with its figures, tracks and settings.

    Parameters
    ----------
    out : path
        The report folder; refused if it exists, unless ``force``.
    map_name : str
        A map with a demo survey (:data:`DEMO_SCENARIOS`).
    seed : int
        Seeds the simulation and every filter (children of one ``SeedSequence``).
    quick : bool
        Half the survey and fewer particles: a check that everything runs, in about a minute.
    map_error : bool
        Simulate a seafloor that is not the map (the map plus a random field) and navigate on a
        prior map gridded from a simulated earlier survey of it (the scenario's ``-map-error``
        variant, :mod:`tangraph.sim.seafloor`); the prior map is written as ``prior_map.nc``.

    Raises
    ------
    tangraph.outputs.Terminated
        On SIGTERM (in the main thread, where no other handler is set), once the unfinished
        report folder is removed; it is a ``SystemExit`` with status 143.
    """
    from tangraph.maps import load
    from tangraph.sim.scenario import load_scenario

    started = time.perf_counter()
    out = Path(out)
    scenario = load_scenario(_scenario_for(map_name, map_error))
    if out.exists() and not force:
        raise FileExistsError(f"{out} exists; pass force=True (CLI: --force) to replace it")
    bathymetry = load(map_name)
    seeds = np.random.SeedSequence(seed).spawn(1 + len(FILTERS))
    remove_stale_partials(out)
    partial = out.parent / f".{out.name}.partial-{os.getpid()}"
    bar, names = _stages(progress)
    with sigterm_exits():  # SIGTERM unwinds like Ctrl-C: the partial folder goes
        try:
            shutil.rmtree(partial, ignore_errors=True)  # this process's name: ours to replace
            (partial / "tracks").mkdir(parents=True)
            bar.set_postfix_str(names[0])
            survey, bathymetry = _simulated(scenario, bathymetry, seeds[0], seed, quick, partial, out)
            bar.update()
            n_particles = 300 if quick else 1000
            tracks = _navigated(survey, bathymetry, seeds[1:], n_particles, bar)
            bar.set_postfix_str("figures")
            figures = _figures(partial, survey, bathymetry, tracks)
            bar.update()
            settings = {"map": map_name, "map_error": map_error, "scenario": scenario.as_dict(), "seed": seed,
                        "quick": quick, "n_particles": n_particles}
            rows, settings = _results(partial, survey, bathymetry, tracks, settings)
            report = _report(partial, survey, bathymetry, rows, settings, time.perf_counter() - started)
        except BaseException as exc:
            with deferred_signals():  # a second Ctrl-C does not stop the clean-up half-way
                shutil.rmtree(partial, ignore_errors=True)
            if isinstance(exc, Terminated):
                log.warning("demo stopped by SIGTERM; its unfinished report %s is removed", partial)
            raise
        finally:
            bar.close()
        _put_in_place(partial, out)
    return DemoResult(
        out=out,
        report=out / report.name,
        rows=rows,
        figures={k: out / p.name for k, p in figures.items()},
        seconds=time.perf_counter() - started,
    )


def _simulated(scenario, bathymetry: BathymetryMap, child: np.random.SeedSequence, seed: int, quick: bool,
               partial: Path, out: Path) -> tuple[Survey, BathymetryMap]:
    """The demo's survey (half of it when ``quick``), written to ``partial/survey.nc``, and the
    map the estimators navigate on: the scenario's prior map (written as ``prior_map.nc``, the
    survey pointing to where it will be in ``out``) when its seafloor is not the map."""
    from tangraph.sim.scenario import simulate_run
    from tangraph.survey import write_survey

    run = simulate_run(scenario, rng=np.random.default_rng(child), bathymetry=bathymetry, seed=seed)
    survey = run.survey
    if run.world is not None:  # the estimators navigate on the prior map
        from tangraph.maps import write_map

        bathymetry = run.bathymetry
        write_map(bathymetry, partial / "prior_map.nc")
        survey = survey.replace(meta={**survey.meta, "map": str((out / "prior_map.nc").resolve()),
                                      "map_read": {}})  # where it will be: smooth finds it
    if quick:
        survey = survey.pings(0, survey.n_pings // 2)
    write_survey(survey, partial / "survey.nc")
    return survey, bathymetry


def _navigated(survey: Survey, bathymetry: BathymetryMap, children, n_particles: int,
               bar) -> dict[str, Track]:
    """The dead reckoning and every method's track (the filters seeded by ``children``, the
    particle filters with ``n_particles``), a stage of ``bar`` each."""
    from tangraph.navigation import dead_reckoning_track, navigate

    tracks: dict[str, Track] = {"dead reckoning": dead_reckoning_track(survey)}
    methods = [*GRAPHS, *FILTERS]
    for name, child in zip(methods, [None] * len(GRAPHS) + list(children), strict=True):
        bar.set_postfix_str(name)
        config = None
        if name == TRACKING:
            from tangraph.graph import GraphConfig

            config = GraphConfig().replace(terrain="soundings", acquire="pmf")
        if name in PARTICLE_FILTERS:
            from tangraph.filters import default_config

            config = dataclasses.replace(default_config(name), n_particles=n_particles)
        rng = None if child is None else np.random.default_rng(child)
        tracks[name] = navigate(survey, bathymetry, "isam2" if name == TRACKING else name, config, rng=rng)
        bar.update()
    return tracks


def _results(partial: Path, survey: Survey, bathymetry: BathymetryMap, tracks: dict[str, Track],
             settings: dict) -> tuple[list[dict], dict]:
    """Every track written to ``partial/tracks`` as CSV, the table's rows against the
    Cramér-Rao bounds, and the settings with the methods' configs, both written as JSON."""
    from tangraph.eval import posterior_crb
    from tangraph.sensors import NavigationModel
    from tangraph.track import write_track_csv

    for label, track in tracks.items():
        write_track_csv(track, partial / "tracks" / f"{label.replace(' ', '_')}.csv", crs=bathymetry.crs,
                        origin=bathymetry.origin)
    model = NavigationModel.from_survey(survey)
    bounds = {kind: posterior_crb(survey, bathymetry, model, kind=kind) for kind in ("smoother", "filter")}
    rows = [_row(label, track, survey, bounds) for label, track in tracks.items()]
    settings = {**settings,
                "filter_configs": {k: tracks[k].meta.get("config") for k in FILTERS},
                "graph_configs": {k: tracks[k].meta.get("config") for k in GRAPHS}}
    (partial / "settings.json").write_text(json.dumps(settings, indent=2, default=str))
    (partial / "results.json").write_text(json.dumps(rows, indent=2))
    return rows, settings


def _put_in_place(partial: Path, out: Path) -> None:
    """The complete report folder moved to ``out``; an old one there goes only once the new one
    is in place, and a signal waits until both moves are done."""
    with deferred_signals():  # never the old report gone and the new one not yet in place
        if out.exists():  # force: the old report goes only once the new one is complete
            old = out.parent / f".{out.name}.old-{os.getpid()}"
            out.rename(old)
            partial.rename(out)
            shutil.rmtree(old, ignore_errors=True)
        else:
            partial.rename(out)
