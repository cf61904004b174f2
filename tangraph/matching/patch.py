"""A window of pings as one patch of soundings, placed relative to the window's reference pose."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from tangraph.errors import TangraphError
from tangraph.survey import Survey, footprints

if TYPE_CHECKING:
    from tangraph.sensors.terrain import MapError

__all__ = ["MatchingError", "Patch", "window_patch"]


class MatchingError(TangraphError):
    """A terrain match cannot be made from this input (the message says why)."""


@dataclasses.dataclass(frozen=True, eq=False)
class Patch:
    """Soundings of a window of pings, relative to the reference (last) ping's DR position.

    ``offsets (N, 2)`` are world-aligned ``(d_north, d_east)`` from the reference position as
    dead reckoning sees them (DR increments inside the window are trusted; the window's absolute
    position is what matching estimates); ``depths (N,)`` the measured depths; ``ping (N,)`` the
    ping of each sounding; ``beam (N,)`` its beam. ``reference_position`` is the DR position of
    ping ``reference``. ``shared (N,)``: the map error variance each sounding shares with the
    survey's other soundings (:func:`tangraph.sensors.shared_map_variances`; None: none), and
    ``error`` the map's error (:class:`tangraph.sensors.MapError`; None: none), from which what
    the window's own soundings share is computed where the fix is made
    (:func:`tangraph.sensors.shared_quadratic`).
    """

    offsets: np.ndarray
    depths: np.ndarray
    ping: np.ndarray
    beam: np.ndarray
    reference: int
    first: int
    reference_position: np.ndarray
    n_dropped: int
    shared: np.ndarray | None = None
    error: MapError | None = None

    @property
    def n_soundings(self) -> int:
        return int(self.depths.size)

    @property
    def n_pings(self) -> int:
        return self.reference - self.first + 1


def window_patch(survey: Survey, end: int, n_pings: int, *, min_soundings: int = 10, poses=None,
                 shared=None, error=None) -> Patch:
    """The patch of the ``n_pings`` pings ending at ping ``end`` (NaN soundings dropped, counted),
    laid with ``poses`` (the window's ``(n_pings, 3)`` poses; default their DR poses). Only the
    window's footprints are computed. ``shared (K, B)``: the survey's soundings' shared map
    error variances (:func:`tangraph.sensors.shared_map_variances`), kept for the window's;
    ``error``: the map's error (:func:`tangraph.sensors.map_error`), kept (:attr:`Patch.error`)
    unless it is zero.

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
        shared=None if shared is None else np.asarray(shared, float)[window][keep],
        error=None if error is None or error.is_zero else error,
    )
