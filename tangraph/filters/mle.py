"""Grid-search maximum-likelihood fixes with dead reckoning between them (Han et al.'s "MLE").

Every ``fix_interval`` pings (default ``window``: consecutive, non-overlapping windows) the
window of the last ``window`` pings is matched against the map by
:func:`tangraph.matching.tap_fix` with criterion ``"mle"`` (Wang et al.'s sigma^2 with the tide
removed: the maximum of the Gaussian likelihood over the search grid), searched around the
current estimate over ``search_sigmas`` times its std (see :mod:`tangraph.filters.fixes`). The
estimate jumps to the fix, with the fix's covariance; between fixes it moves by the dead-reckoned
increments and its covariance grows by the motion model's process noise
(:class:`~tangraph.filters.MotionModel`). Before the first fix the estimate is dead
reckoning from ``N(DR_0, init_std^2 I)``. Only accepted fixes (informative and unimodal,
``TapFix.accepted``) are used by default; ``require_accepted=False`` takes every fix whatever its
quality, as plain MLE does (it can then jump to a wrong basin on flat terrain and search around it
from there on). A window that cannot be matched is skipped.
No particles: ``meta["ess"]`` is NaN and ``n_resampled``, ``n_divergences`` are 0.
"""

from __future__ import annotations

import dataclasses
import time as _time
from typing import Any

import numpy as np

from tangraph.filters.config import check_number
from tangraph.filters.core import step_timings
from tangraph.filters.fixes import attempt_fix, check_fix_search, fix_due, fix_window
from tangraph.filters.model import MotionModel, survey_pings
from tangraph.maps.grid import BathymetryMap
from tangraph.survey import Survey
from tangraph.track import Track

__all__ = ["MLEConfig", "mle_filter"]


@dataclasses.dataclass(frozen=True)
class MLEConfig:
    """Settings of the MLE filter.

    Parameters
    ----------
    init_std : float
        Std (m, per axis) of the initial position around the first dead-reckoned one.
    process_std, process_fraction : float
        Growth of the covariance between fixes (as :class:`~tangraph.filters.MotionModel`).
    window, fix_interval : int or None
        Pings per fix (None: enough for about 30 soundings, at least 5;
        :func:`~tangraph.filters.fixes.fix_window`) and between fixes (None: ``window``).
    search_sigmas, min_half_width, max_half_width : float
        Search half-width: ``search_sigmas`` times the estimate's std, within
        ``[min_half_width (None: the larger of 3 map cells and init_std), max_half_width]`` metres.
    require_accepted : bool
        Use only accepted fixes (informative and unimodal); False: every fix (plain MLE).
    """

    init_std: float = 50.0
    process_std: float = 0.5
    process_fraction: float = 0.1
    window: int | None = None
    fix_interval: int | None = None
    search_sigmas: float = 3.0
    min_half_width: float | None = None
    max_half_width: float = 1000.0
    require_accepted: bool = True

    def __post_init__(self) -> None:
        for name in ("init_std", "process_std", "process_fraction"):
            check_number(self, name)
        check_fix_search(self)
        object.__setattr__(self, "require_accepted", bool(self.require_accepted))

    def as_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


def mle_filter(
    survey: Survey,
    bathymetry: BathymetryMap,
    config: MLEConfig | None = None,
    *,
    rng: np.random.Generator | None = None,
    progress: bool = False,
) -> Track:
    """Run the MLE filter over a survey (deterministic: ``rng`` is not used); see the module
    docstring. ``meta["fixes"]`` records every fix attempted."""
    from tqdm.auto import tqdm

    config = config or MLEConfig()
    motion = MotionModel(config.process_std, config.process_fraction)
    k_total = survey.n_pings
    position = survey.dr_pose[0, :2].copy()
    p = np.eye(2) * config.init_std**2
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
            position = position + ping.increment
            p = p + np.eye(2) * motion.noise_std(ping.increment) ** 2
        if fix_due(config, k, window):
            fix, record = attempt_fix(survey, bathymetry, k, position, p, config, window)
            used = fix is not None and (fix.accepted or not config.require_accepted)
            record["used"] = bool(used)
            fixes.append(record)
            if used:
                position, p = fix.position.copy(), fix.covariance.copy()  # type: ignore[union-attr]
            accepted += int(bool(fix is not None and fix.accepted))
            rejected += int(not (fix is not None and fix.accepted))
        mean[k], cov[k, :2, :2] = position, p
        seconds[k] = _time.perf_counter() - t0
    elapsed = _time.perf_counter() - started
    return Track(
        time=survey.time,
        pose=np.column_stack([mean, survey.dr_pose[:, 2]]),
        covariance=cov,
        method="mle",
        timings=step_timings(elapsed, seconds),
        meta={
            "ess": [float("nan")] * k_total,
            "n_resampled": 0,
            "n_divergences": 0,
            "divergence_steps": [],
            "n_fixes_accepted": accepted,
            "n_fixes_rejected": rejected,
            "n_fixes_used": sum(bool(f["used"]) for f in fixes),
            "fixes": fixes,
            "config": config.as_dict(),
        },
    )
