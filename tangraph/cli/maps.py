"""``tangraph maps``: list, describe, plot and mesh maps; grid soundings into one; check lines; the
seafloor's change since a map."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from tangraph.cli._common import (
    CELL,
    DPI,
    FILL,
    MAP_STD,
    POSITION_STD,
    SOUNDING_STD,
    WINDOW,
    figure_file,
    json_option,
    load_map,
    map_argument,
    output_option,
    print_json,
    write_figure,
)
from tangraph.errors import TangraphError


def cmd_maps_list(args: argparse.Namespace) -> None:
    from tangraph.maps import catalogue

    rows = [(e.name, e.title, e.licence) for e in catalogue().values()]
    width = max(len(r[0]) for r in rows)
    for name, title, licence in rows:
        print(f"{name:<{width}}  {title}  [{licence}]")


def cmd_maps_info(args: argparse.Namespace) -> None:
    from tangraph.maps.statistics import describe

    bathymetry = load_map(args)
    report = {**describe(bathymetry), **bathymetry.error_summary()}
    if args.json:
        print_json(report)
    else:
        print("\n".join(_info_lines(report)))


def _info_lines(r: dict) -> list[str]:
    """``maps info`` as text, one figure a line."""
    d, w = r["depth_m"], r["roughness_window"]
    lines = [
        f"name         {r['name']}",
        f"shape        {r['shape'][0]} x {r['shape'][1]} cells of {r['cell_m'][0]:g} x {r['cell_m'][1]:g} m",
        f"extent       north {r['extent_m']['north'][0]:g} .. {r['extent_m']['north'][1]:g} m, "
        f"east {r['extent_m']['east'][0]:g} .. {r['extent_m']['east'][1]:g} m",
        f"depth        {d['min']:.2f} .. {d['max']:.2f} m (mean {d['mean']:.2f}), "
        f"{r['valid_fraction']:.1%} of cells hold data",
        f"crs          {r['crs']}",
        f"origin       northing {r['origin']['northing']:.3f}, easting {r['origin']['easting']:.3f}",
    ]
    if "centre" in r:
        lines.append(f"centre       {r['centre']['lat']:.5f} N, {r['centre']['lon']:.5f} E")
    lines.append(f"slope        median {r['slope_median_deg']:.2f} deg" if np.isfinite(r["slope_median_deg"])
                 else "slope        not told (no two neighbouring cells hold data)")
    rough = r["roughness_median_m"]
    lines.append(f"roughness    median {rough:.3f} m (plane-fit residual std, {w} x {w} cells)"
                 if np.isfinite(rough) else f"roughness    not told (no {w} x {w} cells hold data)")
    error = [f"depth std median {r['depth_std_m']['median']:.3f} m, max {r['depth_std_m']['max']:.3f} m"
             ] if "depth_std_m" in r else []
    error += [f"correlation length {r['correlation_length_m']:g} m"] if "correlation_length_m" in r else []
    error += [f"a Student-t tail of {r['error_dof']:.3g} degrees of freedom"] if "error_dof" in r else []
    drift = r.get("error_drift")
    error += [f"a track drift of {drift['std_m']:.3g} m over {drift['time_s']:.3g} s"] if drift else []
    lines.append(f"map error    {'; '.join(error) or 'not in the map (the model states its map std)'}")
    return lines


def cmd_maps_plot(args: argparse.Namespace) -> None:
    from matplotlib.figure import Figure

    from tangraph.plot import plot_map

    figure_file(args.output)
    m = load_map(args)
    fig = Figure(figsize=(8, 6.5), layout="constrained")
    plot_map(m, fig.add_subplot(), title=args.title)
    write_figure(fig, args.output, args.force, args.dpi)
    print(f"wrote {args.output}")


def cmd_maps_mesh(args: argparse.Namespace) -> None:
    from tangraph.maps.mesh import write_mesh
    from tangraph.outputs import write_atomically

    sidecar = args.output.with_name(args.output.name + ".json")
    source = Path(args.map).resolve() if Path(args.map).exists() else None
    for path in (args.output, sidecar):
        if path.resolve() == source:
            raise TangraphError(f"maps mesh: refusing to write over the input map {args.map}")
        if path.exists() and not args.force:
            raise FileExistsError(f"{path} exists; pass --force to replace it")
    m = load_map(args)
    write_atomically(
        args.output, args.force, lambda tmp: write_mesh(m, tmp, z_up=args.z_up, sidecar=sidecar)
    )
    print(f"wrote {args.output}, {sidecar}")


def cmd_maps_grid(args: argparse.Namespace) -> None:
    from tangraph.gridding_files import grid_files
    from tangraph.maps.io import write_sounding_grid

    grid, check = grid_files(
        args.inputs, args.output, cell=args.cell, statistic=args.statistic, fill=args.fill,
        position_std=args.position_std, use_dr=args.use_dr, sign=args.sign, crs=args.crs, units=args.units,
        check_lines=args.check_lines, lines=args.lines, window=args.window, sounding_std=args.sounding_std,
        where="maps grid", option_name=_option,
    )
    if check is not None:
        tail = ("a Gaussian tail" if grid.error_dof is None else
                f"the tail of a Student-t of {grid.error_dof:.3g} degrees of freedom (error_dof)")
        print(f"check lines: {check.summary()}; depth_std scaled by {grid.error_scale:.2f}, {tail}")
        print(f"check lines: {_drift_line(check)}")
    elif "check_lines_skipped" in grid.meta:
        print(f"check lines: not made ({grid.meta['check_lines_skipped']}); the map states the gridding's "
              "own error")
    write_sounding_grid(grid, args.output, overwrite=args.force)
    print(_grid_summary(grid, cell=args.cell, fill=args.fill, output=args.output))


def _drift_line(check) -> str:
    """What the check lines say of the depths' drift (:meth:`~tangraph.eval.map_check.MapCheck.drift`)."""
    drift = check.drift()
    if not np.isfinite(drift["std"]):
        return "drift: too few windows to tell"
    return (f"drift: the held-out depths drift from the map's by {drift['std']:.3g} m, forgotten over about "
            f"{drift['time']:.3g} s (a navigation model's tide_drift_std, tide_drift_time), the windows' "
            f"own error at {drift['scale']:.2f} times the stated; F test against none p = "
            f"{drift['p_value']:.2g}")


