"""``tangraph simulate``: a survey simulated from a scenario, written with the map it needs."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from tangraph.cli._common import SEED, map_read_options, output_option, read_options
from tangraph.errors import TangraphError


def cmd_simulate(args: argparse.Namespace) -> None:
    from tangraph.maps import load_any
    from tangraph.sim.scenario import load_scenario, simulate_run

    scenario = load_scenario(args.scenario)
    bathymetry = load_any(args.map or scenario.map, **read_options(args))
    seed = scenario.seed if args.seed is None else args.seed
    prior = _prior_map_path(args.output)
    if scenario.seafloor is not None and prior.exists() and not args.force:
        raise TangraphError(
            f"{prior} exists (the prior map of {args.output.name}): pass --force to replace it"
        )
    run = simulate_run(scenario, rng=np.random.default_rng(seed), bathymetry=bathymetry, seed=seed)
    survey = _write_run(run, args, prior)
    print(survey.summary())
    if run.world is not None:
        print(f"wrote {prior} (the map its estimators navigate on: the seafloor is not the scenario's map)")
    print(f"wrote {args.output}")


def _prior_map_path(output: Path) -> Path:
    """Where the prior map of a seafloor that is not the map goes: beside the survey."""
    return output.with_name(f"{output.stem}_prior_map.nc")


def _write_run(run, args: argparse.Namespace, prior: Path):
    """Write the simulated survey, naming the map its estimators must read (the prior map, written
    here, or the map file given); returns the survey written."""
    from tangraph.maps import write_map
    from tangraph.survey import write_survey

    survey = run.survey
    if run.world is not None:  # the estimators' map is the prior map: written beside the survey
        write_map(run.bathymetry, prior, overwrite=args.force)
        survey = survey.replace(meta={**survey.meta, "map": str(prior.resolve()), "map_read": {}})
    elif args.map is not None and Path(args.map).exists():  # a file: smooth must find it again
        survey = survey.replace(meta={**survey.meta, "map": str(Path(args.map).resolve()),
                                      "map_read": read_options(args)})
    write_survey(survey, args.output, overwrite=args.force)
    return survey


def add_parser(subparsers) -> None:
    """``simulate``."""
    p = subparsers.add_parser("simulate", help="simulate a survey from a scenario")
    p.add_argument(
        "scenario", metavar="SCENARIO.toml|NAME", help="a scenario file or a shipped scenario name"
    )
    p.add_argument("--map", metavar="NAME|PATH", help="run on this map instead of the scenario's")
    map_read_options(p)
    p.add_argument("--seed", type=SEED, help="seed (default: the scenario's)")
    output_option(p, "survey file (.nc)")
    p.set_defaults(func=cmd_simulate)
