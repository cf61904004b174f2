"""The Monte Carlo runner: reproducible seeds on any scheduler, failures, output files.

The run functions live at the top level of this module so that worker processes import them
(``tests`` is a package; pytest puts the repository root on ``sys.path``, which spawned workers
inherit). One two-process cluster serves the module; one more starts inside ``run_many``.
"""

from __future__ import annotations

import dataclasses
import json
import logging
import sys
import time
import types

import numpy as np
import pandas as pd
import psutil
import pytest

import tangraph.experiments.runner as runner
import tangraph.experiments.tables as tables
from tangraph.errors import TangraphError
from tangraph.experiments import RESERVED_COLUMNS, rerun, run_many, run_rng, run_seed_sequence

CONFIGS = [{"mu": 0.0, "label": "a"}, {"mu": 10.0, "label": "b"}, {"mu": -3.0, "label": "c"}]


@dataclasses.dataclass(frozen=True)
class Scenario:
    mu: float
    sigma: float = 1.0


# -- run functions (importable by the workers) ---------------------------------------------------
def draw(config, *, rng):
    return {"x": rng.normal(config["mu"], 1.0), "k": int(rng.integers(1 << 30))}


def draw_scenario(config, *, rng):
    return {"x": rng.normal(config.mu, config.sigma)}


def draw_scenario_sigma(config, *, rng):
    return {"x": rng.normal(config.mu, config.sensor.sigma)}


def draw_two_rows(config, *, rng):
    return [{"beam": beam, "x": rng.normal(config["mu"])} for beam in range(2)]


def standard_normal(config, *, rng):
    return {"x": rng.normal()}


def fails_on_label_b(config, *, rng):
    if config["label"] == "b":
        raise ValueError(f"no terrain under {config['label']}")
    return {"x": rng.normal()}


def returns_config_field(config, *, rng):
    return {"mu": 1.0, "x": rng.normal()}


def returns_array(config, *, rng):
    return {"x": rng.normal(size=3)}


def sleeps(config, *, rng):
    time.sleep(0.2)
    return {"x": rng.normal()}


@pytest.fixture(scope="module")
def cluster():
    distributed = pytest.importorskip("distributed")
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
        scheduler_kwargs={"dashboard_address": ":0"},
    ) as local, distributed.Client(local, set_as_default=False) as client:
        yield client


def quiet(*args, **kwargs):
    return run_many(*args, progress=False, **kwargs)


# -- seeds ---------------------------------------------------------------------------------------
def test_run_seed_is_the_grandchild_of_one_seed_sequence():
    children = np.random.SeedSequence(2024).spawn(3)
    for c, child in enumerate(children):
        for r, grandchild in enumerate(child.spawn(4)):
            ours = run_seed_sequence(2024, c, r)
            assert ours.spawn_key == grandchild.spawn_key == (c, r)
            np.testing.assert_array_equal(ours.generate_state(8), grandchild.generate_state(8))
    fresh = np.random.SeedSequence(2024).spawn(3)[1].spawn(3)[2]  # spawn() counts its children
    assert run_rng(2024, 1, 2).normal() == np.random.default_rng(fresh).normal()


def test_same_seed_same_table_synchronously_on_one_and_on_two_workers(cluster):
    reference = quiet(draw, CONFIGS, 7, seed=11, scheduler="synchronous")
    before = {p.pid for p in psutil.Process().children(recursive=True)}
    one_worker = quiet(draw, CONFIGS, 7, seed=11, workers=1)
    after = {p.pid for p in psutil.Process().children(recursive=True) if p.status() != psutil.STATUS_ZOMBIE}
    assert after <= before  # the local cluster's workers are gone
    two_workers = quiet(draw, CONFIGS, 7, seed=11, scheduler=cluster.scheduler.address, batch_size=3)
    for table in (one_worker, two_workers):
        pd.testing.assert_frame_equal(table, reference)
    assert list(reference.columns) == ["config_index", "run", "mu", "label", "x", "k", *RESERVED_COLUMNS[2:]]
    expected_order = [[c, r] for c in range(3) for r in range(7)]
    assert reference[["config_index", "run"]].to_numpy().tolist() == expected_order
    assert reference["error"].isna().all()
    assert (reference["seed_entropy"] == 11).all()
    assert reference["spawn_key"].iloc[8] == "(1, 1)"
    assert reference.attrs["tangraph"]["scheduler"] == "synchronous"
    assert one_worker.attrs["tangraph"]["scheduler"] == "local cluster of 1 processes"
    # more runs extend the study without changing its first rows
    longer = quiet(draw, CONFIGS, 9, seed=11, scheduler="synchronous")
    pd.testing.assert_frame_equal(longer[longer.run < 7].reset_index(drop=True), reference, check_like=True)


