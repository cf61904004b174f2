"""Maps gridded from files as ``tangraph maps grid`` grids them: survey files (.nc) or one x y z
text file, the map's error checked by its check lines where asked (:func:`grid_files`).

Survey files go to :func:`~tangraph.gridding_surveys.grid_surveys` (placed at their reference
tracks), an x y z text file of scattered soundings (:func:`~tangraph.maps.read_soundings`) to
:func:`~tangraph.maps.gridding.block_reduce`; with ``check_lines`` each survey is held out
against the map of the others (:func:`tangraph.eval.map_check.check_map_error`) and the map's
error scaled by what they found (:func:`~tangraph.eval.map_check.calibrate_error`).

This stands beside :mod:`tangraph.gridding_surveys` rather than in it because the check lines
grid surveys themselves: :mod:`tangraph.eval.map_check` imports ``grid_surveys``, and this
module imports the check, so neither circles back.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Literal, cast

from tangraph.errors import TangraphError
from tangraph.gridding_surveys import grid_surveys
from tangraph.maps.gridding import SoundingGrid, Statistic, block_reduce, fill_gaps
from tangraph.maps.io import read_soundings
from tangraph.survey import read_survey

if TYPE_CHECKING:
    from tangraph.eval.map_check import MapCheck

__all__ = ["grid_files"]


def grid_files(
    inputs: Sequence[str | os.PathLike], output: str | os.PathLike, *, cell: float,
    statistic: Statistic = "median", fill: int = 0, position_std: float = 0.0, use_dr: bool = False,
    sign: str | None = None, crs: str | None = None, units: str | None = None,
    check_lines: bool = False, lines: bool = False, window: float = 50.0, sounding_std: float = 0.1,
    where: str = "grid_files", option_name: Callable[[str], str] = str,
) -> tuple[SoundingGrid, MapCheck | None]:
    """The map of ``inputs`` named after ``output``, and its check (None without ``check_lines``).

    Parameters
    ----------
    inputs : sequence of paths
        Survey files (.nc), or one x y z text file of soundings, not both.
    output : path
        The map's file: its stem names the map, and it may not be one of the inputs (the caller
        writes it, e.g. with :func:`tangraph.maps.io.write_sounding_grid`).
    cell, statistic, fill, position_std
        As in :func:`~tangraph.gridding_surveys.grid_surveys`, for x y z text too.
    use_dr
        Survey files only: place their soundings at the dead reckoning.
    sign, crs, units
        x y z text only (``sign`` required there): as in :func:`~tangraph.maps.read_soundings`.
    check_lines, lines, window, sounding_std
        Survey files only, not with ``use_dr``: hold out each survey (each of its lines with
        ``lines``) against the map of the others in windows of ``window`` m, the soundings' own
        noise ``sounding_std`` m, and scale the map's ``depth_std`` by what they find.
    where, option_name
        How errors name the caller (default ``"grid_files"``) and a keyword (default: as it is;
        ``tangraph maps grid`` gives its options, ``sign`` -> ``--sign``).

    Raises
    ------
    TangraphError
        The output is an input; survey files mixed with text, or several text files; an option of
        one kind of input given for the other; ``check_lines`` with ``use_dr``; and whatever
        gridding, reading and checking refuse.
    """
    output = Path(output)
    paths = [Path(path) for path in inputs]
    if output.resolve() in {path.resolve() for path in paths}:
        raise TangraphError(f"{where}: the output {output} is one of the inputs")
    surveys = [path for path in paths if path.suffix.lower() == ".nc"]
    if (surveys and len(surveys) != len(paths)) or (not surveys and len(paths) > 1):
        raise TangraphError(f"{where}: give survey files (.nc) or one x y z text file, not both")
    gridding = {"cell": cell, "statistic": statistic, "fill": fill, "position_std": position_std}
    if surveys:
        for keyword, given in (("sign", sign), ("crs", crs), ("units", units)):
            if given is not None:
                raise TangraphError(
                    f"{where}: {option_name(keyword)} applies to x y z text; survey files hold depths "
                    "(positive down) in their own CRS"
                )
        return _grid_surveys(surveys, output, use_dr=use_dr, check_lines=check_lines, lines=lines,
                             window=window, sounding_std=sounding_std, where=where,
                             option_name=option_name, **gridding)
    if check_lines or lines:
        raise TangraphError(f"{where}: {option_name('check_lines')} and {option_name('lines')} need "
                            "survey files (.nc)")
    if sign is None:
        raise TangraphError(f"{where}: x y z text input needs {option_name('sign')} (depth or elevation)")
    if use_dr:
        raise TangraphError(f"{where}: {option_name('use_dr')} applies to survey files (.nc), not x y z text")
    soundings = read_soundings(paths[0], sign=cast(Literal["depth", "elevation"], sign), crs=crs, units=units)
    grid = block_reduce(soundings.points, cell=cell, statistic=statistic,
                        name=output.stem, crs=soundings.crs, origin=soundings.origin)
    grid = dataclasses.replace(grid, meta={**grid.meta, "position_std": float(position_std)})
    return (fill_gaps(grid, fill) if fill else grid), None


def _grid_surveys(surveys: list[Path], output: Path, *, cell, statistic, fill, position_std, use_dr,
                  check_lines, lines, window, sounding_std, where, option_name):
    """The map of survey files, calibrated by their check lines with ``check_lines``."""
    loaded = [read_survey(path) for path in surveys]
    names = [str(path) for path in surveys]
    grid = grid_surveys(loaded, cell=cell, statistic=statistic, fill=fill, use_dr=use_dr, names=names,
                        name=output.stem, position_std=position_std)
    if not check_lines:
        return grid, None
    # the check lines, and all of tangraph.eval with them, are loaded only when asked for
    from tangraph.eval.map_check import calibrate_error, check_map_error
    from tangraph.sensors import NavigationModel

    if use_dr:
        raise TangraphError(f"{where}: {option_name('check_lines')} compares soundings at reference "
                            f"tracks; not with {option_name('use_dr')}")
    check = check_map_error(loaded, cell=cell, statistic=statistic, fill=fill, window=window,
                            model=NavigationModel(sounding_std=sounding_std), names=names, lines=lines,
                            position_std=position_std)
    return calibrate_error(grid, check), check
