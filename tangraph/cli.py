"""The ``tangraph`` command: parses arguments and calls one library function per subcommand."""

from __future__ import annotations

import argparse
import logging
import os
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from tangraph.errors import TangraphError

log = logging.getLogger("tangraph")


def _bounded(kind, low, high, what: str):
    """An argparse type: ``kind`` (int or float) within [low, high], refused in one line."""

    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            expected = "an integer" if kind is int else "a number"
            raise argparse.ArgumentTypeError(f"{text!r} is not {expected}") from None
        if not (low <= value <= high) or (kind is float and not np.isfinite(value)):
            raise argparse.ArgumentTypeError(f"{what} must lie in [{low:g}, {high:g}], got {text}")
        return value

    parse.__name__ = what  # argparse names the type in its messages
    return parse


def _figure_file(path: Path) -> None:
    """Refuse, before any work, a figure file whose suffix matplotlib cannot write."""
    from matplotlib.figure import Figure

    known = Figure().canvas.get_supported_filetypes()
    if path.suffix[1:].lower() not in known:
        raise TangraphError(
            f"{path}: a figure is written as {', '.join('.' + k for k in sorted(known))}; "
            f"not {path.suffix or 'a file without a suffix'}"
        )


SEED = _bounded(int, 0, 2**63 - 1, "a seed")
PARTICLES = _bounded(int, 1, 10_000_000, "the particle count")
DPI = _bounded(int, 20, 1200, "the resolution (dpi)")
CELL = _bounded(float, 0.01, 100_000.0, "the cell size (m)")
FILL = _bounded(int, 0, 1000, "the fill distance (cells)")
WINDOW = _bounded(float, 0.01, 1e6, "the window length (m)")
SOUNDING_STD = _bounded(float, 0.0, 1000.0, "the sounding std (m)")


_READ = ("variable", "sign", "crs", "units", "nodata", "cell", "uncertainty")


def _read_options(args: argparse.Namespace) -> dict:
    options = {k: getattr(args, k) for k in _READ if getattr(args, k, None) is not None}
    if isinstance(options.get("uncertainty"), str) and options["uncertainty"].lower() == "none":
        options["uncertainty"] = False  # the depths alone
    return options


def _map_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("map", metavar="NAME|PATH", help="a catalogue map name or a map file")
    _map_read_options(parser)


def _map_read_options(parser: argparse.ArgumentParser, *, crs: bool = True) -> None:
    """How to read a map file, on every command that takes a map (``crs=False`` where the
    command has a ``--crs`` of its own)."""
    parser.add_argument("--variable", help="map file: its grid variable (NetCDF/NPZ)")
    parser.add_argument("--sign", choices=["depth", "elevation"], help="map file: what its values are")
    if crs:
        parser.add_argument("--crs", help="map file: its CRS where it does not say (e.g. EPSG:32755)")
    parser.add_argument("--units", help="map file: the unit of its values where it does not say (m, ft)")
    parser.add_argument("--nodata", type=float, help="map file: the value that marks no data")
    parser.add_argument("--cell", type=CELL, help="resample the map to this cell size (m)")
    parser.add_argument(
        "--uncertainty", metavar="VAR|none",
        help="map file: the variable (band) holding the std of its depths, where the file's "
        "ancillary_variables or names do not tell; 'none' reads the depths alone",
    )


def _output(parser: argparse.ArgumentParser, help_text: str) -> None:
    parser.add_argument("-o", "--output", type=Path, required=True, help=help_text)
    parser.add_argument("--force", action="store_true", help="replace OUTPUT if it exists")


def _load(args: argparse.Namespace):
    from tangraph.maps import load_any

    return load_any(args.map, **_read_options(args))


def cmd_maps_list(args: argparse.Namespace) -> None:
    from tangraph.maps import catalogue

    rows = [(e.name, e.title, e.licence) for e in catalogue().values()]
    width = max(len(r[0]) for r in rows)
    for name, title, licence in rows:
        print(f"{name:<{width}}  {title}  [{licence}]")


def cmd_maps_info(args: argparse.Namespace) -> None:
    from tangraph.maps import load_any
    from tangraph.maps.statistics import describe

    bathymetry = load_any(args.map, **_read_options(args))
    r = {**describe(bathymetry), **bathymetry.error_summary()}
    if args.json:
        _print_json(r)
        return
    print(f"name         {r['name']}")
    print(f"shape        {r['shape'][0]} x {r['shape'][1]} cells of "
          f"{r['cell_m'][0]:g} x {r['cell_m'][1]:g} m")
    print(f"extent       north {r['extent_m']['north'][0]:g} .. {r['extent_m']['north'][1]:g} m, "
          f"east {r['extent_m']['east'][0]:g} .. {r['extent_m']['east'][1]:g} m")
    d = r["depth_m"]
    print(f"depth        {d['min']:.2f} .. {d['max']:.2f} m (mean {d['mean']:.2f}), "
          f"{r['valid_fraction']:.1%} of cells hold data")
    print(f"crs          {r['crs']}")
    print(f"origin       northing {r['origin']['northing']:.3f}, easting {r['origin']['easting']:.3f}")
    if "centre" in r:
        print(f"centre       {r['centre']['lat']:.5f} N, {r['centre']['lon']:.5f} E")
    print(f"slope        median {r['slope_median_deg']:.2f} deg")
    w = r["roughness_window"]
    print(f"roughness    median {r['roughness_median_m']:.3f} m (plane-fit residual std, {w} x {w} cells)")
    error = [f"depth std median {r['depth_std_m']['median']:.3f} m, max {r['depth_std_m']['max']:.3f} m"
             ] if "depth_std_m" in r else []
    error += [f"correlation length {r['correlation_length_m']:g} m"] if "correlation_length_m" in r else []
    print(f"map error    {'; '.join(error) or 'not in the map (the model states its map std)'}")


