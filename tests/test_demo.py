"""The main job (tangraph.demo): ``run_demo`` end to end, an interrupted run, and the scenario a
map's demo runs; the ``demo`` command's refusals are in tests/cli/test_demo.py."""

from __future__ import annotations

import json

import pytest

import tangraph.navigation
from tangraph.demo import run_demo
from tangraph.errors import TangraphError


def test_an_interrupted_demo_leaves_nothing_behind(tmp_path, monkeypatch):
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(tangraph.navigation, "navigate", interrupted)
    out = tmp_path / "demo"
    with pytest.raises(KeyboardInterrupt):
        run_demo(out, quick=True, progress=False)
    assert list(tmp_path.iterdir()) == []


def test_quick_demo_writes_the_report_and_the_graph_beats_dead_reckoning(tmp_path):
    result = run_demo(tmp_path / "demo", quick=True, progress=False)
    text = result.report.read_text()
    for name in ("tracks.png", "errors.png", "fix.png"):
        assert f"]({name})" in text and (result.out / name).read_bytes()[:4] == b"\x89PNG"
    rows = {r["method"]: r for r in json.loads((result.out / "results.json").read_text())}
    assert set(rows) == {"dead reckoning", "isam2", "isam2 tracking", "smoother", "pf", "ipf", "sjcpf", "pmf"}
    assert rows["smoother"]["rmse"] < 0.5 * rows["dead reckoning"]["rmse"]
    assert rows["isam2"]["rmse"] < rows["dead reckoning"]["rmse"]
    assert rows["isam2 tracking"]["rmse"] < rows["dead reckoning"]["rmse"]
    assert "isam2 tracking" in text and (result.out / "tracks" / "isam2_tracking.csv").exists()
    settings = json.loads((result.out / "settings.json").read_text())
    assert settings["seed"] == 7 and settings["quick"] is True
    assert (result.out / "tracks" / "smoother.csv").read_text().startswith("time,lat,lon")
    assert not any(p.name.startswith(".") for p in tmp_path.iterdir())


def test_the_demo_on_a_seafloor_that_is_not_the_map_runs_where_a_variant_exists():
    from tangraph.demo import _scenario_for

    assert _scenario_for("merimbula", map_error=True) == "demo-map-error"
    assert _scenario_for("han2020", map_error=True) == "han2020-map-error"
    assert _scenario_for("merimbula") == "demo"
    with pytest.raises(TangraphError, match="--map-error runs on: merimbula, han2020"):
        _scenario_for("lidar-dem", map_error=True)
