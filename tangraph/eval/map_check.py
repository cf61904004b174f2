"""Does a gridded map's stated error hold? Check lines: each survey against a map of the others.

Hydrographers validate a survey's uncertainty with *check lines*: soundings that did not make the
surface are compared with it (IHO S-44). :func:`check_map_error` does this for a map gridded from
several surveys (days, lines): each survey in turn is held out, the others are gridded with the
same settings (:func:`tangraph.maps.gridding.grid_surveys`, which gives the map its error), and the
held-out soundings, placed at their reference track, are compared with that map in windows of
track.

What is compared is what the estimators lean on. A window's mean residual ``mean(z - h)`` has,
under the terrain measurement model (:mod:`tangraph.sensors.terrain`), the variance

    ``(n sounding_std^2 + sum_fields sum_ij a_i a_j rho(|p_i - p_j|)) / n^2``

(exact for the mean: the row sums of the window's dense covariance, added up), so its
standardised value ``t`` is N(0, 1) where the map errs as it says. Each survey's median
residual is removed first (its datum or tide offset, which the estimators estimate). The check
reports the RMS of ``t`` (1 when the stated error holds; a Gaussian fitted to the map's real
window errors has its std that many times the stated one), a robust scale of ``t`` (the median
``|t|`` over its normal value: the bulk of the windows) and the share of windows with
``|t| > 3`` (0.27 % for a Gaussian). An RMS far above the robust scale says the map's error is
heavy-tailed: most of the map is as good as it says, a few patches are far worse; the Student-t
that fits the scores best says how heavy (:meth:`MapCheck.tail`: its scale, and its degrees of
freedom ``MapCheck.misfit_dof``). The held-out survey's own position error adds to ``t`` (the
slope times the GPS error), so the check errs on the side of finding the map worse than it is.

:func:`calibrate_error` gives a gridded map the error its check lines found: its ``depth_std``
times the Student-t's scale and, when the tail is heavier than a Gaussian's, the Student-t's
degrees of freedom as the map's ``error_dof``, which the filters' local misfit scale takes as
its prior (:mod:`tangraph.sensors.misfit`: the error of most of the map as stated, a patch's
several times it). A Gaussian tail gives the scale of the RMS (the variance the windows really
show). A map is never made better than its gridding says: the scale is at least 1.

Windows mix the map's measured cells with its filled gaps, whose error the gridding states
differently (:mod:`tangraph.maps.gridding_error`). :func:`cell_scores` scores the held-out
soundings one by one and tells which kind of cell each lies in; :meth:`MapCheck.by_cell` and
:func:`cells_summary` give each kind's robust spread of the residuals and of the standardised
residuals (1 where the statement holds there).

Nothing here touches files.
"""

from __future__ import annotations

import dataclasses
import itertools
from collections.abc import Sequence
from typing import Literal, cast

import numpy as np

from tangraph.errors import TangraphError
from tangraph.eval.metrics import robust_spread
from tangraph.eval.windows import window_residuals, window_scores
from tangraph.geometry import wrap_angle
from tangraph.sensors.navigation_model import NavigationModel
from tangraph.survey import Survey

__all__ = ["MapCheck", "calibrate_error", "cell_scores", "cells_summary", "check_map_error", "survey_lines",
           "window_scores"]

MIN_WINDOWS = 10  # a calibration rests on at least this many windows
DRIFT_P_VALUE = 0.01  # a map states the drift its check lines found when the F test gives less
_MAX_DOF = 100.0  # a Student-t of more degrees of freedom than this is a Gaussian here
_GAUSSIAN_TEST = 2.705543454095404  # 2 log-likelihood ratio of the Student-t over the Gaussian, at 5 %
TURN = np.deg2rad(30.0)  # a line ends where the course has turned this far from its start