def cmd_maps_plot(args: argparse.Namespace) -> None:
    from matplotlib.figure import Figure

    from tangraph.maps.io import write_atomically
    from tangraph.plot import plot_map

    _figure_file(args.output)
    m = _load(args)
    fig = Figure(figsize=(8, 6.5), layout="constrained")
    plot_map(m, fig.add_subplot(), title=args.title)
    write_atomically(
        args.output, args.force, lambda tmp: fig.savefig(tmp, dpi=args.dpi, format=args.output.suffix[1:])
    )
    print(f"wrote {args.output}")


def cmd_maps_mesh(args: argparse.Namespace) -> None:
    from tangraph.maps.io import write_atomically
    from tangraph.maps.mesh import write_mesh

    sidecar = args.output.with_name(args.output.name + ".json")
    source = Path(args.map).resolve() if Path(args.map).exists() else None
    for path in (args.output, sidecar):
        if path.resolve() == source:
            raise TangraphError(f"maps mesh: refusing to write over the input map {args.map}")
        if path.exists() and not args.force:
            raise FileExistsError(f"{path} exists; pass --force to replace it")
    m = _load(args)
    write_atomically(
        args.output, args.force, lambda tmp: write_mesh(m, tmp, z_up=args.z_up, sidecar=sidecar)
    )
    print(f"wrote {args.output}, {sidecar}")


def cmd_maps_grid(args: argparse.Namespace) -> None:
    from tangraph.maps import read_soundings
    from tangraph.maps.gridding import block_reduce, fill_gaps, grid_surveys
    from tangraph.maps.io import write_sounding_grid
    from tangraph.survey import read_survey

    inputs = list(args.inputs)
    if args.output.resolve() in {path.resolve() for path in inputs}:
        raise TangraphError(f"maps grid: the output {args.output} is one of the inputs")
    surveys = [path for path in inputs if path.suffix.lower() == ".nc"]
    if (surveys and len(surveys) != len(inputs)) or (not surveys and len(inputs) > 1):
        raise TangraphError("maps grid: give survey files (.nc) or one x y z text file, not both")
    if surveys:
        for option, given in (("--sign", args.sign), ("--crs", args.crs), ("--units", args.units)):
            if given is not None:
                raise TangraphError(
                    f"maps grid: {option} applies to x y z text; survey files hold depths (positive "
                    "down) in their own CRS"
                )
        loaded = [read_survey(path) for path in surveys]
        grid = grid_surveys(
            loaded, cell=args.cell, statistic=args.statistic,
            fill=args.fill, use_dr=args.use_dr, names=[str(path) for path in surveys],
            name=args.output.stem,
        )
        if args.check_lines:
            from tangraph.eval.map_check import calibrate_error, check_map_error
            from tangraph.sensors import NavigationModel

            if args.use_dr:
                raise TangraphError("maps grid: --check-lines compares soundings at reference tracks; "
                                    "not with --use-dr")
            check = check_map_error(loaded, cell=args.cell, statistic=args.statistic, fill=args.fill,
                                    window=args.window, model=NavigationModel(sounding_std=args.sounding_std),
                                    names=[str(path) for path in surveys], lines=args.lines)
            grid = calibrate_error(grid, check)
            print(f"check lines: {check.summary()}; depth_std scaled by {grid.error_scale:.2f}")
    else:
        if args.check_lines or args.lines:
            raise TangraphError("maps grid: --check-lines and --lines need survey files (.nc)")
        if args.sign is None:
            raise TangraphError("maps grid: x y z text input needs --sign (depth or elevation)")
        if args.use_dr:
            raise TangraphError("maps grid: --use-dr applies to survey files (.nc), not x y z text")
        soundings = read_soundings(inputs[0], sign=args.sign, crs=args.crs, units=args.units)
        grid = block_reduce(soundings.points, cell=args.cell, statistic=args.statistic,
                            name=args.output.stem, crs=soundings.crs, origin=soundings.origin)
        grid = fill_gaps(grid, args.fill) if args.fill else grid
    write_sounding_grid(grid, args.output, overwrite=args.force)
    gridded = int(grid.count.sum())
    measured = int(np.count_nonzero(grid.count))
    error = grid.depth.error_summary()
    print(
        f"gridded {gridded} soundings into {measured} of {grid.count.size} cells "
        f"({args.cell:g} m, {grid.statistic}); {grid.n_filled} more filled by --fill {args.fill}; "
        f"dropped {grid.n_dropped} without depth; "
        + (f"map error: std median {error['depth_std_m']['median']:.3f} m, max "
           f"{error['depth_std_m']['max']:.3f} m, correlation length {error['correlation_length_m']:g} m; "
           if error else "map error: not told by these soundings (no depth_std written); ")
        + f"wrote {args.output}"
    )


