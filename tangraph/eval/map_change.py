"""How much has the seafloor changed since its map was surveyed? A later survey's check lines.

A map gridded from earlier surveys states how well they knew the seafloor *then*
(:mod:`tangraph.maps.gridding_error`); check lines among those surveys
(:mod:`tangraph.eval.map_check`) test that statement, but cannot see what changed afterwards.
Soundings of a later survey placed at a reference track (its GPS) can. :func:`measure_change`
compares them with the map and finds the change a navigation model states
(``map_change_std``, ``map_change_length``; :mod:`tangraph.sensors.terrain`):

- its **std** ``c``, from the soundings one by one: the ``c`` at which their residuals (each
  survey's median removed: its datum) over ``sqrt(s^2 + sounding_std^2 + (p |g|)^2 + d^2 + c^2)``
  (``s`` the std the map states at the sounding, ``p`` the reference track's position std,
  ``g`` the map's slope, ``d^2`` the variance of the drift of the depths' offset about the
  survey's mean, as the model states it or the map does,
  :meth:`~tangraph.sensors.NavigationModel.with_map`) have a robust spread of 1 (1.4826 times
  their median absolute value).
  Only the soundings in the map's measured cells count, where its statement is the data's own
  (``measured``: a gridded map's cells that hold soundings, its ``count > 0``; without it, the
  cells where the map states at most its median error). A gridded map states its filled gaps'
  error from the terrain's variogram, on the safe side, and there the change would hide in
  what the gaps are said to err;
- its **range** ``L``, from the same soundings in windows of track
  (:func:`~tangraph.eval.windows.window_residuals`, with the change a field of std ``c`` and range
  ``L`` beside the map's own, and the drift averaged over a window): the
  ``L`` at which the windows' standardised mean residuals have a robust spread of 1. A longer
  range shares more of the change among a window's soundings, so the spread falls as ``L``
  grows. ``L`` is searched between one map cell and :data:`MAX_LENGTH_WINDOWS` windows; a bound
  reached is said (``MapChange.length_bound``). Fewer than :data:`MIN_WINDOWS` windows leave it
  to the map's correlation length.

What is measured is the change beyond what the model states already: a model that states a
large drift leaves less of the residuals to the change.

Nothing here touches files.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Sequence

import numpy as np
from scipy.optimize import brentq

from tangraph.errors import TangraphError
from tangraph.eval.metrics import robust_spread
from tangraph.eval.windows import window_residuals
from tangraph.maps.grid import BathymetryMap
from tangraph.sensors.navigation_model import NavigationModel
from tangraph.sensors.terrain import map_error
from tangraph.survey import Survey
from tangraph.validation import number

__all__ = ["MAX_LENGTH_WINDOWS", "MIN_SOUNDINGS", "MIN_WINDOWS", "MapChange", "measure_change"]

MAX_LENGTH_WINDOWS = 10.0  #: the longest range searched, in windows
MIN_SOUNDINGS = 100  #: a change rests on at least this many soundings
MIN_WINDOWS = 10  #: its range on at least this many windows (else the map's correlation length)


@dataclasses.dataclass(frozen=True)
class MapChange:
    """The seafloor's change since a map (:func:`measure_change`): its ``std`` and ``length`` (m;
    length 0 when there is no change), the soundings and windows they rest on, the robust spread
    of the standardised residuals against the map's own statement (``sounding_z``,
    ``window_z``; 1 where the map's statement holds a survey later), which cells were used
    (``cells``: ``"measured"`` or ``"at most the median std"``) and, when the range search ended at
    a bound, which (``"lower"``: no more shared than a map cell; ``"upper"``; ``"unmeasured"``:
    fewer than ``MIN_WINDOWS`` windows, the length 0 that states the map's correlation length)."""

    std: float
    length: float
    soundings: int
    windows: int
    sounding_z: float
    window_z: float
    window: float
    cells: str = "measured"
    length_bound: str | None = None

    def model_fields(self) -> dict[str, float]:
        """The navigation model's fields that state this change."""
        return {"map_change_std": round(self.std, 4), "map_change_length": round(self.length, 1)}

    def summary(self) -> str:
        """One line: the figures and what they rest on."""
        bound = {"lower": " (no more shared than one map cell)",
                 "upper": f" (at the longest range searched, {MAX_LENGTH_WINDOWS:g} windows)",
                 "unmeasured": " (too few windows to measure it: the map's correlation length)"}.get(
                     self.length_bound or "", "")
        return (f"change since the map: std {self.std:.3f} m, range {self.length:.1f} m{bound}; from "
                f"{self.soundings} soundings in cells {self.cells} (robust z "
                f"{self.sounding_z:.2f} against the map's own statement) and {self.windows} windows of "
                f"{self.window:g} m (robust z {self.window_z:.2f})")


def measure_change(surveys: Sequence[Survey], bathymetry: BathymetryMap, model: NavigationModel | None = None,
                   *, window: float = 50.0, measured: np.ndarray | None = None,
                   position_std: float = 0.0, names: Sequence[str] | None = None) -> MapChange:
    """The seafloor's change since ``bathymetry`` was surveyed, measured by ``surveys`` (later
    surveys with a reference track of position std ``position_std`` m per axis, put in the map's
    frame; ``names`` for errors, default their ``meta["name"]``) as the module docstring says, in
    the cells ``measured (ny, nx)`` (bool) holds; ``model`` gives the sounding noise, the drift of
    the depths' offset and, for a map that states no error, the map's std (its own
    ``map_change_std`` is not used).

    Raises
    ------
    TangraphError
        No survey, a survey without a reference track, one given twice or off the map's data,
        ``window <= 0``, ``position_std < 0``, ``measured`` not of the map's shape, or fewer than
        ``MIN_SOUNDINGS`` soundings in the cells used.
    """
    from tangraph.map_frame import check_overlap, in_map_frame

    names = _checked(surveys, bathymetry, window, measured, names)
    position_std = number(position_std, "measure_change: position_std")
    model = (NavigationModel() if model is None else model).replace(map_change_std=0.0, map_change_length=0.0)
    model = model.with_map(bathymetry)
    stated = map_error(bathymetry, model)
    if stated.is_zero:
        raise TangraphError(f"measure_change: map {bathymetry.name!r} states no error (no depth_std layer, "
                            "and the model's map_std is 0), so a change cannot be told from its own error: "
                            "give the map's error (a map 'maps grid' wrote, or map_std; CLI --map-std)")
    cells = stated.std <= stated.typical_std if measured is None else np.asarray(measured, bool)
    placed, used, residual, std = [], [], [], []
    for survey, name in zip(surveys, names, strict=True):
        if survey.true_pose is None:
            raise TangraphError(f"measure_change: survey {name} has no reference track (true_pose)")
        check_overlap(survey, bathymetry, where=f"measure_change: survey {name}: ",
                      remedy="measure with surveys of the map's area")
        survey = in_map_frame(survey, bathymetry)
        north, east = survey.footprints(survey.true_pose)
        r = survey.beam_depth - bathymetry.depth_at(north, east)
        s = stated.std_at(north, east)
        ok = np.isfinite(r) & np.isfinite(s) & _in_cells(cells, bathymetry, north, east)
        if ok.any():
            slope = np.sum(bathymetry.gradient_at(north[ok], east[ok]) ** 2, axis=-1)
            placed.append(survey)
            used.append(ok)
            residual.append(r[ok] - np.median(r[ok]))
            drift = _drift_variance(survey, model, survey.time[-1] - survey.time[0])
            std.append(np.sqrt(s[ok] ** 2 + model.sounding_std**2 + position_std**2 * np.nan_to_num(slope)
                               + drift))
    count = int(sum(r.size for r in residual))
    where = "measured" if measured is not None else "at most the median std"
    if count < MIN_SOUNDINGS:
        raise TangraphError(
            f"measure_change: {count} soundings of the surveys lie in the cells of map {bathymetry.name!r} "
            f"{where}, fewer than {MIN_SOUNDINGS}: surveys that cross the map's surveyed cells")
    r, s = np.concatenate(residual), np.concatenate(std)
    sounding_z = robust_spread(r / s, about=0.0)
    change, _ = _root(lambda c: robust_spread(r / np.sqrt(s**2 + c**2), about=0.0) - 1.0, 0.0,
                      10.0 * robust_spread(r, about=0.0))

    shared = [_drift_variance(p, model, p.time[-1] - p.time[0], window) for p in placed]

    def windows(length: float, c: float = change) -> np.ndarray:
        told = model.replace(map_change_std=c, map_change_length=length)
        parts = [window_residuals(p, bathymetry, told, window=window, used=u)
                 for p, u in zip(placed, used, strict=True)]
        return np.concatenate([m / np.sqrt(v + d) for (_, m, v), d in zip(parts, shared, strict=True)])

    cell = float(max(bathymetry.cell_size))
    before = windows(cell, 0.0)
    found = functools.partial(MapChange, soundings=count, windows=int(before.size), sounding_z=sounding_z,
                              window_z=robust_spread(before, about=0.0), window=window, cells=where)
    if change == 0:
        return found(change, 0.0)
    if before.size < MIN_WINDOWS:
        return found(change, 0.0, length_bound="unmeasured")
    low, high = np.log(cell), np.log(max(MAX_LENGTH_WINDOWS * window, cell))
    log_length, bound = _root(lambda x: robust_spread(windows(float(np.exp(x))), about=0.0) - 1.0, low, high)
    return found(change, float(np.exp(log_length)), length_bound=bound)


def _checked(surveys, bathymetry: BathymetryMap, window: float, measured, names) -> list[str]:
    """The surveys' names as errors give them (``repr``), once the window, the measured cells'
    shape and the surveys (some, none twice) are checked."""
    from tangraph.gridding_surveys import check_distinct

    if not (np.isfinite(window) and window > 0):
        raise TangraphError(f"measure_change: window must be > 0 m, got {window!r}")
    if not surveys:
        raise TangraphError("measure_change: no survey given (later surveys with a reference track)")
    if measured is not None and np.shape(measured) != bathymetry.shape:
        raise TangraphError(f"measure_change: measured cells of shape {np.shape(measured)}, the map "
                            f"{bathymetry.name!r} {bathymetry.shape}")
    names = [repr(str(name)) for name in names] if names is not None else [
        repr(str(s.meta.get("name") or f"survey {k + 1}")) for k, s in enumerate(surveys)]
    if len(names) != len(surveys):
        raise TangraphError(f"measure_change: {len(names)} names for {len(surveys)} surveys")
    check_distinct(surveys, names, "measure_change")
    return names


def _in_cells(cells: np.ndarray, bathymetry: BathymetryMap, north, east) -> np.ndarray:
    """Whether each point lies in one of the map's ``cells (ny, nx)`` (its nearest cell centre)."""
    i, j = bathymetry.nearest_cells(north, east)
    return (i >= 0) & cells[np.maximum(i, 0), np.maximum(j, 0)]


def _drift_variance(survey: Survey, model: NavigationModel, duration: float, window: float = 0.0) -> float:
    """The variance (m^2) the drift of the depths' offset (``model.tide_drift``: a Gauss-Markov
    process of std ``sigma`` forgetting over ``tau``) gives a sounding's residual (``window``
    0), or a window's mean residual, less the mean over the survey's ``duration`` (s):
    ``sigma^2 (m(T_w) - m(T))``, ``m(T) = 2 (x - 1 + exp(-x)) / x^2`` (``x = T / tau``) the mean
    of its correlation over a time ``T``, ``T_w`` the window's duration at the survey's median
    speed."""
    if model.tide_drift is None:
        return 0.0
    sigma, tau = model.tide_drift
    pose = survey.true_pose
    assert pose is not None  # the caller's surveys have their reference track
    step = np.hypot(*np.diff(pose[:, :2], axis=0).T)
    dt = np.diff(survey.time)
    moving = (dt > 0) & (step > 0)
    speed = float(np.median(step[moving] / dt[moving])) if moving.any() else 0.0
    seconds = window / speed if window > 0 and speed > 0 else 0.0
    return float(sigma**2 * max(_mean_correlation(seconds / tau) - _mean_correlation(duration / tau), 0.0))


def _mean_correlation(x: float) -> float:
    """The mean of ``exp(-|t - s| / tau)`` over ``t, s`` in a span of ``x tau``."""
    return 1.0 if x < 1e-6 else float(2.0 * (x - 1.0 + np.exp(-x)) / x**2)


def _root(f, low: float, high: float) -> tuple[float, str | None]:
    """The root of a decreasing ``f`` in ``[low, high]``, or the bound it lies beyond (and
    which: ``"lower"``, ``"upper"``)."""
    if f(low) <= 0:
        return low, "lower"
    if f(high) > 0:
        return high, "upper"
    return float(brentq(f, low, high, xtol=1e-4 * max(abs(high - low), 1e-12))), None