def _option(keyword: str) -> str:
    """The option of a library keyword, as the library's errors name it here (``use_dr`` -> ``--use-dr``)."""
    return "--" + keyword.replace("_", "-")


def _grid_summary(grid, *, cell: float, fill: int, output: Path) -> str:
    """The line ``maps grid`` prints: what was gridded, filled, dropped, the map's error."""
    gridded = int(grid.count.sum())
    measured = int(np.count_nonzero(grid.count))
    error = grid.depth.error_summary()
    return (
        f"gridded {gridded} soundings into {measured} of {grid.count.size} cells "
        f"({cell:g} m, {grid.statistic}); {grid.n_filled} more filled by --fill {fill}; "
        f"dropped {grid.n_dropped} without depth; "
        + (f"map error: std median {error['depth_std_m']['median']:.3f} m, max "
           f"{error['depth_std_m']['max']:.3f} m, correlation length {error['correlation_length_m']:g} m"
           + (f", a Student-t tail of {grid.error_dof:.3g} degrees of freedom" if grid.error_dof else "")
           + (f", a drift along a track of {grid.error_drift[0]:.3g} m over {grid.error_drift[1]:.3g} s"
              if grid.error_drift else "")
           + ("" if "check_lines" in grid.meta else " (the gridding's own, not checked)") + "; "
           if error else "map error: not told by these soundings (no depth_std written); ")
        + f"wrote {output}"
    )


