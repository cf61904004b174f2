"""How much has the seafloor changed since its map was surveyed? A later survey's check lines.

A map gridded from earlier surveys states how well they knew the seafloor *then*
(:mod:`tangraph.maps.gridding_error`); check lines among those surveys
(:mod:`tangraph.eval.map_check`) test that statement, but cannot see what changed afterwards.
Soundings of a later survey placed at a reference track (its GPS) can. :func:`measure_change`
compares them with the map and finds the change a navigation model states
(``map_change_std``, ``map_change_length``; :mod:`tangraph.sensors.terrain`):

- its **std** ``c``, from the soundings one by one: the ``c`` at which their residuals (each
  survey's median removed: its datum) over ``sqrt(s^2 + sounding_std^2 + c^2)`` (``s`` the std
  the map states at the sounding) have a robust spread of 1 (1.4826 times their median absolute
  value). Only the soundings where the map states at most its median error count: its
  well-surveyed cells, where the statement is the data's own. A gridded map states its filled
  gaps' error from the terrain's variogram, on the safe side, and there the change would hide
  in what the gaps are said to err;
- its **range** ``L``, from the same soundings in windows of track
  (:func:`~tangraph.eval.windows.window_residuals`, with the change a field of std ``c`` and range
  ``L`` beside the map's own): the ``L`` at which the windows' standardised mean residuals have
  a robust spread of 1. A longer range shares more of the change among a window's soundings, so
  the spread falls as ``L`` grows. ``L`` is searched between one map cell and
  :data:`MAX_LENGTH_WINDOWS` windows; a bound reached is said (``MapChange.length_bound``).

The reference track's own error adds to the residuals through the map's slope, so the change
found errs on the large side (the cautious one for an estimator that states it).

Nothing here touches files.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np
from scipy.optimize import brentq

from tangraph.errors import TangraphError
from tangraph.eval.windows import window_residuals
from tangraph.maps.grid import BathymetryMap
from tangraph.sensors.navigation_model import NavigationModel
from tangraph.sensors.terrain import map_error
from tangraph.survey import Survey

__all__ = ["MAX_LENGTH_WINDOWS", "MapChange", "measure_change"]

MAX_LENGTH_WINDOWS = 10.0  #: the longest range searched, in windows
MIN_SOUNDINGS = 100  #: a change rests on at least this many soundings
_NORMAL_MAD = 1.4826  # a Gaussian's std over its median absolute deviation


@dataclasses.dataclass(frozen=True)
class MapChange:
    """The seafloor's change since a map (:func:`measure_change`): its ``std`` and ``length`` (m;
    length 0 when there is no change), the soundings and windows they rest on, the robust spread
    of the standardised residuals against the map's own statement (``sounding_z``,
    ``window_z``; 1 where the map's statement holds a survey later) and, when the range search
    ended at a bound, which (``"lower"``: no more shared than a map cell; ``"upper"``)."""

    std: float
    length: float
    soundings: int
    windows: int
    sounding_z: float
    window_z: float
    window: float
    length_bound: str | None = None

    def model_fields(self) -> dict[str, float]:
        """The navigation model's fields that state this change."""
        return {"map_change_std": round(self.std, 4), "map_change_length": round(self.length, 1)}

    def summary(self) -> str:
        """One line: the figures and what they rest on."""
        bound = {"lower": " (no more shared than one map cell)",
                 "upper": f" (at the longest range searched, {MAX_LENGTH_WINDOWS:g} windows)"}.get(
                     self.length_bound or "", "")
        return (f"change since the map: std {self.std:.3f} m, range {self.length:.1f} m{bound}; from "
                f"{self.soundings} soundings where the map states at most its median error (robust z "
                f"{self.sounding_z:.2f} against the map's own statement) and {self.windows} windows of "
                f"{self.window:g} m (robust z {self.window_z:.2f})")


