"""The configuration every particle filter shares, the point-mass filter's, and the checks all
filter configs use.

Configs are frozen dataclasses validated in ``__post_init__``: a bad value raises
:class:`~tangraph.errors.TangraphError` naming the class, the field and the value.
"""

from __future__ import annotations

import dataclasses
from typing import Any, Literal

import numpy as np

from tangraph.errors import TangraphError
from tangraph.filters.resampling import Resampler
from tangraph.validation import check_count, check_number

__all__ = ["FilterHealth", "PMFConfig", "ParticleConfig"]


@dataclasses.dataclass(frozen=True)
class FilterHealth:
    """How a particle filter tells that it is lost, and what it does then (part of every
    :class:`ParticleConfig`: ``PFConfig(health=FilterHealth(ping_gate=True))``).

    Parameters
    ----------
    lost_alpha : float
        Tail probability of the lost test: a ping is inconsistent when the normalised innovation
        of its mean sounding (against the weighted cloud's predictive spread) exceeds the
        chi-square(1) quantile ``1 - lost_alpha``, or the best particle's ``-2 log p`` exceeds the
        chi-square(B) one.
    lost_pings : int
        A ping is *lost* (``Track.meta["lost_steps"]``) when it and the ``lost_pings - 1``
        previous pings with soundings are all inconsistent.
    ping_gate : bool
        An inconsistent ping (the lost test's, above) does not weigh the cloud: the soundings
        no particle can explain are bad data or a sign of being lost, and in both cases
        weighing by them drags the cloud to a wrong place with a small spread. The cloud then
        moves with the dead reckoning, its spread grows, and a run of such pings is flagged
        lost (``meta["n_gated"]`` counts them). Off by default (every ping weighs the cloud):
        where the dead reckoning's constant errors are still unknown, many good pings look
        inconsistent and a gated filter learns those errors late (on the ``han2020`` survey
        with the demo's drifting DR its RMSE was several times the ungated one); on for data
        with blocks of bad pings (the robustness study measures both).
    gate_pings : int
        The gate's way out: after this many consecutive gated pings (longer than a block of bad
        pings should last) the cloud, not the pings, is taken to be wrong: it is drawn afresh
        around its mean with the first re-initialisation spread (``reinit_std``), calibration
        from the model's prior, and weighed by the ping (``meta["redraw_steps"]``). The spread
        does not grow with further redraws: a wide cloud on a gentle seabed settles on a wrong
        match more often than it finds the right one.
    reinit_std : float or None
        Spread (m) of the cloud drawn after a divergence; None: ``3 * max(s, 1)``, ``s`` the
        model's ``initial_position_std``.
    reinit_growth : float
        Factor on that spread for each further consecutive divergence.
    """

    lost_alpha: float = 1e-3
    lost_pings: int = 3
    ping_gate: bool = False
    gate_pings: int = 30
    reinit_std: float | None = None
    reinit_growth: float = 2.0

    def __post_init__(self) -> None:
        check_number(self, "lost_alpha", open_low=True, high=1.0)
        check_count(self, "lost_pings")
        check_count(self, "gate_pings")
        object.__setattr__(self, "ping_gate", bool(self.ping_gate))
        check_number(self, "reinit_growth", low=1.0)
        if self.reinit_std is not None:
            check_number(self, "reinit_std", open_low=True)

    def reinit_spread(self, initial_position_std: float) -> float:
        """Spread (m) of the first re-initialisation after a divergence, for a model whose start
        uncertainty is ``initial_position_std``."""
        if self.reinit_std is not None:
            return float(self.reinit_std)
        return 3.0 * max(float(initial_position_std), 1.0)


