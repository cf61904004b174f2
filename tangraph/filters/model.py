"""The state-space model every particle filter shares: motion between pings and terrain likelihood.

State of a particle: horizontal position ``x = (north, east)`` (the heading is the dead-reckoned
one) and, when the tide is uncertain, the mean of its Gaussian tide posterior (Rao-Blackwellised).

**Motion** (Han et al. 2020, eq. 1): ``x_k = x_{k-1} + u_k + v_k``, ``u_k`` the dead-reckoned
displacement between pings ``k-1`` and ``k`` and ``v_k ~ N(0, q_k^2 I)`` with
``q_k^2 = process_std^2 + (process_fraction |u_k|)^2`` (a floor plus an error proportional to the
distance run, as dead-reckoning errors are).

**Measurement** (Han et al. 2020, eq. 2): the ``B`` soundings of ping ``k`` (offsets ``o_b`` from
the vehicle, world-aligned by the dead-reckoned heading) measure ``z_b = h(x + o_b) + t + e_b``,
``e_b ~ N(0, sigma^2)``, ``h`` the map's bilinear depth and ``t`` the tide (measured = map + tide).
With ``tide_std = 0`` the tide is known and the log-likelihood is ``-sum (z_b - t - h)^2 /
(2 sigma^2)``, the paper's. With ``tide_std > 0`` the tide has a Gaussian prior ``N(tide,
tide_std^2)`` and each particle carries its conjugate posterior ``N(m, v)`` (``v`` is the same
for all particles: every particle sees the same number of soundings): the weight is the
predictive density of the ping, with ``e_b = z_b - h_b - m`` (Sherman-Morrison on
``sigma^2 I + v 1 1^T``)

    ``log p = -(sum e^2 - v (sum e)^2 / (sigma^2 + B v)) / (2 sigma^2)`` (+ a constant),

and the posterior becomes ``v' = v sigma^2 / (sigma^2 + B v)``, ``m' = m + v' sum e / sigma^2``.
A particle with a sounding off the map or by a NaN cell gets ``-inf``. Constants shared by all
particles are dropped: weights are normalised.
"""

from __future__ import annotations

import dataclasses
import operator

import numpy as np

from tangraph.errors import TangraphError
from tangraph.filters.likelihood import TerrainLikelihood
from tangraph.maps.grid import BathymetryMap
from tangraph.survey import Survey

__all__ = ["MotionModel", "Ping", "TerrainModel", "TerrainUpdate", "survey_pings"]


@dataclasses.dataclass(frozen=True, eq=False)
class Ping:
    """What a filter step needs of ping ``index``: the dead-reckoned ``increment (2,)`` from the
    previous ping (zero and ``first`` True at ping 0), the world-aligned ``offsets (B, 2)`` of
    its finite soundings from the dead-reckoned position, and their ``depths (B,)``.

    Checked on construction: ``index`` an integer >= 0, ``increment`` finite ``(2,)``, ``offsets``
    finite ``(B, 2)``, ``depths`` ``(B,)``. A NaN depth (no return) is dropped with its offset, as
    :func:`survey_pings` does, so a step never mistakes a missing sounding for a divergence; an
    infinite depth is refused.

    Examples
    --------
    >>> Ping(1, np.zeros(2), np.zeros((3, 2)), np.array([10.0, np.nan, 11.0])).n_soundings
    2
    """

    index: int
    increment: np.ndarray
    offsets: np.ndarray
    depths: np.ndarray
    first: bool = False

    def __post_init__(self) -> None:
        try:
            index = operator.index(self.index)
        except TypeError:
            index = -1
        if isinstance(self.index, bool) or index < 0:
            raise TangraphError(f"Ping: index must be an integer >= 0, got {self.index!r}")
        increment = np.asarray(self.increment, dtype=np.float64)
        offsets = np.asarray(self.offsets, dtype=np.float64)
        depths = np.asarray(self.depths, dtype=np.float64)
        if increment.shape != (2,) or not np.all(np.isfinite(increment)):
            raise TangraphError(
                f"Ping {index}: increment must be a finite (2,) array, "
                f"got {increment.shape}: {increment.tolist()!r}"
            )
        if offsets.ndim != 2 or offsets.shape[1] != 2 or depths.shape != (offsets.shape[0],):
            raise TangraphError(
                f"Ping {index}: offsets (B, 2) and depths (B,) do not match: {offsets.shape}, {depths.shape}"
            )
        if not np.all(np.isfinite(offsets)):
            bad = np.flatnonzero(~np.all(np.isfinite(offsets), axis=1))
            raise TangraphError(
                f"Ping {index}: offsets must be finite, got {offsets[bad[0]].tolist()!r} at sounding {bad[0]}"
            )
        if np.any(np.isinf(depths)):
            bad = int(np.flatnonzero(np.isinf(depths))[0])
            raise TangraphError(
                f"Ping {index}: depths must be finite or NaN, got {float(depths[bad])!r} at sounding {bad}"
            )
        keep = ~np.isnan(depths)
        if not keep.all():
            offsets, depths = offsets[keep], depths[keep]
        object.__setattr__(self, "index", int(index))
        object.__setattr__(self, "increment", increment)
        object.__setattr__(self, "offsets", offsets)
        object.__setattr__(self, "depths", depths)
        object.__setattr__(self, "first", bool(self.first))

    @property
    def n_soundings(self) -> int:
        return int(self.depths.size)


