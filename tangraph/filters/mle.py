"""Grid-search maximum-likelihood fixes with dead reckoning between them (Han et al.'s "MLE").

Every ``fix_interval`` pings (default ``window``: consecutive, non-overlapping windows) the
window of the last ``window`` pings is matched against the map by
:func:`tangraph.matching.tap_fix` with criterion ``"mle"`` (Wang et al.'s sigma^2 with the tide
removed: the maximum of the Gaussian likelihood over the search grid), searched around the
current estimate over ``search_sigmas`` times its std (see :mod:`tangraph.filters.fixes`). The
estimate jumps to the fix, with the fix's covariance; between fixes it moves by the dead-reckoned
increments calibrated by the prior mean ``(k, b)`` of the navigation model, and its covariance
is propagated to first order on ``(north, east, k, b)``: the white DR errors
(:class:`~tangraph.filters.MotionModel`), the heading walk, and the prior uncertainty of the
constant errors, which turns and stretches every step alike (so the position error it causes
grows with the distance run, not its square root). A fix resets the position covariance and its
correlation with ``(k, b)``; the calibration itself is not estimated (``meta["calibration"]`` is
the prior, its heading std grown by the walk). Before the first fix the estimate is dead
reckoning from ``N(DR_0, s^2 I)``, ``s`` the model's ``initial_position_std``. Only accepted
fixes (informative and unimodal, ``TapFix.accepted``) are used by default;
``require_accepted=False`` takes every fix whatever its quality, as plain MLE does (it can
then jump to a wrong basin on flat terrain and search around it from there on). A window that
cannot be matched is skipped. No particles: ``meta["ess"]`` is NaN and ``n_resampled``,
``n_divergences``, ``n_lost`` are 0.
"""

from __future__ import annotations

import dataclasses
import time as _time
from typing import Any

import numpy as np

from tangraph.filters.fixes import attempt_fix, check_fix_search, fix_due, fix_window
from tangraph.filters.model import MotionModel, survey_pings
from tangraph.filters.runner import check_run_inputs, step_timings
from tangraph.geometry import rotate
from tangraph.maps.grid import BathymetryMap
from tangraph.sensors import NavigationModel, survey_navigation_model
from tangraph.survey import Survey
from tangraph.track import Track

__all__ = ["MLEConfig", "mle_filter"]


@dataclasses.dataclass(frozen=True)
class MLEConfig:
    """Settings of the MLE filter.

    Parameters
    ----------
    window, fix_interval : int or None
        Pings per fix (None: enough for about 30 soundings, at least 5;
        :func:`~tangraph.filters.fixes.fix_window`) and between fixes (None: ``window``).
    search_sigmas, min_half_width, max_half_width : float
        Search half-width: ``search_sigmas`` times the estimate's std, within
        ``[min_half_width (None: the larger of 3 map cells and the model's initial_position_std),
        max_half_width]`` metres.
    require_accepted : bool
        Use only accepted fixes (informative and unimodal); False: every fix (plain MLE).
    """

    window: int | None = None
    fix_interval: int | None = None
    search_sigmas: float = 3.0
    min_half_width: float | None = None
    max_half_width: float = 1000.0
    require_accepted: bool = True

    def __post_init__(self) -> None:
        check_fix_search(self)
        object.__setattr__(self, "require_accepted", bool(self.require_accepted))

    def as_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def _propagate(p: np.ndarray, step: np.ndarray, k: float, noise: np.ndarray, walk_var: float) -> np.ndarray:
    """Covariance ``(4, 4)`` of ``(north, east, k, b)`` after a calibrated step ``step``."""
    f = np.eye(4)
    f[:2, 2] = -step / (1.0 + k)  # d step / d k
    f[:2, 3] = -np.array([-step[1], step[0]])  # d R(-b) u / d b
    q = np.zeros((4, 4))
    q[:2, :2] = noise
    q[3, 3] = walk_var
    return f @ p @ f.T + q


