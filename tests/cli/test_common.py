"""What the commands share (tangraph.cli._common): arguments within bounds, refused in one line with
exit status 2, and a figure's suffix checked before any work.

Each usage case is (arguments, text the message must hold).
"""

from __future__ import annotations

import pytest

from tangraph.cli import main

USAGE = [
    (["navigate", "s.nc", "--particles", "1e9", "-o", "x.csv"], "'1e9' is not an integer"),
    (["navigate", "s.nc", "--particles", "1000000000", "-o", "x.csv"], "the particle count must lie in"),
    (["navigate", "s.nc", "--seed", "-1", "-o", "x.csv"], "a seed must lie in [0,"),
    (["maps", "plot", "merimbula", "--dpi", "0", "-o", "x.png"], "the resolution (dpi) must lie in"),
    (["maps", "plot", "merimbula", "--dpi", "100000", "-o", "x.png"], "the resolution (dpi) must lie in"),
    (["maps", "grid", "a.xyz", "--sign", "depth", "--cell", "0.001", "-o", "g.nc"],
     "the cell size (m) must lie in"),
    (["maps", "info", "merimbula", "--cell", "nan"], "the cell size (m) must lie in"),
    (["maps", "grid", "a.xyz", "--sign", "depth", "--cell", "5", "--position-std", "-1", "-o", "g.nc"],
     "the position std (m) must lie in"),
]


@pytest.mark.parametrize(("args", "text"), USAGE)
def test_usage_errors_are_one_line_with_status_2(args, text, capsys):
    with pytest.raises(SystemExit) as exit_:
        main(args)
    err = capsys.readouterr().err
    assert exit_.value.code == 2 and text in err and "Traceback" not in err


def test_a_figure_to_an_unknown_suffix_is_refused_before_any_work(tmp_path, capsys):
    out = tmp_path / "map.xyz"
    assert main(["maps", "plot", "merimbula", "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "a figure is written as" in err and ".png" in err and not out.exists()