def survey_pings(survey: Survey) -> list[Ping]:
    """The pings of a survey as filter inputs (NaN soundings dropped)."""
    north, east = survey.footprints()
    dr = survey.dr_pose
    valid = np.isfinite(survey.beam_depth)
    pings = []
    for k in range(survey.n_pings):
        keep = valid[k]
        offsets = np.column_stack([north[k, keep] - dr[k, 0], east[k, keep] - dr[k, 1]])
        increment = dr[k, :2] - dr[k - 1, :2] if k > 0 else np.zeros(2)
        pings.append(Ping(k, increment, offsets, survey.beam_depth[k, keep].copy(), first=k == 0))
    return pings


@dataclasses.dataclass(frozen=True)
class MotionModel:
    """Dead-reckoned displacement plus Gaussian process noise (see the module docstring).

    Examples
    --------
    >>> MotionModel(process_std=0.5, process_fraction=0.1).noise_std(np.array([30.0, 40.0]))
    5.024937810560445
    """

    process_std: float = 0.5  # m per ping and axis
    process_fraction: float = 0.1  # per axis, of the distance run between pings

    def noise_std(self, increment: np.ndarray) -> float:
        """Std (m, per axis) of the process noise over a dead-reckoned ``increment``."""
        return float(np.hypot(self.process_std, self.process_fraction * np.hypot(*increment)))

    def predict(
        self, particles: np.ndarray, ping: Ping, *, rng: np.random.Generator, extra_std: float = 0.0
    ) -> np.ndarray:
        """New particles ``(N, 2)``: moved by the ping's increment plus process noise (and
        ``extra_std`` of independent jitter); unchanged at the first ping."""
        if ping.first:
            return particles
        std = float(np.hypot(self.noise_std(ping.increment), extra_std))
        return particles + ping.increment + std * rng.standard_normal(particles.shape)


@dataclasses.dataclass(frozen=True, eq=False)
class TerrainUpdate:
    """The terrain measurement of one ping for every particle: ``log_likelihood (N,)`` (up to a
    constant), the tide posterior ``tide (N,)``, ``tide_var``, and the mean predicted depth of
    the ping's soundings ``predicted (N,)`` (map depth plus tide; NaN off the map)."""

    log_likelihood: np.ndarray
    tide: np.ndarray
    tide_var: float
    predicted: np.ndarray


@dataclasses.dataclass(frozen=True, eq=False)
class TerrainModel:
    """The terrain likelihood of a ping with a known (``tide_std = 0``) or uncertain tide."""

    bathymetry: BathymetryMap
    sounding_std: float
    tide_std: float = 0.0
    likelihood: TerrainLikelihood = dataclasses.field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "likelihood", TerrainLikelihood(self.bathymetry, self.sounding_std))

    def evaluate(self, particles: np.ndarray, tide: np.ndarray, tide_var: float, ping: Ping) -> TerrainUpdate:
        """Likelihood of ``ping`` at ``particles (N, 2)`` whose tide posteriors are ``N(tide (N,),
        tide_var)``; see the module docstring."""
        b = ping.n_soundings
        s2_noise = self.sounding_std**2
        log_likelihood, new_tide, predicted = self.likelihood.tide_update(
            particles, ping.offsets, ping.depths, tide, tide_var
        )
        new_var = tide_var * s2_noise / (s2_noise + b * tide_var)
        return TerrainUpdate(log_likelihood, new_tide, float(new_var), predicted)
