"""Terrain factors per ping: every sounding's residual against the map, in the batch smoother.

A TAP fix gives the graph one Gaussian summary per window of pings. Here every sounding enters
the smoother's least squares directly. Each ping hangs from the key pose before it, through the
DR increment from that key, which is exact in the DR frame up to the white DR noise
(:mod:`tangraph.graph.calibration`). A sounding ``b`` of ping ``i`` measures

    ``z = h(f(x_a, c)) + t + e``,   ``f = p_w + R(psi_w) o_b``,

with ``x_a`` the key pose, ``c = (k, b)`` the calibration, ``t`` the tide, ``p_w`` and ``psi_w``
the ping's world position and heading (the key composed with the increment, mapped to the world
by ``c``), ``o_b`` the beam's body-frame offset and ``h`` the map's bilinear depth. Its residual
``r = z - t - h(f)`` is linearised with the map's gradient (:func:`sounding_jacobians`, checked
against numerical derivatives in the tests).

Each sounding's variance is the terrain model's (:func:`~tangraph.sensors.sounding_variances`:
the noise plus the map error it shares with the survey's soundings, the row-sum bound), plus what
the white DR noise between the key and the ping moves its depth by. Soundings that fall on no
map data are left out, as are those beyond a gate on their standardised residual and the pings
whose soundings together fit the map worse than noise allows, re-judged at each converged solve
(:func:`gate`).

The normal equations of a key's soundings are summed into one small information block on the
key pose, the calibration and the tide. A :class:`gtsam.JacobianFactor` of at most 6 rows
carries it (:func:`linear_factors`), so a ping's soundings cost the linear solve no more than a
fix does.
"""

from __future__ import annotations

import dataclasses

import gtsam
import numpy as np
from scipy import stats

from tangraph.graph.calibration import CALIBRATION, TIDE
from tangraph.graph.keyposes import increments
from tangraph.maps.grid import BathymetryMap
from tangraph.sensors import rotation_matrix, sounding_variances

__all__ = ["NONLINEAR_SIGMAS", "PingTerrain", "chain_information", "footprints", "gate", "information_factor",
           "linear_factors", "ping_terrain", "sounding_jacobians", "tangent_departure", "terrain_cost",
           "terrain_residuals"]

_J = np.array([[0.0, -1.0], [1.0, 0.0]])  # d R(a) / da = R(a) J
PING_PROBABILITY = 0.999  #: a ping's soundings together beyond this chi-square quantile: left out
#: How far a belief reaches when :func:`tangent_departure` tests the map's tangent plane over it:
#: the points this many stds along its principal axes (its 2-sigma ellipse: where the vehicle
#: is, not only its centre)
NONLINEAR_SIGMAS = 2.0


@dataclasses.dataclass(frozen=True, eq=False)
class PingTerrain:
    """The soundings of a survey hung from the key poses of a graph: per ping the index of its
    key among ``keys`` (``key_index (K,)``), the DR increment from the key and its white
    covariance (``increment (K, 3)``, ``increment_cov (K, 3, 3)``, frame of the key), the beams'
    body offsets ``offsets (K, B, 2)`` (forward, starboard), measured ``depth (K, B)`` and the
    terrain model's ``variance (K, B)`` (NaN: no sounding). ``origin`` is the calibration's,
    ``calibrated`` whether the graph holds ``c``, ``tide`` and ``tide_std`` the tide's prior
    (a tide variable when ``tide_std > 0``), ``map_offset_std`` that of the map's horizontal
    offset ``o`` (m per axis; a variable when above zero: a footprint ``f`` lies on the map at
    ``f + o``)."""

    keys: np.ndarray
    key_index: np.ndarray
    increment: np.ndarray
    increment_cov: np.ndarray
    offsets: np.ndarray
    depth: np.ndarray
    variance: np.ndarray
    origin: np.ndarray
    calibrated: bool
    tide: float
    tide_std: float
    map_offset_std: float = 0.0

    @property
    def estimates_tide(self) -> bool:
        """Whether the tide is a variable (a prior std above zero)."""
        return self.tide_std > 0

    @property
    def estimates_offset(self) -> bool:
        """Whether the map's horizontal offset is a variable (a prior std above zero)."""
        return self.map_offset_std > 0

    @property
    def n_parameters(self) -> int:
        """Columns of a sounding's Jacobian: the pose, then ``c``, the tide and the map's offset
        when they are variables."""
        return 3 + 2 * self.calibrated + int(self.estimates_tide) + 2 * self.estimates_offset


