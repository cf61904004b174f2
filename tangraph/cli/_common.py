"""What the commands share: argparse types within bounds, the options of a map argument and of
an output file, the help formatter, and the few steps every handler takes (read options, load a
map, print JSON)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from tangraph.errors import TangraphError


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


SEED = _bounded(int, 0, 2**63 - 1, "a seed")
PARTICLES = _bounded(int, 1, 10_000_000, "the particle count")
DPI = _bounded(int, 20, 1200, "the resolution (dpi)")
CELL = _bounded(float, 0.01, 100_000.0, "the cell size (m)")
FILL = _bounded(int, 0, 1000, "the fill distance (cells)")
WINDOW = _bounded(float, 0.01, 1e6, "the window length (m)")
SOUNDING_STD = _bounded(float, 0.001, 1000.0, "the sounding std (m)")
MAP_STD = _bounded(float, 0.0, 1000.0, "the map's error std (m)")
POSITION_STD = _bounded(float, 0.0, 100_000.0, "the position std (m)")
DECLINATION = _bounded(float, -180.0, 180.0, "the declination (deg)")


class DefaultsHelpFormatter(argparse.HelpFormatter):
    """Help that shows an option's default where it has one and its help does not say it."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if action.default not in (None, False, argparse.SUPPRESS) and "default" not in text \
                and not isinstance(action, argparse._VersionAction):
            text += " (default: %(default)s)"
        return text


# -- options ------------------------------------------------------------------------------------
def map_argument(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("map", metavar="NAME|PATH", help="a catalogue map name or a map file")
    map_read_options(parser)


def map_read_options(parser: argparse.ArgumentParser, *, crs: bool = True) -> None:
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


def output_file(text: str) -> Path:
    """An output path that is not an existing folder (refused at once, before any work)."""
    if Path(text).is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a folder; give the file's name (in it, if you like)")
    return Path(text)


def output_option(parser: argparse.ArgumentParser, help_text: str) -> None:
    parser.add_argument("-o", "--output", type=output_file, required=True, help=help_text)
    parser.add_argument("--force", action="store_true", help="replace OUTPUT if it exists")


def json_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print the figures as one JSON object")


# -- steps of the handlers ----------------------------------------------------------------------
_READ = ("variable", "sign", "crs", "units", "nodata", "cell", "uncertainty")


def read_options(args: argparse.Namespace) -> dict:
    """The map-reading options given (keywords of :func:`tangraph.maps.load_any`)."""
    options = {k: getattr(args, k) for k in _READ if getattr(args, k, None) is not None}
    if isinstance(options.get("uncertainty"), str) and options["uncertainty"].lower() == "none":
        options["uncertainty"] = False  # the depths alone
    return options


def load_map(args: argparse.Namespace):
    from tangraph.maps import load_any

    return load_any(args.map, **read_options(args))


def survey_map_options(args: argparse.Namespace, survey) -> dict:
    """How to read the map of a survey: the options given, over those the survey recorded for its
    own map (where no ``--map`` is given)."""
    return read_options(args) if args.map else {**survey.meta.get("map_read", {}), **read_options(args)}


def figure_file(path: Path) -> None:
    """Refuse, before any work, a figure file whose suffix matplotlib cannot write."""
    from matplotlib.figure import Figure

    known = Figure().canvas.get_supported_filetypes()
    if path.suffix[1:].lower() not in known:
        raise TangraphError(
            f"{path}: a figure is written as {', '.join('.' + k for k in sorted(known))}; "
            f"not {path.suffix or 'a file without a suffix'}"
        )


def write_figure(fig, path: Path, force: bool, dpi: int) -> None:
    """Write a matplotlib figure to ``path`` in the format of its suffix, whole or not at all."""
    from tangraph.outputs import write_atomically

    write_atomically(path, force, lambda tmp: fig.savefig(tmp, dpi=dpi, format=path.suffix[1:]))


def progress(args: argparse.Namespace) -> bool:
    """Progress bars only on a terminal, and not with -q."""
    return not args.quiet and sys.stderr.isatty()


def print_json(report: dict) -> None:
    import json

    print(json.dumps(report, indent=2, default=_plain))


def _plain(value):
    """numpy scalars and anything else json does not know, as plain Python."""
    return value.item() if hasattr(value, "item") else str(value)