@dataclasses.dataclass(frozen=True)
class MapCheck:
    """The check-line statistics of a gridded map (:func:`check_map_error`): the standardised
    window mean residuals ``scores`` of every held-out survey (``survey (W,)`` says whose, by its
    index), and the window length (m)."""

    scores: np.ndarray
    survey: np.ndarray
    names: tuple[str, ...]
    window: float
    time: np.ndarray | None = None  #: each window's mean time (s), with ``mean`` and ``variance``
    mean: np.ndarray | None = None  #: each window's mean residual (m), its survey's median removed
    variance: np.ndarray | None = None  #: the variance (m^2) the stated errors give ``mean``
    #: every held-out sounding's ``(residual, stated std, measured)`` (:func:`cell_scores`)
    cells: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None

    @property
    def windows(self) -> int:
        """How many windows were scored."""
        return int(self.scores.size)

    def by_cell(self) -> dict[str, dict[str, float]]:
        """The held-out soundings one by one, in the cells with data and in the filled cells
        (:func:`cells_summary`); empty without them."""
        return cells_summary(*self.cells) if self.cells is not None else {}

    @property
    def rms(self) -> float:
        """The RMS of the scores: 1 when the map errs as it says; the factor by which the
        stated std would have to grow for a Gaussian of the same variance (NaN: no window)."""
        return float(np.sqrt(np.mean(self.scores**2))) if self.scores.size else float("nan")

    @property
    def robust(self) -> float:
        """The median ``|score|`` over its Gaussian value (0.6745): the scale of the bulk
        (:func:`~tangraph.eval.metrics.robust_spread` about 0)."""
        return robust_spread(self.scores, about=0.0)

    @property
    def share_beyond_3(self) -> float:
        """The share of windows with ``|score| > 3`` (0.0027 for a Gaussian)."""
        return float(np.mean(np.abs(self.scores) > 3.0)) if self.scores.size else float("nan")

    @property
    def misfit_dof(self) -> float:
        """The degrees of freedom of the Student-t that fits the scores best (:meth:`tail`): the
        tail of the map's error the check lines support, the map's ``error_dof``
        (:mod:`tangraph.sensors.misfit`: a patch's error scale shared by its soundings, whose
        mixture over patches is that Student-t); ``inf`` when a Gaussian tail fits as well, NaN
        with no window."""
        return self.tail()[1]

    def tail(self) -> tuple[float, float]:
        """``(scale, dof)``: the Student-t that fits the scores best by maximum likelihood, its
        scale never below 1 (a map is never made better than its gridding says: where the bulk
        of the scores is narrower, the degrees of freedom are fitted at scale 1). ``dof`` is
        ``inf`` when a Gaussian fits as well (the likelihood-ratio test of the Gaussian at 5 %,
        on the boundary: half a chi-square(1), 2.71, at the scale kept; the scale is then the
        RMS, at least 1);
        ``(NaN, NaN)`` with no window."""
        if not self.scores.size:
            return float("nan"), float("nan")
        from scipy import optimize, stats

        scores = self.scores

        def cost(x: np.ndarray) -> float:
            return -float(np.sum(stats.t.logpdf(scores, np.exp(x[0]), scale=np.exp(x[1]))))

        low, high = np.log(0.2), np.log(_MAX_DOF)
        start = np.array([np.log(4.0), np.log(max(self.robust, 1e-3))])
        best = optimize.minimize(cost, start, method="L-BFGS-B", bounds=[(low, high), (-7.0, 7.0)])
        dof, scale = float(np.exp(best.x[0])), float(np.exp(best.x[1]))
        gaussian = -float(np.sum(stats.norm.logpdf(scores, scale=max(self.rms, 1e-12))))
        if dof > 0.99 * _MAX_DOF or 2.0 * (gaussian - best.fun) < _GAUSSIAN_TEST:
            return max(1.0, self.rms), float("inf")
        if scale < 1.0:  # the bulk better than stated: the tail at the stated scale, tested there
            unit = optimize.minimize_scalar(lambda x: cost(np.array([x, 0.0])), bounds=(low, high),
                                            method="bounded", options={"xatol": 1e-4})
            dof, scale = float(np.exp(unit.x)), 1.0
            if 2.0 * (-float(np.sum(stats.norm.logpdf(scores))) - unit.fun) < _GAUSSIAN_TEST:
                return 1.0, float("inf")
        if dof > 0.99 * _MAX_DOF:
            return max(1.0, self.rms), float("inf")
        return scale, dof

    def drift(self, *, max_lag: int = 12) -> dict[str, float]:
        """How the held-out surveys' window mean residuals drift along their tracks: ``m_i`` and
        ``m_j``, ``l`` windows apart in one survey, differ by

            ``E[(m_i - m_j)^2] = c^2 (v_i + v_j) + 2 s^2 (1 - exp(-|t_i - t_j| / T))``,

        the map's error at a scale ``c`` of its stated variances ``v`` (independent from window to
        window: the part the gridding states) and an offset of std ``s`` shared by windows less
        than about ``T`` seconds apart (an error of the map that holds over a stretch of track,
        the water level, the sound speed). For each lag ``l`` up to ``max_lag`` the pairs' mean
        square is taken robustly (their median ``|m_i - m_j|`` over the Gaussian 0.6745, as
        :attr:`robust`: the map's heavy-tailed patches do not pass for a drift) and ``(c^2, s^2,
        T)`` are fitted to the lags by least squares in relative error. Returns ``scale`` (``c``),
        ``std`` (``s``, m) and ``time`` (``T``, s), the ``NavigationModel.tide_drift_std`` and
        ``tide_drift_time`` the check lines support, and ``walk`` (m per sqrt(s)), how fast the
        drift parts windows at first, ``sqrt(2 s^2 / T)`` (the figure that is well determined
        when ``T`` is not: a drift slower than the surveys' windows span), and ``p_value``, the F
        test of the fit against the map's error alone (``s = 0``; small: the lags need the drift).
        NaN without the windows' times or with fewer than 10 pairs at each of three lags (four
        for ``p_value``)."""
        nan = {"scale": float("nan"), "std": float("nan"), "time": float("nan"), "walk": float("nan"),
               "p_value": float("nan")}
        if self.time is None or self.mean is None or self.variance is None:
            return nan
        from scipy import stats
        from scipy.optimize import least_squares

        rows = []
        for lag in range(1, max_lag + 1):
            gap, step, stated = [], [], []
            for i in np.unique(self.survey):
                own = self.survey == i
                t, m, v = self.time[own], self.mean[own], self.variance[own]
                if t.size > lag:
                    gap.append(np.abs(t[lag:] - t[:-lag]))
                    step.append(np.abs(m[lag:] - m[:-lag]))
                    stated.append(v[lag:] + v[:-lag])
            if gap and sum(g.size for g in gap) >= 10:
                rows.append((np.median(np.concatenate(gap)), (np.median(np.concatenate(step)) / 0.6745) ** 2,
                             np.median(np.concatenate(stated))))
        if len(rows) < 3:
            return nan
        gap_s, square, stated_v = (np.array(c) for c in zip(*rows, strict=True))

        def misfit(x: np.ndarray) -> np.ndarray:
            c2, s2, log_t = x
            return (c2 * stated_v + 2.0 * s2 * -np.expm1(-gap_s / np.exp(log_t))) / square - 1.0

        span = (np.log(2.0 * gap_s.min()), np.log(1e3 * gap_s.max()))  # a drift spans windows
        start = np.array([0.5 * square.min() / stated_v.mean(), 0.5 * square.max(), np.log(np.median(gap_s))])
        fit = least_squares(misfit, start, bounds=([0.0, 0.0, span[0]], [np.inf, np.inf, span[1]]))
        c2, s2, log_t = fit.x
        ratio = stated_v / square  # the map's error alone: its best c^2, in closed form
        alone = float(np.sum((np.sum(ratio) / np.sum(ratio**2) * ratio - 1.0) ** 2))
        full, dof = 2.0 * float(fit.cost), gap_s.size - 3
        gain = max(alone - full, 0.0)  # what the drift explains
        p_value = float("nan") if dof < 1 else float(gain <= 0) if full <= 0 else \
            float(stats.f.sf(gain / 2.0 / (full / dof), 2, dof))
        return {"scale": float(np.sqrt(c2)), "std": float(np.sqrt(s2)), "time": float(np.exp(log_t)),
                "walk": float(np.sqrt(2.0 * s2 / np.exp(log_t))), "p_value": p_value}

    def per_survey(self) -> list[dict]:
        """One row per held-out survey: name, windows, RMS, robust scale, share beyond 3."""
        rows = []
        for i, name in enumerate(self.names):
            part = dataclasses.replace(self, scores=self.scores[self.survey == i],
                                       survey=self.survey[self.survey == i], time=None, mean=None,
                                       variance=None)
            rows.append({"survey": name, "windows": part.windows, "rms": part.rms,
                         "robust": part.robust, "share_beyond_3": part.share_beyond_3})
        return rows

    def summary(self) -> str:
        """One line: windows, RMS, robust scale, share beyond 3 sigma, the best Student-t."""
        scale, dof = self.tail()
        return (f"{self.windows} windows of {self.window:g} m: RMS {self.rms:.2f}, robust "
                f"{self.robust:.2f}, {100 * self.share_beyond_3:.1f} % beyond 3 (1, 1 and 0.3 % when the "
                f"map's error is as stated); a Student-t of scale {scale:.2f} and {dof:.2g} degrees of "
                "freedom fits best")


