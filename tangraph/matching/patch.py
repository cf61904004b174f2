"""A window of pings as one patch of soundings, placed relative to the window's reference pose."""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from tangraph.errors import TangraphError
from tangraph.survey import Survey, footprints

if TYPE_CHECKING:
    from tangraph.sensors.terrain import MapError

__all__ = ["MatchingError", "Patch", "calibrated_window", "shape_covariance", "window_patch"]


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
    (:func:`tangraph.sensors.shared_quadratic`). ``drift (P, P)``: the covariance of the tide's
    drift between the window's pings (``first`` to ``reference``; None: a constant tide), an
    error every sounding of a ping shares.
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
    drift: np.ndarray | None = None

    @property
    def n_soundings(self) -> int:
        return int(self.depths.size)

    @property
    def n_pings(self) -> int:
        return self.reference - self.first + 1


def window_patch(survey: Survey, end: int, n_pings: int, *, min_soundings: int = 10, poses=None,
                 shared=None, error=None, drift: tuple[float, float] | None = None) -> Patch:
    """The patch of the ``n_pings`` pings ending at ping ``end`` (NaN soundings dropped, counted),
    laid with ``poses`` (the window's ``(n_pings, 3)`` poses; default their DR poses). Only the
    window's footprints are computed. ``shared (K, B)``: the survey's soundings' shared map
    error variances (:func:`tangraph.sensors.shared_map_variances`), kept for the window's;
    ``error``: the map's error (:func:`tangraph.sensors.map_error`), kept (:attr:`Patch.error`)
    unless it is zero; ``drift``: the tide's drift ``(std, time)`` (m, s;
    ``NavigationModel.tide_drift``), whose covariance between the window's pings is kept.

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
        drift=None if drift is None else _drift_covariance(survey.time[window], *drift),
    )


def _drift_covariance(time: np.ndarray, std: float, forget: float) -> np.ndarray:
    """``std^2 exp(-|t_i - t_j| / forget)`` between the pings at ``time (P,)``."""
    return std**2 * np.exp(-np.abs(time[:, None] - time[None, :]) / forget)


def calibrated_window(survey: Survey, end: int, n_pings: int, calibration) -> tuple[np.ndarray, np.ndarray]:
    """The window of ``n_pings`` pings ending at ``end`` laid with the dead reckoning corrected by
    ``calibration = (k, b)`` (:func:`tangraph.geometry.from_dr_frame` about the end ping, where
    the patch is referenced), and the shape Jacobian ``(2, 2)``: how the middle ping's offset from
    the end moves with ``(k, b)``. For :func:`shape_covariance` and :func:`window_patch`'s
    ``poses``; a filter lays its windows so with its own calibration estimate.

    Examples
    --------
    A straight 40 m leg north with a 5 % slow DVL (k = -0.05): the window is 42.1 m long once
    laid, and a heading error of ``b`` turns its middle ping by ``b`` times that offset:

    >>> import numpy as np
    >>> from types import SimpleNamespace
    >>> dr = np.column_stack([np.arange(0.0, 50.0, 10.0), np.zeros(5), np.zeros(5)])
    >>> poses, jac = calibrated_window(SimpleNamespace(dr_pose=dr), 4, 5, (-0.05, 0.0))
    >>> round(float(poses[-1, 0] - poses[0, 0]), 1), (jac.round(2) + 0.0).tolist()
    (42.1, [[22.16, 0.0], [0.0, 21.05]])
    """
    from tangraph.geometry import from_dr_frame

    end, first = int(end), int(end) - int(n_pings) + 1
    k, b = float(calibration[0]), float(calibration[1])
    dr = np.asarray(survey.dr_pose[first : end + 1], float)
    poses = from_dr_frame(dr, (k, b), dr[-1, :2])
    offset = poses[(end - first) // 2, :2] - poses[-1, :2]  # R(-b) (dr_mid - dr_end) / (1 + k)
    turned = np.array([offset[1], -offset[0]])  # its derivative in b
    return poses, np.column_stack([-offset / (1.0 + k), turned])


def shape_covariance(survey: Survey, white, first: int, end: int, shape_jacobian,
                     calibration_cov) -> np.ndarray:
    """What a window laid with a calibrated dead reckoning adds to its fix's covariance ``(2, 2)``:
    what is still uncertain of the laying moves the window's middle ping relative to its
    reference (end) ping: the white DR noise from the middle ping to the end
    (:func:`tangraph.sensors.increment_covariance` of ``white``) and the calibration's remaining
    covariance ``calibration_cov (2, 2)`` through ``shape_jacobian (2, 2)`` (the middle ping's
    world offset from the end against ``(k, b)``); zero for a window of one ping."""
    from tangraph.geometry import rotation_matrix
    from tangraph.sensors import increment_covariance

    first, end = int(first), int(end)
    mid = (first + end) // 2
    if mid >= end:
        return np.zeros((2, 2))
    w = slice(first, end + 1)
    cov = increment_covariance(white, survey.time[w], survey.dr_pose[w], mid - first, end - first)[:2, :2]
    rot = rotation_matrix(survey.dr_pose[mid, 2])
    jac = np.asarray(shape_jacobian, float)
    return rot @ cov @ rot.T + jac @ np.asarray(calibration_cov, float) @ jac.T