def cmd_maps_check(args: argparse.Namespace) -> None:
    from tangraph.eval.map_check import check_map_error
    from tangraph.sensors import NavigationModel
    from tangraph.survey import read_survey

    surveys = [read_survey(path) for path in args.inputs]
    said = None if args.quiet else (lambda i, n: print(f"held out {i} of {n}", file=sys.stderr, flush=True))
    check = check_map_error(
        surveys, cell=args.cell, statistic=args.statistic, fill=args.fill, window=args.window,
        model=NavigationModel(sounding_std=args.sounding_std), names=[str(path) for path in args.inputs],
        progress=said, lines=args.lines, position_std=args.position_std,
    )
    print("survey,windows,rms,robust,share_beyond_3")
    for row in check.per_survey():
        print(f"{row['survey']},{row['windows']},{row['rms']:.3f},{row['robust']:.3f},{row['share_beyond_3']:.3f}")
    print(f"all: {check.summary()}")
    print(_drift_line(check))
    kinds = check.by_cell().items()
    print("soundings one by one: " + "; ".join(
        f"{kind.replace('_', ' ')} {v['soundings']}" + (
            f", residual spread {v['robust_residual_m']:.3f} m against {v['median_std_m']:.3f} m stated, "
            f"robust z {v['robust_z']:.2f}" if v["soundings"] else "") for kind, v in kinds))


def cmd_maps_change(args: argparse.Namespace) -> None:
    from tangraph.eval.map_change import measure_change
    from tangraph.maps.netcdf import measured_cells
    from tangraph.sensors import NavigationModel
    from tangraph.survey import read_survey

    bathymetry = load_map(args)
    surveys = [read_survey(path) for path in args.inputs]
    measured = measured_cells(args.map, bathymetry) if Path(args.map).is_file() else None
    model = NavigationModel(sounding_std=args.sounding_std, map_std=args.map_std)
    change = measure_change(surveys, bathymetry, model, window=args.window, measured=measured,
                            position_std=args.position_std, names=[str(path) for path in args.inputs])
    print(change.summary())
    print("# the navigation model's fields (a --dr-model file) that state it:")
    for key, value in change.model_fields().items():
        print(f"{key} = {value:g}")


# -- the parsers --------------------------------------------------------------------------------
def _gridding_options(p: argparse.ArgumentParser) -> None:
    """``--cell``, ``--statistic`` and ``--fill``: how soundings are gridded into a map."""
    p.add_argument("--cell", type=CELL, required=True, help="cell size (m)")
    p.add_argument(
        "--statistic", choices=["mean", "median"], default="median",
        help="the statistic that becomes the map's depth (default: median, robust to outliers)",
    )
    p.add_argument(
        "--fill", type=FILL, default=0, metavar="CELLS",
        help="fill empty cells from cells with data within CELLS cells (a plane across a gap closed from "
        "both sides, else inverse distance squared); "
        "farther cells stay no-data (default: 0, no fill)",
    )
    p.add_argument(
        "--position-std", type=POSITION_STD, default=0.0, metavar="M",
        help="std (m per axis) of the positions the soundings are placed at (their GPS): the map's "
        "error gains it times the map's slope (default: 0, the positions taken as exact)",
    )


def _check_line_options(p: argparse.ArgumentParser, prefix: str = "") -> None:
    """``--lines``, ``--window`` and ``--sounding-std``: how check lines are scored."""
    p.add_argument("--lines", action="store_true",
                   help=f"{prefix}split every survey into its lines (straight stretches of at least a "
                   "window) and hold out each line against the map of the others: a map of one survey")
    p.add_argument("--window", type=WINDOW, default=50.0, help=f"{prefix}window of track (m; default 50)")
    p.add_argument("--sounding-std", type=SOUNDING_STD, default=0.1,
                   help=f"{prefix}the soundings' own noise std (m; default 0.1)")


