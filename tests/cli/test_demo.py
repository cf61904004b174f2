"""The ``tangraph demo`` command (tangraph.cli.demo): an unknown map and an existing folder refused
before any work."""

from __future__ import annotations

from tangraph.cli import main


def test_unknown_map_lists_the_demo_maps(tmp_path, capsys):
    assert main(["demo", "--map", "atlantis", "--out", str(tmp_path / "d")]) == 2
    err = capsys.readouterr().err
    assert "unknown map 'atlantis'" in err and "merimbula" in err and "polar500" in err
    assert main(["demo", "--map", "vancouver", "--out", str(tmp_path / "d")]) == 2
    assert "no survey laid out on map 'vancouver'" in capsys.readouterr().err
    assert not (tmp_path / "d").exists()


def test_an_existing_folder_is_not_clobbered(tmp_path, capsys):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("precious")
    assert main(["demo", "--out", str(out), "--quick", "-q"]) == 2
    assert "--force" in capsys.readouterr().err
    assert (out / "notes.txt").read_text() == "precious"