def ping_terrain(survey, bathymetry: BathymetryMap, model, keys, white, origin,
                 calibrated: bool, poses=None) -> PingTerrain:  # fmt: skip
    """Hang every ping of ``survey`` from the last key pose at or before it (``keys``, ping
    indices ascending, the first at ping 0); ``white`` is the DR's white error model,
    ``model`` the :class:`~tangraph.sensors.NavigationModel` (sounding and map error, tide).
    Each sounding's variance is read at its footprint from ``poses (K, 3)`` (world poses; an
    estimate of the track: default the dead reckoning, tens of metres off by mid-survey)."""
    keys = np.asarray(keys, np.int64)
    ping = np.arange(survey.n_pings)
    index = np.searchsorted(keys, ping, side="right") - 1
    increment, cov = increments(white, survey.time, survey.dr_pose, keys[index], ping)
    offsets = np.stack([survey.beam_forward, survey.beam_starboard], axis=-1).astype(float)
    variance = sounding_variances(survey, bathymetry, model, poses=poses)
    return PingTerrain(keys, index, increment, cov, offsets, np.asarray(survey.beam_depth, float), variance,
                       np.asarray(origin, float), bool(calibrated), float(model.tide), float(model.tide_std))


def sounding_jacobians(terrain: PingTerrain, bathymetry: BathymetryMap, key_pose, calibration, tide: float,
                       offset: np.ndarray | None = None, map_offset=None):  # fmt: skip
    """Residuals ``r = z - t - h(f + o) (K, B)``, their Jacobians ``(K, B, P)`` with respect to
    the key pose (GTSAM's tangent: x, y in the key's frame, then the heading), ``c``, the tide
    and the map's offset ``o`` (:attr:`PingTerrain.n_parameters` columns), and the variance the
    white DR noise between the key and the ping adds to each ``(K, B)``. NaN where there is no
    sounding or no map.

    ``offset (K, B)`` is added to the map's depth under each sounding where given (the map's
    error as estimated there: :mod:`tangraph.graph.field_solve`); ``map_offset`` is ``o``
    ``(north, east)`` (None: zero)."""
    return _evaluate(terrain, bathymetry, key_pose, calibration, tide, offset=offset,
                     map_offset=map_offset)[:3]


def terrain_residuals(terrain: PingTerrain, bathymetry: BathymetryMap, key_pose, calibration,
                      tide: float, map_offset=None) -> np.ndarray:  # fmt: skip
    """The residuals ``r = z - t - h(f + o) (K, B)`` alone (NaN where no sounding or no map)."""
    return _evaluate(terrain, bathymetry, key_pose, calibration, tide, jacobian=False,
                     map_offset=map_offset)[0]


def footprints(terrain: PingTerrain, bathymetry: BathymetryMap, key_pose, calibration,
               map_offset=None) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """``(north, east)`` of every footprint ``(K, B)`` on the map at the given key poses, ``c``
    and map offset (world positions when that is None)."""
    return _evaluate(terrain, bathymetry, key_pose, calibration, 0.0, jacobian=False,
                     map_offset=map_offset)[4:6]


