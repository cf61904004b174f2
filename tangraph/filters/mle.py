"""Grid-search maximum-likelihood fixes with dead reckoning between them (Han et al.'s "MLE").

Every ``fix_interval`` pings (default ``window``: consecutive, non-overlapping windows) the
window of the last ``window`` pings is matched against the map by
:func:`tangraph.matching.tap_fix` with criterion ``"mle"`` (Wang et al.'s sigma^2 with the tide
removed: the maximum of the Gaussian likelihood over the search grid), searched around the
current estimate over ``search_sigmas`` times its std (see :mod:`tangraph.filters.fixes`).
The state is ``(north, east, k, b)``: between fixes it moves by the dead-reckoned increments
calibrated by its ``(k, b)``, and its covariance is propagated to first order: the white DR
errors (:class:`~tangraph.filters.model.MotionModel`), the heading walk, and the uncertainty of the
constant errors, which turns and stretches every step alike (so the position error it causes
grows with the distance run, not its square root). Before the first fix it is dead reckoning
from ``N(DR_0, s^2 I)``, ``s`` the model's ``initial_position_std``, and the model's calibration
prior.

Only accepted fixes (informative and unimodal, ``TapFix.accepted``) are used by default, and a
surprising one only once a later one confirms it (:func:`tangraph.filters.fixes.decide_fix`;
the displacement between the two is the DR's, its covariance propagated as above from the
calibration's alone); ``Track.fixes`` holds each fix's
:class:`~tangraph.fix_records.FixRecord` (what became of it, its NIS against the prediction). A
fix that is used updates the state as a measurement of the position (a Kalman update, so a vague
fix does not throw away a better prediction and the constant errors are learnt through their
correlation with the position); a confirmed one, which says the
prediction is wrong, replaces the position and its covariance. ``fuse=False`` jumps to every fix
used, ``require_accepted=False`` and ``confirm_probability=None`` take every fix as it comes:
the three together are plain MLE (it can then jump to a wrong basin on flat terrain or where the
map is wrong, and search around it from there on). A window that cannot be matched is skipped.
No particles: ``meta["ess"]`` is NaN and ``n_resampled``, ``n_divergences``, ``n_lost`` are 0.
"""

from __future__ import annotations

import dataclasses
import time as _time
from typing import Any

import numpy as np

