"""The command line every study shares: runs, seed, where to run, and where its results go.

A study's ``main`` builds its parser with :func:`study_parser` (adding its own options) and
gets its output folder from :func:`output_folder`: the folder the user names with ``--out``, or,
for a study run from a checkout of the repository, its ``results/`` beside it (where the
committed tables live). An installed study (inside the package) never writes into the package:
it asks for ``--out``. A folder that already holds files is written into only with ``--force``.
"""

from __future__ import annotations

import argparse
import functools
from pathlib import Path

from tangraph.cli import DefaultsHelpFormatter
from tangraph.errors import TangraphError

__all__ = ["field_values", "graph_settings", "output_folder", "per_process", "study_parser"]

_CACHE: dict = {}  # per process, here in the package: see per_process


def per_process(fn):
    """Cache ``fn``'s results (hashable arguments) for the life of the process.

    A study's module travels to the workers by value (:func:`~tangraph.experiments.run_many`), so
    ``functools.cache`` on one of its functions cannot be unpickled there, and a cache dict of
    its own would travel, full, with every task. This one lives in the package, which each worker
    imports by name: every worker fills its own.
    """
    name = f"{fn.__module__}.{fn.__qualname__}"

    @functools.wraps(fn)
    def cached(*args):
        from tangraph.experiments import study  # by name in the worker, not by value

        key = (name, args)
        if key not in study._CACHE:
            study._CACHE[key] = fn(*args)
        return study._CACHE[key]

    return cached


def study_parser(here: Path, description: str, *, runs: int | None, seed: int,
                 quick: str) -> argparse.ArgumentParser:
    """The parser of the study in folder ``here`` with the options every study has.

    ``runs`` is the default number of runs (None: the study's config file says); ``seed`` the
    default root seed; ``quick`` what ``--quick`` does, for the help.
    """
    parser = argparse.ArgumentParser(
        prog=f"tangraph experiment {here.name}", description=description,
        formatter_class=DefaultsHelpFormatter,
    )
    where = " (default: the study's config.toml)" if runs is None else ""
    parser.add_argument("--runs", type=int, default=runs, help="runs per configuration" + where)
    parser.add_argument("--seed", type=int, default=seed, help="root seed of every run")
    parser.add_argument("--scheduler",
                        help="Dask scheduler address, or 'synchronous' (default: local processes)")
    parser.add_argument("--workers", type=int, help="local worker processes (default: all cores)")
    parser.add_argument("--quick", action="store_true", help=quick)
    parser.add_argument("--out", type=Path, help="folder for the tables and figures (default: results/ "
                        "beside the study in a checkout; required for an installed study)")
    parser.add_argument("--force", action="store_true", help="write into an --out folder that holds files")
    return parser


def field_values(items, option: str = "--graph") -> dict:
    """``FIELD=VALUE`` items (a study's ``--graph`` options) as a mapping: each value a Python
    literal (``3``, ``0.5``, ``None``, ``"pmf"``) or, when it is none, the bare string.

    >>> field_values(["n_pings=30", "front_end=pmf", 'smoother_terrain="soundings"'])
    {'n_pings': 30, 'front_end': 'pmf', 'smoother_terrain': 'soundings'}
    """
    import ast

    fields = {}
    for item in items:
        name, sep, value = item.partition("=")
        if not sep or not name:
            raise TangraphError(f"{option} {item!r}: expected FIELD=VALUE")
        try:
            fields[name] = ast.literal_eval(value)
        except (ValueError, SyntaxError):
            fields[name] = value
    return fields


def graph_settings(fields: dict, option: str = "--graph"):
    """The :class:`~tangraph.graph.GraphConfig` of a study's ``--graph FIELD=VALUE`` options (the
    fields of any of its parts, by name), a bad one refused naming ``option``.

    >>> graph_settings({"n_pings": 30, "smoother_terrain": "soundings"}).fixes.n_pings
    30
    >>> graph_settings({"n_ping": 30})
    Traceback (most recent call last):
    ...
    tangraph.errors.TangraphError: --graph: unknown GraphConfig field 'n_ping'
    """
    from tangraph.graph import GraphConfig

    try:
        return GraphConfig().replace(**fields)
    except TangraphError as exc:
        raise TangraphError(f"{option}: {exc}") from None


def output_folder(args: argparse.Namespace, here: Path) -> Path:
    """The folder the study writes to (created), checked as the module docstring says.

    Raises
    ------
    TangraphError
        No ``--out`` for an installed study, or a folder with files and no ``--force``.
    """
    installed = here.parent.name != "experiments"  # the wheel puts studies in tangraph/_experiments
    out = args.out
    if out is None:
        if installed:
            raise TangraphError(
                f"{here.name}: pass --out DIR (an installed study does not write into its package)"
            )
        out, checkout = here / "results", True
    else:
        checkout = False
    out = Path(out)
    if out.is_file():
        raise TangraphError(f"{here.name}: --out {out} is a file, not a folder")
    if not checkout and out.is_dir() and any(out.iterdir()) and not args.force:
        raise TangraphError(f"{here.name}: {out} already holds files; pass --force to write into it")
    out.mkdir(parents=True, exist_ok=True)
    return out