def _evaluate(terrain: PingTerrain, bathymetry: BathymetryMap, key_pose, calibration, tide: float, *,
              jacobian: bool = True, offset: np.ndarray | None = None, map_offset=None, noise: bool = False):
    """:func:`sounding_jacobians`, the map's gradient ``(K, B, 2)`` under every footprint and the
    footprints on the map ``north, east (K, B)``; the Jacobians None unless ``jacobian`` (the
    cost and the gate need none). With ``noise``, also the residuals' derivatives in the white
    DR noise of each ping's increment from the key ``(K, B, 3)`` (:func:`chain_information`)."""
    key_pose = np.asarray(key_pose, float)[terrain.key_index]
    k, b = (float(calibration[0]), float(calibration[1])) if terrain.calibrated else (0.0, 0.0)
    delta = terrain.increment
    rot_a = rotation_matrix(key_pose[:, 2])  # (K, 2, 2)
    frame = key_pose[:, :2] + np.matmul(rot_a, delta[:, :2, None])[..., 0]
    heading = key_pose[:, 2] + delta[:, 2] - b
    scale = rotation_matrix(-b) / (1.0 + k)  # DR frame -> world
    rel = frame - terrain.origin
    world = terrain.origin + rel @ scale.T
    rot_w = rotation_matrix(heading)
    rot_w_t = np.swapaxes(rot_w, 1, 2)  # (small products as matmul: einsum's overhead was most of it)
    lever = np.matmul(terrain.offsets, rot_w_t)  # (K, B, 2)
    shift = np.zeros(2) if map_offset is None else np.asarray(map_offset, float)
    north, east = world[:, None, 0] + lever[..., 0] + shift[0], world[:, None, 1] + lever[..., 1] + shift[1]
    residual = terrain.depth - tide - bathymetry.depth_at(north, east)
    grad = bathymetry.gradient_at(north, east)  # (K, B, 2)
    if offset is not None:
        residual = residual - offset
    d_heading = np.matmul(terrain.offsets @ _J.T, rot_w_t)  # d f / d psi_w (K, B, 2)
    d_xy = np.matmul(scale, rot_a)  # d f / d (x, y) of the key, (K, 2, 2)
    # the white DR noise from the key to the ping: d f / d increment = [scale R_a, d_heading]
    g_xy = np.matmul(grad, d_xy)  # (K, B, 2)
    g_inc = np.concatenate([g_xy, np.sum(grad * d_heading, axis=-1)[..., None]], axis=-1)
    dr_variance = np.sum(np.matmul(g_inc, terrain.increment_cov) * g_inc, axis=-1)
    extra = (-g_inc,) if noise else ()
    if not jacobian:
        return (residual, None, dr_variance, grad, north, east, *extra)
    d_theta = np.matmul(d_xy, (delta[:, :2] @ _J.T)[..., None])[..., 0]  # d f / d key heading, less turn
    jac = np.zeros((*residual.shape, terrain.n_parameters))
    jac[..., 0:2] = -g_xy
    jac[..., 2] = -np.sum(grad * (d_theta[:, None, :] + d_heading), axis=-1)
    column = 3
    if terrain.calibrated:
        d_k = -(rel @ scale.T) / (1.0 + k)  # (K, 2)
        d_b = -(rel @ (scale @ _J).T)
        jac[..., column] = -np.sum(grad * d_k[:, None, :], axis=-1)
        jac[..., column + 1] = -np.sum(grad * (d_b[:, None, :] - d_heading), axis=-1)
        column += 2
    if terrain.estimates_tide:
        jac[..., column] = -1.0
        column += 1
    if terrain.estimates_offset:
        jac[..., column:column + 2] = -grad
    return (residual, jac, dr_variance, grad, north, east, *extra)


def gate(terrain: PingTerrain, bathymetry: BathymetryMap, key_pose, calibration, tide: float,
         threshold: float, prior=None, offset_variance=None, map_offset=None) -> np.ndarray:  # fmt: skip
    """The soundings used at the given solution, judged as innovations against ``prior (K, 2,
    2)``, the covariance of each ping's world position the solution is uncertain by (None: 0),
    and ``offset_variance (K,)``, that of an error all of a ping's soundings share (None: 0; the
    map's error under a footprint smaller than its correlation length):

    - a sounding with map data under it whose residual is within ``threshold`` of its std
      (its variance plus ``g^T P g``, ``g`` the map's gradient under it, plus the offset's);
    - of a ping whose soundings are consistent together: ``r^T (V + G P G^T + o 1 1^T)^-1 r``
      over all its soundings with map data, each residual cut at the gate, within the
      chi-square quantile ``PING_PROBABILITY`` of their number. A ping whose footprints are
      misplaced as a whole (a position or attitude fault) fits the map nowhere near, though
      some of its soundings may each pass: the ping test leaves it out.
    """
    residual, _, dr_variance, grad, _, _ = _evaluate(terrain, bathymetry, key_pose, calibration, tide,
                                                     jacobian=False, map_offset=map_offset)
    variance = terrain.variance + dr_variance
    n = residual.shape[0]
    cov = np.zeros((n, 3, 3))
    if prior is not None:
        cov[:, :2, :2] = np.asarray(prior, float)
    if offset_variance is not None:
        cov[:, 2, 2] = np.asarray(offset_variance, float)
    g = np.concatenate([grad, np.ones((*residual.shape, 1))], axis=-1)  # shift, then offset
    spread = np.sum(np.matmul(g, cov) * g, axis=-1)
    limit = threshold * np.sqrt(variance + spread)
    finite = np.isfinite(residual) & np.isfinite(spread)
    ok = finite & (np.abs(residual) <= limit)
    # the ping test weighs all its soundings, each at most at the gate (one spike cannot fail a
    # good ping; many soundings beyond the gate fail it)
    w = np.where(finite, 1.0 / variance, 0.0)
    r = np.where(finite, np.clip(residual, -limit, limit), 0.0)
    g = np.where(finite[..., None], g, 0.0)
    # Woodbury: less b^T P (I + C P)^-1 b, what a shift within P (and the offset) explains
    b = np.sum((w * r)[..., None] * g, axis=1)
    c = np.matmul(np.swapaxes(g * w[..., None], 1, 2), g)
    y = np.linalg.solve(np.eye(3) + c @ cov, b[..., None])[..., 0]
    stat = np.sum(w * r * r, axis=1) - np.sum(np.matmul(b[:, None, :], cov)[:, 0] * y, axis=-1)
    count = finite.sum(axis=1)
    consistent = stat <= stats.chi2.ppf(PING_PROBABILITY, np.maximum(count, 1))
    return ok & consistent[:, None]


