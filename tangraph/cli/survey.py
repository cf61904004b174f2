"""``tangraph survey``: describe a survey file, import one recorded by another system, plot one."""

from __future__ import annotations

import argparse
from pathlib import Path

from tangraph.cli._common import (
    DECLINATION,
    figure_file,
    json_option,
    map_read_options,
    output_option,
    print_json,
    survey_map_options,
    write_figure,
)
from tangraph.errors import TangraphError


def cmd_survey_info(args: argparse.Namespace) -> None:
    from tangraph.survey import read_survey

    survey = read_survey(args.survey)
    if args.json:
        print_json(survey.report())
    else:
        print(survey.summary())


#: ``survey import``'s options: the reader's keyword, and the option that gives it
_IMPORT_FLAGS = {
    "columns": "--columns", "header": "--no-header", "time_format": "--time-format", "sign": "--sign",
    "units": "--units", "water_level": "--water-level",
    "water_level_interpolate": "--water-level-interpolate", "draft": "--draft",
    "dr_heading": "--dr-heading", "declination_deg": "--declination", "timezone": "--timezone",
}


def cmd_survey_import(args: argparse.Namespace) -> None:
    from tangraph.formats import import_survey
    from tangraph.survey import write_survey

    options = _import_options(args)
    _check_import(args, options)
    if options.get("columns") is not None:
        options["columns"] = _columns(options["columns"])
    survey = import_survey(args.format, args.files, **options)
    write_survey(survey, args.output, overwrite=args.force)
    print(survey.summary())
    counts = [f"{k} {v}" for k, v in survey.meta.items() if k.startswith("n_")]
    if counts:
        print("counts       " + ", ".join(counts))
    print(f"wrote {args.output}")


def _import_options(args: argparse.Namespace) -> dict:
    """The reader's keywords given (``crs``, and what its format reads by default, always)."""
    given = {
        "columns": args.columns, "header": False if args.no_header else None, "time_format": args.time_format,
        "sign": args.sign, "units": args.units, "water_level": args.water_level,
        "water_level_interpolate": args.water_level_interpolate or None, "draft": args.draft,
        "dr_heading": args.dr_heading, "declination_deg": args.declination, "timezone": args.timezone,
    }
    always = {"csv-xyz": {"crs": args.crs, "timezone": args.timezone, "columns": None, "header": True},
              "sontek-sum": {"crs": args.crs, "timezone": args.timezone, "water_level": None,
                             "water_level_interpolate": False}}.get(args.format, {"crs": args.crs})
    return {**always, **{k: v for k, v in given.items() if v is not None}}


def _check_import(args: argparse.Namespace, options: dict) -> None:
    """Before any reading: options of another format, the file count, no output over an input,
    and none that exists without --force."""
    from tangraph.formats import SURVEY_FORMATS

    kind = SURVEY_FORMATS[args.format]
    wrong = [flag for key, flag in _IMPORT_FLAGS.items() if key in options and key not in kind.options]
    if wrong:
        raise TangraphError(
            f"{', '.join(wrong)} {'does' if len(wrong) == 1 else 'do'} not apply to --format {args.format}"
        )
    if kind.files is not None and len(args.files) != kind.files:
        raise TangraphError(f"--format {args.format} takes {kind.files_text}, got {len(args.files)}")
    for path in [*args.files, *([args.water_level] if args.water_level else [])]:
        if args.output.resolve() == Path(path).resolve():
            raise TangraphError(f"refusing to write the survey over the input {path}")
    if args.output.suffix.lower() != ".nc":
        raise TangraphError(f"-o {args.output}: a survey is written as NetCDF; name it .nc")
    if args.output.exists() and not args.force:
        raise FileExistsError(f"{args.output} exists; pass --force to replace it")


def _columns(text: str) -> dict[str, int | str]:
    """``--columns KEY=COL,...``: a column by name, or by position where it is digits."""
    columns: dict[str, int | str] = {}
    for item in text.split(","):
        key, sep, column = (v.strip() for v in item.partition("="))
        if not (sep and key and column):
            raise TangraphError(f"--columns: {item!r} is not KEY=COLUMN (e.g. time=0,lat=2,lon=3)")
        columns[key] = int(column) if column.isdigit() else column
    return columns


def cmd_survey_plot(args: argparse.Namespace) -> None:
    from matplotlib.figure import Figure

    from tangraph.maps import load_any
    from tangraph.plot import plot_survey
    from tangraph.survey import read_survey

    figure_file(args.output)
    survey = read_survey(args.survey)
    name = args.map or survey.meta.get("map")
    bathymetry = load_any(name, **survey_map_options(args, survey)) if name else None
    fig = Figure(figsize=(8, 7), layout="constrained")
    plot_survey(survey, bathymetry, fig.add_subplot())
    write_figure(fig, args.output, args.force, 150)
    print(f"wrote {args.output}")


# -- the parser ---------------------------------------------------------------------------------
def add_parser(subparsers) -> None:
    """``survey`` and its subcommands."""
    survey = subparsers.add_parser("survey", help="survey files: info, import, plot")
    survey_sub = survey.add_subparsers(dest="survey_command", required=True)
    p = survey_sub.add_parser("info", help="describe a survey file")
    p.add_argument("survey", type=Path, help="survey file (.nc)")
    json_option(p)
    p.set_defaults(func=cmd_survey_info)
    _add_import(survey_sub)
    p = survey_sub.add_parser(
        "plot", help="truth vs dead reckoning over the hill-shaded map, swath footprints"
    )
    p.add_argument("survey", type=Path, help="survey file (.nc)")
    p.add_argument("--map", metavar="NAME|PATH", help="the map (default: the one named in the survey)")
    map_read_options(p)
    output_option(p, "figure file (.png, .pdf, .svg)")
    p.set_defaults(func=cmd_survey_plot)


def _add_import(survey_sub) -> None:
    from tangraph.formats import SURVEY_FORMATS

    p = survey_sub.add_parser(
        "import",
        help="a survey recorded by another system: CSV log + XYZ soundings, or SonTek .sum files",
    )
    p.add_argument("--format", choices=list(SURVEY_FORMATS), default="csv-xyz",
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
    p.add_argument("--declination", type=DECLINATION, metavar="DEG",
                   help="sontek-sum: added to the compass heading (deg)")
    output_option(p, "survey file (.nc)")
    p.set_defaults(func=cmd_survey_import)
