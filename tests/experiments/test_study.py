"""The shared study command line: defaults, and where a study may write."""

from __future__ import annotations

import pytest

from tangraph.errors import TangraphError
from tangraph.experiments.study import output_folder, study_parser


def test_a_study_in_a_checkout_writes_beside_itself_and_an_installed_one_asks(tmp_path):
    checkout = tmp_path / "experiments" / "demo_study"
    installed = tmp_path / "site-packages" / "tangraph" / "_experiments" / "demo_study"
    for here in (checkout, installed):
        here.mkdir(parents=True)
    parser = study_parser(checkout, "a study", runs=10, seed=3, quick="quick")
    args = parser.parse_args([])
    assert (args.runs, args.seed, args.quick, args.out) == (10, 3, False, None)
    assert output_folder(args, checkout) == checkout / "results"
    with pytest.raises(TangraphError, match="pass --out DIR"):
        output_folder(parser.parse_args([]), installed)
    out = tmp_path / "mine"
    assert output_folder(parser.parse_args(["--out", str(out)]), installed) == out and out.is_dir()
    (out / "summary.md").write_text("earlier results")
    with pytest.raises(TangraphError, match="already holds files; pass --force"):
        output_folder(parser.parse_args(["--out", str(out)]), installed)
    assert output_folder(parser.parse_args(["--out", str(out), "--force"]), installed) == out
    assert (out / "summary.md").read_text() == "earlier results"


def test_the_help_shows_defaults_once(capsys):
    parser = study_parser(__import__("pathlib").Path("experiments/x"), "a study", runs=None, seed=1,
                          quick="quick")
    text = parser.format_help()
    assert "(default: 1)" in text and "default: None" not in text and "config.toml" in text
