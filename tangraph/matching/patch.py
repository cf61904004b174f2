"""A window of pings as one patch of soundings, placed relative to the window's reference pose."""

from __future__ import annotations

import dataclasses

import numpy as np

from tangraph.errors import TangraphError
from tangraph.survey import Survey, footprints

__all__ = ["MatchingError", "Patch", "soundings_per_cell", "window_patch"]


class MatchingError(TangraphError):
    """A terrain match cannot be made from this input (the message says why)."""


@dataclasses.dataclass(frozen=True, eq=False)
class Patch:
    """Soundings of a window of pings, relative to the reference (last) ping's DR position.

    ``offsets (N, 2)`` are world-aligned ``(d_north, d_east)`` from the reference position as
    dead reckoning sees them (DR increments inside the window are trusted; the window's absolute
    position is what matching estimates); ``depths (N,)`` the measured depths; ``ping (N,)`` the
    ping of each sounding; ``beam (N,)`` its beam. ``reference_position`` is the DR position of
    ping ``reference``.
    """

    offsets: np.ndarray
    depths: np.ndarray
    ping: np.ndarray
    beam: np.ndarray
    reference: int
    first: int
    reference_position: np.ndarray
    n_dropped: int

    @property
    def n_soundings(self) -> int:
        return int(self.depths.size)

    @property
    def n_pings(self) -> int:
        return self.reference - self.first + 1


def window_patch(survey: Survey, end: int, n_pings: int, *, min_soundings: int = 10, poses=None) -> Patch:
    """The patch of the ``n_pings`` pings ending at ping ``end`` (NaN soundings dropped, counted),
    laid with ``poses`` (the window's ``(n_pings, 3)`` poses; default their DR poses). Only the
    window's footprints are computed.

    Raises
    ------
    MatchingError
        An empty window, indices outside the survey, or fewer than ``min_soundings`` soundings.
    """
    end = int(end)
    if n_pings < 1:
        raise MatchingError(f"window of {n_pings} pings: at least 1 is needed")
    if not 0 <= end < survey.n_pings:
        raise MatchingError(f"window end {end} is outside the survey's pings 0..{survey.n_pings - 1}")
    first = end - n_pings + 1
    if first < 0:
        raise MatchingError(f"window of {n_pings} pings ending at ping {end} starts before the survey")
    window = slice(first, end + 1)
    laid = survey.dr_pose[window] if poses is None else np.asarray(poses, float)
    if laid.shape != (n_pings, 3):
        raise MatchingError(
            f"poses of window {first}..{end} must have shape ({n_pings}, 3), got {laid.shape}"
        )
    north, east = footprints(laid, survey.beam_forward[window], survey.beam_starboard[window])
    depth = survey.beam_depth[window]
    keep = np.isfinite(depth)
    if keep.sum() < min_soundings:
        raise MatchingError(
            f"window of pings {first}..{end} holds {int(keep.sum())} soundings, fewer than "
            f"min_soundings = {min_soundings}"
        )
    ref = laid[-1, :2].copy()
    offsets = np.column_stack([north[keep] - ref[0], east[keep] - ref[1]])
    ping, beam = np.nonzero(keep)
    return Patch(
        offsets=offsets,
        depths=depth[keep],
        ping=ping + first,
        beam=beam,
        reference=end,
        first=first,
        reference_position=ref,
        n_dropped=int((~keep).sum()),
    )


def soundings_per_cell(survey: Survey, bathymetry, first: int, end: int) -> float:
    """Soundings of pings ``first..end`` per distinct map cell they fall into, at their DR
    footprints: how many soundings share each cell's map error (at least 1). A model whose map
    error is shared per cell (``NavigationModel.map_error_shared``) counts a window's soundings
    that many times fewer.

    >>> import numpy as np
    >>> from tangraph.maps import BathymetryMap
    >>> m = BathymetryMap(north=np.arange(0, 50, 5.0), east=np.arange(0, 50, 5.0), depth=np.ones((10, 10)))
    >>> t = np.arange(4.0)
    >>> s = Survey(time=t, dr_pose=np.column_stack([t, 0 * t + 10, 0 * t]), vehicle_depth=0 * t,
    ...            beam_forward=np.zeros((4, 3)), beam_starboard=np.tile([-1.0, 0, 1], (4, 1)),
    ...            beam_depth=np.ones((4, 3)))
    >>> soundings_per_cell(s, m, 0, 3)  # 12 soundings in two cells (centred at north 0 and 5)
    6.0
    """
    w = slice(int(first), int(end) + 1)
    north, east = survey.footprints()
    north, east, has = north[w], east[w], np.isfinite(survey.beam_depth[w])
    if not has.any():
        return 1.0
    dn, de = bathymetry.cell_size
    i = np.floor((north[has] - bathymetry.north[0]) / dn + 0.5).astype(np.int64)
    j = np.floor((east[has] - bathymetry.east[0]) / de + 0.5).astype(np.int64)
    cells = np.unique(i * (bathymetry.east.size + 1) + j).size
    return max(float(has.sum()) / cells, 1.0)
