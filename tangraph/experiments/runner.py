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
"""

from __future__ import annotations

import dataclasses
import datetime
import enum
import importlib.metadata
import json
import logging
import math
import os
import pickle
import platform
import time
import traceback
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd
from tqdm import tqdm

from tangraph import __version__
from tangraph.errors import TangraphError
from tangraph.outputs import write_atomically

if TYPE_CHECKING:
    from distributed import Client

__all__ = ["RESERVED_COLUMNS", "rerun", "run_many", "run_rng", "run_seed_sequence"]

logger = logging.getLogger(__name__)

#: Columns the runner adds to every row; neither configs nor results may use these names.
RESERVED_COLUMNS = ("config_index", "run", "error", "seed_entropy", "spawn_key")

_SEED_SCHEME = (
    "numpy.random.default_rng(numpy.random.SeedSequence(seed, spawn_key=(config_index, run))), "
    "i.e. SeedSequence(seed).spawn(n_configs)[config_index].spawn(runs)[run]; PCG64"
)
_TARGET_BATCHES_PER_WORKER = 10

RunFunction = Callable[..., Mapping[str, Any] | Sequence[Mapping[str, Any]]]
# (run, rows or None, error or None, traceback or None)
_RunOutcome = tuple[int, list[dict[str, Any]] | None, str | None, str | None]


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


# -- the work of one task (runs in the workers) ------------------------------------------------
def _as_rows(result: Any) -> list[dict[str, Any]]:
    """``fn``'s result as a list of flat rows of scalars."""
    if isinstance(result, Mapping):
        result = [result]
    elif not isinstance(result, list | tuple):
        raise TangraphError(f"fn must return a dict or a list of dicts, not {type(result).__name__}")
    rows = []
    for item in result:
        if not isinstance(item, Mapping):
            raise TangraphError(f"fn returned a list holding a {type(item).__name__}, not a dict")
        row = {}
        for key, value in item.items():
            if not isinstance(key, str):
                raise TangraphError(f"fn's result keys must be strings, got {key!r}")
            if isinstance(value, np.ndarray) and value.ndim == 0:
                value = value.item()
            if isinstance(value, Mapping | list | tuple | set | np.ndarray):
                raise TangraphError(
                    f"fn's result {key!r} is a {type(value).__name__}; results must be flat dicts "
                    "of scalars (return a list of dicts for several rows)"
                )
            row[key] = value
        rows.append(row)
    return rows


def _run_batch(
    fn: RunFunction, config: Any, config_index: int, runs: range, entropy: int, fail_fast: bool
) -> list[_RunOutcome]:
    """Runs ``runs`` of one config; failures are recorded (or re-raised under ``fail_fast``)."""
    outcomes: list[_RunOutcome] = []
    for run in runs:
        rng = np.random.default_rng(np.random.SeedSequence(entropy, spawn_key=(config_index, run)))
        try:
            rows = _as_rows(fn(config, rng=rng))
        except Exception as exc:
            if fail_fast:
                exc.add_note(f"raised by config_index={config_index}, run={run} of seed {entropy}")
                raise
            outcomes.append((run, None, f"{type(exc).__name__}: {exc}", traceback.format_exc()))
        else:
            outcomes.append((run, rows, None, None))
    return outcomes


# -- checks ------------------------------------------------------------------------------------
def _check_int(name: str, value: Any, low: int, high: float = math.inf) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or not low <= value < high:
        bound = f"in [{low}, 2**63)" if high < math.inf else f">= {low}"
        raise TangraphError(f"{name} must be an integer {bound}, got {value!r}")
    return int(value)


