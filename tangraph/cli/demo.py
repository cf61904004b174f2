"""``tangraph demo``: simulate, navigate with every method, and write a report."""

from __future__ import annotations

import argparse
from pathlib import Path

from tangraph.cli._common import SEED, progress


def cmd_demo(args: argparse.Namespace) -> None:
    from tangraph.demo import format_table, run_demo

    result = run_demo(args.out, map_name=args.map, seed=args.seed, quick=args.quick, force=args.force,
                      progress=progress(args), map_error=args.map_error)
    print(format_table(result.rows))
    print(f"wrote {result.report} and {len(result.figures)} figures in {result.seconds:.0f} s")


def add_parser(subparsers) -> None:
    """``demo``."""
    p = subparsers.add_parser("demo", help="simulate, navigate with every method, and write a report")
    p.add_argument("--map", default="merimbula", help="map with a demo survey (default: merimbula)")
    p.add_argument("--out", type=Path, default=Path("demo"), help="report folder (default: ./demo)")
    p.add_argument("--seed", type=SEED, default=7, help="seed of the simulation and the filters")
    p.add_argument("--quick", action="store_true", help="half the survey, fewer particles")
    p.add_argument("--force", action="store_true", help="replace the report folder if it exists")
    p.add_argument("--map-error", action="store_true",
                   help="a seafloor that is not the map: navigate on a prior map gridded from a simulated "
                   "earlier survey of it")
    p.set_defaults(func=cmd_demo)
