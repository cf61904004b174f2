"""The ``tangraph`` command: parses arguments and calls one library function per subcommand.

One module per group of subcommands, each with its ``add_parser(subparsers)`` and its handlers
(``cmd_*``): :mod:`~tangraph.cli.maps` (``maps list|info|plot|mesh|grid|check``),
:mod:`~tangraph.cli.simulate`, :mod:`~tangraph.cli.survey` (``survey info|import|plot``),
:mod:`~tangraph.cli.experiment`, :mod:`~tangraph.cli.tracks` (``navigate``, ``smooth``) and
:mod:`~tangraph.cli.demo`; what they share is in :mod:`~tangraph.cli._common`. Here: the parser
they make together (:func:`build_parser`) and the entry point with its error contract
(:func:`main`).
"""

from __future__ import annotations

import argparse
import logging
import os
import sys
from collections.abc import Sequence

from tangraph.cli import demo, experiment, maps, simulate, survey, tracks
from tangraph.cli._common import DefaultsHelpFormatter
from tangraph.errors import TangraphError

__all__ = ["DefaultsHelpFormatter", "build_parser", "main"]

#: the command groups, in the order the help lists them
GROUPS = (maps, simulate, survey, experiment, tracks, demo)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser (also used to document the CLI)."""
    from tangraph import __version__

    parser = argparse.ArgumentParser(prog="tangraph", description="Terrain-aided navigation of AUVs.")
    parser.add_argument("--version", action="version", version=f"tangraph {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress bars")
    parser.add_argument("--debug", action="store_true", help="show the traceback of an error")
    sub = parser.add_subparsers(dest="command", required=True)
    for group in GROUPS:
        group.add_parser(sub)
    for leaf in _leaves(parser):  # -v and -q after the subcommand too; defaults in every help
        leaf.add_argument("-v", "--verbose", action="store_true", default=argparse.SUPPRESS,
                          help="log progress")
        leaf.add_argument("-q", "--quiet", action="store_true", default=argparse.SUPPRESS,
                          help="no progress bars")
    for each in (parser, *_leaves(parser)):
        each.formatter_class = DefaultsHelpFormatter
    return parser


def _leaves(parser: argparse.ArgumentParser) -> list[argparse.ArgumentParser]:
    found = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    children = dict(found[0].choices) if found else {}
    return [leaf for child in children.values() for leaf in _leaves(child)] if children else [parser]


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