@dataclasses.dataclass(frozen=True)
class ParticleConfig:
    """Algorithm settings shared by the particle filters (each filter's config adds its own).

    What the filters believe about the vehicle and its sensors (process noise, start uncertainty,
    sounding and map errors, tide prior, the priors of the speed scale and heading bias) is the
    run's :class:`~tangraph.sensors.NavigationModel`, not a config.

    Parameters
    ----------
    n_particles : int
        Number of particles.
    resampler : Resampler
        Resampling scheme.
    ess_threshold : float
        Resample when the effective sample size falls below ``ess_threshold * n_particles``.
    process_floor : float
        Extra white position noise (m per ping and axis) on top of the model's white DR errors: a
        roughening floor; 0 by default (the model's noise is the process noise).
    kernel_bandwidth : float
        ``h`` of the Liu-West shrinkage kernel that moves the calibration ``(k, b)`` after every
        resampling (at most: see ``kernel_ess``; and the whole state between tempering stages),
        so that the constant errors do
        not collapse onto the few values drawn at the start: a particle's state ``s`` becomes
        ``a s + (1 - a) m + h L e``, ``a = sqrt(1 - h^2)``, ``m`` and ``L L^T`` the weighted mean
        and covariance before resampling (for the calibration: conditional on the position, by
        linear regression), ``e`` standard normal. The cloud's mean and covariance are kept (in
        expectation); 0 turns it off.
    kernel_ess : float
        The kernel has its full ``kernel_bandwidth`` after a resampling whose weights held at
        least as much as a cloud of ESS ``kernel_ess * n_particles``; after one whose weights
        were more even, its variance ``h^2`` is scaled by their squared coefficient of variation
        ``N / ESS - 1`` over that cloud's ``1 / kernel_ess - 1``
        (:func:`~tangraph.filters.steps.kernel_bandwidth`). A filter that resamples at every
        ping (``ess_threshold = 1``) then moves the calibrations by as much in all as one that
        resamples at ``kernel_ess``; at the full bandwidth at every ping, it re-drew each
        particle's calibration towards the cloud's every ``1 / (1 - a)`` pings, a walk of the
        constant errors the model does not have (on Lake Caputh's compass DR a heading error of
        a few degrees walked to 100 deg and the cloud left the map).
    kernel_floor : float
        Floor of the kernel's calibration spread, a fraction of the prior std of ``k`` and ``b``
        (keeps a cloud that has collapsed onto one value from staying there).
    tempering : bool
        Progressive correction: when a ping's likelihood would leave an ESS below
        ``tempering_ess * n_particles``, split it into stages ``p(z | x)^phi_j`` (exponents
        summing to 1, each the largest that keeps the ESS at or above the threshold), resampling
        and moving the particles by the kernel between stages.
    tempering_ess : float
        The stages' ESS threshold, a fraction of ``n_particles``.
    max_stages : int
        At most this many stages per ping (the last takes what remains of the exponent).
    health : FilterHealth
        The lost test, the ping gate and recovery (:class:`FilterHealth`).
    """

    n_particles: int = 1000
    resampler: Resampler = Resampler.SYSTEMATIC
    ess_threshold: float = 0.5
    process_floor: float = 0.0
    kernel_bandwidth: float = 0.3
    kernel_ess: float = 0.5
    kernel_floor: float = 1e-3
    tempering: bool = True
    tempering_ess: float = 0.5
    max_stages: int = 20
    health: FilterHealth = dataclasses.field(default_factory=FilterHealth)

    def __post_init__(self) -> None:
        check_count(self, "n_particles")
        check_number(self, "ess_threshold", high=1.0)
        check_number(self, "process_floor")
        check_number(self, "kernel_bandwidth", high=1.0)
        check_number(self, "kernel_ess", open_low=True, high=1.0)
        check_number(self, "kernel_floor")
        object.__setattr__(self, "tempering", bool(self.tempering))
        check_number(self, "tempering_ess", open_low=True, high=1.0)
        check_count(self, "max_stages")
        if isinstance(self.health, dict):  # a table of its fields (JSON, TOML)
            object.__setattr__(self, "health", FilterHealth(**self.health))
        if not isinstance(self.health, FilterHealth):
            raise TangraphError(f"{type(self).__name__}.health must be a FilterHealth, got "
                                f"{type(self.health).__name__}")
        try:
            object.__setattr__(self, "resampler", Resampler(self.resampler))
        except ValueError:
            known = ", ".join(r.value for r in Resampler)
            raise TangraphError(
                f"{type(self).__name__}.resampler must be one of {known}, got {self.resampler!r}"
            ) from None

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form (enums as their values, ``health`` a table), as stored in
        ``Track.meta["config"]``."""
        return {k: (v.value if hasattr(v, "value") else v) for k, v in dataclasses.asdict(self).items()}

    def replace(self, **changes: Any) -> ParticleConfig:
        """A copy with some fields changed; a :class:`FilterHealth` field (``ping_gate=True``)
        changes ``health``. Checked again."""
        names = {f.name for f in dataclasses.fields(FilterHealth)}
        health = {k: changes.pop(k) for k in list(changes) if k in names}
        if health:
            changes["health"] = dataclasses.replace(changes.get("health", self.health), **health)
        return dataclasses.replace(self, **changes)


@dataclasses.dataclass(frozen=True)
class PMFConfig:
    """Settings of the point-mass filter.

    Parameters
    ----------
    grid_points : int
        Points per axis of a member's position grid (odd, >= 5). With the calibration per
        point the grid's step is also how finely the motion tells the calibration (it is
        conditioned on the lattice's steps): 31 points were 4 % less accurate than 41 on
        ``demo`` (the graph_vs_filters study).
    grid_sigmas : float
        Half-width of the grid in standard deviations of the density along each principal axis.
    min_spacing : float
        Smallest grid spacing (m): the floor a grid shrinks to around a density narrower than
        its points (a coarser floor gives up precision: each sounding's variance grows with the
        spacing, see the module docstring).
    calibration_points : tuple of int
        Gauss-Hermite nodes of the calibration bank along the principal axes of the
        calibration's covariance (first: the speed scale's, second: the heading error's; 1 on an
        axis whose std is 0, whatever is asked).
    calibration : {"points", "bank"}
        How the DR's constant errors are held: ``"points"`` (the default), one grid whose every
        point carries the calibration's Gaussian posterior given that the vehicle is there
        (Rao-Blackwellised, :mod:`tangraph.filters.pmf_points`: one grid to weigh, and a heading
        error that changes at turns keeps one continuous density); ``"bank"``, the Gauss-Hermite
        bank of ``calibration_points`` nodes, each with its own grid (for constant errors and a
        slow walk; several times the time per ping).
    lost_alpha, lost_pings : float, int
        A ping is inconsistent when its innovation is beyond the ``1 - lost_alpha`` chi-square
        quantile; ``lost_pings`` in a row flag the filter lost.
    ping_gate, gate_pings : bool, int
        With ``ping_gate`` an inconsistent ping (the lost test's) does not weigh the density
        (bad data or a lost filter: weighing by it drags the density to a wrong place with a
        small spread; ``meta["gated_steps"]``), until ``gate_pings`` in a row, longer than a
        block of bad pings lasts, say the density is wrong: it starts afresh around its mean,
        wider (by ``3 max(s, 1)``, ``s`` the model's start std), with the tide and the
        calibration at their priors, and the pings are weighed again
        (``meta["reopened_steps"]``).
    relocalise : bool
        When lost, start afresh from a uniform density on the global grid (off by default: on
        a map whose error the model under-states, as on a flat lake gridded from an earlier
        survey, the lost test fires where the filter is not lost, and a global restart there
        chose a wrong place in most runs; use it where the terrain is distinctive).
    relocalise_points : int
        Points per axis of the global grid (odd, >= 5).
    relocalise_radius : float or None
        Half-width (m) of the global grid around the estimate; None: the map's data extent.

    Examples
    --------
    >>> PMFConfig().grid_points
    41
    >>> PMFConfig(grid_points=4)
    Traceback (most recent call last):
    ...
    tangraph.errors.TangraphError: PMFConfig.grid_points must be an odd integer >= 5, got 4
    """

    grid_points: int = 41
    grid_sigmas: float = 5.0
    min_spacing: float = 0.01
    calibration_points: tuple[int, int] = (3, 3)
    calibration: Literal["points", "bank"] = "points"
    lost_alpha: float = 1e-3
    lost_pings: int = 5
    ping_gate: bool = False
    gate_pings: int = 30
    relocalise: bool = False
    relocalise_points: int = 201
    relocalise_radius: float | None = None

    def __post_init__(self) -> None:
        n = self.grid_points
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 5 or n % 2 == 0:
            raise TangraphError(f"PMFConfig.grid_points must be an odd integer >= 5, got {n!r}")
        object.__setattr__(self, "grid_points", int(n))
        check_number(self, "grid_sigmas", low=1.0)
        check_number(self, "min_spacing", low=0.0, open_low=True)
        points = self.calibration_points
        if (not isinstance(points, (tuple, list)) or len(points) != 2
                or any(isinstance(p, bool) or not isinstance(p, (int, np.integer)) or p < 1 for p in points)):
            raise TangraphError(f"PMFConfig.calibration_points must be two integers >= 1, got {points!r}")
        object.__setattr__(self, "calibration_points", (int(points[0]), int(points[1])))
        if self.calibration not in ("bank", "points"):
            raise TangraphError(f"PMFConfig.calibration must be 'bank' or 'points', got {self.calibration!r}")
        check_number(self, "lost_alpha", low=0.0, open_low=True, high=0.5)
        check_count(self, "lost_pings", low=1)
        object.__setattr__(self, "ping_gate", bool(self.ping_gate))
        check_count(self, "gate_pings", low=1)
        object.__setattr__(self, "relocalise", bool(self.relocalise))
        n = self.relocalise_points
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 5 or n % 2 == 0:
            raise TangraphError(f"PMFConfig.relocalise_points must be an odd integer >= 5, got {n!r}")
        object.__setattr__(self, "relocalise_points", int(n))
        if self.relocalise_radius is not None:
            check_number(self, "relocalise_radius", low=0.0, open_low=True)

    def as_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)
