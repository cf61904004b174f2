"""Monte Carlo runs on Dask: many seeded runs of one function over a list of configurations.

``run_many(fn, configs, runs, seed)`` calls ``fn(config, rng=...)`` ``runs`` times for every
config and gathers the results into one tidy table, a row per run (or several, if ``fn`` returns
a list of rows).

Seeds
    One ``numpy.random.SeedSequence(seed)`` is the root. Run ``r`` of config ``c`` draws from
    ``numpy.random.default_rng(SeedSequence(seed, spawn_key=(c, r)))`` (PCG64), which is the
    grandchild ``SeedSequence(seed).spawn(n_configs)[c].spawn(runs)[r]``. A run's stream depends on
    ``(seed, c, r)`` only: not on the scheduler, the number of workers, the batch size, the number
    of runs or the configs after it; a study extended from 100 to 1000 runs keeps its first 100
    rows. :func:`rerun` re-creates any single run in-process.
Scheduling
    ``scheduler=None`` starts a local cluster of single-threaded worker processes and closes it
    at the end; an address (``"tcp://host:8786"``) or a ``distributed.Client`` uses an existing
    cluster; ``"synchronous"`` runs everything serially in this process (debugging, tests).
    Runs are submitted in batches of consecutive runs of one config (``batch_size``; by default
    about ten batches per worker, so 10^4 trivial runs cost a few dozen tasks, not 10^4), and each
    config is sent to the cluster once. A Dask task costs milliseconds of scheduling; batched,
    1000 trivial runs take about 0.2 s on two local workers (once the cluster is up, which takes
    a few seconds), one task per run about 5 s.
Failures
    A run that raises is kept as a row whose ``error`` column holds ``"Type: message"``; the others
    are unaffected and a warning gives the count. ``fail_fast=True`` re-raises the first error.

The parts: this module holds the entry point (the checks of its arguments, the choice of the
scheduler, the progress bar) and the seeds; :mod:`~tangraph.experiments.tasks` the work of one
task (a batch of runs, on a worker); :mod:`~tangraph.experiments.scheduling` the run loop, serial
or on Dask, and its clean-up after an interrupt; :mod:`~tangraph.experiments.tables` the table,
the summary of the failed runs and the files written from the runs.
"""

from __future__ import annotations

import datetime
import functools
import logging
import math
import os
import time
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd
from tqdm import tqdm

from tangraph.errors import TangraphError
from tangraph.experiments.scheduling import _run_dask, _run_synchronous
from tangraph.experiments.tables import (
    RESERVED_COLUMNS,
    _all_config_columns,
    _metadata,
    _output_paths,
    _report_failures,
    _save,
    _table,
)
from tangraph.experiments.tasks import RunFunction

if TYPE_CHECKING:
    from distributed import Client

__all__ = ["RESERVED_COLUMNS", "rerun", "run_many", "run_rng", "run_seed_sequence"]

logger = logging.getLogger(__name__)


# -- seeds -------------------------------------------------------------------------------------
def run_seed_sequence(seed: int, config_index: int, run: int) -> np.random.SeedSequence:
    """The seed sequence of run ``run`` of config ``config_index`` in a study seeded ``seed``.

    Examples
    --------
    >>> import numpy as np
    >>> from tangraph.experiments import run_seed_sequence
    >>> child = run_seed_sequence(42, 1, 2)
    >>> child.spawn_key
    (1, 2)
    >>> bool(np.all(child.generate_state(4)
    ...             == np.random.SeedSequence(42).spawn(3)[1].spawn(5)[2].generate_state(4)))
    True
    """
    return np.random.SeedSequence(seed, spawn_key=(int(config_index), int(run)))


def run_rng(seed: int, config_index: int, run: int) -> np.random.Generator:
    """The generator that :func:`run_many` hands to run ``run`` of config ``config_index``."""
    return np.random.default_rng(run_seed_sequence(seed, config_index, run))


