"""Maps gridded from surveys: the soundings of one or more :class:`~tangraph.survey.Survey`
placed at their reference tracks, in the frame of the first, binned into one map
(:func:`grid_surveys`).

Every sounding (a beam with a return; beams without one are dropped and counted) is placed by
:meth:`Survey.footprints <tangraph.survey.Survey.footprints>` seen from the survey's
``true_pose`` (its GPS track, or the truth of a simulated run). The surveys are put in the frame
of the first: its ``meta["crs"]`` and ``meta["origin"]`` (local coordinates + origin =
projected coordinates). Another survey in the same CRS is shifted by the difference of the
origins, one in another CRS is reprojected with pyproj. The cell centres lie on multiples of
``cell`` in that frame, over the soundings' extent. The map keeps the first survey's CRS and
origin, and its error (:func:`tangraph.maps.gridding_error.gridded_error`) gains the surveys'
positioning std through its slope.

This module stands above :mod:`tangraph.maps` and :mod:`tangraph.survey`, the two it joins, so
that the maps never import the surveys; ``tangraph.maps.grid_surveys`` is this function, found
when first asked for.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from tangraph.errors import TangraphError
from tangraph.maps._grid_checks import check_cell
from tangraph.maps.gridding import SoundingGrid, Statistic, block_reduce, fill_gaps
from tangraph.maps.projection import same_crs
from tangraph.survey import Survey

__all__ = ["DEFAULT_VERTICAL_DATUM", "check_distinct", "grid_surveys"]

DEFAULT_VERTICAL_DATUM = "water surface"  # what a survey without meta["vertical_datum"] means


def _to_frame(north, east, crs, origin, frame_crs, frame_origin, names: tuple[str, str]):
    """Local ``(north, east)`` of one survey's frame in the frame ``(frame_crs, frame_origin)``."""
    if (crs is None) != (frame_crs is None):
        raise TangraphError(
            f"surveys in different frames: {names[0]} has CRS {frame_crs!r}, {names[1]} has "
            f"{crs!r}; a survey without a CRS can only be gridded with others without one"
        )
    import pyproj

    try:
        if crs is None or same_crs(crs, frame_crs):
            return north + (origin[0] - frame_origin[0]), east + (origin[1] - frame_origin[1])
        transformer = pyproj.Transformer.from_crs(crs, frame_crs, always_xy=True)
    except pyproj.exceptions.CRSError as exc:
        raise TangraphError(f"{names[0]} ({frame_crs!r}) or {names[1]} ({crs!r}): bad CRS ({exc})") from None
    x, y = transformer.transform(east + origin[1], north + origin[0])
    return np.asarray(y) - frame_origin[0], np.asarray(x) - frame_origin[1]


def _frame_of(survey: Survey, name: str) -> tuple[str | None, tuple[float, float]]:
    crs = survey.meta.get("crs")
    origin = survey.meta.get("origin", (0.0, 0.0))
    try:
        origin = (float(origin[0]), float(origin[1]))
    except (TypeError, ValueError, IndexError):
        raise TangraphError(f"{name}: meta origin must be (northing, easting), got {origin!r}") from None
    return (None if crs is None else str(crs)), origin


def _vertical_datum(surveys: Sequence[Survey], names: Sequence[str]) -> str:
    datums = [str(s.meta.get("vertical_datum", DEFAULT_VERTICAL_DATUM)) for s in surveys]
    for name, datum in zip(names, datums, strict=True):
        if datum != datums[0]:
            raise TangraphError(
                f"surveys with different vertical datums: {names[0]} {datums[0]!r}, {name} "
                f"{datum!r}; reduce them to one datum first"
            )
    return datums[0]