def add_parser(subparsers) -> None:
    """``maps`` and its subcommands."""
    maps = subparsers.add_parser("maps",
                                 help="bathymetry maps: list, inspect, plot, mesh, grid, check, change")
    maps_sub = maps.add_subparsers(dest="maps_command", required=True)
    p = maps_sub.add_parser("list", help="list the map catalogue")
    p.set_defaults(func=cmd_maps_list)
    p = maps_sub.add_parser("info", help="describe a map (and its error layer, if it has one)")
    map_argument(p)
    json_option(p)
    p.set_defaults(func=cmd_maps_info)
    p = maps_sub.add_parser("plot", help="hill-shaded figure of a map")
    map_argument(p)
    output_option(p, "figure file (.png, .pdf, .svg)")
    p.add_argument("--title", help="figure title (default: the map's name)")
    p.add_argument("--dpi", type=DPI, default=150, help="resolution of a raster figure")
    p.set_defaults(func=cmd_maps_plot)
    p = maps_sub.add_parser(
        "mesh", help="export a map as a triangle mesh (NED vertices, or ENU with --z-up)",
        description="Export a map as a triangle mesh, with its CRS, origin, units and axes in a "
        "JSON sidecar named after it (lake.ply -> lake.ply.json).",
    )
    map_argument(p)
    output_option(p, "mesh file (.ply or .obj); its sidecar OUTPUT.json is written too")
    p.add_argument(
        "--z-up", action="store_true",
        help="vertices east, north, elevation (= -depth): a right-handed ENU mesh for viewers "
        "that expect z up (default: north, east, depth, NED)",
    )
    p.set_defaults(func=cmd_maps_mesh)
    _add_grid(maps_sub)
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
    p = maps_sub.add_parser(
        "change",
        help="how much has the seafloor changed since a map was made? later surveys' check lines",
        description="Compare later surveys' soundings (.nc, at their reference track) with MAP where "
        "it was measured (a map 'maps grid' wrote: its cells holding soundings; else where it states "
        "at most its median error), one by one and in windows of track, and print the change since "
        "the map (its std and range) that would make the map's stated error hold, with the "
        "navigation model's map_change_std and map_change_length that state it.",
    )
    map_argument(p)
    p.add_argument("inputs", type=Path, nargs="+", metavar="SURVEY", help="later survey files (.nc)")
    p.add_argument("--window", type=WINDOW, default=50.0, help="window of track (m; default 50)")
    p.add_argument("--sounding-std", type=SOUNDING_STD, default=0.1,
                   help="the soundings' own noise std (m; default 0.1)")
    p.add_argument("--position-std", type=POSITION_STD, default=0.0, metavar="M",
                   help="std (m per axis) of the surveys' reference track (their GPS): its error seen "
                   "through the map's slope is not counted as change (default: 0)")
    p.add_argument("--map-std", type=MAP_STD, default=0.0, metavar="M",
                   help="for a map that states no error (no depth_std layer): the std it errs by "
                   "(m); without it such a map's own error cannot be told from a change")
    p.set_defaults(func=cmd_maps_change)


def _add_grid(maps_sub) -> None:
    p = maps_sub.add_parser(
        "grid",
        help="grid surveys (.nc, at their reference tracks) or scattered soundings (x y z text) into a map",
        description="Grid the soundings of one or more survey files (.nc), each placed at its "
        "reference track (GPS or truth) and put in the frame (CRS, origin) of the first, or of one "
        "x y z text file, into a map: median or mean, count and std per cell, and the map's error "
        "(depth_std per cell: the standard error of a measured cell, growing with the distance to "
        "the data in a filled one; a correlation length), checked by the surveys' check lines.",
    )
    p.add_argument("inputs", type=Path, nargs="+", metavar="INPUT",
                   help="survey files (.nc), or one x/east y/north z text file")
    _gridding_options(p)
    p.add_argument(
        "--use-dr", action="store_true",
        help="place survey soundings at the dead reckoning (for surveys without a reference track)",
    )
    p.add_argument(
        "--check-lines", action=argparse.BooleanOptionalAction, default=None,
        help="survey files: hold out each survey (a single one: each of its lines), grid the others, "
        "and give the map the error the held-out windows find: depth_std scaled by their RMS when above "
        "1, or by a Student-t's scale with its degrees of freedom (error_dof) for a heavier tail (see "
        "'maps check'). Default: wherever it can be made (else the map keeps the gridding's error and "
        "says why); --check-lines: an error where it cannot; --no-check-lines: never",
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
    output_option(p, "NetCDF file: depth (the statistic) with its depth_std, mean, median, count and std "
                  "per cell")
    p.set_defaults(func=cmd_maps_grid)