def terrain_cost(terrain: PingTerrain, bathymetry: BathymetryMap, key_pose, calibration, tide: float,
                 used: np.ndarray, offset: np.ndarray | None = None, map_offset=None) -> float:  # fmt: skip
    """``1/2 sum r^2 / v`` over the soundings ``used`` (the least-squares cost the factors add;
    a sounding that has lost its map since it was gated counts as at its gate)."""
    residual, _, dr_variance, *_ = _evaluate(terrain, bathymetry, key_pose, calibration, tide, jacobian=False,
                                             offset=offset, map_offset=map_offset)
    z2 = residual[used] ** 2 / (terrain.variance + dr_variance)[used]
    return 0.5 * float(np.sum(np.where(np.isfinite(z2), z2, np.nanmax(z2, initial=0.0))))


def linear_factors(terrain: PingTerrain, bathymetry: BathymetryMap, key_pose, calibration, tide: float,
                   used: np.ndarray) -> list[gtsam.JacobianFactor]:  # fmt: skip
    """The linearised terrain factors at a solution: one :class:`gtsam.JacobianFactor` per key
    with soundings ``used``, on the key pose, ``c`` and the tide, whose information is the sum
    of its soundings' (``sum J^T J / v``, with the gradient ``sum J^T r / v``)."""
    residual, jac, dr_variance = sounding_jacobians(terrain, bathymetry, key_pose, calibration, tide)
    ok = used & np.isfinite(residual) & np.all(np.isfinite(jac), axis=-1)
    weight = np.where(ok, 1.0 / (terrain.variance + dr_variance), 0.0)
    jac = np.where(ok[..., None], jac, 0.0)
    residual = np.where(ok, residual, 0.0)
    p = terrain.n_parameters
    per_ping_h = np.matmul(np.swapaxes(jac * weight[..., None], 1, 2), jac)
    per_ping_g = np.sum((weight * residual)[..., None] * jac, axis=1)
    n = terrain.keys.size
    info = np.zeros((n, p, p))
    grad = np.zeros((n, p))
    np.add.at(info, terrain.key_index, per_ping_h)
    np.add.at(grad, terrain.key_index, per_ping_g)
    others = ([CALIBRATION] if terrain.calibrated else []) + ([TIDE] if terrain.estimates_tide else [])
    keys = [[int(key), *others] for key in terrain.keys]
    factors = (information_factor(info[n_key], grad[n_key], keys[n_key]) for n_key in range(n))
    return [f for f in factors if f is not None]


def information_factor(info, gradient, keys) -> gtsam.JacobianFactor | None:
    """The :class:`gtsam.JacobianFactor` whose cost is ``1/2 d^T info d + gradient^T d`` (up to a
    constant) in the tangent ``d`` of the variables ``keys``: a key pose, then ``c`` and the tide
    when given (the columns of ``info (P, P)``: 3, 2, 1); None when ``info`` is zero. Directions
    ``info`` holds nothing of are left out (its positive eigenvalues only)."""
    values, vectors = np.linalg.eigh(np.asarray(info, float))
    keep = values > 1e-12 * max(float(values.max()), 1e-300)
    if not keep.any():
        return None
    root = np.sqrt(values[keep])
    a = root[:, None] * vectors[:, keep].T  # A^T A = info
    b = -(vectors[:, keep].T @ np.asarray(gradient, float)) / root  # A^T b = -gradient: minimises |A d - b|^2
    blocks, column = [], 0
    for key in keys:
        width = 3 if column == 0 else (2 if key == CALIBRATION else 1)
        blocks += [key, a[:, column:column + width]]
        column += width
    noise = gtsam.noiseModel.Unit.Create(int(keep.sum()))
    if len(blocks) == 2:
        return gtsam.JacobianFactor(blocks[0], blocks[1], b, noise)
    if len(blocks) == 4:
        return gtsam.JacobianFactor(blocks[0], blocks[1], blocks[2], blocks[3], b, noise)
    return gtsam.JacobianFactor(blocks[0], blocks[1], blocks[2], blocks[3], blocks[4], blocks[5], b, noise)


