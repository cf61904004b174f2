"""The local misfit scale: how far the soundings here err beyond what the map states.

A real map errs as it states over most of its area and by several times that in patches: where
the seafloor moved since the map's survey, where its lines left a gap, where a sounder's
refraction bent a line (the Lake Caputh check lines: most of the map fits its stated error,
one window of track in ten lies beyond three times it). A terrain likelihood that trusts the stated
error everywhere weighs the soundings of such a patch as if they were metres more precise than
they are, and a filter converges on the patch's changed depths and reports it with confidence.

The model here holds the patch's error scale as a variable shared by the soundings near each
other along the track: each sounding's residual variance ``v_b`` (the terrain measurement model
of :mod:`tangraph.sensors.terrain`) is multiplied by a local factor ``kappa``, whose precision
``1 / kappa`` has a gamma distribution ``Gamma(shape, rate)``. Its prior is
``Gamma(dof / 2, dof / 2)``: the stated error on average (``E[1 / kappa] = 1``), with the tail of a
Student-t of ``dof`` degrees of freedom. Integrating ``kappa`` out, a ping's soundings of
whitened residual sum ``Q`` and (effective) count ``n`` have the multivariate Student-t density

    ``log p = lgamma(shape + n/2) - lgamma(shape) + shape log(rate) - (shape + n/2) log(rate + Q/2)``

(up to constants shared by every candidate position), whose slope in ``Q`` at the expected
``Q = n rate / shape`` is the Gaussian's at the current scale ``rate / shape``: where the map
errs as stated the likelihood is the Gaussian one, where the residuals grow it flattens. After
the ping the scale's posterior is ``Gamma(shape + n/2, rate + Q/2)``, averaged over the
filter's posterior cloud (one scale shared by the cloud: the assumed-density approximation that
the scale and the position are independent given the past). Along the track the scale forgets
towards its prior as the vehicle leaves the patch: over a distance ``d`` the excess of both
parameters over the prior's is multiplied by ``exp(-d / length)`` (an exponential forgetting of
the gamma statistics, as the variational adaptive Kalman filter of Särkkä & Nummenmaa 2009
does in time).

**Never better than stated.** The scale's estimate ``rate / shape`` is kept at 1 or more: residuals
smaller than the stated errors do not make the soundings more precise than the map and the
sonar say they are (the map's error is shared by soundings far apart, which a run of small
residuals along the track cannot show), as a map is never made better than its gridding says.

**Counting.** The terrain model's variances already count the map error that soundings share
(the row-sum bound), so a sounding's expected whitened square is not 1 but
``c_b = (sounding_std^2 + s_b^2) / v_b`` (``s_b`` the map's stated error under it); each sounding
adds ``c_b`` (times its information exponent) to ``n``, so that ``E[Q] = n`` where the map errs
as stated and the scale's estimate ``rate / shape`` stays at 1 there.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from tangraph.errors import TangraphError

__all__ = ["MisfitScale", "misfit_counts"]


@dataclasses.dataclass(frozen=True)
class MisfitScale:
    """The gamma posterior ``Gamma(shape, rate)`` of the local precision factor ``1 / kappa``
    (module docstring), its prior ``Gamma(dof / 2, dof / 2)`` and the forgetting ``length``
    (m) along the track.

    Examples
    --------
    >>> scale = MisfitScale.prior(8.0, 100.0)
    >>> scale.factor
    1.0
    >>> later = scale.after(np.array([40.0]), np.array([10.0]), np.array([1.0]))
    >>> round(later.factor, 3)  # ten soundings twice as far off as stated
    2.667
    >>> round(later.forget(1e9).factor, 3)  # far away, back to the stated error
    1.0
    """

    shape: float
    rate: float
    dof: float
    length: float

    def __post_init__(self) -> None:
        for name in ("shape", "rate", "dof", "length"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise TangraphError(f"MisfitScale.{name} must be a finite number > 0, got {value!r}")

    @classmethod
    def prior(cls, dof: float, length: float) -> MisfitScale:
        """The prior: the stated error on average, a Student-t tail of ``dof`` degrees of
        freedom, forgotten towards over ``length`` m."""
        return cls(float(dof) / 2.0, float(dof) / 2.0, float(dof), float(length))

    @property
    def factor(self) -> float:
        """The current estimate of ``kappa``, ``rate / shape`` (1: the map errs as stated)."""
        return self.rate / self.shape

    def forget(self, distance: float) -> MisfitScale:
        """The scale after the vehicle moved ``distance`` m: the excess of its parameters over
        the prior's shrunk by ``exp(-distance / length)``."""
        keep = math.exp(-max(float(distance), 0.0) / self.length)
        base = self.dof / 2.0
        return dataclasses.replace(self, shape=base + keep * (self.shape - base),
                                   rate=base + keep * (self.rate - base))

    def after(self, quadratic: np.ndarray, count: np.ndarray, weights: np.ndarray) -> MisfitScale:
        """The scale after a ping whose candidates (particles, grid points) have whitened
        residual sums ``quadratic (N,)`` (at scale 1) and effective counts ``count (N,)``,
        averaged over their posterior ``weights (N,)`` (normalised here; NaN entries and
        zero weights are left out), its estimate never below 1 (module docstring). Unchanged
        when no candidate of positive weight has one."""
        q = np.asarray(quadratic, dtype=np.float64)
        c = np.asarray(count, dtype=np.float64)
        w = np.asarray(weights, dtype=np.float64)
        ok = np.isfinite(q) & np.isfinite(c) & np.isfinite(w) & (w > 0)
        total = float(w[ok].sum())
        if total <= 0:
            return self
        w = w[ok] / total
        shape = self.shape + 0.5 * float(w @ c[ok])
        return dataclasses.replace(self, shape=shape, rate=max(self.rate + 0.5 * float(w @ q[ok]), shape))


def misfit_counts(variance: np.ndarray, map_variance: np.ndarray | None, noise_variance: float) -> np.ndarray:
    """Each sounding's expected whitened square ``c_b = (noise_variance + s_b^2) / v_b``, at most
    1 (module docstring); 1 for every sounding when the map is perfect (``map_variance`` None)."""
    v = np.asarray(variance, dtype=np.float64)
    if map_variance is None:
        return np.ones(v.shape)
    own = float(noise_variance) + np.asarray(map_variance, dtype=np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.clip(np.where(v > 0, own / v, 1.0), 0.0, 1.0)