def cmd_maps_check(args: argparse.Namespace) -> None:
    from tangraph.eval.map_check import check_map_error
    from tangraph.sensors import NavigationModel
    from tangraph.survey import read_survey

    surveys = [read_survey(path) for path in args.inputs]
    check = check_map_error(
        surveys, cell=args.cell, statistic=args.statistic, fill=args.fill, window=args.window,
        model=NavigationModel(sounding_std=args.sounding_std), names=[str(path) for path in args.inputs],
        progress=lambda i, n: print(f"held out {i} of {n}", file=sys.stderr, flush=True), lines=args.lines,
    )
    print("survey,windows,rms,robust,share_beyond_3")
    for row in check.per_survey():
        print(f"{row['survey']},{row['windows']},{row['rms']:.3f},{row['robust']:.3f},{row['share_beyond_3']:.3f}")
    print(f"all: {check.summary()}")


def cmd_simulate(args: argparse.Namespace) -> None:
    from tangraph.maps import load_any, write_map
    from tangraph.sim.scenario import load_scenario, simulate_run
    from tangraph.survey import write_survey

    scenario = load_scenario(args.scenario)
    bathymetry = load_any(args.map or scenario.map, **_read_options(args))
    seed = scenario.seed if args.seed is None else args.seed
    output = Path(args.output)
    prior = output.with_name(f"{output.stem}_prior_map.nc")  # a seafloor that is not the map: its map
    if scenario.seafloor is not None and prior.exists() and not args.force:
        raise TangraphError(f"{prior} exists (the prior map of {output.name}): pass --force to replace it")
    run = simulate_run(scenario, rng=np.random.default_rng(seed), bathymetry=bathymetry, seed=seed)
    survey = run.survey
    if run.world is not None:  # the estimators' map is the prior map: written beside the survey
        write_map(run.bathymetry, prior, overwrite=args.force)
        survey = survey.replace(meta={**survey.meta, "map": str(prior.resolve()), "map_read": {}})
    elif args.map is not None and Path(args.map).exists():  # a file: smooth must find it again
        survey = survey.replace(meta={**survey.meta, "map": str(Path(args.map).resolve()),
                                      "map_read": _read_options(args)})
    write_survey(survey, args.output, overwrite=args.force)
    print(survey.summary())
    if run.world is not None:
        print(f"wrote {prior} (the map its estimators navigate on: the seafloor is not the scenario's map)")
    print(f"wrote {args.output}")


def cmd_survey_info(args: argparse.Namespace) -> None:
    from tangraph.survey import read_survey

    survey = read_survey(args.survey)
    if args.json:
        _print_json(survey.report())
    else:
        print(survey.summary())


def cmd_survey_import(args: argparse.Namespace) -> None:
    from tangraph.survey import write_survey

    csv_only = {"--columns": args.columns, "--no-header": args.no_header or None,
                "--time-format": args.time_format, "--sign": args.sign, "--units": args.units}
    sontek_only = {"--water-level": args.water_level,
                   "--water-level-interpolate": args.water_level_interpolate or None,
                   "--draft": args.draft, "--dr-heading": args.dr_heading, "--declination": args.declination}
    refused = {"csv-xyz": sontek_only, "sontek-sum": csv_only}.get(
        args.format, {**csv_only, **sontek_only, "--timezone": args.timezone})  # xtf, gsf: UTC files
    wrong = [k for k, v in refused.items() if v is not None]
    if wrong:
        raise TangraphError(
            f"{', '.join(wrong)} {'does' if len(wrong) == 1 else 'do'} not apply to --format {args.format}"
        )
    if args.format == "csv-xyz" and len(args.files) != 2:
        raise TangraphError(
            f"--format csv-xyz takes two files (navigation log, soundings), got {len(args.files)}"
        )
    if args.format in ("xtf", "gsf") and len(args.files) != 1:
        raise TangraphError(f"--format {args.format} takes one file, got {len(args.files)}")
    for path in [*args.files, *([args.water_level] if args.water_level else [])]:
        if args.output.resolve() == Path(path).resolve():
            raise TangraphError(f"refusing to write the survey over the input {path}")
    if args.output.exists() and not args.force:
        raise FileExistsError(f"{args.output} exists; pass --force to replace it")
    columns: dict[str, int | str] | None = None
    for item in [] if args.columns is None else args.columns.split(","):  # digits are positions
        key, sep, column = (v.strip() for v in item.partition("="))
        if not (sep and key and column):
            raise TangraphError(f"--columns: {item!r} is not KEY=COLUMN (e.g. time=0,lat=2,lon=3)")
        columns = {**(columns or {}), key: int(column) if column.isdigit() else column}
    if args.format == "csv-xyz":
        from tangraph.formats import import_csv_xyz

        options = {k: v for k, v in (("sign", args.sign), ("time_format", args.time_format),
                                     ("units", args.units)) if v is not None}
        survey = import_csv_xyz(*args.files, crs=args.crs, timezone=args.timezone,
                                columns=columns, header=not args.no_header, **options)
    elif args.format == "xtf":
        from tangraph.formats.xtf import import_xtf

        survey = import_xtf(args.files[0], crs=args.crs)
    elif args.format == "gsf":
        from tangraph.formats.gsf import import_gsf

        survey = import_gsf(args.files[0], crs=args.crs)
    else:
        from tangraph.formats.sontek import import_sontek_sum

        given = {"draft": args.draft, "dr_heading": args.dr_heading, "declination_deg": args.declination}
        survey = import_sontek_sum(
            args.files, crs=args.crs, timezone=args.timezone, water_level=args.water_level,
            water_level_interpolate=args.water_level_interpolate,
            **{k: v for k, v in given.items() if v is not None},
        )
    write_survey(survey, args.output, overwrite=args.force)
    print(survey.summary())
    counts = [f"{k} {v}" for k, v in survey.meta.items() if k.startswith("n_")]
    if counts:
        print("counts       " + ", ".join(counts))
    print(f"wrote {args.output}")


