"""``tangraph navigate`` and ``tangraph smooth``: a survey's track by one estimator, written as a
track file (CSV, GeoJSON, GeoPackage, TUM) with its TUM copy, figure and refined map."""

from __future__ import annotations

import argparse
import dataclasses
import logging
import sys
from pathlib import Path

import numpy as np

from tangraph.cli._common import (
    PARTICLES,
    SEED,
    figure_file,
    json_option,
    map_read_options,
    output_file,
    output_option,
    print_json,
    progress,
    survey_map_options,
)
from tangraph.errors import TangraphError

log = logging.getLogger("tangraph")


def cmd_navigate(args: argparse.Namespace) -> None:
    from tangraph.navigation import Method, navigate

    method = Method(args.method)
    config = _method_config(args, method)
    _check_outputs(args)
    survey, bathymetry = _survey_and_map(args)
    track = navigate(survey, bathymetry, method, config, rng=np.random.default_rng(args.seed),
                     model=_model(args), progress=progress(args), other_map=args.other_map)
    _summary(args, track, survey)
    _write_track(args, track, survey, bathymetry)


def cmd_smooth(args: argparse.Namespace) -> None:
    from tangraph.navigation import navigate

    _check_outputs(args)
    config = _smoother_config(args)
    survey, bathymetry = _survey_and_map(args)
    model = _model(args)
    unrefined = TangraphError(f"--refined-map {args.refined_map}: the map {bathymetry.name!r} states no "
                              "error (no depth_std layer, or one of zeros, and the navigation model's "
                              "map_std and map_change_std are 0), so there is nothing to refine; give a map "
                              "error (map_std or map_change_std in --dr-model)")
    if args.refined_map is not None and bathymetry.depth_std is None and model is not None \
            and model.map_std == 0 and model.map_change_std == 0:
        raise unrefined
    track = navigate(survey, bathymetry, "smoother", config, model=model, progress=progress(args),
                     other_map=args.other_map)
    if args.refined_map is not None and "refined_map" not in track.meta:
        raise unrefined
    _summary(args, track, survey)
    for fix in track.fixes or ():
        if not fix.accepted:
            log.info("fix at ping %s refused: %s", fix.index, fix.reason)
    _write_track(args, track, survey, bathymetry)


# -- the steps ----------------------------------------------------------------------------------
def _method_config(args: argparse.Namespace, method):
    """The estimator's settings: --graph-config for a graph, --particles for a particle filter."""
    config = _graph_config(args)
    if config is not None and not method.is_graph:
        raise TangraphError(f"--graph-config does not apply to method {method.value!r}")
    if args.particles is not None:
        if not method.is_random:
            raise TangraphError(f"--particles does not apply to method {method.value!r}")
        from tangraph.filters import default_config

        config = dataclasses.replace(default_config(method.value), n_particles=args.particles)
    return config


def _smoother_config(args: argparse.Namespace):
    """--graph-config, with the terrain as a field where --refined-map asks for the refined map."""
    config = _graph_config(args)
    if args.refined_map is None:
        return config
    from tangraph.graph import GraphConfig
    from tangraph.maps.io import map_format

    map_format(args.refined_map)  # a map format, before any work
    config = (config or GraphConfig()).replace(smoother_terrain="field")
    if config.batch.smoother_covariance != "all":
        raise TangraphError("--refined-map: the refined map's std needs the covariances; the graph "
                            "config sets smoother_covariance = 'none'")
    return config


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
    bathymetry = load_any(name, **survey_map_options(args, survey))
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
        figure_file(args.plot)


def _summary(args: argparse.Namespace, track, survey) -> None:
    from tangraph.track_reports import track_report, track_summary

    if args.json:
        print_json(track_report(track, survey))
    else:
        print(track_summary(track, survey))


def _write_track(args: argparse.Namespace, track, survey, bathymetry) -> None:
    """The track file, its TUM copy, figure and refined map, as one (:func:`write_track_outputs`)."""
    from tangraph.track_outputs import write_track_outputs

    if args.output.suffix.lower() in (".geojson", ".gpkg") and bathymetry.crs is None:
        raise TangraphError(
            f"-o {args.output}: the map {bathymetry.name!r} has no CRS, so the track cannot be placed "
            "on the Earth; pass --map with a map that has a CRS"
        )
    written = write_track_outputs(
        track, survey, bathymetry, args.output, tum=args.tum, frame=args.frame or "ned", plot=args.plot,
        refined_map=getattr(args, "refined_map", None), overwrite=args.force,
    )
    # with --json the figures alone go to standard output
    print("wrote " + ", ".join(str(p) for p in written), file=sys.stderr if args.json else sys.stdout)


# -- the parsers --------------------------------------------------------------------------------
def add_parser(subparsers) -> None:
    """``navigate`` and ``smooth``."""
    from tangraph.navigation import Method

    p = subparsers.add_parser(
        "navigate", help="estimate a survey's track with one method (filters or online graph)"
    )
    _track_options(p)
    p.add_argument("--method", choices=[m.value for m in Method], default="isam2", help="the estimator")
    p.add_argument("--seed", type=SEED, default=0, help="seed of a particle filter")
    p.add_argument("--particles", type=PARTICLES, help="particle count (default: the filter's)")
    json_option(p)
    p.set_defaults(func=cmd_navigate)

    p = subparsers.add_parser(
        "smooth", help="re-navigate a recorded survey with the batch factor-graph smoother"
    )
    _track_options(p)
    p.add_argument("--refined-map", type=output_file, metavar="OUT",
                   help="also write the map corrected by its error as estimated with the track, with the "
                   "posterior std as its error layer (any map format by suffix, as maps grid writes); "
                   "sets the graph's smoother_terrain to 'field'")
    json_option(p)
    p.set_defaults(func=cmd_smooth)


def _track_options(p: argparse.ArgumentParser) -> None:
    """The survey, its map, the outputs and the models: what navigate and smooth share."""
    p.add_argument("survey", type=Path, help="survey file (.nc)")
    p.add_argument("--map", metavar="NAME|PATH", help="the map (default: the one named in the survey)")
    map_read_options(p)
    p.add_argument("--other-map", action="store_true",
                   help="navigate a survey on a map not its own: one simulated on another map, or "
                   "one that does not overlap the map's data (refused otherwise)")
    output_option(
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
    p.add_argument("--plot", type=output_file, help="figure of the track vs DR (and truth) over the map")
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
        help="settings of the factor graph (GraphConfig): key_interval, and its parts' fields in "
        "[graph.fixes] (window, gate, search; TapConfig in [graph.fixes.tap]), [graph.online] "
        "(iSAM2, front end, lost test) and [graph.batch] (solve, terrain)",
    )