def _fields(value: Any) -> dict[Any, Any] | None:
    """A dataclass instance's fields or a mapping's items (shallow), or ``None`` for anything else."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {field.name: getattr(value, field.name) for field in dataclasses.fields(value)}
    if isinstance(value, Mapping):
        return dict(value)
    return None


def _cell(value: Any) -> Any:
    """A config value as a table cell, or ``_LEFT_OUT`` for arrays and other objects."""
    if isinstance(value, enum.Enum):
        return value.name
    if value is None or isinstance(value, str | bytes | bool | int | float | complex | np.generic):
        return value
    if isinstance(value, np.ndarray) and value.ndim == 0:
        return value.item()
    if isinstance(value, list | tuple):
        items = [_cell(item) for item in value]
        if all(item is not _LEFT_OUT for item in items):
            return str([item.item() if isinstance(item, np.generic) else item for item in items])
    return _LEFT_OUT


_LEFT_OUT = object()


def _config_columns(config: Any, index: int, left_out: set[str]) -> dict[str, Any]:
    """The table columns of one config.

    A dataclass's fields or a dict's items; nested dataclasses and dicts become dotted names
    (``sensor.sigma``), lists and tuples of scalars their string, and arrays or other objects
    are left out (their names are added to ``left_out``).
    """
    fields = _fields(config)
    if fields is None:
        raise TangraphError(
            f"configs[{index}] is a {type(config).__name__}; configs must be dicts or dataclass instances"
        )
    for key in fields:
        if key in RESERVED_COLUMNS:
            raise TangraphError(
                f"configs[{index}] has a field {key!r}, a name the runner reserves for its own "
                f"columns {RESERVED_COLUMNS}; rename it"
            )
    columns: dict[str, Any] = {}

    def flatten(fields: dict[Any, Any], prefix: str) -> None:
        for key, value in fields.items():
            if not isinstance(key, str):
                raise TangraphError(f"configs[{index}] has a non-string key {key!r}")
            nested = _fields(value)
            if nested is not None:
                flatten(nested, f"{prefix}{key}.")
            elif (cell := _cell(value)) is _LEFT_OUT:
                left_out.add(prefix + key)
            else:
                columns[prefix + key] = cell

    flatten(fields, "")
    return columns


def _check_result_keys(rows: list[dict[str, Any]], config_columns: dict[str, Any], where: str) -> None:
    for row in rows:
        clash = [key for key in row if key in config_columns or key in RESERVED_COLUMNS]
        if clash:
            raise TangraphError(
                f"fn's result keys {clash} ({where}) clash with the config's fields or the runner's "
                f"columns {RESERVED_COLUMNS}; rename the result keys or the config fields"
            )


def _pickled(fn: RunFunction, configs: list[Any]) -> tuple[bytes, list[bytes]]:
    """``fn`` and the configs as cloudpickle bytes, which the workers unpickle inside the task.

    Dask pickles a task by reference unless it sees ``__main__``; shipping bytes made by
    cloudpickle lets functions and dataclasses of a module registered with
    ``cloudpickle.register_pickle_by_value`` (a study's ``run.py``) reach workers that cannot
    import it, and turns a worker's failure to unpickle into an error of the task instead of a
    dead worker. Lambdas and nested functions are refused: they have no name to rerun them by.
    """
    import cloudpickle

    name = getattr(fn, "__qualname__", repr(fn))
    try:
        pickle.dumps(fn)
    except Exception as exc:
        raise TangraphError(
            f"fn {name!r} cannot be sent to worker processes ({type(exc).__name__}: {exc}); use a "
            "function defined at the top level of a module (not a lambda, a nested function or a "
            "closure; pass its parameters through the config), or scheduler='synchronous'"
        ) from exc
    blobs = []
    for index, config in enumerate(configs):
        try:
            blobs.append(cloudpickle.dumps(config))
        except Exception as exc:
            raise TangraphError(
                f"configs[{index}] cannot be sent to worker processes ({type(exc).__name__}: {exc})"
            ) from exc
    return cloudpickle.dumps(fn), blobs


def _run_pickled_batch(
    fn_blob: bytes, config_blob: bytes, config_index: int, runs: range, entropy: int, fail_fast: bool
) -> list[_RunOutcome]:
    """:func:`_run_batch` on a worker, from the bytes made by :func:`_pickled`."""
    import cloudpickle

    try:
        fn, config = cloudpickle.loads(fn_blob), cloudpickle.loads(config_blob)
    except Exception as exc:
        raise TangraphError(
            f"a worker cannot unpickle fn or configs[{config_index}] ({type(exc).__name__}: {exc}); "
            "define them in a module the workers can import"
        ) from exc
    return _run_batch(fn, config, config_index, runs, entropy, fail_fast)


def _output_paths(output: str | os.PathLike[str], overwrite: bool) -> tuple[Path, Path]:
    """The table's path and its sidecar's, checked before any run starts."""
    path = Path(output)
    suffix = path.suffix.lower()
    if suffix not in (".csv", ".parquet", ".pq"):
        raise TangraphError(f"output {str(path)!r} must end in .csv or .parquet")
    if suffix != ".csv" and not any(_installed(engine) for engine in ("pyarrow", "fastparquet")):
        raise TangraphError(f"writing {str(path)!r} needs pyarrow or fastparquet; install one or use .csv")
    if not path.parent.is_dir():
        raise TangraphError(f"the folder of output {str(path)!r} does not exist")
    meta = path.with_name(path.name + ".meta.json")
    if not overwrite:
        for existing in (path, meta):
            if existing.exists():
                raise TangraphError(f"{str(existing)!r} exists; pass overwrite=True to replace it")
    return path, meta


def _installed(distribution: str) -> bool:
    try:
        importlib.metadata.version(distribution)
    except importlib.metadata.PackageNotFoundError:
        return False
    return True


def _version(distribution: str) -> str | None:
    try:
        return importlib.metadata.version(distribution)
    except importlib.metadata.PackageNotFoundError:
        return None


# -- scheduling --------------------------------------------------------------------------------
def _batches(n_configs: int, runs: int, size: int) -> list[tuple[int, range]]:
    return [
        (c, range(start, min(start + size, runs))) for c in range(n_configs) for start in range(0, runs, size)
    ]


def _auto_batch_size(n_total: int, n_workers: int) -> int:
    return max(1, n_total // (_TARGET_BATCHES_PER_WORKER * max(1, n_workers)))


class _Collector:
    """Gathers outcomes as batches complete, checks their keys, and advances the progress bar."""

    def __init__(self, config_columns: list[dict[str, Any]], bar: tqdm) -> None:
        self.config_columns = config_columns
        self.bar = bar
        self.outcomes: dict[tuple[int, int], _RunOutcome] = {}

    def add(self, config_index: int, outcomes: list[_RunOutcome]) -> None:
        for outcome in outcomes:
            run, rows, _, _ = outcome
            if rows is not None:
                where = f"config_index={config_index}, run={run}"
                _check_result_keys(rows, self.config_columns[config_index], where)
            self.outcomes[config_index, run] = outcome
        self.bar.update(len(outcomes))


def _run_synchronous(
    fn: RunFunction, configs: list[Any], batches: list[tuple[int, range]], entropy: int,
    fail_fast: bool, collector: _Collector,
) -> None:
    for config_index, runs in batches:
        outcomes = _run_batch(fn, configs[config_index], config_index, runs, entropy, fail_fast)
        collector.add(config_index, outcomes)


def _connect(scheduler: str | Client | None, workers: int | None) -> tuple[Client, Any, str]:
    """A client (and the cluster this call owns, if any) and a description of the scheduler."""
    from distributed import Client, LocalCluster

    if isinstance(scheduler, Client):
        return scheduler, None, f"client of {scheduler.scheduler.address}"
    if scheduler is None:
        n_workers = workers or os.cpu_count() or 1
        cluster = LocalCluster(
            n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=None,
            # no dashboard, and the scheduler's health/metrics server on a free port, not 8787
            scheduler_kwargs={"dashboard_address": ":0"},
        )
        try:
            client = Client(cluster, set_as_default=False)
        except BaseException:
            cluster.close()
            raise
        return client, cluster, f"local cluster of {n_workers} processes"
    if not isinstance(scheduler, str):
        raise TangraphError(
            "scheduler must be None, 'synchronous', a scheduler address or a distributed.Client, "
            f"not {scheduler!r}"
        )
    try:
        client = Client(scheduler, set_as_default=False)
    except (OSError, ValueError) as exc:
        raise TangraphError(f"cannot reach a Dask scheduler at {scheduler!r}: {exc}") from exc
    return client, None, str(scheduler)


def _identity(value: Any) -> Any:
    return value


def _lost_batch_error(future: Any) -> str:
    try:
        exc = future.exception()
    except BaseException as cancelled:  # a cancelled future has no exception but raises
        exc = cancelled
    return f"{type(exc).__name__}: {exc}"


def _quietly(cleanup: Callable[..., Any], *args: Any) -> None:
    """A clean-up step that must not hide the exception on its way out (the scheduler may be gone)."""
    try:
        cleanup(*args)
    except Exception:
        logger.debug("%s failed during clean-up", getattr(cleanup, "__name__", cleanup), exc_info=True)


def _run_dask(
    fn: RunFunction, configs: list[Any], runs: int, entropy: int, fail_fast: bool,
    scheduler: str | Client | None, workers: int | None, batch_size: int | None, progress: bool,
    config_columns: list[dict[str, Any]],
) -> tuple[_Collector, dict[str, Any]]:
    from distributed import Client, as_completed

    fn_blob, config_blobs = _pickled(fn, configs)  # before any cluster starts

    client, cluster, description = _connect(scheduler, workers)
    owns_client = not isinstance(scheduler, Client)
    futures: dict[Any, tuple[int, range]] = {}
    remote_configs: list[Any] = []
    try:
        n_workers = max(1, sum(client.nthreads().values()))
        size = batch_size or _auto_batch_size(len(configs) * runs, n_workers)
        logger.info("%d runs on %s (%d worker threads), batches of %d",
                    len(configs) * runs, description, n_workers, size)
        # each config travels once, as a task (not scattered data, which a dying worker loses
        # for good) holding its bytes, which any worker can pass on
        remote_configs = [client.submit(_identity, blob, pure=False) for blob in config_blobs]
        for config_index, batch in _batches(len(configs), runs, size):
            future = client.submit(
                _run_pickled_batch, fn_blob, remote_configs[config_index], config_index, batch, entropy,
                fail_fast, pure=False,
            )
            futures[future] = (config_index, batch)
        with tqdm(total=len(configs) * runs, unit="run", disable=not progress) as bar:
            collector = _Collector(config_columns, bar)
            for future in as_completed(list(futures), loop=client.loop):
                config_index, batch = futures[future]
                if future.status != "finished" and not fail_fast:  # a lost batch (say, a worker died)
                    lost = _lost_batch_error(future)
                    collector.add(config_index, [(run, None, lost, None) for run in batch])
                else:
                    collector.add(config_index, future.result())
                future.release()  # the workers may forget the batch's results now
    except BaseException:
        _quietly(client.cancel, list(futures))
        raise
    finally:
        # a caller's client (or a traceback holding this frame) must not keep our data alive
        for future in [*futures, *remote_configs]:
            _quietly(future.release)
        if owns_client:
            _quietly(client.close)
        if cluster is not None:
            cluster.close()
    return collector, {"scheduler": description, "n_workers": n_workers, "batch_size": size}


# -- the table ---------------------------------------------------------------------------------
def _table(collector: _Collector, entropy: int) -> pd.DataFrame:
    config_keys: dict[str, None] = {}
    result_keys: dict[str, None] = {}
    records = []
    for (config_index, run), (_, rows, error, _) in sorted(collector.outcomes.items()):
        config = collector.config_columns[config_index]
        config_keys.update(dict.fromkeys(config))
        base = {"config_index": config_index, "run": run, **config}
        tail = {"seed_entropy": entropy, "spawn_key": str((config_index, run))}
        if rows is None:
            records.append({**base, "error": error, **tail})
        for row in rows or ():
            result_keys.update(dict.fromkeys(row))
            records.append({**base, **row, "error": None, **tail})
    columns = ["config_index", "run", *config_keys, *result_keys, "error", "seed_entropy", "spawn_key"]
    return pd.DataFrame.from_records(records, columns=columns)


def _save(table: pd.DataFrame, meta: dict[str, Any], path: Path, meta_path: Path, overwrite: bool) -> None:
    if not overwrite and (path.exists() or meta_path.exists()):  # appeared while the runs ran
        stamp = meta["start_time"].replace(":", "").replace("-", "")[:15]
        moved = path.with_name(f"{path.stem}-{stamp}{path.suffix}")
        logger.warning("%s appeared while the runs ran; writing %s instead", path, moved)
        path, meta_path = moved, moved.with_name(moved.name + ".meta.json")
    meta["output"] = str(path)
    if path.suffix.lower() == ".csv":
        write_atomically(path, True, lambda p: table.to_csv(p, index=False))
    else:
        write_atomically(path, True, lambda p: table.to_parquet(p, index=False))
    write_atomically(meta_path, True, lambda p: p.write_text(json.dumps(meta, indent=2) + "\n"))
    logger.info("wrote %s and %s", path, meta_path.name)


# -- the entry point ---------------------------------------------------------------------------
def run_many(
    fn: RunFunction,
    configs: Sequence[Any],
    runs: int,
    seed: int,
    *,
    scheduler: str | Client | None = None,
    workers: int | None = None,
    progress: bool = True,
    output: str | os.PathLike[str] | None = None,
    overwrite: bool = False,
    fail_fast: bool = False,
    batch_size: int | None = None,
) -> pd.DataFrame:
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
    runs
        Runs per config.
    seed
        Root of all the runs' seeds (see the module's notes on seeds), an integer in [0, 2**63).
    scheduler
        ``None``: a local cluster of ``workers`` single-threaded processes, started and closed
        here; a scheduler address or a ``distributed.Client``: an existing cluster (left running);
        ``"synchronous"``: serially in this process.
    workers
        Worker processes of the local cluster (default: ``os.cpu_count()``); only with
        ``scheduler=None``.
    progress
        Show a tqdm progress bar (on stderr) over completed runs.
    output
        Save the table to this ``.csv`` or ``.parquet`` file (written atomically), with a JSON
        sidecar ``<output>.meta.json`` (seed, runs, configs, versions, scheduler, times). Checked
        before the first run.
    overwrite
        Replace an existing ``output`` (and sidecar) instead of refusing.
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
    left_out: set[str] = set()
    config_columns = [_config_columns(config, index, left_out) for index, config in enumerate(configs)]
    if left_out:
        logger.info("config fields %s are not scalars and are left out of the table", sorted(left_out))
    paths = _output_paths(output, overwrite) if output is not None else None

    start, started = time.perf_counter(), datetime.datetime.now(datetime.UTC)
    if scheduler == "synchronous":
        size = batch_size or 1
        with tqdm(total=len(configs) * runs, unit="run", disable=not progress) as bar:
            collector = _Collector(config_columns, bar)
            _run_synchronous(fn, configs, _batches(len(configs), runs, size), entropy, fail_fast, collector)
        used = {"scheduler": "synchronous", "n_workers": 1, "batch_size": size}
    else:
        collector, used = _run_dask(
            fn, configs, runs, entropy, fail_fast, scheduler, workers, batch_size, progress, config_columns
        )
    wall_time = time.perf_counter() - start

    table = _table(collector, entropy)
    failed = [(key, outcome) for key, outcome in sorted(collector.outcomes.items()) if outcome[2] is not None]
    if failed:
        (config_index, run), (_, _, error, trace) = failed[0]
        logger.warning(
            "%d of %d runs failed; the first, config_index=%d run=%d: %s (rerun(fn, configs[%d], %d, %d, %d) "
            "repeats it)", len(failed), len(collector.outcomes), config_index, run, error,
            config_index, entropy, config_index, run,
        )
        if trace:
            logger.debug("traceback of config_index=%d run=%d:\n%s", config_index, run, trace)
    meta = {
        "seed": entropy,
        "runs": runs,
        "n_configs": len(configs),
        "n_rows": len(table),
        "n_failed_runs": len(failed),
        "fn": f"{getattr(fn, '__module__', '?')}:{getattr(fn, '__qualname__', repr(fn))}",
        "seed_scheme": _SEED_SCHEME,
        **used,
        "host": platform.node(),
        "versions": {"tangraph": __version__, "python": platform.python_version()}
        | {name: _version(name) for name in ("dask", "distributed", "numpy", "pandas")},
        "start_time": started.isoformat(timespec="seconds"),
        "end_time": datetime.datetime.now(datetime.UTC).isoformat(timespec="seconds"),
        "wall_time_s": round(wall_time, 3),
    }
    table.attrs["tangraph"] = meta
    if paths is not None:
        _save(table, meta, *paths, overwrite)
    return table