def cmd_survey_plot(args: argparse.Namespace) -> None:
    from matplotlib.figure import Figure

    from tangraph.maps import load_any
    from tangraph.maps.io import write_atomically
    from tangraph.plot import plot_survey
    from tangraph.survey import read_survey

    _figure_file(args.output)
    survey = read_survey(args.survey)
    name = args.map or survey.meta.get("map")
    options = _read_options(args) if args.map else {**survey.meta.get("map_read", {}), **_read_options(args)}
    bathymetry = load_any(name, **options) if name else None
    fig = Figure(figsize=(8, 7), layout="constrained")
    plot_survey(survey, bathymetry, fig.add_subplot())
    write_atomically(
        args.output, args.force, lambda tmp: fig.savefig(tmp, dpi=150, format=args.output.suffix[1:])
    )
    print(f"wrote {args.output}")


def cmd_experiment(args: argparse.Namespace) -> None:
    from tangraph.experiments.registry import list_experiments, run_experiment

    if args.name is None:
        print("\n".join(list_experiments()))
        return
    status = run_experiment(args.name, args.study_args)
    if status:
        raise SystemExit(status)


def _survey_and_map(args: argparse.Namespace):
    """The survey file and its map; the survey put on the map as the library does
    (:func:`tangraph.navigation.survey_on_map`), for the summary and the written reference."""
    from tangraph.maps import load_any
    from tangraph.navigation import survey_on_map
    from tangraph.survey import read_survey

    survey = read_survey(args.survey)
    name = args.map or survey.meta.get("map")
    if not name:
        raise TangraphError(f"{args.survey} names no map: pass --map NAME|PATH")
    options = _read_options(args) if args.map else {**survey.meta.get("map_read", {}), **_read_options(args)}
    bathymetry = load_any(name, **options)
    return survey_on_map(survey, bathymetry, other_map=args.other_map), bathymetry


def _model(args: argparse.Namespace):
    from tangraph.sensors import load_navigation_model

    return None if args.dr_model is None else load_navigation_model(args.dr_model)


def _graph_config(args: argparse.Namespace):
    from tangraph.graph import load_graph_config

    return None if args.graph_config is None else load_graph_config(args.graph_config)


def _check_outputs(args: argparse.Namespace) -> None:
    """Before any work: no output over an input or over another output, none that exists without
    --force, --frame only with a TUM output, a figure only to a suffix matplotlib writes."""
    outputs = [p for p in (args.output, args.tum, args.plot, getattr(args, "refined_map", None))
               if p is not None]
    inputs = {"survey": args.survey, "map": args.map, "--dr-model": args.dr_model,
              "--graph-config": args.graph_config}
    taken = {Path(p).resolve(): f"the input {what} {p}" for what, p in inputs.items()
             if p is not None and Path(p).exists()}
    for path in outputs:
        if path.resolve() in taken:
            raise TangraphError(f"refusing to write {path} over {taken[path.resolve()]}")
        taken[path.resolve()] = f"another output ({path})"
    for path in outputs:
        if path.exists() and not args.force:
            raise FileExistsError(f"{path} exists; pass --force to replace it")
    if args.frame is not None and args.tum is None and args.output.suffix.lower() != ".tum":
        raise TangraphError("--frame applies to TUM output: -o TRACK.tum or --tum TRACK.tum")
    if args.plot is not None:
        _figure_file(args.plot)


def _write_track(args: argparse.Namespace, track, survey, bathymetry) -> None:
    """Write the track, its TUM copy and its figure as one: all of them, or (after an error,
    Ctrl-C or SIGTERM) none, and no existing file touched."""
    from tangraph.outputs import OutputSet, sigterm_exits
    from tangraph.track import write_track_csv, write_track_geojson, write_track_gpkg, write_track_tum

    suffix = args.output.suffix.lower()
    if suffix in (".geojson", ".gpkg") and bathymetry.crs is None:
        raise TangraphError(
            f"-o {args.output}: the map {bathymetry.name!r} has no CRS, so the track cannot be placed "
            "on the Earth; pass --map with a map that has a CRS"
        )
    frame = args.frame or "ned"
    placed = {
        "crs": bathymetry.crs, "origin": bathymetry.origin, "reference": survey.true_pose,
        "start_time": survey.meta.get("start_time"), "overwrite": True,  # onto the set's temporary file
    }
    refined = getattr(args, "refined_map", None)
    written = [p for p in (args.output, args.tum, args.plot, refined) if p is not None]
    with sigterm_exits(), OutputSet(overwrite=args.force) as outputs:
        output = outputs.path(args.output)
        if suffix == ".tum":
            write_track_tum(track, output, frame=frame, overwrite=True)
        elif suffix == ".geojson":
            write_track_geojson(track, output, **placed)
        elif suffix == ".gpkg":
            write_track_gpkg(track, output, **placed)
        else:
            write_track_csv(track, output, **placed)
        if args.tum is not None:
            write_track_tum(track, outputs.path(args.tum), frame=frame, overwrite=True)
        if refined is not None:
            from tangraph.maps.io import write_map

            write_map(track.meta["refined_map"], outputs.path(refined), overwrite=True)
        if args.plot is not None:
            from matplotlib.figure import Figure

            from tangraph.navigation import dead_reckoning_track
            from tangraph.plot import plot_tracks

            fig = Figure(figsize=(8, 7.5), layout="constrained")
            tracks = {"dead reckoning": dead_reckoning_track(survey), track.method: track}
            plot_tracks(
                tracks,
                bathymetry,
                fig.add_subplot(),
                truth=survey.true_pose,
                ellipses=track.method,
                title=f"{track.method} on {bathymetry.name}",
            )
            fig.savefig(outputs.path(args.plot), dpi=130, format=args.plot.suffix[1:])
    # with --json the figures alone go to standard output
    print("wrote " + ", ".join(str(p) for p in written), file=sys.stderr if args.json else sys.stdout)