def rerun(
    fn: RunFunction, config: Any, seed: int, config_index: int, run: int
) -> Mapping[str, Any] | Sequence[Mapping[str, Any]]:
    """Re-create one run of a :func:`run_many` study in this process (for debugging).

    Parameters
    ----------
    fn, config
        The function and the config (``configs[config_index]``) of the study.
    seed
        The study's seed (the ``seed_entropy`` column).
    config_index, run
        The row's ``config_index`` and ``run``.

    Returns
    -------
    dict or list of dict
        What ``fn`` returns; exceptions propagate.

    Examples
    --------
    >>> from tangraph.experiments import rerun, run_many
    >>> def draw(config, *, rng):
    ...     return {"x": rng.normal(config["mu"])}
    >>> table = run_many(draw, [{"mu": 0.0}, {"mu": 10.0}], runs=4, seed=3,
    ...                  scheduler="synchronous", progress=False)
    >>> row = table.iloc[6]
    >>> bool(rerun(draw, {"mu": 10.0}, 3, row.config_index, row.run)["x"] == row.x)
    True
    """
    return fn(config, rng=run_rng(seed, config_index, run))


# -- checks ------------------------------------------------------------------------------------
def _check_int(name: str, value: Any, low: int, high: float = math.inf) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or not low <= value < high:
        bound = f"in [{low}, 2**63)" if high < math.inf else f">= {low}"
        raise TangraphError(f"{name} must be an integer {bound}, got {value!r}")
    return int(value)


def _checked_arguments(
    fn: RunFunction, configs: Sequence[Any], runs: int, seed: int, scheduler: str | Client | None,
    workers: int | None, batch_size: int | None,
) -> tuple[list[Any], int, int, int | None, int | None]:
    """``configs`` as a list, ``runs``, the seed's entropy, ``workers`` and ``batch_size``, checked."""
    if not callable(fn):
        raise TangraphError(f"fn must be callable, got {fn!r}")
    configs = list(configs)
    if not configs:
        raise TangraphError("configs is empty")
    runs = _check_int("runs", runs, 1)
    entropy = _check_int("seed", seed, 0, 2**63)
    if workers is not None:
        workers = _check_int("workers", workers, 1)
        if scheduler is not None:
            raise TangraphError("workers= sizes the local cluster; it needs scheduler=None")
    if batch_size is not None:
        batch_size = _check_int("batch_size", batch_size, 1)
    return configs, runs, entropy, workers, batch_size


# -- the runs ----------------------------------------------------------------------------------
def _progress_bar(total: int, progress: bool) -> tqdm:
    """The tqdm bar (on stderr) over the ``total`` runs, hidden unless ``progress``; the run loop
    gets it from here, made by this module's ``tqdm`` whichever the scheduler."""
    return tqdm(total=total, unit="run", disable=not progress)


def _study(
    fn: RunFunction, configs: list[Any], runs: int, entropy: int, fail_fast: bool,
    scheduler: str | Client | None, workers: int | None, batch_size: int | None, progress: bool,
    config_columns: list[dict[str, Any]],
) -> pd.DataFrame:
    """The runs, serially or on Dask, as the table, with their metadata in ``table.attrs["tangraph"]``
    (the failed runs reported)."""
    start, started = time.perf_counter(), datetime.datetime.now(datetime.UTC)
    new_bar = functools.partial(_progress_bar, len(configs) * runs, progress)
    if scheduler == "synchronous":
        collector, used = _run_synchronous(
            fn, configs, runs, entropy, fail_fast, batch_size, new_bar, config_columns
        )
    else:
        collector, used = _run_dask(
            fn, configs, runs, entropy, fail_fast, scheduler, workers, batch_size, new_bar, config_columns
        )
    wall_time = time.perf_counter() - start

    table = _table(collector, entropy)
    n_failed = _report_failures(collector, entropy)
    table.attrs["tangraph"] = _metadata(
        fn, entropy, runs, len(configs), len(table), n_failed, used, started, wall_time
    )
    return table


