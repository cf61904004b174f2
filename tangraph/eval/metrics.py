"""Metrics of estimated tracks against the truth: RMSE, final error, NEES and its chi-square band.

Every estimator returns a :class:`~tangraph.track.Track`; these functions compare one with the
true poses of a simulated survey (or a GPS-surveyed ship track). They never touch files.
"""

from __future__ import annotations

import numpy as np
from scipy import stats

from tangraph.errors import TangraphError
from tangraph.eval.crb import CramerRaoBound
from tangraph.geometry import mahalanobis2
from tangraph.track import Track, position_errors

__all__ = ["anees_band", "bound_rmse", "format_figure", "metrics_with_bound", "position_nees",
           "robust_spread", "track_metrics"]


def position_nees(track: Track, true_pose: np.ndarray) -> np.ndarray:
    """Normalised estimation error squared ``e^T P^-1 e`` of each horizontal position, shape (K,).

    NaN where the track's position covariance is unknown (NaN) or not positive definite.

    Examples
    --------
    >>> import numpy as np
    >>> from tangraph.track import Track
    >>> cov = np.tile(np.diag([4.0, 1.0, np.nan]), (2, 1, 1))
    >>> t = Track(time=[0.0, 1.0], pose=[[2.0, 0.0, 0.0], [0.0, 1.0, 0.0]], covariance=cov)
    >>> position_nees(t, np.zeros((2, 3))).tolist()
    [1.0, 1.0]
    """
    true_pose = np.asarray(true_pose, float)
    if true_pose.shape != track.pose.shape:
        raise TangraphError(f"truth has shape {true_pose.shape}, the track {track.pose.shape}")
    e = track.pose[:, :2] - true_pose[:, :2]
    assert track.covariance is not None  # Track.__post_init__ fills it
    p = track.covariance[:, :2, :2]
    a, b, d = p[:, 0, 0], p[:, 0, 1], p[:, 1, 1]
    det = a * d - b * b
    ok = np.isfinite(det) & (det > 0) & (a > 0)
    return np.where(ok, mahalanobis2(e, np.where(ok[:, None, None], p, np.eye(2))), np.nan)


def anees_band(n: int, dof: int = 2, probability: float = 0.95) -> tuple[float, float]:
    """Two-sided ``probability`` band of the average of ``n`` independent chi-square(``dof``) NEES.

    A consistent estimator's ANEES over ``n`` independent samples lies inside it with that
    probability: ``chi2.ppf([a/2, 1 - a/2], n dof) / n``. (Consecutive poses of one track are
    correlated, so over a single track the band is only a guide; over independent runs it is exact.)
    """
    if n < 1:
        raise TangraphError(f"anees_band: n must be at least 1, got {n}")
    a = 1.0 - probability
    lo, hi = stats.chi2.ppf([a / 2, 1 - a / 2], n * dof) / n
    return float(lo), float(hi)


def track_metrics(track: Track, true_pose: np.ndarray, *, skip: int = 0,
                  nees_limit: float = 20.0) -> dict[str, float]:
    """RMSE, mean, median, final and maximum horizontal error (m), ANEES and final NEES of a track.

    Over independent runs, the final NEES values are independent chi-square(2) samples, so their
    mean can be checked against :func:`anees_band` exactly; the ANEES of one track averages
    correlated poses and is a guide only.

    ``lost_fraction`` is the share of poses the estimator flagged as lost (``Track.lost``) and
    ``confident_wrong`` the share of all poses that are not flagged and whose NEES exceeds
    ``nees_limit`` (a confident wrong answer: the estimator neither knew the truth nor said it
    was lost).

    ``skip`` leaves out the first poses (a filter's convergence) from every figure.
    """
    errors = position_errors(track, true_pose)[skip:]
    if errors.size == 0:
        raise TangraphError(f"track_metrics: skip={skip} leaves no pose of {track.n_poses}")
    nees = position_nees(track, true_pose)[skip:]
    known = np.isfinite(nees)
    lost = track.lost[skip:]
    return {
        "lost_fraction": float(np.mean(lost)),
        "confident_wrong": float(np.mean(~lost & (nees > nees_limit))),
        "rmse": float(np.sqrt(np.mean(errors**2))),
        "mean_error": float(np.mean(errors)),
        "median_error": float(np.median(errors)),
        "final_error": float(errors[-1]),
        "max_error": float(np.max(errors)),
        "anees": float(np.mean(nees[known])) if known.any() else float("nan"),
        "final_nees": float(nees[-1]),
        "nees_fraction_known": float(np.mean(known)),
    }


