"""The work of one Dask task of :func:`~tangraph.experiments.run_many`: a batch of seeded runs of one
config, done on a worker (or in this process), with ``fn``'s results checked into flat rows; and
``fn`` and the configs as cloudpickle bytes for the trip to the workers."""

from __future__ import annotations

import pickle
import traceback
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from tangraph.errors import TangraphError

__all__ = ["RunFunction"]

RunFunction = Callable[..., Mapping[str, Any] | Sequence[Mapping[str, Any]]]
# (run, rows or None, error or None, traceback or None)
_RunOutcome = tuple[int, list[dict[str, Any]] | None, str | None, str | None]


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