def grid_surveys(
    surveys: Sequence[Survey],
    *,
    cell: float,
    statistic: Statistic = "median",
    fill: int = 0,
    use_dr: bool = False,
    names: Sequence[str] | None = None,
    name: str = "surveys",
    position_std: float = 0.0,
) -> SoundingGrid:
    """Grid the soundings of one or more surveys, placed at their reference tracks, into a map.

    Every sounding is placed by :meth:`Survey.footprints <tangraph.survey.Survey.footprints>`
    seen from the survey's reference track, in the frame of the first survey, on cells whose
    centres lie on multiples of ``cell`` (the module docstring says how).

    Parameters
    ----------
    surveys : sequence of Survey
    cell : float
        Cell size, metres.
    statistic : {"mean", "median"}
        The depth layer of the map (median: robust to outliers); the other one, the count and
        the std are kept in the result (and written as extra NetCDF variables).
    fill : int
        Fill empty cells from the data within this many cells
        (:func:`~tangraph.maps.gridding.fill_gaps`); 0: none.
    use_dr : bool
        Place the soundings of every survey at its dead reckoning instead (for surveys
        without a reference track).
    names : sequence of str, optional
        Names of the surveys (e.g. their files) in errors and in the result's ``meta``.
    name : str
        Name of the map.
    position_std : float
        The std (m per axis) of the positions the soundings are placed at (the reference
        track's: a GPS's error; the dead reckoning's with ``use_dr``): the map's error gains it
        times the map's slope (:func:`~tangraph.maps.gridding_error.gridded_error`). 0: the
        positions are exact.

    Returns
    -------
    SoundingGrid
        The map is ``.depth``, in the first survey's CRS and origin; ``meta`` holds the
        sources, the vertical datum, the track used, the position std and the gap fill.

    Raises
    ------
    TangraphError
        No surveys; a survey without ``true_pose`` (unless ``use_dr``); surveys with different
        vertical datums (``meta["vertical_datum"]``, ``"water surface"`` if missing); a survey
        with a CRS mixed with one without.

    Examples
    --------
    >>> import numpy as np
    >>> from tangraph.survey import Survey
    >>> pose = np.column_stack([np.arange(20.0), np.zeros(20), np.zeros(20)])
    >>> s = Survey(time=np.arange(20.0), dr_pose=pose, vehicle_depth=np.zeros(20),
    ...            beam_forward=np.zeros((20, 3)), beam_starboard=np.tile([-2.0, 0, 2], (20, 1)),
    ...            beam_depth=np.full((20, 3), 30.0), true_pose=pose)
    >>> g = grid_surveys([s], cell=2.0)
    >>> g.depth.shape, int(g.count.sum()), g.meta["vertical_datum"]
    ((11, 3), 60, 'water surface')
    """
    surveys = list(surveys)
    names = _checked_names(surveys, names, position_std)
    datum = _vertical_datum(surveys, names)
    points, frame_crs, frame_origin = _placed_soundings(surveys, names, use_dr)
    cell = check_cell(cell, f"surveys {name!r}")
    grid = block_reduce(points, cell=cell, extent=_snapped_extent(points, cell, name), statistic=statistic,
                        name=name, crs=frame_crs, origin=frame_origin)
    meta = {**grid.meta, "sources": names, "vertical_datum": datum,
            "track": "dr_pose" if use_dr else "true_pose", "position_std": float(position_std)}
    grid = SoundingGrid(grid.mean, grid.count, grid.std, grid.n_dropped, median=grid.median,
                        statistic=grid.statistic, meta=meta)
    return fill_gaps(grid, fill) if fill else grid


def check_distinct(surveys: Sequence[Survey], names: Sequence[str], where: str) -> None:
    """Refuse two surveys that hold the same pings (the same times and depths, not all one value:
    one survey given twice, perhaps imported in another CRS), whose soundings would count twice
    as evidence."""
    for a in range(len(surveys)):
        for b in range(a + 1, len(surveys)):
            s, t = surveys[a], surveys[b]
            common, i, j = np.intersect1d(s.time, t.time, assume_unique=True, return_indices=True)
            if not common.size or s.beam_depth.shape[1] != t.beam_depth.shape[1]:
                continue
            depth = s.beam_depth[i]
            finite = depth[np.isfinite(depth)]
            if finite.size and np.ptp(finite) > 0 and np.array_equal(depth, t.beam_depth[j], equal_nan=True):
                raise TangraphError(f"{where}: {names[a]} and {names[b]} hold the same {common.size} pings "
                                    "(their times and depths): a survey given twice counts its soundings "
                                    "twice; give each once")


def _checked_names(surveys: list[Survey], names: Sequence[str] | None, position_std) -> list[str]:
    """The surveys' names (by default ``survey 1``, ...), once the surveys and ``position_std``
    are checked."""
    if not surveys:
        raise TangraphError("grid_surveys: no surveys")
    if isinstance(position_std, bool) or not isinstance(position_std, int | float | np.floating) \
            or not (math.isfinite(position_std) and position_std >= 0):
        raise TangraphError(f"grid_surveys: position_std must be a number of metres >= 0, "
                            f"got {position_std!r}")
    names = [f"survey {k + 1}" for k in range(len(surveys))] if names is None else [str(n) for n in names]
    if len(names) != len(surveys):
        raise TangraphError(f"grid_surveys: {len(names)} names for {len(surveys)} surveys")
    check_distinct(surveys, names, "grid_surveys")
    return names


def _placed_soundings(surveys: list[Survey], names: list[str], use_dr: bool):
    """Every survey's soundings ``(north, east, depth)`` placed at its reference track (or its dead
    reckoning with ``use_dr``) in the first survey's frame, with that frame's CRS and origin."""
    frame_crs, frame_origin = _frame_of(surveys[0], names[0])
    blocks = []
    for survey, survey_name in zip(surveys, names, strict=True):
        if not use_dr and survey.true_pose is None:
            raise TangraphError(
                f"{survey_name}: the survey has no reference track (true_pose: GPS or truth); "
                "grid it on its dead reckoning with use_dr (CLI: --use-dr)"
            )
        north, east = survey.footprints(survey.dr_pose if use_dr else survey.true_pose)
        crs, origin = _frame_of(survey, survey_name)
        north, east = _to_frame(north, east, crs, origin, frame_crs, frame_origin, (names[0], survey_name))
        blocks.append(np.column_stack([north.ravel(), east.ravel(), survey.beam_depth.ravel()]))
    return np.concatenate(blocks), frame_crs, frame_origin


def _snapped_extent(points: np.ndarray, cell: float, name: str) -> tuple[float, float, float, float]:
    """The soundings' extent with its ends on multiples of ``cell`` (at least one cell each way)."""
    finite = np.all(np.isfinite(points), axis=1)
    if not finite.any():
        raise TangraphError(f"surveys {name!r}: no soundings")
    lo = np.rint(points[finite, :2].min(axis=0) / cell) * cell
    hi = np.maximum(np.rint(points[finite, :2].max(axis=0) / cell) * cell, lo + cell)
    return lo[0], hi[0], lo[1], hi[1]