def robust_spread(values, about: float | None = None) -> float:
    """The robust spread of ``values``: their median absolute deviation from their median (or
    from ``about``: 0 for scores centred by construction) scaled to a Gaussian's std
    (``scipy.stats.median_abs_deviation``, ``scale="normal"``, 1.4826 times it); NaN for none.

    >>> round(robust_spread([1.0, 2.0, 3.0, 4.0, 100.0]), 4)
    1.4826
    >>> round(robust_spread([-1.0, 1.0, 3.0], about=0.0), 4)
    1.4826
    """
    values = np.ravel(np.asarray(values, dtype=np.float64))
    if not values.size:
        return float("nan")
    centre = np.median if about is None else (lambda x, axis: float(about))
    return float(stats.median_abs_deviation(values, center=centre, scale="normal"))


def format_figure(value) -> str:
    """A metric for a table: two decimals, scientific beyond 10^4 (a collapsed filter's NEES),
    empty where unknown (NaN); anything else as ``str``.

    Examples
    --------
    >>> [format_figure(v) for v in (3.14159, 2.5e33, float("nan"), "pf")]
    ['3.14', '2.5e+33', '', 'pf']
    """
    if not isinstance(value, float | np.floating):
        return str(value)
    if not np.isfinite(value):
        return ""
    return f"{value:.2f}" if abs(float(value)) < 1e4 else f"{value:.1e}"


def bound_rmse(bound: CramerRaoBound, skip: int = 0) -> float:
    """The bound's horizontal RMSE, ``sqrt(mean over pings of trace(position_cov))``, m.

    The figure to set next to an estimator's position RMSE (``track_metrics(...)["rmse"]``, with
    the same ``skip``): their ratio ``RMSE / PCRB`` is at least about 1 for any estimator.

    Examples
    --------
    >>> import numpy as np
    >>> bound = CramerRaoBound(np.tile(np.diag([3.0, 1.0]), (4, 1, 1)), np.eye(2), 0.1, "filter")
    >>> bound_rmse(bound)
    2.0
    """
    if not isinstance(bound, CramerRaoBound):
        raise TangraphError(f"bound_rmse: bound must be a CramerRaoBound, got {type(bound).__name__}")
    skip = int(skip)
    if not 0 <= skip < bound.n_pings:
        raise TangraphError(f"bound_rmse: skip={skip} leaves no ping of {bound.n_pings}")
    trace = np.trace(bound.position_cov[skip:], axis1=1, axis2=2)
    return float(np.sqrt(max(float(np.mean(trace)), 0.0)))


def metrics_with_bound(metrics: dict[str, float], bound: CramerRaoBound, *,
                       skip: int = 0) -> dict[str, float]:
    """A copy of :func:`~tangraph.eval.track_metrics` figures with ``pcrb`` (the bound's RMSE,
    :func:`bound_rmse`) and ``rmse_over_pcrb`` added; ``skip`` must be the one the metrics used.

    Examples
    --------
    >>> import numpy as np
    >>> bound = CramerRaoBound(np.tile(np.diag([3.0, 1.0]), (4, 1, 1)), np.eye(2), 0.1, "smoother")
    >>> metrics_with_bound({"rmse": 3.0}, bound)
    {'rmse': 3.0, 'pcrb': 2.0, 'rmse_over_pcrb': 1.5}
    """
    if "rmse" not in metrics:
        raise TangraphError("metrics_with_bound: the metrics have no 'rmse' (use track_metrics)")
    pcrb = bound_rmse(bound, skip)
    ratio = float(metrics["rmse"]) / pcrb if pcrb > 0 else float("inf")
    return {**metrics, "pcrb": pcrb, "rmse_over_pcrb": ratio}