def survey_lines(survey: Survey, *, min_length: float = 50.0) -> list[Survey]:
    """The lines of a survey (:meth:`Survey.pings` each): stretches of its reference track
    whose course stays within ``TURN`` of the course it started on, at least ``min_length`` m
    long (turns and short legs are left out), numbered in ``meta["line"]``.

    Raises
    ------
    TangraphError
        A survey without a reference track.
    """
    from tangraph.survey import SurveyError

    if survey.true_pose is None:
        raise TangraphError(f"survey {survey.meta.get('name', '')!r}: no reference track to split into lines")
    step = np.diff(survey.true_pose[:, :2], axis=0)
    length = np.hypot(*step.T)
    course = np.arctan2(step[:, 1], step[:, 0])
    starts, reference = [0], None
    for i in range(course.size):
        if length[i] == 0:
            continue
        if reference is not None and abs(wrap_angle(course[i] - reference)) > TURN:
            starts.append(i + 1)
            reference = None
        if reference is None:
            reference = course[i]
    bounds = [*starts, survey.n_pings]
    lines: list[Survey] = []
    for a, b in itertools.pairwise(bounds):
        if b - a < 2 or np.sum(length[a:b - 1]) < min_length:
            continue
        try:
            part = survey.pings(a, b)
        except SurveyError:  # a stretch without soundings
            continue
        lines.append(part.replace(meta={**part.meta, "line": len(lines)}))
    return lines


