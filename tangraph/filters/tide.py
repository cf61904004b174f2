"""The tide posterior every filter carries per particle (or grid point), with a drifting tide.

The soundings see the depths' offset against the map ``s`` (the "tide"). With a drift
(``NavigationModel.tide_drift_std`` ``S``, ``tide_drift_time`` ``T``) it is a constant datum
``c ~ N(tide, tide_std^2)`` plus a Gauss-Markov drift ``d``: ``d_0 ~ N(0, S^2)``,
``d_k = phi d_{k-1} + w_k``, ``phi = exp(-dt / T)``, ``w_k ~ N(0, S^2 (1 - phi^2))``, ``s = c + d``.
Each particle holds the Gaussian posterior of ``(s, d)``: its means ``tide`` and
:attr:`TideDrift.mean`, and a covariance every particle shares (their soundings' precisions
are the same): ``tide_var`` (``Var s``), :attr:`TideDrift.cross` (``Cov(s, d)``) and
:attr:`TideDrift.var` (``Var d``). The terrain likelihood (:mod:`tangraph.filters.likelihood`)
marginalises ``s`` as before; this module moves the pair:

- **prediction** (:func:`predict_tide`): ``(s, d) <- A (s, d) + w (1, 1)`` with
  ``A = [[1, -(1 - phi)], [0, phi]]``: the drift forgets, the datum learnt is kept;
- **update** (:func:`update_drift`): the soundings tell ``s`` only, and ``d`` follows by its
  regression on ``s``, ``d+ = d + C / v (s+ - s)``, ``C+ = C v+ / v``,
  ``Var d+ = Var d - C^2 / v (1 - v+ / v)`` (``v``, ``v+`` the variance of ``s`` before and
  after): exact for the linear Gaussian model, so a datum known only to metres is learnt once
  and kept while the drift about it is followed.

Without a drift the tide is one constant (``TideDrift`` None) and nothing moves between pings.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from tangraph.filters.model import Ping
    from tangraph.sensors import NavigationModel

__all__ = ["TideDrift", "predict_tide", "update_drift"]


@dataclasses.dataclass(frozen=True, eq=False)
class TideDrift:
    """The drifting part of the tide posterior: its mean per particle (or point, any shape),
    its covariance with the whole offset (``cross``) and its variance (``var``), shared."""

    mean: np.ndarray
    cross: float
    var: float

    @classmethod
    def start(cls, navigation: NavigationModel, shape: Any) -> TideDrift | None:
        """The drift's stationary law, uncorrelated with the datum (None without a drift)."""
        drift = navigation.tide_drift
        if drift is None:
            return None
        return cls(np.zeros(shape), drift[0] ** 2, drift[0] ** 2)

    def take(self, index) -> TideDrift:
        """The drift of the particles ``index``."""
        return dataclasses.replace(self, mean=self.mean[index])


def predict_tide(tide, tide_var: float, drift: TideDrift | None, navigation: NavigationModel,
                 ping: Ping) -> tuple[Any, float, TideDrift | None]:
    """The tide posterior ``(tide, tide_var, drift)`` carried to ``ping`` (unchanged at the first
    ping and without a drift)."""
    if drift is None or ping.first:
        return tide, tide_var, drift
    keep = float(navigation.tide_memory(ping.dt))
    lose = 1.0 - keep
    q = (navigation.tide_drift_std or 0.0) ** 2 * (1.0 - keep**2)
    variance = tide_var - 2.0 * lose * drift.cross + lose**2 * drift.var + q
    moved = TideDrift(keep * drift.mean, keep * drift.cross - keep * lose * drift.var + q,
                      keep**2 * drift.var + q)
    return tide - lose * drift.mean, variance, moved


def update_drift(drift: TideDrift | None, before, var_before: float, after,
                 var_after: float) -> TideDrift | None:
    """The drift after the soundings moved the tide posterior from ``(before, var_before)`` to
    ``(after, var_after)`` (means per particle or point)."""
    if drift is None or var_before <= 0:
        return drift
    gain = drift.cross / var_before
    shrink = var_after / var_before
    return TideDrift(drift.mean + gain * (np.asarray(after) - np.asarray(before)), drift.cross * shrink,
                     max(drift.var - drift.cross * gain * (1.0 - shrink), 0.0))