def cmd_navigate(args: argparse.Namespace) -> None:
    import dataclasses

    from tangraph.navigation import Method, navigate

    method = Method(args.method)
    config = _graph_config(args)
    if config is not None and not method.is_graph:
        raise TangraphError(f"--graph-config does not apply to method {method.value!r}")
    if args.particles is not None:
        if not method.is_random:
            raise TangraphError(f"--particles does not apply to method {method.value!r}")
        from tangraph.filters import default_config

        config = dataclasses.replace(default_config(method.value), n_particles=args.particles)
    _check_outputs(args)
    survey, bathymetry = _survey_and_map(args)
    track = navigate(
        survey,
        bathymetry,
        method,
        config,
        rng=np.random.default_rng(args.seed),
        model=_model(args),
        progress=_progress(args),
        other_map=args.other_map,
    )
    _summary(args, track, survey)
    _write_track(args, track, survey, bathymetry)


def _summary(args: argparse.Namespace, track, survey) -> None:
    from tangraph.navigation import track_report, track_summary

    if args.json:
        _print_json(track_report(track, survey))
    else:
        print(track_summary(track, survey))


def cmd_smooth(args: argparse.Namespace) -> None:
    import dataclasses

    from tangraph.graph import GraphConfig
    from tangraph.navigation import navigate

    _check_outputs(args)
    config = _graph_config(args)
    if args.refined_map is not None:
        from tangraph.maps.io import map_format

        map_format(args.refined_map)  # a map format, before any work
        config = dataclasses.replace(config or GraphConfig(), smoother_terrain="field")
        if config.smoother_covariance != "all":
            raise TangraphError("--refined-map: the refined map's std needs the covariances; the graph "
                                "config sets smoother_covariance = 'none'")
    survey, bathymetry = _survey_and_map(args)
    model = _model(args)
    unrefined = TangraphError(f"--refined-map {args.refined_map}: the map {bathymetry.name!r} states no "
                              "error (no depth_std layer, and the navigation model's map_std is 0), so "
                              "there is nothing to refine; give a map error (map_std in --dr-model)")
    if args.refined_map is not None and bathymetry.depth_std is None and model is not None \
            and model.map_std == 0:
        raise unrefined
    track = navigate(survey, bathymetry, "smoother", config, model=model, progress=_progress(args),
                     other_map=args.other_map)
    if args.refined_map is not None and "refined_map" not in track.meta:
        raise unrefined
    _summary(args, track, survey)
    for fix in track.meta.get("fixes", []):
        if not fix.accepted:
            log.info("fix at ping %s refused: %s", fix.index, fix.reason)
    _write_track(args, track, survey, bathymetry)


def cmd_demo(args: argparse.Namespace) -> None:
    from tangraph.demo import format_table, run_demo

    result = run_demo(
        args.out,
        map_name=args.map,
        seed=args.seed,
        quick=args.quick,
        force=args.force,
        progress=_progress(args),
        map_error=args.map_error,
    )
    print(format_table(result.rows))
    print(f"wrote {result.report} and {len(result.figures)} figures in {result.seconds:.0f} s")


def _gridding_options(p: argparse.ArgumentParser) -> None:
    """``--cell``, ``--statistic`` and ``--fill``: how soundings are gridded into a map."""
    p.add_argument("--cell", type=CELL, required=True, help="cell size (m)")
    p.add_argument(
        "--statistic", choices=["mean", "median"], default="median",
        help="the statistic that becomes the map's depth (default: median, robust to outliers)",
    )
    p.add_argument(
        "--fill", type=FILL, default=0, metavar="CELLS",
        help="fill empty cells from cells with data within CELLS cells (inverse distance squared); "
        "farther cells stay no-data (default: 0, no fill)",
    )


def _check_line_options(p: argparse.ArgumentParser, prefix: str = "") -> None:
    """``--lines``, ``--window`` and ``--sounding-std``: how check lines are scored."""
    p.add_argument("--lines", action="store_true",
                   help=f"{prefix}split every survey into its lines (straight stretches of at least a "
                   "window) and hold out each line against the map of the others: a map of one survey")
    p.add_argument("--window", type=WINDOW, default=50.0, help=f"{prefix}window of track (m; default 50)")
    p.add_argument("--sounding-std", type=SOUNDING_STD, default=0.1,
                   help=f"{prefix}the soundings' own noise std (m; default 0.1)")


