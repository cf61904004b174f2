"""Maps gridded from files as ``tangraph maps grid`` grids them: survey files (.nc) or one x y z
text file, the map's error checked by its check lines (:func:`grid_files`).

Survey files go to :func:`~tangraph.gridding_surveys.grid_surveys` (placed at their reference
tracks), an x y z text file of scattered soundings (:func:`~tangraph.maps.read_soundings`) to
:func:`~tangraph.maps.gridding.block_reduce`; with ``check_lines`` each survey is held out
against the map of the others (:func:`tangraph.eval.map_check.check_map_error`) and the map's
error scaled by what they found (:func:`~tangraph.eval.map_check.calibrate_error`).

**Checked by default.** A map gridded from surveys states an error (its ``depth_std``) that
every estimator leans on, and a map that errs beyond it in patches makes every estimator
converge on its noise with confidence. Hydrographers validate a surface's uncertainty with
check lines (IHO S-44), so a map gridded from survey files is checked unless told not to
(``check_lines=False``): several files are held out file by file, a single file line by line.
Where the check cannot be made (soundings placed at the dead reckoning, surveys that overlap in
fewer than :data:`~tangraph.eval.map_check.MIN_WINDOWS` windows) the map keeps the gridding's
own error and says why in its ``meta["check_lines_skipped"]``; asked for explicitly
(``check_lines=True``), the same is an error.

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
    check_lines: bool | None = None, lines: bool = False, window: float = 50.0, sounding_std: float = 0.1,
    where: str = "grid_files", option_name: Callable[[str], str] = str,
) -> tuple[SoundingGrid, MapCheck | None]:
    """The map of ``inputs`` named after ``output``, and its check (None when none was made).

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
        noise ``sounding_std`` m, and scale the map's ``depth_std`` by what they find. None
        (default): wherever it can be made (module docstring; a single survey file is checked
        line by line), else the map keeps the gridding's error and ``meta["check_lines_skipped"]``
        says why; False: never.
    where, option_name
        How errors name the caller (default ``"grid_files"``) and a keyword (default: as it is;
        ``tangraph maps grid`` gives its options, ``sign`` -> ``--sign``).

    Raises
    ------
    TangraphError
        The output is an input; survey files mixed with text, or several text files; an option of
        one kind of input given for the other; ``check_lines=True`` with ``use_dr``; and whatever
        gridding, reading and checking (when asked for) refuse.
    """
    output = Path(output)
    paths = [Path(path) for path in inputs]
    if output.resolve() in {path.resolve() for path in paths}:
        raise TangraphError(f"{where}: the output {output} is one of the inputs")
    surveys = [path for path in paths if path.suffix.lower() == ".nc"]
    if surveys and len(surveys) != len(paths):
        raise TangraphError(f"{where}: give survey files (.nc) or one x y z text file, not both")
    if not surveys and len(paths) > 1:
        raise TangraphError(f"{where}: {len(paths)} x y z text files; give one (their soundings joined in "
                            "one file), or survey files (.nc)")
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
    skipped = {} if check_lines is False else {"check_lines_skipped": "x y z text has no tracks to hold out"}
    if sign is None:
        raise TangraphError(f"{where}: x y z text input needs {option_name('sign')} (depth or elevation)")
    if use_dr:
        raise TangraphError(f"{where}: {option_name('use_dr')} applies to survey files (.nc), not x y z text")
    soundings = read_soundings(paths[0], sign=cast(Literal["depth", "elevation"], sign), crs=crs, units=units)
    grid = block_reduce(soundings.points, cell=cell, statistic=statistic,
                        name=output.stem, crs=soundings.crs, origin=soundings.origin)
    grid = dataclasses.replace(grid, meta={**grid.meta, "position_std": float(position_std), **skipped})
    return (fill_gaps(grid, fill) if fill else grid), None


def _grid_surveys(surveys: list[Path], output: Path, *, cell, statistic, fill, position_std, use_dr,
                  check_lines, lines, window, sounding_std, where, option_name):
    """The map of survey files, calibrated by their check lines (``check_lines``: True, None for
    wherever they can be made, False)."""
    loaded = [read_survey(path) for path in surveys]
    names = [str(path) for path in surveys]
    grid = grid_surveys(loaded, cell=cell, statistic=statistic, fill=fill, use_dr=use_dr, names=names,
                        name=output.stem, position_std=position_std)
    if check_lines is False:
        return grid, None
    # the check lines, and all of tangraph.eval with them, are loaded only when made
    from tangraph.eval.map_check import calibrate_error, check_map_error
    from tangraph.sensors import NavigationModel

    if use_dr:
        if check_lines is None:
            return _skipped(grid, "soundings placed at the dead reckoning (check lines compare them at "
                                  "reference tracks)"), None
        raise TangraphError(f"{where}: {option_name('check_lines')} compares soundings at reference "
                            f"tracks; not with {option_name('use_dr')}")
    try:
        check = check_map_error(loaded, cell=cell, statistic=statistic, fill=fill, window=window,
                                model=NavigationModel(sounding_std=sounding_std), names=names,
                                lines=lines or (check_lines is None and len(loaded) == 1),
                                position_std=position_std)
        return calibrate_error(grid, check), check
    except TangraphError as err:
        if check_lines:
            raise
        return _skipped(grid, str(err)), None


def _skipped(grid: SoundingGrid, why: str) -> SoundingGrid:
    """The map keeping the gridding's own error, with why no check lines were made."""
    return dataclasses.replace(grid, meta={**grid.meta, "check_lines_skipped": why})
