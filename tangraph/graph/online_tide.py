"""The tide the online graph holds: one variable, or one per key pose when it drifts.

The graph holds the tide (the offset between the survey's depths and the map's, ``measured =
map + tide``) when its terrain tells it (``GraphConfig.online.learns_tide``): the point-mass
filter's factors and the tracking factors are on the position and the tide together.

**A constant tide** is one variable (:data:`~tangraph.graph.calibration.TIDE`), its prior the
model's ``tide, tide_std``, never marginalised; after a step of the tide (or when the
acquisition's filter starts afresh) a new one from that key on (:func:`new_tide`).

**A drifting tide** (``NavigationModel.tide_drift``: std ``S``, time ``T``) is the filters' model
(:mod:`tangraph.filters.tide`) as a chain of variables: a datum ``c ~ N(tide, tide_std^2)``
(never marginalised; none when ``tide_std`` is 0, the datum then the model's ``tide``) and the
tide ``s_k`` of every key pose, ``s_0 - c ~ N(0, S^2)`` and ``s_k - phi s_(k-1) - (1 - phi) c ~
N(0, S^2 (1 - phi^2))`` with ``phi = exp(-dt / T)`` over the ``dt`` seconds between the keys: a
datum known only to metres is learnt once and kept while the drift about it is followed. The
chain's factors are linear (:class:`gtsam.LinearContainerFactor`), and the key tides are
marginalised with their key poses. A factor on key ``k``'s pose takes ``s_k``
(:func:`of_key`); the pings after a key see its tide plus the drift since, which the tracking
factors integrate out as a walk from the key (:func:`ping_variance`; its pull back to the datum
over a key's few seconds, ``1 - phi`` of the key tide's departure from it, is left out).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import gtsam
import numpy as np

from tangraph.graph.calibration import TIDE

if TYPE_CHECKING:
    from tangraph.graph.online import GraphNavigator

__all__ = ["KEY_TIDE", "carried", "held_keys", "key_tide", "meta", "new_tide", "of_key", "ping_variance",
           "start"]

KEY_TIDE = "s"  #: the GTSAM symbol of a key pose's tide when it drifts: ``symbol(KEY_TIDE, key)``


def start(nav: GraphNavigator) -> None:
    """The tide's prior at the first key pose (0): the one tide, or the datum and the first key's
    tide when it drifts."""
    m = nav.model
    nav.datum_key = TIDE if m.tide_std > 0 else None
    if nav.datum_key is not None:
        nav._new_factors.add(gtsam.PriorFactorVector(TIDE, np.array([m.tide]),
                                                     gtsam.noiseModel.Isotropic.Sigma(1, m.tide_std)))
        nav._new_values.insert(TIDE, np.array([m.tide]))
    nav._tide_mean = float(m.tide)
    nav._tide_joint[5, 5] = m.tide_variance
    if m.tide_drift is not None:
        nav._tide_restart = True
        key_tide(nav, 0, 0)


def key_tide(nav: GraphNavigator, prev: int, k: int) -> None:
    """With a drifting tide, the tide variable of the new key pose ``k`` (``prev`` the latest
    key): its chain factor from ``prev``'s tide and the datum, or from the datum alone after a
    restart (:func:`new_tide`); the held tide is then ``k``'s. Nothing without a drift."""
    drift = nav.model.tide_drift
    if drift is None:
        return
    std, forget = drift
    tide = _datum(nav)
    key = of_key(nav, k)
    keys, a = [key], [1.0]
    if nav._tide_restart:  # s_k - c ~ N(0, S^2)
        phi, sigma, start_value = 0.0, std, nav._tide_mean
    else:
        phi = float(np.exp(-(nav.survey.time[k] - nav.survey.time[prev]) / forget))
        sigma = std * float(np.sqrt(1.0 - phi**2))
        keys.append(of_key(nav, prev))
        a.append(-phi)
        start_value = phi * nav._tide_mean + (1.0 - phi) * tide
    b = 0.0
    if nav.datum_key is not None:
        keys.append(nav.datum_key)
        a.append(-(1.0 - phi))
    else:
        b = (1.0 - phi) * float(nav.model.tide)  # the datum known
    nav._tide_restart = False
    nav._new_factors.add(_linear_factor(keys, a, b, sigma))
    nav._new_values.insert(key, np.array([start_value]))
    nav.tide_key = key


