"""Check-line scores: a survey's soundings against a map in windows of track, each window's
mean residual over the std the map's error and the sounding noise give it
(:func:`window_scores`). The check lines of a gridded map (:mod:`tangraph.eval.map_check`) and
the smoother's variance factor (:mod:`tangraph.graph.terrain_solve`) are made of them; this
module sits below both.
"""

from __future__ import annotations

import numpy as np

from tangraph.errors import TangraphError
from tangraph.maps.grid import BathymetryMap
from tangraph.sensors.navigation_model import NavigationModel
from tangraph.sensors.terrain import MapError, map_error, shared_among
from tangraph.survey import Survey

__all__ = ["MIN_SOUNDINGS", "window_residuals", "window_scores"]

MIN_SOUNDINGS = 10  #: a window with fewer soundings on the map is not scored


def window_scores(
    survey: Survey, bathymetry: BathymetryMap, model: NavigationModel, *, window: float,
    error: MapError | None = None, poses=None, used=None,
) -> np.ndarray:
    """The standardised mean residuals of ``survey``'s soundings (at its reference track, or at
    ``poses (K, 3)``, less their median; only those ``used (K, B)`` if given) against
    ``bathymetry`` in consecutive windows of ``window`` m of track ; windows
    with fewer than ``MIN_SOUNDINGS`` soundings on the map are left out (the statistics are
    those of :mod:`tangraph.eval.map_check`'s module docstring)."""
    _, mean, variance = window_residuals(survey, bathymetry, model, window=window, error=error,
                                         poses=poses, used=used)
    return mean / np.sqrt(variance)


def window_residuals(
    survey: Survey, bathymetry: BathymetryMap, model: NavigationModel, *, window: float,
    error: MapError | None = None, poses=None, used=None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The windows of :func:`window_scores` before they are standardised: each window's mean
    time (s), mean residual (m, the survey's median residual removed) and the variance the
    sounding noise and the map's stated error give that mean (m^2)."""
    if poses is None and survey.true_pose is None:
        name = survey.meta.get("name", "")
        raise TangraphError(f"survey {name!r}: no reference track (true_pose) to check the map with")
    poses = survey.true_pose if poses is None else np.asarray(poses, float)
    error = map_error(bathymetry, model) if error is None else error
    north, east = survey.footprints(poses)
    residual = survey.beam_depth - bathymetry.depth_at(north, east)
    ok = np.isfinite(residual) & (True if used is None else np.asarray(used, bool))
    if not ok.any():
        return np.empty(0), np.empty(0), np.empty(0)
    residual = residual - np.median(residual[ok])
    step = np.hypot(*np.diff(poses[:, :2], axis=0).T)
    block = np.floor(np.concatenate([[0.0], np.cumsum(step)]) / window).astype(np.int64)
    rows_out = []
    for b in np.unique(block):
        rows = block == b
        use = ok & rows[:, None]
        n = int(use.sum())
        if n < MIN_SOUNDINGS:
            continue
        pn, pe = north[use], east[use]
        variance = n * float(model.sounding_std) ** 2
        for part in error.components():
            a = part.std_at(pn, pe)
            a = np.where(np.isfinite(a), a, part.typical_std)
            variance += float(np.sum(a * a))
        variance += float(np.sum(shared_among(pn, pe, error)))
        rows_out.append((float(np.mean(survey.time[rows])), float(np.mean(residual[use])), variance / n**2))
    if not rows_out:
        return np.empty(0), np.empty(0), np.empty(0)
    table = np.asarray(rows_out)
    return table[:, 0], table[:, 1], table[:, 2]