def measure_change(surveys: Sequence[Survey], bathymetry: BathymetryMap, model: NavigationModel | None = None,
                   *, window: float = 50.0) -> MapChange:
    """The seafloor's change since ``bathymetry`` was surveyed, measured by ``surveys`` (later
    surveys with a reference track, put in the map's frame) as the module docstring says;
    ``model`` gives the sounding noise and, for a map that states no error, the map's std (its
    own ``map_change_std`` is not used).

    Raises
    ------
    TangraphError
        No survey, a survey without a reference track, ``window <= 0``, or fewer than
        ``MIN_SOUNDINGS`` soundings where the map states at most its median error.
    """
    from tangraph.map_frame import in_map_frame

    if not (np.isfinite(window) and window > 0):
        raise TangraphError(f"measure_change: window must be > 0 m, got {window!r}")
    if not surveys:
        raise TangraphError("measure_change: no survey given (later surveys with a reference track)")
    model = (NavigationModel() if model is None else model).replace(map_change_std=0.0, map_change_length=0.0)
    stated = map_error(bathymetry, model)
    placed, used, residual, std = [], [], [], []
    for survey in surveys:
        name = survey.meta.get("name", "")
        if survey.true_pose is None:
            raise TangraphError(f"measure_change: survey {name!r} has no reference track (true_pose)")
        survey = in_map_frame(survey, bathymetry)
        north, east = survey.footprints(survey.true_pose)
        r = survey.beam_depth - bathymetry.depth_at(north, east)
        s = stated.std_at(north, east)
        ok = np.isfinite(r) & np.isfinite(s) & (s <= stated.typical_std)
        if ok.any():
            placed.append(survey)
            used.append(ok)
            residual.append(r[ok] - np.median(r[ok]))
            std.append(np.sqrt(s[ok] ** 2 + model.sounding_std**2))
    count = int(sum(r.size for r in residual))
    if count < MIN_SOUNDINGS:
        raise TangraphError(
            f"measure_change: {count} soundings of the surveys lie where map {bathymetry.name!r} states at "
            f"most its median error, fewer than {MIN_SOUNDINGS}: surveys that cross the map's surveyed cells")
    r, s = np.concatenate(residual), np.concatenate(std)
    sounding_z = _spread(r / s)
    change, _ = _root(lambda c: _spread(r / np.sqrt(s**2 + c**2)) - 1.0, 0.0, 10.0 * _spread(r))

    def windows(length: float, c: float = change) -> np.ndarray:
        told = model.replace(map_change_std=c, map_change_length=length)
        parts = [window_residuals(p, bathymetry, told, window=window, used=u)
                 for p, u in zip(placed, used, strict=True)]
        return np.concatenate([m / np.sqrt(v) for _, m, v in parts])

    cell = float(max(bathymetry.cell_size))
    before = windows(cell, 0.0)
    if change == 0 or before.size == 0:
        return MapChange(change, 0.0, count, int(before.size), sounding_z, _spread(before), window)
    low, high = np.log(cell), np.log(max(MAX_LENGTH_WINDOWS * window, cell))
    log_length, bound = _root(lambda x: _spread(windows(float(np.exp(x)))) - 1.0, low, high)
    return MapChange(change, float(np.exp(log_length)), count, int(before.size), sounding_z, _spread(before),
                     window, bound)


def _spread(z: np.ndarray) -> float:
    """The robust spread of zero-centred scores: 1.4826 times their median absolute value."""
    return float(_NORMAL_MAD * np.median(np.abs(z))) if z.size else float("nan")


def _root(f, low: float, high: float) -> tuple[float, str | None]:
    """The root of a decreasing ``f`` in ``[low, high]``, or the bound it lies beyond (and
    which: ``"lower"``, ``"upper"``)."""
    if f(low) <= 0:
        return low, "lower"
    if f(high) > 0:
        return high, "upper"
    return float(brentq(f, low, high, xtol=1e-4 * max(abs(high - low), 1e-12))), None