# -- the entry point ---------------------------------------------------------------------------
def run_many(fn: RunFunction, configs: Sequence[Any], runs: int, seed: int, *,
             scheduler: str | Client | None = None, workers: int | None = None, progress: bool = True,
             output: str | os.PathLike[str] | None = None, overwrite: bool = False,
             fail_fast: bool = False, batch_size: int | None = None) -> pd.DataFrame:
    """Run ``fn`` ``runs`` times on every config, each run with its own seeded generator.

    Parameters
    ----------
    fn
        ``fn(config, *, rng) -> dict`` of scalars (or a list of such dicts: several rows). With
        worker processes it must be a function defined at the top level of an importable module
        (a script's ``__main__`` works too; guard the script with ``if __name__ == "__main__":``).
    configs
        Dicts or dataclass instances (frozen ones, ideally); ``fn`` gets them unchanged. Their
        fields become columns: nested dicts and dataclasses as dotted names (``sensor.sigma``),
        lists and tuples of scalars as strings; arrays and other objects are left out of the
        table. A result key that repeats a column name is an error.
    runs, seed
        Runs per config, and the root of all the runs' seeds (see the module's notes on seeds),
        an integer in [0, 2**63).
    scheduler, workers
        ``None``: a local cluster of ``workers`` single-threaded processes (default:
        ``os.cpu_count()``; ``workers`` is only for this case), started and closed here; a
        scheduler address or a ``distributed.Client``: an existing cluster (left running);
        ``"synchronous"``: serially in this process.
    progress
        Show a tqdm progress bar (on stderr) over completed runs.
    output, overwrite
        Save the table to this ``.csv`` or ``.parquet`` file (written atomically), with a JSON
        sidecar ``<output>.meta.json`` (seed, runs, configs, versions, scheduler, times). Checked
        before the first run: an existing one (or its sidecar) is replaced only if ``overwrite``.
    fail_fast
        Re-raise the first exception of a run, cancelling the others. By default a failed run
        becomes a row whose ``error`` column holds ``"Type: message"``, and a warning is logged.
    batch_size
        Consecutive runs of one config per task (default: about ten tasks per worker thread; 1
        with ``"synchronous"``). Results do not depend on it.

    Returns
    -------
    pandas.DataFrame
        One row per result, sorted by ``(config_index, run)``: ``config_index``, ``run``, the
        config's fields, the result's keys, ``error`` (``None`` where the run succeeded),
        ``seed_entropy`` and ``spawn_key`` (``"(config_index, run)"``; see :func:`rerun`). The
        metadata of the sidecar is in ``table.attrs["tangraph"]``.

    Raises
    ------
    TangraphError
        Bad arguments, an existing output, a clash of result keys with config fields, or an
        ``fn`` that cannot be sent to worker processes.
    KeyboardInterrupt
        After cancelling the outstanding runs and closing the local cluster.

    Examples
    --------
    >>> from tangraph.experiments import run_many
    >>> def fix_error(config, *, rng):
    ...     return {"error_m": abs(rng.normal(0.0, config["sigma"]))}
    >>> table = run_many(fix_error, [{"sigma": 1.0}, {"sigma": 5.0}], runs=3, seed=7,
    ...                  scheduler="synchronous", progress=False)
    >>> len(table), table["sigma"].tolist()
    (6, [1.0, 1.0, 1.0, 5.0, 5.0, 5.0])
    >>> list(table.columns)
    ['config_index', 'run', 'sigma', 'error_m', 'error', 'seed_entropy', 'spawn_key']

    On four local processes, or on a cluster::

        table = run_many(fix_error, configs, runs=500, seed=7, workers=4, output="study.csv")
        table = run_many(fix_error, configs, runs=500, seed=7, scheduler="tcp://10.0.0.5:8786")
    """
    configs, runs, entropy, workers, batch_size = _checked_arguments(fn, configs, runs, seed, scheduler,
                                                                     workers, batch_size)
    config_columns = _all_config_columns(configs)
    paths = _output_paths(output, overwrite) if output is not None else None
    table = _study(fn, configs, runs, entropy, fail_fast, scheduler, workers, batch_size, progress,
                   config_columns)
    if paths is not None:
        _save(table, table.attrs["tangraph"], *paths, overwrite)
    return table
