"""``tangraph experiment``: run a study of ``experiments/``, or list them."""

from __future__ import annotations

import argparse


def cmd_experiment(args: argparse.Namespace) -> None:
    from tangraph.experiments.registry import list_experiments, run_experiment

    if args.name is None:
        print("\n".join(list_experiments()))
        return
    status = run_experiment(args.name, args.study_args)
    if status:
        raise SystemExit(status)


def add_parser(subparsers) -> None:
    """``experiment``."""
    p = subparsers.add_parser(
        "experiment",
        help="run a study of experiments/ (no name: list them)",
        description="Run experiments/NAME/run.py; arguments after NAME go to the study "
        "(e.g. --runs 200 --scheduler ADDR --quick; NAME --help lists them).",
    )
    p.add_argument("name", nargs="?", help="the study")
    p.add_argument("study_args", nargs=argparse.REMAINDER, help="arguments of the study")
    p.set_defaults(func=cmd_experiment)
