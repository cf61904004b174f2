"""Gridding files into a map (tangraph.gridding_files): the library's errors name its keywords,
``tangraph maps grid``'s name its options."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.gridding_files import grid_files
from tangraph.survey import write_survey
from tests.gridding_cases import nadir_survey, random_soundings


def test_grid_files_names_its_keywords_or_the_callers_options(tmp_path):
    """The library's errors name its keywords; ``tangraph maps grid`` passes its own name and options,
    and its messages are exactly those it always printed."""
    pts = random_soundings(n=300)
    plain = write_survey(nadir_survey(pts, origin=(0, 0)), tmp_path / "plain.nc")
    xyz = tmp_path / "s.xyz"
    np.savetxt(xyz, pts[:, [1, 0, 2]])
    out = tmp_path / "out.nc"
    cli = {"where": "maps grid", "option_name": lambda keyword: "--" + keyword.replace("_", "-")}
    cases = [
        ([plain], {"units": "ft"}, "grid_files: units applies to x y z text; survey files hold depths "
         "(positive down) in their own CRS", "maps grid: --units applies to x y z text; survey files hold "
         "depths (positive down) in their own CRS"),
        ([xyz], {"lines": True}, "grid_files: check_lines and lines need survey files (.nc)",
         "maps grid: --check-lines and --lines need survey files (.nc)"),
        ([xyz], {}, "grid_files: x y z text input needs sign (depth or elevation)",
         "maps grid: x y z text input needs --sign (depth or elevation)"),
        ([xyz], {"sign": "depth", "use_dr": True}, "grid_files: use_dr applies to survey files (.nc), not "
         "x y z text", "maps grid: --use-dr applies to survey files (.nc), not x y z text"),
        ([plain], {"use_dr": True, "check_lines": True}, "grid_files: check_lines compares soundings at "
         "reference tracks; not with use_dr", "maps grid: --check-lines compares soundings at reference "
         "tracks; not with --use-dr"),
        ([plain, xyz], {}, "grid_files: give survey files (.nc) or one x y z text file, not both",
         "maps grid: give survey files (.nc) or one x y z text file, not both"),
        ([xyz, xyz], {}, "grid_files: 2 x y z text files; give one (their soundings joined in one file), or "
         "survey files (.nc)", "maps grid: 2 x y z text files; give one (their soundings joined in one "
         "file), or survey files (.nc)"),
        ([plain], {"output": plain}, f"grid_files: the output {plain} is one of the inputs",
         f"maps grid: the output {plain} is one of the inputs"),
    ]
    for inputs, options, library, command in cases:
        options = {"output": out, **options}
        for wording, message in (({}, library), (cli, command)):
            with pytest.raises(TangraphError) as err:
                grid_files(inputs, cell=10.0, **options, **wording)
            assert str(err.value) == message
    grid, check = grid_files([xyz], tmp_path / "xyz.nc", cell=10.0, sign="depth", position_std=0.5)
    assert check is None and grid.mean.name == "xyz" and grid.meta["position_std"] == 0.5
    assert grid.meta["check_lines_skipped"] == "x y z text has no tracks to hold out"
    assert "check_lines_skipped" not in grid_files([xyz], tmp_path / "xyz.nc", cell=10.0, sign="depth",
                                                   check_lines=False)[0].meta


def test_a_map_of_surveys_is_checked_by_its_check_lines_unless_told_not_to(tmp_path):
    """Checked wherever it can be (the same map as asked for), else the gridding's own error with
    the reason in its meta; asked for where it cannot be made, an error."""
    pts = random_soundings(n=300)
    plain = write_survey(nadir_survey(pts, origin=(0, 0)), tmp_path / "plain.nc")
    out = tmp_path / "out.nc"
    grid, check = grid_files([plain], out, cell=10.0)  # one scattered survey: no lines to hold out
    assert check is None and "check_lines_skipped" in grid.meta
    unchecked, _ = grid_files([plain], out, cell=10.0, check_lines=False)
    np.testing.assert_array_equal(grid.depth.depth_std, unchecked.depth.depth_std)
    with pytest.raises(TangraphError):
        grid_files([plain], out, cell=10.0, check_lines=True, lines=True)
    grid, check = grid_files([plain], out, cell=10.0, use_dr=True)
    assert check is None and "dead reckoning" in grid.meta["check_lines_skipped"]