def check_map_error(
    surveys: Sequence[Survey], *, cell: float, statistic: str = "median", fill: int = 0,
    model: NavigationModel | None = None, window: float = 50.0, names: Sequence[str] | None = None,
    progress=None, lines: bool = False, position_std: float = 0.0,
) -> MapCheck:
    """Hold out each survey in turn, grid the others (``cell``, ``statistic``, ``fill`` as
    :func:`~tangraph.maps.gridding.grid_surveys`, and ``position_std``, the surveys' positioning
    std) and score the held-out soundings against that
    map in windows of ``window`` m (:func:`window_scores`; the module docstring says what the
    figures mean). ``model`` gives the sounding std (default: a :class:`NavigationModel`'s);
    the map's error is the gridded map's own. ``progress(i, n)`` is called after each survey.
    With ``lines`` each survey is first split into its lines (:func:`survey_lines`), each held
    out in turn against the map of all the others: the check of a map gridded from one survey.

    Raises
    ------
    TangraphError
        Fewer than two surveys, a survey without a reference track or given twice, ``window <= 0``,
        no window of a held-out survey on the map of the others.
    """
    from tangraph.gridding_surveys import check_distinct, grid_surveys
    from tangraph.map_frame import in_map_frame

    surveys = list(surveys)
    if not (np.isfinite(window) and window > 0):
        raise TangraphError(f"check_map_error: window must be > 0 m, got {window!r}")
    if names is not None and len(names) != len(surveys):
        raise TangraphError(f"check_map_error: {len(names)} names for {len(surveys)} surveys")
    names = list(names) if names is not None else [
        str(s.meta.get("name") or f"survey {i}") for i, s in enumerate(surveys)]
    if lines:
        split = [(f"{name} line {line.meta['line']}", line)
                 for name, survey in zip(names, surveys, strict=True)
                 for line in survey_lines(survey, min_length=window)]
        names, surveys = [name for name, _ in split], [line for _, line in split]
    if len(surveys) < 2:
        what = "lines of at least one window" if lines else "surveys"
        hint = "" if lines else " (one survey: split it into its lines, lines=True, CLI --lines)"
        raise TangraphError(f"check_map_error: needs at least two {what} (one held out, the others "
                            f"gridded), got {len(surveys)}{hint}")
    names = tuple(names)
    check_distinct(surveys, names, "check_map_error")
    model = NavigationModel() if model is None else model
    columns: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    cells: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    owner = []
    for i, held in enumerate(surveys):
        if held.true_pose is None:
            raise TangraphError(f"check_map_error: survey {names[i]!r} has no reference track (true_pose)")
        others = [s for j, s in enumerate(surveys) if j != i]
        grid = grid_surveys(others, cell=cell, fill=fill, name=f"without {names[i]}",
                            statistic=cast(Literal["mean", "median"], statistic), position_std=position_std)
        placed = in_map_frame(held, grid.depth)
        columns.append(window_residuals(placed, grid.depth, model, window=window))
        cells.append(cell_scores(placed, grid, model))
        owner.append(np.full(columns[-1][0].size, i))
        if progress is not None:
            progress(i + 1, len(surveys))
    time, mean, variance = (np.concatenate([c[k] for c in columns]) for k in range(3))
    if not mean.size:
        raise TangraphError(f"check_map_error: no window of {window:g} m of a held-out survey lies on the "
                            "map of the others (the surveys do not cross, or are shorter than a window): "
                            "surveys that overlap, or a shorter window")
    return MapCheck(mean / np.sqrt(variance), np.concatenate(owner), names, float(window), time, mean,
                    variance, tuple(np.concatenate([c[k] for c in cells]) for k in range(3)))  # type: ignore[arg-type]