def build_parser() -> argparse.ArgumentParser:
    """The argument parser (also used to document the CLI)."""
    from tangraph import __version__

    parser = argparse.ArgumentParser(prog="tangraph", description="Terrain-aided navigation of AUVs.")
    parser.add_argument("--version", action="version", version=f"tangraph {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    parser.add_argument("--debug", action="store_true", help="show the traceback of an error")
    sub = parser.add_subparsers(dest="command", required=True)

    maps = sub.add_parser("maps", help="bathymetry maps: list, inspect, plot, mesh, grid, check")
    maps_sub = maps.add_subparsers(dest="maps_command", required=True)
    p = maps_sub.add_parser("list", help="list the map catalogue")
    p.set_defaults(func=cmd_maps_list)
    p = maps_sub.add_parser("info", help="describe a map (and its error layer, if it has one)")
    _map_argument(p)
    p.set_defaults(func=cmd_maps_info)
    p = maps_sub.add_parser("plot", help="hill-shaded figure of a map")
    _map_argument(p)
    _output(p, "figure file (.png, .pdf, .svg)")
    p.add_argument("--title", help="figure title (default: the map's name)")
    p.add_argument("--dpi", type=DPI, default=150, help="resolution of a raster figure")
    p.set_defaults(func=cmd_maps_plot)
    p = maps_sub.add_parser(
        "mesh", help="export a map as a triangle mesh (NED vertices, or ENU with --z-up)",
        description="Export a map as a triangle mesh, with its CRS, origin, units and axes in a "
        "JSON sidecar named after it (lake.ply -> lake.ply.json).",
    )
    _map_argument(p)
    _output(p, "mesh file (.ply or .obj); its sidecar OUTPUT.json is written too")
    p.add_argument(
        "--z-up", action="store_true",
        help="vertices east, north, elevation (= -depth): a right-handed ENU mesh for viewers "
        "that expect z up (default: north, east, depth, NED)",
    )
    p.set_defaults(func=cmd_maps_mesh)
    p = maps_sub.add_parser(
        "grid",
        help="grid surveys (.nc, at their reference tracks) or scattered soundings (x y z text) into a map",
        description="Grid the soundings of one or more survey files (.nc), each placed at its "
        "reference track (GPS or truth) and put in the frame (CRS, origin) of the first, or of one "
        "x y z text file, into a map: median or mean, count and std per cell, and the map's error "
        "(depth_std per cell: the standard error of a measured cell, growing with the distance to "
        "the data in a filled one; a correlation length).",
    )
    p.add_argument("inputs", type=Path, nargs="+", metavar="INPUT",
                   help="survey files (.nc), or one x/east y/north z text file")
    _gridding_options(p)
    p.add_argument(
        "--use-dr", action="store_true",
        help="place survey soundings at the dead reckoning (for surveys without a reference track)",
    )
    p.add_argument(
        "--check-lines", action="store_true",
        help="survey files only: hold out each survey, grid the others, and scale depth_std by the RMS "
        "of the held-out windows' standardised mean residuals when above 1 (see 'maps check')",
    )
    _check_line_options(p, "--check-lines: ")
    p.add_argument(
        "--sign",
        choices=["depth", "elevation"],
        help="x y z text only (required there): what z is, depth (positive down) or elevation",
    )
    p.add_argument("--crs", help="x y z text only: CRS of x, y (e.g. EPSG:4326); default local metres")
    p.add_argument(
        "--units",
        help="x y z text only: unit of z (m, ft, us-ft, US survey foot, fathom; default m; required "
        "with x, y in a CRS in feet)",
    )
    _output(p, "NetCDF file: depth (the statistic) with its depth_std, mean, median, count and std "
            "per cell")
    p.set_defaults(func=cmd_maps_grid)
    p = maps_sub.add_parser(
        "check",
        help="check lines: is the error a map gridded from these surveys states right?",
        description="Hold out each survey (.nc, at its reference track) in turn, grid the others as "
        "'maps grid' would (--cell, --statistic, --fill) and compare the held-out soundings with that "
        "map in windows of track: each window's mean residual over the std the map's error and the "
        "sounding noise give it. Prints, per survey and for all, the RMS of these scores (1 when the "
        "map errs as it says), a robust scale (the bulk of the windows) and the share beyond 3.",
    )
    p.add_argument("inputs", type=Path, nargs="+", metavar="SURVEY",
                   help="two or more survey files (.nc), or one with --lines")
    _gridding_options(p)
    _check_line_options(p)
    p.set_defaults(func=cmd_maps_check)

    p = sub.add_parser("simulate", help="simulate a survey from a scenario")
    p.add_argument(
        "scenario", metavar="SCENARIO.toml|NAME", help="a scenario file or a shipped scenario name"
    )
    p.add_argument("--map", metavar="NAME|PATH", help="run on this map instead of the scenario's")
    _map_read_options(p)
    p.add_argument("--seed", type=SEED, help="seed (default: the scenario's)")
    _output(p, "survey file (.nc)")
    p.set_defaults(func=cmd_simulate)

    survey = sub.add_parser("survey", help="survey files: info, import, plot")
    survey_sub = survey.add_subparsers(dest="survey_command", required=True)
    p = survey_sub.add_parser("info", help="describe a survey file")
    p.add_argument("survey", type=Path, help="survey file (.nc)")
    p.set_defaults(func=cmd_survey_info)
    p = survey_sub.add_parser(
        "import",
        help="a survey recorded by another system: CSV log + XYZ soundings, or SonTek .sum files",
    )
    p.add_argument("--format", choices=["csv-xyz", "sontek-sum", "xtf", "gsf"], default="csv-xyz",
                   help="csv-xyz: FILE is a navigation log and a soundings file; "
                   "sontek-sum: one or more RiverSurveyor .sum files of one run; xtf, gsf: one "
                   "multibeam file (XTF bathymetry packets of type 65, GSF swath pings)")
    p.add_argument("files", nargs="+", type=Path, metavar="FILE",
                   help="csv-xyz: the log (time, north, east or lat, lon, heading deg, depth) and "
                   "the soundings (time x y z)")
    p.add_argument("--crs", help="projected CRS of the survey: of north/east, or the one lat/lon "
                   "go into (e.g. EPSG:32633; one in feet is converted to metres); csv-xyz lat/lon "
                   "default: a local transverse Mercator")
    p.add_argument("--timezone", help="zone of times written without one (e.g. UTC, Europe/Berlin)")
    p.add_argument("--columns", metavar="KEY=COL,...",
                   help="csv-xyz: log columns by name or 0-based position, keys time, north, east, "
                   "lat, lon, heading, depth (e.g. time=0,lat=2,lon=3,heading=4,depth=5)")
    p.add_argument("--no-header", action="store_true", help="csv-xyz: the log has no header row")
    p.add_argument("--time-format", choices=["auto", "seconds", "epoch", "iso"],
                   help="csv-xyz: how times read (default auto: text ISO 8601, numbers from 1e8 epoch)")
    p.add_argument("--sign", choices=["depth", "elevation"], help="csv-xyz: what z is (default depth)")
    p.add_argument("--units", help="csv-xyz: unit of z and the log's depth (m, ft, US survey foot; "
                   "default m; required with north/east in a CRS in feet)")
    p.add_argument("--water-level", type=Path, metavar="LEVEL.csv",
                   help="sontek-sum: water-level table; depths below its zero")
    p.add_argument("--water-level-interpolate", action="store_true",
                   help="sontek-sum: interpolate the level between the table's dates")
    p.add_argument("--draft", type=float, metavar="M", help="sontek-sum: transducer depth (m)")
    p.add_argument("--dr-heading", choices=["boat", "compass"],
                   help="sontek-sum: DR along the boat direction (default) or the compass heading")
    p.add_argument("--declination", type=float, metavar="DEG",
                   help="sontek-sum: added to the compass heading (deg)")
    _output(p, "survey file (.nc)")
    p.set_defaults(func=cmd_survey_import)
    p = survey_sub.add_parser(
        "plot", help="truth vs dead reckoning over the hill-shaded map, swath footprints"
    )
    p.add_argument("survey", type=Path, help="survey file (.nc)")
    p.add_argument("--map", metavar="NAME|PATH", help="the map (default: the one named in the survey)")
    _map_read_options(p)
    _output(p, "figure file (.png, .pdf, .svg)")
    p.set_defaults(func=cmd_survey_plot)

    p = sub.add_parser(
        "experiment",
        help="run a study of experiments/ (no name: list them)",
        description="Run experiments/NAME/run.py; arguments after NAME go to the study "
        "(e.g. --runs 200 --scheduler ADDR --quick; NAME --help lists them).",
    )
    p.add_argument("name", nargs="?", help="the study")
    p.add_argument("study_args", nargs=argparse.REMAINDER, help="arguments of the study")
    p.set_defaults(func=cmd_experiment)

    from tangraph.navigation import Method

    def track_outputs(p: argparse.ArgumentParser) -> None:
        p.add_argument("survey", type=Path, help="survey file (.nc)")
        p.add_argument("--map", metavar="NAME|PATH", help="the map (default: the one named in the survey)")
        _map_read_options(p)
        p.add_argument("--other-map", action="store_true",
                       help="navigate a survey on a map not its own: one simulated on another map, or "
                       "one that does not overlap the map's data (refused otherwise)")
        _output(
            p,
            "track file by suffix: .csv (time, utc, lat, lon, north, east, heading, covariance), "
            ".geojson or .gpkg (WGS84 line and per-pose points with those attributes; needs a map "
            "with a CRS) or .tum",
        )
        p.add_argument("--tum", type=Path, help="also write the track in TUM format here")
        p.add_argument(
            "--frame", choices=["ned", "enu"],
            help="axes of TUM output: ned (default; x north, y east, z down) or enu (x east, "
            "y north, z up; for evo and ROS tools)",
        )
        p.add_argument("--plot", type=Path, help="figure of the track vs DR (and truth) over the map")
        p.add_argument(
            "--dr-model",
            type=Path,
            metavar="FILE.toml",
            help="the navigation model: the DR's white errors and the priors of its constant "
            "errors (speed scale, heading bias), the start uncertainty and the sounding noise "
            "(NavigationModel fields, angles as NAME_deg); needed for a recorded survey, which "
            "does not carry one",
        )
        p.add_argument(
            "--graph-config",
            type=Path,
            metavar="FILE.toml",
            help="settings of the factor graph (GraphConfig fields, TapConfig ones in [tap]): "
            "window length, fix criterion, gate, robust kernel...",
        )

    p = sub.add_parser("navigate", help="estimate a survey's track with one method (filters or online graph)")
    track_outputs(p)
    p.add_argument("--method", choices=[m.value for m in Method], default="isam2", help="the estimator")
    p.add_argument("--seed", type=SEED, default=0, help="seed of a particle filter")
    p.add_argument("--particles", type=PARTICLES, help="particle count (default: the filter's)")
    p.set_defaults(func=cmd_navigate)

    p = sub.add_parser("smooth", help="re-navigate a recorded survey with the batch factor-graph smoother")
    track_outputs(p)
    p.add_argument("--refined-map", type=Path, metavar="OUT",
                   help="also write the map corrected by its error as estimated with the track, with the "
                   "posterior std as its error layer (any map format by suffix, as maps grid writes); "
                   "sets the graph's smoother_terrain to 'field'")
    p.set_defaults(func=cmd_smooth)

    p = sub.add_parser("demo", help="simulate, navigate with every method, and write a report")
    p.add_argument("--map", default="merimbula", help="map with a demo survey (default: merimbula)")
    p.add_argument("--out", type=Path, default=Path("demo"), help="report folder (default: ./demo)")
    p.add_argument("--seed", type=SEED, default=7, help="seed of the simulation and the filters")
    p.add_argument("--quick", action="store_true", help="half the survey, fewer particles")
    p.add_argument("--force", action="store_true", help="replace the report folder if it exists")
    p.add_argument("--map-error", action="store_true",
                   help="a seafloor that is not the map: navigate on a prior map gridded from a simulated "
                   "earlier survey of it")
    p.set_defaults(func=cmd_demo)
    for name in ("maps info", "survey info", "navigate", "smooth"):
        _json_option(_subparser(parser, name.split()))
    for leaf in _leaves(parser):  # -v and -q after the subcommand too; defaults in every help
        leaf.add_argument("-v", "--verbose", action="store_true", default=argparse.SUPPRESS,
                          help="log progress")
        leaf.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS,
                          help="no progress bars")
    for each in (parser, *_leaves(parser)):
        each.formatter_class = DefaultsHelpFormatter
    return parser


