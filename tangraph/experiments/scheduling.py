"""The run loop of :func:`~tangraph.experiments.run_many`: the runs in batches of consecutive runs of
one config, done serially in this process or as tasks on a Dask cluster (a local one started and
closed here, or an existing one), gathered as they complete while the progress bar advances; on
the way out, an interrupt or an error included, the outstanding tasks are cancelled, the cluster's
data released and the cluster this call started closed."""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from tangraph.errors import TangraphError
from tangraph.experiments.tables import _check_result_keys
from tangraph.experiments.tasks import RunFunction, _pickled, _run_batch, _run_pickled_batch, _RunOutcome

if TYPE_CHECKING:
    from distributed import Client
    from tqdm import tqdm

__all__: list[str] = []

logger = logging.getLogger("tangraph.experiments.runner")  # the runner's messages, one logger for them

_TARGET_BATCHES_PER_WORKER = 10


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
    fn: RunFunction, configs: list[Any], runs: int, entropy: int, fail_fast: bool, batch_size: int | None,
    new_bar: Callable[[], tqdm], config_columns: list[dict[str, Any]],
) -> tuple[_Collector, dict[str, Any]]:
    """The runs serially in this process, in batches of ``batch_size`` runs (default 1)."""
    size = batch_size or 1
    with new_bar() as bar:
        collector = _Collector(config_columns, bar)
        for config_index, batch in _batches(len(configs), runs, size):
            outcomes = _run_batch(fn, configs[config_index], config_index, batch, entropy, fail_fast)
            collector.add(config_index, outcomes)
    return collector, {"scheduler": "synchronous", "n_workers": 1, "batch_size": size}


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
    scheduler: str | Client | None, workers: int | None, batch_size: int | None,
    new_bar: Callable[[], tqdm], config_columns: list[dict[str, Any]],
) -> tuple[_Collector, dict[str, Any]]:
    """The runs as tasks on a Dask cluster, gathered as they complete. On an error or an interrupt
    the outstanding tasks are cancelled; in any case this call's futures are released and the
    client and the cluster it opened are closed."""
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
        with new_bar() as bar:
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