def test_different_seeds_give_different_runs():
    a = quiet(draw, CONFIGS, 5, seed=1, scheduler="synchronous")
    b = quiet(draw, CONFIGS, 5, seed=2, scheduler="synchronous")
    assert not np.isin(a["k"], b["k"]).any()
    assert a["k"].nunique() == len(a)  # and every run of one study differs from the others


def test_rerun_reproduces_a_row():
    table = quiet(draw, CONFIGS, 4, seed=5, scheduler="synchronous")
    row = table.iloc[9]
    again = rerun(draw, CONFIGS[row.config_index], int(row.seed_entropy), row.config_index, row.run)
    assert again == {"x": row.x, "k": row.k}


def test_dataclass_configs_and_several_rows_per_run():
    configs = [Scenario(mu=0.0), Scenario(mu=5.0, sigma=2.0)]
    table = quiet(draw_scenario, configs, 3, seed=0, scheduler="synchronous")
    assert list(table.columns[:5]) == ["config_index", "run", "mu", "sigma", "x"]
    assert table["sigma"].tolist() == [1.0] * 3 + [2.0] * 3
    rows = quiet(draw_two_rows, CONFIGS, 2, seed=0, scheduler="synchronous")
    assert len(rows) == 12
    assert rows["beam"].tolist() == [0, 1] * 6
    first = rows[(rows.config_index == 2) & (rows.run == 1)]
    assert first["x"].tolist() == [r["x"] for r in rerun(draw_two_rows, CONFIGS[2], 0, 2, 1)]


# -- statistics ----------------------------------------------------------------------------------
def test_draws_are_standard_normal_and_independent_across_configs(cluster):
    n = 200
    table = quiet(standard_normal, [{"c": 0}, {"c": 1}], n, seed=123, scheduler=cluster)
    x = table["x"].to_numpy()
    assert len(x) == 2 * n and len(np.unique(x)) == 2 * n
    assert abs(x.mean()) < 4 / np.sqrt(2 * n)  # 4 standard errors
    assert abs(x.var(ddof=1) - 1) < 4 * np.sqrt(2 / (2 * n - 1))
    first, second = x[:n], x[n:]  # run r of config 0 against run r of config 1
    assert abs(np.corrcoef(first, second)[0, 1]) < 4 / np.sqrt(n)


# -- failures ------------------------------------------------------------------------------------
def test_failed_runs_become_rows_with_their_error(cluster, caplog):
    with caplog.at_level(logging.WARNING, logger="tangraph.experiments"):
        table = quiet(fails_on_label_b, CONFIGS, 4, seed=3, scheduler=cluster.scheduler.address)
    failed = table[table.error.notna()]
    assert failed["config_index"].tolist() == [1] * 4
    assert set(failed["error"]) == {"ValueError: no terrain under b"}
    assert failed["x"].isna().all()
    assert table[table.error.isna()]["x"].notna().sum() == 8
    assert table.attrs["tangraph"]["n_failed_runs"] == 4
    assert "4 of 12 runs failed" in caplog.text
    assert "config_index=1 run=0" in caplog.text


@pytest.mark.parametrize("scheduler", ["synchronous", "cluster"])
def test_fail_fast_reraises_the_error(cluster, scheduler):
    scheduler = cluster if scheduler == "cluster" else scheduler
    with pytest.raises(ValueError, match="no terrain under b") as info:
        quiet(fails_on_label_b, CONFIGS, 4, seed=3, scheduler=scheduler, fail_fast=True)
    assert any("config_index=1" in note for note in getattr(info.value, "__notes__", []))


def test_results_must_be_flat_dicts():
    table = quiet(returns_array, CONFIGS[:1], 2, seed=0, scheduler="synchronous")
    assert table["error"].str.startswith("TangraphError: fn's result 'x' is a ndarray").all()


