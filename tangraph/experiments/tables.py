"""What :func:`~tangraph.experiments.run_many` makes of the runs: the configs' fields as columns,
the tidy table of the runs' rows, the warning that sums up the failed runs, and the files written
from them (the ``.csv`` or ``.parquet`` table, its paths checked before the first run, and the
JSON sidecar of metadata)."""

from __future__ import annotations

import dataclasses
import datetime
import enum
import importlib.metadata
import json
import logging
import os
import platform
from collections.abc import Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from tangraph import __version__
from tangraph.errors import TangraphError
from tangraph.outputs import write_atomically

if TYPE_CHECKING:
    from tangraph.experiments.scheduling import _Collector
    from tangraph.experiments.tasks import RunFunction

__all__ = ["RESERVED_COLUMNS"]

logger = logging.getLogger("tangraph.experiments.runner")  # the runner's messages, one logger for them

#: Columns the runner adds to every row; neither configs nor results may use these names.
RESERVED_COLUMNS = ("config_index", "run", "error", "seed_entropy", "spawn_key")

_SEED_SCHEME = (
    "numpy.random.default_rng(numpy.random.SeedSequence(seed, spawn_key=(config_index, run))), "
    "i.e. SeedSequence(seed).spawn(n_configs)[config_index].spawn(runs)[run]; PCG64"
)


# -- the configs' columns ----------------------------------------------------------------------
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


def _all_config_columns(configs: list[Any]) -> list[dict[str, Any]]:
    """The table columns of every config; the fields left out are logged."""
    left_out: set[str] = set()
    config_columns = [_config_columns(config, index, left_out) for index, config in enumerate(configs)]
    if left_out:
        logger.info("config fields %s are not scalars and are left out of the table", sorted(left_out))
    return config_columns


def _check_result_keys(rows: list[dict[str, Any]], config_columns: dict[str, Any], where: str) -> None:
    for row in rows:
        clash = [key for key in row if key in config_columns or key in RESERVED_COLUMNS]
        if clash:
            raise TangraphError(
                f"fn's result keys {clash} ({where}) clash with the config's fields or the runner's "
                f"columns {RESERVED_COLUMNS}; rename the result keys or the config fields"
            )


# -- the table and its summaries ---------------------------------------------------------------
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


def _report_failures(collector: _Collector, entropy: int) -> int:
    """The number of failed runs, with a warning naming the first (and its traceback, at debug)."""
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
    return len(failed)


def _metadata(
    fn: RunFunction, entropy: int, runs: int, n_configs: int, n_rows: int, n_failed: int,
    used: dict[str, Any], started: datetime.datetime, wall_time: float,
) -> dict[str, Any]:
    """The study's metadata (``table.attrs["tangraph"]`` and the sidecar), ending now."""
    return {
        "seed": entropy,
        "runs": runs,
        "n_configs": n_configs,
        "n_rows": n_rows,
        "n_failed_runs": n_failed,
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


# -- the files ---------------------------------------------------------------------------------
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