def cell_scores(survey: Survey, grid, model: NavigationModel) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every sounding of ``survey`` (at its reference track, in the frame of ``grid``, a
    :class:`~tangraph.maps.SoundingGrid`) against the grid's map one by one: its residual less
    the survey's median (m), the std the map states there with the model's sounding noise (m),
    and whether its cell holds soundings (else the gap fill made it); soundings off the map's
    data are left out. The marginal check of the map's statement, where the windows of
    :func:`check_map_error` test what the soundings share."""
    from tangraph.sensors.terrain import map_error

    if survey.true_pose is None:
        raise TangraphError(f"cell_scores: survey {survey.meta.get('name', '')!r} has no reference track "
                            "(true_pose) to score the map with")
    bathymetry = grid.depth
    north, east = survey.footprints(survey.true_pose)
    residual = survey.beam_depth - bathymetry.depth_at(north, east)
    std = map_error(bathymetry, model).std_at(north, east)
    i, j = bathymetry.nearest_cells(north, east)
    ok = np.isfinite(residual) & np.isfinite(std) & (i >= 0)
    if not ok.any():
        return np.empty(0), np.empty(0), np.empty(0, dtype=bool)
    measured = grid.count[i[ok], j[ok]] > 0
    stated = np.sqrt(std[ok] ** 2 + float(model.sounding_std) ** 2)
    return residual[ok] - np.median(residual[ok]), stated, measured


def cells_summary(residual: np.ndarray, std: np.ndarray, measured: np.ndarray) -> dict[str, dict[str, float]]:
    """Per kind of cell (``"data_cells"``, ``"filled_cells"``) of soundings scored by
    :func:`cell_scores`: how many, the robust spread of their residuals (m: 1.4826 times the
    median absolute deviation), the median std stated and the robust spread of the residuals
    over it (1 where the statement holds; the factor its std would have to take)."""

    out = {}
    for kind, sel in (("data_cells", measured), ("filled_cells", ~measured)):
        r, s = residual[sel], std[sel]
        out[kind] = {"soundings": int(sel.sum()), "robust_residual_m": round(robust_spread(r), 4),
                     "median_std_m": round(float(np.median(s)), 4) if s.size else float("nan"),
                     "robust_z": round(robust_spread(r / s), 3) if s.size else float("nan")}
    return out


def calibrate_error(grid, check: MapCheck):
    """The :class:`~tangraph.maps.SoundingGrid` ``grid`` with the error its check lines found:
    the Student-t that fits their scores best (:meth:`MapCheck.tail`), its scale the grid's
    ``error_scale`` and its degrees of freedom the ``error_dof`` (None, with the RMS as the
    scale, when a Gaussian fits as well), its ``error_drift`` the drift along a track
    (:meth:`MapCheck.drift`'s ``(std, time)``, when its F test's p-value is below
    ``DRIFT_P_VALUE``; else None), the check's figures kept in its ``meta["check_lines"]``.

    Raises
    ------
    TangraphError
        A check of fewer than ``MIN_WINDOWS`` windows (the held-out surveys hardly overlap the
        others' maps).
    """
    if check.windows < MIN_WINDOWS:
        raise TangraphError(
            f"calibrate_error: the check lines scored {check.windows} windows of {check.window:g} m, fewer "
            f"than {MIN_WINDOWS}: too few to calibrate the map's error with (surveys that overlap more, or "
            "a shorter window)")
    scale, dof = check.tail()
    drift = check.drift()
    figures = {"windows": check.windows, "window_m": check.window, "rms": round(check.rms, 4),
               "robust": round(check.robust, 4), "share_beyond_3": round(check.share_beyond_3, 4),
               "misfit_dof": round(dof, 4), "scale": round(scale, 4)}
    if np.isfinite(drift["walk"]):
        figures |= {"drift_" + k: round(v, 6) for k, v in drift.items()}
    drifts = drift["p_value"] < DRIFT_P_VALUE and drift["std"] > 0
    return dataclasses.replace(grid, error_scale=scale, error_dof=dof if np.isfinite(dof) else None,
                               error_drift=(drift["std"], drift["time"]) if drifts else None,
                               meta={**grid.meta, "check_lines": figures})
