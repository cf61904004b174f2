"""``tangraph experiment`` (:mod:`tangraph.cli.experiment`) and the study registry behind it
(:mod:`tangraph.experiments.registry`): list, run by name, refuse an unknown name."""

from __future__ import annotations

import pytest

from tangraph.cli import main
from tangraph.experiments.registry import list_experiments


def test_without_a_name_the_studies_are_listed(capsys):
    assert main(["experiment"]) == 0
    listed = capsys.readouterr().out.split()
    assert listed == list_experiments()
    assert {"graph_vs_filters", "robustness", "caputh_replay"} <= set(listed)


def test_an_unknown_study_is_refused_in_one_line_naming_the_known_ones(capsys):
    assert main(["experiment", "graph_vs_filter"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("tangraph: error: no experiment named 'graph_vs_filter'; known: ")
    assert "graph_vs_filters" in err and "\n" not in err


def test_the_arguments_after_the_name_go_to_the_study(tmp_path, capsys):
    with pytest.raises(SystemExit) as exited:
        main(["experiment", "robustness", "--help"])
    assert exited.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: tangraph experiment robustness") and "--quick" in out
    for study in ("robustness", "graph_vs_filters"):
        out = tmp_path / study
        assert main(["experiment", study, "--graph", "n_ping=3", "--out", str(out)]) == 2
        assert "--graph: unknown GraphConfig field 'n_ping'" in capsys.readouterr().err
        assert not out.exists()  # refused before its output folder is made
