"""The particle belief: a weighted cloud, its start and its moments.

A :class:`Belief` is read-only: a filter step returns a new one and never writes into its
inputs. Each particle carries its position, the constant DR errors ``(k, b)`` (drawn from the
model's priors at the start, :func:`model_belief`) and its tide posterior; the track records
the cloud's weighted mean and covariance (:func:`weighted_moments`) and, at the last ping, its
calibration estimate (:func:`calibration_estimate`).
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numba
import numpy as np

from tangraph.errors import TangraphError
from tangraph.filters.model import FilterModel
from tangraph.filters.tide import TideDrift, update_drift
from tangraph.sensors.misfit import MisfitScale
from tangraph.validation import check_count, check_number

if TYPE_CHECKING:
    from tangraph.filters.fixes import HeldFix

__all__ = [
    "Belief",
    "calibration_estimate",
    "calibration_moments",
    "initial_belief",
    "model_belief",
    "state_moments",
    "weighted_moments",
]


def _frozen(a, dtype=np.float64) -> np.ndarray:
    a = np.asarray(a, dtype=dtype)
    if a.flags.writeable:
        a = a.view()
        a.setflags(write=False)
    return a


@dataclasses.dataclass(frozen=True, eq=False)
class Belief:
    """A weighted particle cloud (read-only arrays).

    ``particles (N, 2)`` positions; ``log_weights (N,)`` normalised log weights; ``tide (N,)``
    and ``tide_var`` the per-particle tide posterior; ``history (N, L)`` the last ``L`` predicted
    depths of each particle and ``measured (L,)`` the measured ones (SJCPF; ``L = 0`` otherwise),
    of which the last ``n_history`` are filled; ``n_fixes`` batch fixes absorbed (TERCOM-PF);
    ``calibration (N, 2)`` each particle's constant DR errors ``(k, b)`` (speed scale, heading
    error in rad, DR minus true; None: zeros); ``held`` a batch fix waiting to be confirmed
    (TERCOM-PF, :func:`tangraph.filters.fixes.decide_fix`; resampling takes its anchor along);
    ``misfit`` the local misfit scale the cloud shares (:mod:`tangraph.sensors.misfit`; None:
    the stated errors trusted); ``tide_drift`` the drifting part of the tide posterior
    (:mod:`tangraph.filters.tide`; None: a constant tide).
    """

    particles: np.ndarray
    log_weights: np.ndarray
    tide: np.ndarray
    tide_var: float
    history: np.ndarray
    measured: np.ndarray
    n_history: int = 0
    n_fixes: int = 0
    calibration: np.ndarray | None = None
    held: HeldFix | None = None
    misfit: MisfitScale | None = None
    tide_drift: TideDrift | None = None

    def __post_init__(self) -> None:
        if self.calibration is None:
            object.__setattr__(self, "calibration", np.zeros((np.shape(self.particles)[0], 2)))
        for name in ("particles", "log_weights", "tide", "history", "measured", "calibration"):
            object.__setattr__(self, name, _frozen(getattr(self, name)))
        particles, history = self.particles, self.history
        if particles.ndim != 2 or particles.shape[1] != 2:
            raise TangraphError(f"Belief.particles must have shape (N, 2), got {particles.shape}")
        n = particles.shape[0]
        if n < 1:
            raise TangraphError("Belief.particles must hold at least one particle, got shape (0, 2)")
        for name in ("log_weights", "tide"):
            shape = getattr(self, name).shape
            if shape != (n,):
                raise TangraphError(f"Belief.{name} must have shape ({n},) as particles, got {shape}")
        if history.ndim != 2 or history.shape[0] != n:
            raise TangraphError(f"Belief.history must have shape ({n}, L) as particles, got {history.shape}")
        assert self.calibration is not None  # filled above
        if self.calibration.shape != (n, 2):
            raise TangraphError(
                f"Belief.calibration must have shape ({n}, 2) as particles, got {self.calibration.shape}"
            )
        length = history.shape[1]
        if self.measured.shape != (length,):
            raise TangraphError(
                f"Belief.measured must have shape ({length},) as history's (N, L), got {self.measured.shape}"
            )
        check_number(self, "tide_var")
        if self.tide_drift is not None and np.shape(self.tide_drift.mean) != (n,):
            raise TangraphError(f"Belief.tide_drift.mean must have shape ({n},) as particles, got "
                                f"{np.shape(self.tide_drift.mean)}")
        check_count(self, "n_history", low=0)
        if self.n_history > length:
            raise TangraphError(f"Belief.n_history must be <= L = {length}, got {self.n_history!r}")
        check_count(self, "n_fixes", low=0)

    @property
    def n_particles(self) -> int:
        return int(self.particles.shape[0])

    @property
    def weights(self) -> np.ndarray:
        """Normalised weights ``(N,)``."""
        return np.exp(self.log_weights)

    def take(self, index: np.ndarray) -> Belief:
        """The particles ``index`` (with their tides and histories), equally weighted."""
        n = index.size
        assert self.calibration is not None  # __post_init__ fills it
        return self.replace(
            particles=self.particles[index],
            log_weights=np.full(n, -np.log(n)),
            tide=self.tide[index],
            history=self.history[index] if self.history.shape[1] else np.empty((n, 0)),
            calibration=self.calibration[index],
            held=None if self.held is None else self.held.take(index),
            tide_drift=None if self.tide_drift is None else self.tide_drift.take(index),
        )

    def tide_updated(self, update) -> Belief:
        """The belief with the tide posterior of a ping's terrain ``update``
        (:class:`~tangraph.filters.likelihood.PingLikelihood`'s ``tide``, ``tide_var``), its
        drifting part following (:func:`~tangraph.filters.tide.update_drift`)."""
        drift = update_drift(self.tide_drift, self.tide, self.tide_var, update.tide, update.tide_var)
        return self.replace(tide=update.tide, tide_var=update.tide_var, tide_drift=drift)

    def replace(self, **changes) -> Belief:
        """A copy with some fields changed (new arrays are made read-only; no other checks, as
        this runs several times per step)."""
        new = object.__new__(Belief)
        fields = dict(self.__dict__)
        for name, value in changes.items():
            if name not in fields:
                raise TypeError(f"Belief has no field {name!r}")
            fields[name] = _frozen(value) if isinstance(value, np.ndarray) else value
        new.__dict__.update(fields)
        return new


def initial_belief(
    centre,
    std: float,
    n: int,
    *,
    rng: np.random.Generator,
    tide: float = 0.0,
    tide_var: float = 0.0,
    history_length: int = 0,
    calibration=(0.0, 0.0),
    calibration_std=(0.0, 0.0),
) -> Belief:
    """``n`` equally weighted particles drawn from ``N(centre, std^2 I)``; ``centre`` is a
    position ``(north, east)``, shape ``(2,)`` (not a pose). Their constant DR errors ``(k, b)``
    are drawn from ``N(calibration, diag(calibration_std^2))`` (after the positions; no draws
    when both stds are 0).

    Raises
    ------
    TangraphError
        ``centre`` not a finite ``(2,)`` array, ``std`` negative or not finite, ``n < 1``,
        ``history_length < 0``.
    """
    try:
        centre = np.asarray(centre, dtype=np.float64)
    except (TypeError, ValueError):
        raise TangraphError(
            f"initial_belief: centre must be a (north, east) position, got {centre!r}"
        ) from None
    if centre.shape != (2,) or not np.all(np.isfinite(centre)):
        raise TangraphError(
            f"initial_belief: centre must be a finite (north, east) position of shape (2,), "
            f"got shape {centre.shape}: {centre.tolist()!r}"
        )
    try:
        spread = float(std)
    except (TypeError, ValueError):
        spread = np.nan
    if not (np.isfinite(spread) and spread >= 0):
        raise TangraphError(f"initial_belief: std must be a finite number >= 0, got {std!r}")
    for name, value, low in (("n", n, 1), ("history_length", history_length, 0)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
            raise TangraphError(f"initial_belief: {name} must be an integer >= {low}, got {value!r}")
    particles = centre + spread * rng.standard_normal((n, 2))
    cal_mean = np.broadcast_to(np.asarray(calibration, dtype=np.float64), (2,))
    cal_std = np.broadcast_to(np.asarray(calibration_std, dtype=np.float64), (2,))
    if np.any(cal_std > 0):
        cal = cal_mean + cal_std * rng.standard_normal((n, 2))
    else:
        cal = np.tile(cal_mean, (n, 1))
    return Belief(
        particles=particles,
        log_weights=np.full(n, -np.log(n)),
        tide=np.full(n, float(tide)),
        tide_var=float(tide_var),
        history=np.full((n, history_length), np.nan),
        measured=np.full(history_length, np.nan),
        calibration=cal,
    )


def model_belief(
    centre, model: FilterModel, n: int, *, rng: np.random.Generator, std: float | None = None,
    history_length: int = 0,
) -> Belief:  # fmt: skip
    """The start cloud of a model: ``n`` particles around ``centre`` with the model's
    ``initial_position_std`` (or ``std``), tide prior and calibration priors."""
    nav = model.navigation
    return initial_belief(
        centre,
        nav.initial_position_std if std is None else std,
        n,
        rng=rng,
        tide=nav.tide,
        tide_var=nav.tide_variance,
        history_length=history_length,
        calibration=nav.calibration_prior,
        calibration_std=nav.calibration_std,
    ).replace(misfit=model.misfit_prior(), tide_drift=TideDrift.start(nav, n))


@numba.njit(cache=True, nogil=True)
def _moments(log_weights, particles):
    """Weighted mean (2,) and covariance (2, 2) of normalised log weights ``(N,)`` and particles
    ``(N, 2)`` (the caller checks the shapes: no bounds checks here)."""
    n = log_weights.size
    mean = np.zeros(2)
    for p in range(n):
        w = np.exp(log_weights[p])
        mean[0] += w * particles[p, 0]
        mean[1] += w * particles[p, 1]
    cov = np.zeros((2, 2))
    for p in range(n):
        w = np.exp(log_weights[p])
        dn = particles[p, 0] - mean[0]
        de = particles[p, 1] - mean[1]
        cov[0, 0] += w * dn * dn
        cov[0, 1] += w * dn * de
        cov[1, 1] += w * de * de
    cov[1, 0] = cov[0, 1]
    return mean, cov


def weighted_moments(belief: Belief) -> tuple[np.ndarray, np.ndarray]:
    """Weighted mean ``(2,)`` and covariance ``(2, 2)`` (second moment about the mean).

    Raises
    ------
    TangraphError
        The particles are not ``(N, 2)`` with ``N`` the number of weights (a belief made by
        :meth:`Belief.replace`, which does not check shapes).
    """
    particles, log_weights = belief.particles, belief.log_weights
    if particles.ndim != 2 or particles.shape[1] != 2 or log_weights.shape != (particles.shape[0],):
        raise TangraphError(
            f"weighted_moments: particles (N, 2) and log_weights (N,) do not match: "
            f"{particles.shape}, {log_weights.shape}"
        )
    return _moments(log_weights, particles)


def state_moments(belief: Belief) -> tuple[np.ndarray, np.ndarray]:
    """Weighted mean ``(4,)`` and covariance ``(4, 4)`` of the particles' full state
    ``(north, east, k, b)``."""
    assert belief.calibration is not None  # Belief.__post_init__ fills it
    z = np.column_stack([belief.particles, belief.calibration])
    w = belief.weights
    mean = w @ z
    d = z - mean
    return mean, (d * w[:, None]).T @ d


def calibration_moments(belief: Belief) -> tuple[np.ndarray, np.ndarray]:
    """The weighted mean ``(2,)`` and covariance ``(2, 2)`` of the particles' ``(k, b)``."""
    w = belief.weights
    mean = w @ belief.calibration
    centred = belief.calibration - mean
    return mean, (w[:, None] * centred).T @ centred


def calibration_estimate(belief: Belief) -> dict[str, float]:
    """The weighted mean and std of the particles' ``(k, b)``, as ``Track.meta["calibration"]``:
    ``speed_scale``, ``speed_scale_std``, ``heading_error`` (rad, DR minus true),
    ``heading_error_std``.

    Examples
    --------
    >>> b = initial_belief([0.0, 0.0], 1.0, 4000, rng=np.random.default_rng(0),
    ...                    calibration=(0.02, 0.05), calibration_std=(0.01, 0.0))
    >>> {k: round(v, 2) for k, v in calibration_estimate(b).items()}
    {'speed_scale': 0.02, 'speed_scale_std': 0.01, 'heading_error': 0.05, 'heading_error_std': 0.0}
    """
    mean, cov = calibration_moments(belief)
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    return {
        "speed_scale": float(mean[0]),
        "speed_scale_std": float(std[0]),
        "heading_error": float(mean[1]),
        "heading_error_std": float(std[1]),
    }