def mle_filter(
    survey: Survey,
    bathymetry: BathymetryMap,
    config: MLEConfig | None = None,
    *,
    model: NavigationModel | None = None,
    rng: np.random.Generator | None = None,
    progress: bool = False,
) -> Track:
    """Run the MLE filter over a survey (deterministic: ``rng`` is not used); ``model`` is the
    navigation model (None: ``NavigationModel.from_survey(survey)``). See the module docstring.
    ``meta["fixes"]`` records every fix attempted; ``meta["calibration"]`` is the model's prior
    (not estimated)."""
    from tqdm.auto import tqdm

    check_run_inputs(survey, bathymetry, rng, where="mle", rng_optional=True)
    config = config or MLEConfig()
    navigation = survey_navigation_model(survey, model, where="mle")
    motion = MotionModel.from_model(navigation)
    k_prior, b_prior = navigation.calibration_prior
    k_total = survey.n_pings
    position = survey.dr_pose[0, :2].copy()
    p = np.diag([navigation.initial_position_std**2] * 2 + list(navigation.calibration_std**2))
    mean = np.empty((k_total, 2))
    cov = np.full((k_total, 3, 3), np.nan)
    seconds = np.empty(k_total)
    fixes: list[dict[str, Any]] = []
    accepted = rejected = 0
    window = fix_window(config, survey)
    started = _time.perf_counter()
    for ping in tqdm(survey_pings(survey), disable=not progress, desc="mle", unit="ping", leave=False):
        t0 = _time.perf_counter()
        k = ping.index
        if not ping.first:
            step = rotate(-b_prior, ping.increment) / (1.0 + k_prior)
            position = position + step
            walk = navigation.heading_walk**2 * ping.dt
            p = _propagate(p, step, k_prior, motion.noise_covariance(ping), walk)
        if fix_due(config, k, window):
            fix, record = attempt_fix(
                survey, bathymetry, k, position, p[:2, :2], config, window,
                initial_std=navigation.initial_position_std, model=navigation,
            )  # fmt: skip
            used = fix is not None and (fix.accepted or not config.require_accepted)
            record["used"] = bool(used)
            fixes.append(record)
            if used:
                position = fix.position.copy()  # type: ignore[union-attr]
                p[:2, :2] = fix.covariance  # type: ignore[union-attr]
                p[:2, 2:] = 0.0
                p[2:, :2] = 0.0
            accepted += int(bool(fix is not None and fix.accepted))
            rejected += int(not (fix is not None and fix.accepted))
        mean[k], cov[k, :2, :2] = position, p[:2, :2]
        seconds[k] = _time.perf_counter() - t0
    elapsed = _time.perf_counter() - started
    return Track(
        time=survey.time,
        pose=np.column_stack([mean, survey.dr_pose[:, 2]]),
        covariance=cov,
        method="mle",
        timings=step_timings(elapsed, seconds),
        meta=_meta(navigation, config, p, fixes, accepted, rejected, k_total),
    )


def _meta(navigation: NavigationModel, config: MLEConfig, p: np.ndarray, fixes: list[dict[str, Any]],
          accepted: int, rejected: int, k_total: int) -> dict[str, Any]:
    """The MLE track's ``meta``: the filters' keys (no particles: nothing resampled, never lost),
    the fixes and the calibration, the model's prior with the final covariance ``p``'s stds."""
    k_prior, b_prior = navigation.calibration_prior
    calibration = {
        "speed_scale": float(k_prior),
        "speed_scale_std": float(np.sqrt(p[2, 2])),
        "heading_error": float(b_prior),
        "heading_error_std": float(np.sqrt(p[3, 3])),
    }
    return {
        "ess": [float("nan")] * k_total,
        "n_resampled": 0,
        "n_divergences": 0,
        "divergence_steps": [],
        "n_lost": 0,
        "lost_steps": [],
        "calibration": calibration,
        "n_fixes_accepted": accepted,
        "n_fixes_rejected": rejected,
        "n_fixes_used": sum(bool(f["used"]) for f in fixes),
        "fixes": fixes,
        "navigation_model": navigation.as_dict(),
        "config": config.as_dict(),
    }