from tangraph.filters.fixes import (
    HeldFix,
    attempt_fix,
    check_fix_search,
    decide_fix,
    decided,
    expired,
    fix_due,
    fix_window,
    waited,
)
from tangraph.filters.model import MotionModel, survey_pings
from tangraph.filters.runner import check_run_inputs, step_timings
from tangraph.fix_records import FixRecord
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
    confirm_probability : float or None
        A fix whose NIS against the prediction exceeds the ``chi2(2)`` quantile of this
        probability is held until a later one confirms it (:func:`~tangraph.filters.fixes.decide_fix`);
        None: every fix is used at once.
    gate : float
        The NIS, under both fixes' covariances and the DR displacement's, within which a later
        surprising fix confirms a held one (default: ``chi2(2)`` at 0.999).
    fuse : bool
        A fix that is used updates the prediction as a measurement of the position (a Kalman
        update of ``(north, east, k, b)``, so the constant DR errors are learnt); False: the
        estimate jumps to the fix, as Han et al.'s MLE does.
    """

    window: int | None = None
    fix_interval: int | None = None
    search_sigmas: float = 3.0
    min_half_width: float | None = None
    max_half_width: float = 1000.0
    require_accepted: bool = True
    confirm_probability: float | None = 0.9
    gate: float = 13.8
    fuse: bool = True

    def __post_init__(self) -> None:
        check_fix_search(self)
        object.__setattr__(self, "require_accepted", bool(self.require_accepted))
        object.__setattr__(self, "fuse", bool(self.fuse))

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


def _update(x: np.ndarray, p: np.ndarray, fix, fuse: bool) -> tuple[np.ndarray, np.ndarray]:
    """The state ``x = (north, east, k, b)`` and its covariance after a fix that is used: a
    Kalman update by the fix as a measurement of the position (``fuse``; Joseph form), or a
    jump to it (its position and covariance, no correlation with ``(k, b)`` left)."""
    x, p = x.copy(), p.copy()
    if not fuse:
        x[:2], p[:2, :2], p[:2, 2:], p[2:, :2] = fix.position, fix.covariance, 0.0, 0.0
        return x, p
    gain = np.linalg.solve(p[:2, :2] + fix.covariance, p[:2, :]).T  # (4, 2): P H^T S^-1
    x = x + gain @ (fix.position - x[:2])
    a = np.eye(4)
    a[:, :2] -= gain
    p = a @ p @ a.T + gain @ fix.covariance @ gain.T
    return x, 0.5 * (p + p.T)


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
    ``Track.fixes`` records every fix attempted; ``meta["calibration"]`` the estimate of the
    constant DR errors (the model's prior when ``fuse`` is False)."""
    from tqdm.auto import tqdm

    check_run_inputs(survey, bathymetry, rng, where="mle", rng_optional=True)
    config = config or MLEConfig()
    navigation = survey_navigation_model(survey, model, where="mle", bathymetry=bathymetry)
    motion = MotionModel.from_model(navigation)
    k_total = survey.n_pings
    x = np.array([*survey.dr_pose[0, :2], *navigation.calibration_prior], float)  # (north, east, k, b)
    p = np.diag([navigation.initial_position_std**2] * 2 + list(navigation.calibration_std**2))
    mean = np.empty((k_total, 2))
    cov = np.full((k_total, 3, 3), np.nan)
    seconds = np.empty(k_total)
    fixes: dict[int, FixRecord] = {}  # by ping: a held fix's record is settled later
    accepted = 0  # fixes TAP accepted
    held: HeldFix | None = None
    # the DR displacement since the held fix: its mean, and its covariance with (k, b)
    shift, d = np.zeros(2), np.zeros((4, 4))
    window = fix_window(config, survey)
    started = _time.perf_counter()
    for ping in tqdm(survey_pings(survey), disable=not progress, desc="mle", unit="ping", leave=False):
        t0 = _time.perf_counter()
        k = ping.index
        if not ping.first:
            step = rotate(-x[3], ping.increment) / (1.0 + x[2])
            x[:2] += step
            shift += step
            walk = motion.walk_variance(ping)
            noise = motion.noise_covariance(ping)
            p = _propagate(p, step, x[2], noise, walk)
            d = _propagate(d, step, x[2], noise, walk)
        if fix_due(config, k, window):
            fix, record = attempt_fix(
                survey, bathymetry, k, x[:2], p[:2, :2], config, window,
                initial_std=navigation.initial_position_std, model=navigation, calibration=(x[2:], p[2:, 2:]),
            )  # fmt: skip
            accepted += fix is not None and fix.accepted
            action, held, records = _judge(fix, record, k, x, p, held, (shift, d[:2, :2]), config)
            fixes.update((r.index, r) for r in records)
            if action in ("use", "confirm"):  # a confirmed fix says the prediction is wrong: jump
                x, p = _update(x, p, fix, config.fuse and action == "use")
            if held is not None and action == "hold":  # the displacement from here, with (k, b)'s spread
                shift, d = np.zeros(2), np.zeros((4, 4))
                d[2:, 2:] = p[2:, 2:]
        mean[k], cov[k, :2, :2] = x[:2], p[:2, :2]
        seconds[k] = _time.perf_counter() - t0
    elapsed = _time.perf_counter() - started
    return Track(
        time=survey.time,
        pose=np.column_stack([mean, survey.dr_pose[:, 2]]),
        covariance=cov,
        method="mle",
        timings=step_timings(elapsed, seconds),
        meta=_meta(navigation, config, x, p, list(fixes.values()), accepted, k_total),
        fixes=tuple(fixes.values()),
    )


def _judge(fix, record: FixRecord, k: int, x: np.ndarray, p: np.ndarray, held: HeldFix | None,
           displacement: tuple[np.ndarray, np.ndarray],
           config: MLEConfig) -> tuple[str, HeldFix | None, tuple[FixRecord, ...]]:
    """What to do with the fix attempted at ping ``k`` (``"use"``, ``"confirm"``, ``"hold"``,
    ``"wait"`` or ``"skip"``), the held fix after it (:func:`~tangraph.filters.fixes.decide_fix`)
    and the records it writes (the held fix's, when settled, then this one's)."""
    if fix is None or not (fix.accepted or not config.require_accepted):
        after = waited(held)
        return "skip", after, (*expired(held, after), record)
    decision = decide_fix(fix, k, x[:2], p[:2, :2], held, displacement, config,
                          half_width=record.half_width)
    detail = "" if fix.accepted else "used as TAP flagged it: " + record.detail
    records, after = decided(record, decision, held, detail)
    return decision.action, after, records


def _meta(navigation: NavigationModel, config: MLEConfig, x: np.ndarray, p: np.ndarray,
          fixes: list[FixRecord], accepted: int, k_total: int) -> dict[str, Any]:
    """The MLE track's ``meta``: the filters' keys (no particles: nothing resampled, never lost),
    the fixes' counts and the calibration estimate ``x[2:]`` with the final covariance ``p``'s stds."""
    calibration = {
        "speed_scale": float(x[2]),
        "speed_scale_std": float(np.sqrt(p[2, 2])),
        "heading_error": float(x[3]),
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
        "n_fixes_rejected": len(fixes) - accepted,
        "n_fixes_used": sum(f.accepted for f in fixes),
        "navigation_model": navigation.as_dict(),
        "config": config.as_dict(),
    }
