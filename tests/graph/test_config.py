"""The graph's settings (tangraph.graph.config): every part checks its fields, naming the part and the
field, and a TOML file gives the parts as tables."""

from __future__ import annotations

import pytest

from tangraph.errors import TangraphError
from tangraph.graph import GraphConfig, load_graph_config
from tangraph.matching import TapConfig


@pytest.mark.parametrize(("changes", "named"), [
    ({"front_end": "ekf"}, "OnlineConfig.front_end"), ({"key_interval": 0.0}, "GraphConfig.key_interval"),
    ({"n_pings": 0}, "FixConfig.n_pings"), ({"gate_probability": 1.5}, "FixConfig.gate_probability"),
    ({"isam_window": 1}, "OnlineConfig.isam_window"),
    ({"min_half_width_cells": 10.0, "max_half_width_cells": 5.0}, "FixConfig: max_half_width_cells"),
    ({"relinearize_threshold": float("nan")}, "OnlineConfig.relinearize_threshold"),
    ({"ramp_pings": 0}, "FixConfig.ramp_pings"),
    ({"tap": TapConfig(half_width=30.0)}, "FixConfig: tap.half_width"),
    ({"tap": TapConfig(step=2.0), "tap_step_cells": 1.0}, "FixConfig: tap.step"),
    ({"front_end_pings": 5}, "OnlineConfig: front_end_pings = 5 is the point-mass front end's"),
    ({"rematch_iterations": -1}, "BatchConfig.rematch_iterations"),
    ({"gnc_probability": 1.0}, "BatchConfig.gnc_probability"),
    ({"n_ping": 20}, "unknown GraphConfig field 'n_ping'"),
    ({"optimizer": "lm"}, "GraphConfig.optimizer is no longer a setting"),
])
def test_config_is_validated(changes, named):
    """Every part checks its fields, naming the part and the field."""
    with pytest.raises(TangraphError, match=named):
        GraphConfig().replace(**changes)


def test_front_end_is_validated():
    from tangraph.errors import TangraphError

    with pytest.raises(TangraphError, match="OnlineConfig.front_end must be one of tap, pmf, got 'grid'"):
        GraphConfig().replace(front_end="grid")


def test_robust_solve_is_validated():
    from tangraph.errors import TangraphError

    with pytest.raises(TangraphError, match="robust_solve"):
        GraphConfig().replace(robust_solve="ransac")
    with pytest.raises(TangraphError, match="gnc_probability"):
        GraphConfig().replace(gnc_probability=1.0)


def test_graph_config_from_a_toml_file(tmp_path):
    """A file gives the parts as tables; a part's field at the top level is refused naming its
    table, a moved or unknown key by name."""
    path = tmp_path / "graph.toml"
    path.write_text('[graph]\nkey_interval = 30.0\n[graph.fixes]\nn_pings = 40\n[graph.fixes.tap]\n'
                    'criterion = "msd"\n[graph.online]\nfront_end = "pmf"\n[graph.batch]\n'
                    'smoother_terrain = "field"\n')
    config = load_graph_config(path)
    assert (config.key_interval, config.fixes.n_pings, config.fixes.tap.criterion.value) == (30.0, 40, "msd")
    assert (config.online.front_end, config.batch.smoother_terrain) == ("pmf", "field")
    assert config == GraphConfig.from_mapping(config.as_dict())  # the track's metadata reads back
    assert config.spacing == config.window == 3  # the point-mass front end's windows
    path.write_text('[graph]\nn_pings = 60\n')
    with pytest.raises(TangraphError, match=r"graph.toml: GraphConfig.n_pings is now in the fixes part"):
        load_graph_config(path)
    with pytest.raises(TangraphError, match=r"GraphConfig.lost_windows is now in the online part"):
        GraphConfig.from_mapping({"lost_windows": 3}, "cfg.toml")
    with pytest.raises(TangraphError, match="cfg.toml: GraphConfig.batch must be a table"):
        GraphConfig.from_mapping({"batch": 3}, "cfg.toml")
    path.write_text('[graph]\nrobust_kernel = "cauchy"\n')
    moved = r"graph.toml: GraphConfig.robust_kernel .* NavigationModel.robust_kernel"
    with pytest.raises(TangraphError, match=moved):
        load_graph_config(path)
    path.write_text('[graph.fixes.tap]\ncriterio = "msd"\n')
    with pytest.raises(TangraphError, match="unknown TapConfig field 'criterio'"):
        load_graph_config(path)
    path.write_text('[graph.online]\nn_pings = 3\n')
    with pytest.raises(TangraphError, match="unknown OnlineConfig field 'n_pings'"):
        load_graph_config(path)
    path.write_text("[graph]\nkey_interval = 60.0\n[other]\nx = 1\n")
    with pytest.raises(TangraphError, match="keys outside \\[graph\\]: other"):
        load_graph_config(path)