class DefaultsHelpFormatter(argparse.HelpFormatter):
    """Help that shows an option's default where it has one and its help does not say it."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if action.default not in (None, False, argparse.SUPPRESS) and "default" not in text \
                and not isinstance(action, argparse._VersionAction):
            text += " (default: %(default)s)"
        return text


def _children(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    found = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(found[0].choices) if found else {}


def _leaves(parser: argparse.ArgumentParser) -> list[argparse.ArgumentParser]:
    children = _children(parser)
    return [leaf for child in children.values() for leaf in _leaves(child)] if children else [parser]


def _subparser(parser: argparse.ArgumentParser, path: list[str]) -> argparse.ArgumentParser:
    for name in path:
        parser = _children(parser)[name]
    return parser


def _json_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print the figures as one JSON object")


def _progress(args: argparse.Namespace) -> bool:
    """Progress bars only on a terminal, and not with -q."""
    return not args.quiet and sys.stderr.isatty()


def _print_json(report: dict) -> None:
    import json

    print(json.dumps(report, indent=2, default=_plain))


def _plain(value):
    """numpy scalars and anything else json does not know, as plain Python."""
    return value.item() if hasattr(value, "item") else str(value)


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``tangraph`` command; returns the exit status.

    0: done. 2: a usage error or bad input (the arguments, or a file that cannot be read as
    what it should be), one line naming it. 1: a runtime error (a folder that cannot be
    written, memory, anything unforeseen), one line; ``--debug`` shows its traceback. 130: an
    interrupt (Ctrl-C). 141: standard output closed early (``tangraph ... | head``).
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(name)s: %(message)s"
    )
    if not args.verbose:  # Dask logs every worker's start and stop at INFO
        for name in ("distributed", "tornado"):
            logging.getLogger(name).setLevel(logging.WARNING)
        # distributed sets its loggers' levels from its config when first imported (later, lazily)
        os.environ.setdefault("DASK_LOGGING__DISTRIBUTED", "warning")
    try:
        args.func(args)
    except BrokenPipeError:
        _quiet_stdout()
        return 141
    except (TangraphError, FileNotFoundError, FileExistsError) as exc:
        if args.debug:
            raise
        print(f"tangraph: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("tangraph: interrupted", file=sys.stderr)
        return 130
    except Exception as exc:  # the contract: one line, never a traceback unless asked
        if args.debug:
            raise
        if type(exc).__name__ == "CRSError":  # pyproj's: a CRS the user gave is not known
            print(f"tangraph: error: the CRS is not understood by pyproj: {_one_line(exc)}", file=sys.stderr)
            return 2
        kind = "out of memory" if isinstance(exc, MemoryError) else type(exc).__name__
        print(f"tangraph: error: {kind}: {_one_line(exc)} (--debug shows where)", file=sys.stderr)
        return 1
    try:
        sys.stdout.flush()
    except BrokenPipeError:
        _quiet_stdout()
        return 141
    return 0


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text if len(text) <= 400 else text[:397] + "..."


def _quiet_stdout() -> None:
    """After a closed pipe: point stdout at /dev/null so that the interpreter's last flush is quiet."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, sys.stdout.fileno())


if __name__ == "__main__":
    sys.exit(main())