def chain_information(a, a_noise, residual, weight, increment_cov) -> tuple[np.ndarray, np.ndarray]:
    """The information ``(P, P)`` and gradient ``(P,)`` on the parameters ``theta`` of the
    soundings of ``K`` pings hung in a row from one key pose, with the white DR noise between
    the key and each ping integrated out: every sounding of a ping shares its ping's noise, and
    each ping the noise of those before it.

    A sounding ``b`` of ping ``j`` (in order from the key) is ``r_jb = residual + a_jb d_theta +
    n_jb u_j + e_jb`` (``a (K, B, P)`` and ``a_noise (K, B, Q)`` the residual's derivatives in
    the parameters and in the DR noise ``u_j`` of the ping's increment from the key, ``Q = 3``,
    or 4 with the tide's drift since the key; ``e`` of precision ``weight (K, B)``, 0: not used).
    ``u`` is taken as a walk, ``u_j = u_(j-1) + w_j`` (``u = 0`` at the key), its steps'
    covariances the growth of the cumulative covariances ``increment_cov (K, Q, Q)`` (made
    positive semi-definite: the DR model's white heading noise is carried over as if it
    persisted, which tells less of the heading than it holds). An information filter backwards
    along the pings gives ``A^T C^-1 A`` and ``A^T C^-1 r`` for the soundings' dense covariance
    ``C`` under that walk, at the cost of a few ``(P + Q)``-square
    products per ping (the tests check it against ``C``). Counting each sounding's share of the
    DR noise as its own instead, the ``B`` soundings of one ping would tell its position ``B``
    times over."""
    a, a_noise = np.asarray(a, float), np.asarray(a_noise, float)
    k, _, p = a.shape
    q = a_noise.shape[2]
    w = np.where(weight > 0, weight, 0.0)
    rows = np.where(w[..., None] > 0, np.concatenate([a, a_noise], axis=2), 0.0)  # (K, B, P + Q)
    ping_info = np.matmul(np.swapaxes(rows * w[..., None], 1, 2), rows)  # each ping's normal equations
    ping_grad = np.sum((w * np.where(w > 0, residual, 0.0))[..., None] * rows, axis=1)
    cov = np.asarray(increment_cov, float)
    steps = cov - np.concatenate([np.zeros((1, q, q)), cov[:-1]])
    values, vectors = np.linalg.eigh(0.5 * (steps + np.swapaxes(steps, 1, 2)))
    steps = np.matmul(vectors * np.maximum(values, 0.0)[:, None, :], np.swapaxes(vectors, 1, 2))
    lam, eta = np.zeros((p + q, p + q)), np.zeros(p + q)
    for j in range(k - 1, -1, -1):
        lam += ping_info[j]
        eta += ping_grad[j]
        gain = steps[j] @ np.linalg.inv(np.eye(q) + lam[p:, p:] @ steps[j])  # (L_uu + Q^-1)^-1
        cross = lam[:, p:].copy()
        eta -= cross @ gain @ eta[p:]
        lam -= cross @ gain @ cross.T
    return lam[:p, :p], eta[:p]  # u = 0 at the key


def tangent_departure(bathymetry, north, east, variance, cov) -> float:
    """How far the map departs from its tangent plane over a belief of position covariance ``cov
    (2, 2)``, or one per ping ``(K, 2, 2)``, against the soundings' noise: the mean over the
    soundings at ``north, east (K, B)`` on the map (their variances ``variance``) and the four
    points ``NONLINEAR_SIGMAS`` stds along the principal axes of their ping's covariance of
    ``(h(f + d) - h(f) - g^T d)^2 / v``. At most 1, a Gauss-Newton step on the soundings errs less
    than they do; NaN with no sounding on the map."""
    cov = np.broadcast_to(np.asarray(cov, float), (np.shape(north)[0], 2, 2))
    values, vectors = np.linalg.eigh(cov)
    # (K, 2 axes, 2 coordinates): the steps along each ping's principal axes
    steps = np.swapaxes(vectors * NONLINEAR_SIGMAS * np.sqrt(np.maximum(values, 0.0))[:, None, :], 1, 2)
    depth = bathymetry.depth_at(north, east)
    grad = bathymetry.gradient_at(north, east)
    parts = []
    for d in (steps[:, 0], steps[:, 1], -steps[:, 0], -steps[:, 1]):
        dn, de = d[:, 0, None], d[:, 1, None]
        bent = bathymetry.depth_at(north + dn, east + de) - depth - (grad[..., 0] * dn + grad[..., 1] * de)
        parts.append(bent**2 / variance)
    bent = np.stack(parts)
    ok = np.isfinite(bent)
    return float(np.mean(bent[ok])) if ok.any() else float("nan")
