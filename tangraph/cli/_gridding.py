"""``maps grid``'s input dispatch: survey files (.nc) or one x y z text file into a grid, checked
by its check lines where asked.

Library logic kept here for now: it belongs beside :func:`tangraph.maps.gridding.grid_surveys`
(with its messages in keyword terms), where it goes when that module can take it. Until then its
messages name the command's options, as they always did.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from tangraph.errors import TangraphError


def grid_inputs(inputs: list[Path], output: Path, *, cell: float, statistic: str, fill: int,
                use_dr: bool, sign: str | None, crs: str | None, units: str | None,
                check_lines: bool, lines: bool, window: float, sounding_std: float,
                position_std: float = 0.0):
    """The grid of ``inputs`` named after ``output``, and its check (None without ``check_lines``)."""
    if output.resolve() in {path.resolve() for path in inputs}:
        raise TangraphError(f"maps grid: the output {output} is one of the inputs")
    surveys = [path for path in inputs if path.suffix.lower() == ".nc"]
    if (surveys and len(surveys) != len(inputs)) or (not surveys and len(inputs) > 1):
        raise TangraphError("maps grid: give survey files (.nc) or one x y z text file, not both")
    gridding = {"cell": cell, "statistic": statistic, "fill": fill, "position_std": position_std}
    if surveys:
        for option, given in (("--sign", sign), ("--crs", crs), ("--units", units)):
            if given is not None:
                raise TangraphError(
                    f"maps grid: {option} applies to x y z text; survey files hold depths (positive "
                    "down) in their own CRS"
                )
        return _grid_surveys(surveys, output, use_dr=use_dr, check_lines=check_lines, lines=lines,
                             window=window, sounding_std=sounding_std, **gridding)
    if check_lines or lines:
        raise TangraphError("maps grid: --check-lines and --lines need survey files (.nc)")
    if sign is None:
        raise TangraphError("maps grid: x y z text input needs --sign (depth or elevation)")
    if use_dr:
        raise TangraphError("maps grid: --use-dr applies to survey files (.nc), not x y z text")
    from tangraph.maps import read_soundings
    from tangraph.maps.gridding import block_reduce, fill_gaps

    soundings = read_soundings(inputs[0], sign=sign, crs=crs, units=units)
    grid = block_reduce(soundings.points, cell=cell, statistic=statistic,
                        name=output.stem, crs=soundings.crs, origin=soundings.origin)
    grid = dataclasses.replace(grid, meta={**grid.meta, "position_std": float(position_std)})
    return (fill_gaps(grid, fill) if fill else grid), None


def _grid_surveys(surveys: list[Path], output: Path, *, cell, statistic, fill, position_std, use_dr,
                  check_lines, lines, window, sounding_std):
    from tangraph.maps.gridding import grid_surveys
    from tangraph.survey import read_survey

    loaded = [read_survey(path) for path in surveys]
    names = [str(path) for path in surveys]
    grid = grid_surveys(loaded, cell=cell, statistic=statistic, fill=fill, use_dr=use_dr, names=names,
                        name=output.stem, position_std=position_std)
    if not check_lines:
        return grid, None
    from tangraph.eval.map_check import calibrate_error, check_map_error
    from tangraph.sensors import NavigationModel

    if use_dr:
        raise TangraphError("maps grid: --check-lines compares soundings at reference tracks; "
                            "not with --use-dr")
    check = check_map_error(loaded, cell=cell, statistic=statistic, fill=fill, window=window,
                            model=NavigationModel(sounding_std=sounding_std), names=names, lines=lines,
                            position_std=position_std)
    return calibrate_error(grid, check), check


def grid_summary(grid, *, cell: float, fill: int, output: Path) -> str:
    """The line ``maps grid`` prints: what was gridded, filled, dropped, the map's error."""
    gridded = int(grid.count.sum())
    measured = int(np.count_nonzero(grid.count))
    error = grid.depth.error_summary()
    return (
        f"gridded {gridded} soundings into {measured} of {grid.count.size} cells "
        f"({cell:g} m, {grid.statistic}); {grid.n_filled} more filled by --fill {fill}; "
        f"dropped {grid.n_dropped} without depth; "
        + (f"map error: std median {error['depth_std_m']['median']:.3f} m, max "
           f"{error['depth_std_m']['max']:.3f} m, correlation length {error['correlation_length_m']:g} m; "
           if error else "map error: not told by these soundings (no depth_std written); ")
        + f"wrote {output}"
    )