def test_result_keys_clashing_with_config_fields_are_an_error(cluster):
    with pytest.raises(TangraphError, match=r"result keys \['mu'\].*clash"):
        quiet(returns_config_field, CONFIGS, 2, seed=0, scheduler="synchronous")
    with pytest.raises(TangraphError, match=r"result keys \['mu'\].*clash"):
        quiet(returns_config_field, CONFIGS, 2, seed=0, scheduler=cluster)
    with pytest.raises(TangraphError, match="'run', a name the runner reserves"):
        quiet(draw, [{"mu": 0.0, "run": 3}], 2, seed=0, scheduler="synchronous")


def test_a_lambda_cannot_go_to_worker_processes(cluster):
    with pytest.raises(TangraphError, match="top level of a module"):
        quiet(lambda config, *, rng: {"x": 1}, CONFIGS, 2, seed=0, scheduler=cluster)

    def nested(config, *, rng):
        return {"x": 1}

    with pytest.raises(TangraphError, match="not a lambda, a nested function"):
        quiet(nested, CONFIGS, 2, seed=0)  # refused before any cluster starts
    table = quiet(lambda config, *, rng: {"x": 1}, CONFIGS, 2, seed=0, scheduler="synchronous")
    assert table["x"].tolist() == [1] * 6


def test_bad_arguments():
    for kwargs, match in [
        ({"runs": 0}, "runs must be an integer >= 1"),
        ({"seed": -1}, "seed must be an integer in"),
        ({"seed": 1.5}, "seed must be an integer in"),
        ({"configs": []}, "configs is empty"),
        ({"configs": [3]}, r"configs\[0\] is a int"),
        ({"workers": 2, "scheduler": "synchronous"}, "needs scheduler=None"),
        ({"scheduler": "sync"}, "cannot reach a Dask scheduler at 'sync'"),
    ]:
        arguments = {"configs": CONFIGS, "runs": 2, "seed": 0, "scheduler": "synchronous"} | kwargs
        with pytest.raises(TangraphError, match=match):
            quiet(draw, **arguments)


@pytest.mark.slow  # flaky under load: distributed's client loop can miss its 10 s start-up timeout
def test_keyboard_interrupt_cancels_the_outstanding_runs(cluster, monkeypatch):
    def clients(dask_scheduler):
        return len(dask_scheduler.clients)

    def tasks(dask_scheduler):
        return len(dask_scheduler.tasks)

    # other tests' clients and tasks may still be leaving the scheduler: compare with "no more than"
    n_clients = cluster.run_on_scheduler(clients)
    n_tasks = cluster.run_on_scheduler(tasks)

    class Interrupted(runner.tqdm):
        def update(self, n=1):
            raise KeyboardInterrupt

    monkeypatch.setattr(runner, "tqdm", Interrupted)
    with pytest.raises(KeyboardInterrupt):
        quiet(sleeps, CONFIGS, 10, seed=0, scheduler=cluster.scheduler.address, batch_size=1)
    deadline = time.monotonic() + 30  # a guard against a hang, not a timing test
    while cluster.run_on_scheduler(tasks) > n_tasks or cluster.run_on_scheduler(clients) > n_clients:
        assert time.monotonic() < deadline, "the interrupted runs were left on the cluster"
        time.sleep(0.05)


# -- output --------------------------------------------------------------------------------------
def test_output_csv_with_its_sidecar(tmp_path):
    path = tmp_path / "study.csv"
    table = quiet(draw, CONFIGS, 3, seed=9, scheduler="synchronous", output=path)
    saved = pd.read_csv(path)
    pd.testing.assert_frame_equal(saved.drop(columns="error"), table.drop(columns="error"))
    assert saved["error"].isna().all()
    meta = json.loads((tmp_path / "study.csv.meta.json").read_text())
    assert meta["seed"] == 9 and meta["runs"] == 3 and meta["n_configs"] == 3 and meta["n_rows"] == 9
    assert meta["scheduler"] == "synchronous"
    assert meta["fn"] == f"{__name__}:draw"
    assert set(meta["versions"]) >= {"tangraph", "dask", "numpy"}
    assert meta["start_time"] <= meta["end_time"] and meta["wall_time_s"] >= 0
    assert meta["output"] == str(path)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["study.csv", "study.csv.meta.json"]  # no temp left