def _linear_factor(keys: list[int], a: list[float], b: float, sigma: float) -> gtsam.LinearContainerFactor:
    """The factor ``sum_i a_i x_i - b ~ N(0, sigma^2)`` on the 1-vectors ``keys``: linear, kept as
    it is (linearised at zero, where the tangent is the value itself)."""
    noise = gtsam.noiseModel.Isotropic.Sigma(1, sigma)
    blocks = [np.array([[value]]) for value in a]
    rhs = np.array([b])
    if len(keys) == 1:
        factor = gtsam.JacobianFactor(keys[0], blocks[0], rhs, noise)
    elif len(keys) == 2:
        factor = gtsam.JacobianFactor(keys[0], blocks[0], keys[1], blocks[1], rhs, noise)
    else:
        factor = gtsam.JacobianFactor(keys[0], blocks[0], keys[1], blocks[1], keys[2], blocks[2], rhs, noise)
    at = gtsam.Values()
    for key in keys:
        at.insert(key, np.zeros(1))
    return gtsam.LinearContainerFactor(factor, at)


def new_tide(nav: GraphNavigator, k: int, tide: float) -> None:
    """The graph holds a new tide from key ``k`` on (the held one is wrong), its prior ``tide``
    with the model's tide std: a new variable, or with a drift a new datum (the model's
    ``tide`` when ``tide_std`` is 0) and the chain started afresh at ``k``."""
    nav.tide_steps.append(k)
    m = nav.model
    nav._tide_mean = tide
    nav._tide_joint[5, :] = nav._tide_joint[:, 5] = 0.0
    nav._tide_joint[5, 5] = m.tide_variance
    if m.tide_drift is not None:
        nav._tide_restart = True
    if m.tide_std > 0:
        key = int(gtsam.symbol("t", len(nav.tide_steps)))
        nav._new_factors.add(gtsam.PriorFactorVector(key, np.array([tide]),
                                                     gtsam.noiseModel.Isotropic.Sigma(1, m.tide_std)))
        nav._new_values.insert(key, np.array([tide]))
        nav.datum_key = key
        if m.tide_drift is None:
            nav.tide_key = key


def of_key(nav: GraphNavigator, key: int) -> int:
    """The tide variable a factor on key pose ``key`` takes: its own when the tide drifts, else
    the one held."""
    return int(gtsam.symbol(KEY_TIDE, int(key))) if nav.model.tide_drift is not None else int(nav.tide_key)


def held_keys(nav: GraphNavigator) -> list[int]:
    """The tide variables never marginalised: the one held, or the datum of a drifting tide."""
    if not nav.tide:
        return []
    if nav.model.tide_drift is None:
        return [int(nav.tide_key)]
    return [] if nav.datum_key is None else [int(nav.datum_key)]


def _datum(nav: GraphNavigator) -> float:
    """The datum's estimate now (the model's tide while none is held or it is not yet solved)."""
    key = nav.datum_key
    if key is None or not nav.isam.valueExists(key):
        return float(nav.model.tide)
    return float(nav.isam.calculateEstimateVector(key)[0])


def carried(nav: GraphNavigator, dt: float, mean: float, joint: np.ndarray) -> tuple[float, np.ndarray]:
    """The held tide's ``mean`` and its ``joint (6, 6)`` with a pose and the calibration (the tide
    last) carried ``dt`` seconds on by the drift: ``s = phi s + (1 - phi) c + w`` (the datum at
    its estimate: its uncertainty over a key's seconds, ``1 - phi`` of it, left out)."""
    drift = nav.model.tide_drift
    if drift is None or dt <= 0:
        return mean, joint
    phi = float(np.exp(-dt / drift[1]))
    joint = joint.copy()
    joint[5, :] *= phi
    joint[:, 5] *= phi
    joint[5, 5] += drift[0] ** 2 * (1.0 - phi**2)
    return phi * mean + (1.0 - phi) * _datum(nav), joint


def ping_variance(nav: GraphNavigator, key: int, pings: np.ndarray) -> np.ndarray | None:
    """The variance ``(K,)`` the tide's drift adds between key pose ``key`` and each of the
    ``pings`` after it, ``S^2 (1 - phi^2)`` (None without a drift or a held tide)."""
    drift = nav.model.tide_drift
    if drift is None or not nav.tide:
        return None
    dt = np.maximum(nav.survey.time[np.asarray(pings, np.int64)] - nav.survey.time[int(key)], 0.0)
    return drift[0] ** 2 * (1.0 - np.exp(-2.0 * dt / drift[1]))


def meta(nav: GraphNavigator) -> dict:
    """What ``Track.meta["tide"]`` says: the latest key's tide estimate and std (m), the keys a
    new tide was held from (``steps``), and with a drift the datum's estimate and std."""
    out = {"tide": nav._tide_mean, "tide_std": float(np.sqrt(nav._tide_joint[5, 5])),
           "steps": list(nav.tide_steps)}
    if nav.model.tide_drift is not None and nav.datum_key is not None:
        out["datum"] = float(nav.isam.calculateEstimateVector(nav.datum_key)[0])
        out["datum_std"] = float(np.sqrt(nav.isam.marginalCovariance(nav.datum_key)[0, 0]))
    return out