def test_output_is_never_overwritten_unless_asked(tmp_path):
    path = tmp_path / "study.csv"
    path.write_text("precious\n")
    with pytest.raises(TangraphError, match="exists; pass overwrite=True"):
        quiet(draw, CONFIGS, 2, seed=0, scheduler="synchronous", output=path)
    assert path.read_text() == "precious\n"
    assert not (tmp_path / "study.csv.meta.json").exists()
    quiet(draw, CONFIGS, 2, seed=0, scheduler="synchronous", output=path, overwrite=True)
    assert len(pd.read_csv(path)) == 6
    with pytest.raises(TangraphError, match=r"must end in \.csv or \.parquet"):
        quiet(draw, CONFIGS, 2, seed=0, scheduler="synchronous", output=tmp_path / "study.xlsx")
    with pytest.raises(TangraphError, match="does not exist"):
        quiet(draw, CONFIGS, 2, seed=0, scheduler="synchronous", output=tmp_path / "no" / "study.csv")


def test_output_parquet(tmp_path):
    path = tmp_path / "study.parquet"
    if not (tables._installed("pyarrow") or tables._installed("fastparquet")):
        with pytest.raises(TangraphError, match="needs pyarrow or fastparquet"):
            quiet(draw, CONFIGS, 2, seed=0, scheduler="synchronous", output=path)
        return
    table = quiet(draw, CONFIGS, 2, seed=0, scheduler="synchronous", output=path)
    pd.testing.assert_frame_equal(pd.read_parquet(path), table, check_dtype=False)


@dataclasses.dataclass(frozen=True)
class Sensor:
    sigma: float
    beams: tuple[int, ...]


@dataclasses.dataclass(frozen=True)
class Study:
    mu: float
    sensor: Sensor
    terrain: np.ndarray


def test_nested_configs_become_dotted_columns_and_arrays_stay_out(caplog):
    config = Study(mu=1.0, sensor=Sensor(sigma=0.5, beams=(1, 2)), terrain=np.zeros((2, 2)))
    with caplog.at_level(logging.INFO, logger="tangraph.experiments"):
        table = quiet(draw, [{"mu": 1.0, "tide": {"amplitude": 0.3}}], 1, seed=0, scheduler="synchronous")
        nested = quiet(draw_scenario_sigma, [config], 1, seed=0, scheduler="synchronous")
    assert list(table.columns[:4]) == ["config_index", "run", "mu", "tide.amplitude"]
    assert list(nested.columns[:6]) == ["config_index", "run", "mu", "sensor.sigma", "sensor.beams", "x"]
    assert nested["sensor.beams"].tolist() == ["[1, 2]"]
    assert "['terrain'] are not scalars and are left out" in caplog.text


STUDY_SOURCE = '''
import dataclasses

@dataclasses.dataclass(frozen=True)
class Config:
    mu: float

def one_run(config, *, rng):
    return {"x": rng.normal(config.mu)}
'''


def study_module(name, monkeypatch):
    """A study imported from source under a name the workers cannot import (like the registry's)."""
    module = types.ModuleType(name)
    monkeypatch.setitem(sys.modules, name, module)  # dataclasses look their module up while executing
    exec(compile(STUDY_SOURCE, f"<{name}>", "exec"), module.__dict__)
    return module


def test_a_study_module_registered_by_value_reaches_the_workers(cluster, monkeypatch):
    cloudpickle = pytest.importorskip("cloudpickle")
    study = study_module("tangraph_experiment_test_by_value", monkeypatch)
    cloudpickle.register_pickle_by_value(study)
    try:
        configs = [study.Config(mu=1.0), study.Config(mu=2.0)]
        table = quiet(study.one_run, configs, 3, seed=8, scheduler=cluster)
    finally:
        cloudpickle.unregister_pickle_by_value(study)
    pd.testing.assert_frame_equal(table, quiet(study.one_run, configs, 3, seed=8, scheduler="synchronous"))


def test_a_function_the_workers_cannot_import_fails_its_runs_clearly(cluster, monkeypatch):
    study = study_module("tangraph_experiment_test_not_importable", monkeypatch)
    table = quiet(study.one_run, [study.Config(mu=1.0)], 2, seed=8, scheduler=cluster)
    assert table["error"].str.contains("a worker cannot unpickle fn.*No module named", regex=True).all()
