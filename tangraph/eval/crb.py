"""The posterior Cramér-Rao bound (PCRB) of a survey with truth: the limit of any estimator.

The bound is that of the survey's error-state model linearised at the true track (the standard
Bayesian bound of terrain-aided navigation): a linear-Gaussian model, so its bound is the
covariance of the exact estimator: ``kind="filter"``, the recursive PCRB (every ping's position
given the soundings up to it), or ``kind="smoother"`` (every ping's position given the whole
survey: the inverse of the full information of odometry, calibration and tide priors, every
sounding and, when the map has an error, the prior of that error).

The error state
---------------
The dead-reckoning (DR) error of ping ``k`` is ``dp_k = DR position - true position`` (north,
east). With the DR simulated as in :func:`tangraph.sensors.simulate_dead_reckoning` (the true
world step ``d_k = p_{k+1} - p_k`` seen in the true body frame, read by the DVL as ``(1 + s)``
times itself plus white noise, and turned back into the world with the DR heading
``psi_k + e_k``), and ``R(psi + e) = R(psi) (I + e J)`` to first order::

    dp_{k+1} = dp_k + s d_k + e_k J d_k + v_k,    e_k = b + w_k + n_k,    J = [[0, -1], [1, 0]]

(``J d = (-d_east, d_north)`` is ``d`` turned 90 degrees to starboard, ``d R(psi) / d psi =
R(psi) J``), where ``s`` is the speed scale, ``b`` the heading bias, ``w_k`` the heading
walk (``w_0 = 0``, ``w_{k+1} = w_k + N(0, heading_walk^2 dt_k + heading_turn_std^2 |dpsi_k| / pi)``,
``dpsi_k`` the true heading's turn), ``n_k`` the white heading error
of ping ``k`` (``N(0, heading_noise^2)``, fresh at every ping) and ``v_k ~ N(0, speed_noise^2
dt_k^2 I)`` (isotropic, so its rotation does not matter). Terms of second order (``s e``,
``e v``, ``e^2``) are dropped. The tide of ping ``k`` is ``tide + x_k``: a constant and its drift
``x_k`` (``NavigationModel.tide_drift_std`` ``S``, ``tide_drift_time`` ``T``: ``x_0 ~ N(0, S^2)``,
``x_{k+1} = a_k x_k + N(0, (1 - a_k^2) S^2)``, ``a_k = exp(-dt_k / T)``). The state of ping ``k``
is ``(dp_k, w_k, n_k, s, b, tide, x_k)``; the walk, white and drift states are left out when
their std is zero, the tide when its prior std is zero. The prior at the first ping is ``dp_0 ~
N(0, initial_position_std^2 I)``, ``s``, ``b`` and the tide of their prior stds, ``w_0 = 0``.

The soundings
-------------
A sounding of ping ``k`` with body offset ``o`` lies at ``r = R(psi_k) o`` from the true position
``p_k`` and measures, as :mod:`tangraph.sensors.terrain` states, ``z = h(q) + d(q) + tide + e``
at its true footprint ``q = p_k + r``: ``h`` the map, ``d`` the map's error, ``e ~ N(0,
sounding_std^2)``. Laid from the DR pose it would be at ``q + dp_k + e_k J r``, so its residual
``z - map`` has, with ``g`` the map gradient at the TRUE footprint, the Jacobian ``-g`` on
``dp_k``, ``-g . J r`` on each of ``b``, ``w_k``, ``n_k``, ``1`` on the tide and ``x_k``, ``0`` on ``s`` and
``+1`` on ``d(q)``. Soundings without a depth (NaN) or whose true footprint is off the map (NaN
gradient) are left out. The ``B`` soundings of a ping give the state an information of rank at
most 4 (in the features ``g_n, g_e, g . J r, 1``).

Without a map error (the map is the truth: ``map_error(...).is_zero``) every sounding's noise is
``sounding_std`` and independent, and the bound is the covariance of the Kalman filter and the
Rauch-Tung-Striebel smoother of this state.

The map's error: a Gaussian-Markov field
----------------------------------------
With a map error, ``d`` is a zero-mean Gaussian random field correlated in space
(``cov(d(p), d(q)) = s(p) s(q) rho(|p - q|)``, Matérn nu = 1 of range ``L``): soundings that
share it do not average it away, and a second pass over the same ground meets the same errors.
The bound treats ``d`` as nuisance unknowns with their prior (:mod:`tangraph.eval.map_field`):
``d = S u`` on a regular grid of nodes over the soundings' true footprints (a margin of two
ranges, spacing ``L / 3``, coarser beyond 100 000 nodes a field; the filter bound's, for time,
no finer than the map's cell and 40 000 nodes), ``u`` of the sparse SPDE precision of Lindgren,
Rue & Lindström (2011) scaled to unit variance, ``S`` the map's error std at the nodes. A
sounding sees ``w^T S u`` (``w`` its bilinear weights on the 4 nodes around ``q``) and, as
independent noise besides ``sounding_std^2``, the variance of the field that the interpolation
misses (its nugget), so each sounding's map error has the model's variance ``s(q)^2``.

The unknowns (the states held per ping, the constants ``s, b, tide`` once, and the nodes) have a
sparse joint information: the prior, every step, every sounding and the field's precision. It is
factorised once (LDL^T in a minimum-degree order) and every ping's position covariance read from
its selected inverse (:mod:`tangraph.eval.selected_inverse`): the smoother bound. The filter
bound at ping ``k`` is the smoother bound of the survey cut after ``k``, read at ``k``: solved at
every ping of a survey of up to 60 pings, else at 60 evenly spaced ones (the first and the last
among them); in between it is the filter bound were the map error known (a Kalman filter at
every ping) plus what the map error adds to it, interpolated linearly, and never below the
smoother bound. (On the ``demo`` survey, 1256 pings, with 250 pings solved that interpolation
was within 1.5 % of the bound solved at every ping in RMS, 17 % at worst, 0.3 % in
:func:`bound_rmse`; 60 are solved by default, so that a study's bounds take seconds per run.)

The map's horizontal offset
---------------------------
A map is placed by its earlier surveys' positioning, so it may lie metres from where its
coordinates say (``NavigationModel.map_offset_std``): a sounding at ``q`` then meets the map at
``q + o`` and its residual has the Jacobian ``-g`` on ``o``, as on ``dp_k``. One offset for the
survey (``map_offset_length = 0``) is two more constants of the state; a field of offsets
(``map_offset_length > 0``) is two more fields beside the depth error's, one per axis, seen
through the map's slope (:func:`tangraph.eval.map_field.map_error_field`), and the depth
error is the part of the map's stated error the offset leaves.

Approximations, beyond the linearisation: the field lives on the nodes (the lattice's
correlation at ``L`` is 0.126 against Matérn's 0.140 at ``L / 3``) and the nugget is independent
between soundings (at ``L / 5`` the simulated realistic maps' bounds move by 1 %); a step whose
variance is zero (a DR without speed noise) gets the variance ``1e-8`` in units of its state's
natural spread (an information matrix cannot hold a constraint: the bound moves by about that
much times the pings, relatively); the gradient of ``d`` is not
counted as information on the position (the estimators know only the map's).

Not modelled: DVL dropouts (a survey does not record when they happened).
"""

from __future__ import annotations

import dataclasses
import logging
from typing import Any, Literal

import numpy as np

from tangraph.errors import TangraphError
from tangraph.eval.kalman import covariance_filter, covariance_smoother
from tangraph.geometry import wrap_angle
from tangraph.maps.grid import BathymetryMap
from tangraph.sensors.dead_reckoning import walk_variance
from tangraph.sensors.navigation_model import KNOWN_STD, NavigationModel
from tangraph.sensors.terrain import MapError, map_error
from tangraph.survey import Survey

__all__ = ["BoundKind", "CramerRaoBound", "posterior_crb"]

logger = logging.getLogger(__name__)

BoundKind = Literal["smoother", "filter"]
_KINDS = ("smoother", "filter")


@dataclasses.dataclass(frozen=True, eq=False)
class CramerRaoBound:
    """The posterior Cramér-Rao bound of a survey (from :func:`posterior_crb`).

    Parameters
    ----------
    position_cov : ndarray, shape (K, 2, 2)
        Bound on the covariance of every ping's horizontal ``(north, east)`` position, m^2.
    calibration_cov : ndarray, shape (2, 2)
        Bound on the covariance of the constant DR errors ``(speed scale, heading bias)`` given
        the whole survey (the filter's at the last ping; the smoother's is the same).
    tide_std : float
        Bound on the std of the tide given the whole survey, m.
    kind : {"smoother", "filter"}
        The smoother (all soundings) or the filter (soundings up to each ping) bound.
    n_soundings : int
        Soundings that entered the bound (with a depth and a true footprint on the map).
    map_error : bool
        The map's error entered the bound as a Gaussian-Markov field (False: the map was taken
        as the truth, or no sounding entered).
    field_nodes : int
        Nodes of that field (0 without it).
    field_spacing : float
        Their spacing, m (0 without it).
    """

    position_cov: np.ndarray
    calibration_cov: np.ndarray
    tide_std: float
    kind: BoundKind
    n_soundings: int = 0
    map_error: bool = False
    field_nodes: int = 0
    field_spacing: float = 0.0

    def __post_init__(self) -> None:
        pos = np.array(self.position_cov, dtype=np.float64)
        cal = np.array(self.calibration_cov, dtype=np.float64)
        if pos.ndim != 3 or pos.shape[1:] != (2, 2) or pos.shape[0] < 1:
            raise TangraphError(f"CramerRaoBound.position_cov must be (K, 2, 2), got {pos.shape}")
        if cal.shape != (2, 2):
            raise TangraphError(f"CramerRaoBound.calibration_cov must be (2, 2), got {cal.shape}")
        if self.kind not in _KINDS:
            raise TangraphError(f"CramerRaoBound.kind must be one of {_KINDS}, got {self.kind!r}")
        for name, a in (("position_cov", pos), ("calibration_cov", cal)):
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        object.__setattr__(self, "tide_std", float(self.tide_std))
        object.__setattr__(self, "n_soundings", int(self.n_soundings))
        object.__setattr__(self, "map_error", bool(self.map_error))
        object.__setattr__(self, "field_nodes", int(self.field_nodes))
        object.__setattr__(self, "field_spacing", float(self.field_spacing))

    @property
    def n_pings(self) -> int:
        return int(self.position_cov.shape[0])

    @property
    def drms(self) -> np.ndarray:
        """Bound on the horizontal distance RMS of every ping, ``sqrt(trace(position_cov))`` (K,), m."""
        return np.sqrt(np.maximum(np.trace(self.position_cov, axis1=1, axis2=2), 0.0))


def posterior_crb(survey: Survey, bathymetry: BathymetryMap, model: NavigationModel, *,
                  kind: BoundKind = "smoother", order: Literal[1, 3] = 1) -> CramerRaoBound:
    """Posterior Cramér-Rao bound of a survey's positions, linearised at its true track.

    Parameters
    ----------
    survey : Survey
        A survey with ``true_pose`` (simulated, or a GPS-surveyed ship track).
    bathymetry : BathymetryMap
        The map the soundings are matched against; its gradient at the true footprints is the
        information of each sounding, and its error (its ``depth_std`` and
        ``correlation_length``, else the model's) the error every sounding shares with those near
        it (:func:`tangraph.sensors.map_error`).
    model : NavigationModel
        The DR errors, start uncertainty, sounding noise, map error and tide prior (see the module
        notes for the linearised model and its signs), with the map's tide drift as every estimator's.
    kind : {"smoother", "filter"}
        ``"smoother"``: the bound given the whole survey (the inverse of the full information);
        ``"filter"``: the recursive bound given the pings up to each one, the limit of an online
        estimator (with a map error, solved at up to 60 pings and interpolated between them:
        see the module notes).
    order : {1, 3}
        Interpolation of the map gradient (bilinear or bicubic), as in
        :meth:`BathymetryMap.gradient_at`.

    Returns
    -------
    CramerRaoBound
        With ``map_error`` True and the field's node count and spacing where the map has an
        error.

    Raises
    ------
    TangraphError
        The survey has no truth, an argument has the wrong type, or ``kind`` is unknown.

    Examples
    --------
    A sloped seabed (depth grows northwards) sounded by a vehicle going north, the tide known: the
    slope pins the north error, while the east error is only bounded by the dead reckoning (with
    an unknown tide, a plane could not tell a north offset from the tide).

    >>> import numpy as np
    >>> from tangraph.maps import BathymetryMap
    >>> from tangraph.sensors import NavigationModel
    >>> from tangraph.survey import Survey
    >>> axis = np.arange(0.0, 1001.0, 10.0)
    >>> seabed = BathymetryMap(north=axis, east=axis, depth=20 + 0.05 * axis[:, None] + 0 * axis)
    >>> t = np.arange(100.0)
    >>> truth = np.column_stack([100 + 2 * t, 500 + 0 * t, 0 * t])
    >>> offset = np.tile(np.linspace(-20.0, 20.0, 9), (100, 1))
    >>> survey = Survey(time=t, dr_pose=truth, vehicle_depth=0 * t, beam_forward=0 * offset,
    ...                 beam_starboard=offset, beam_depth=25 + 0 * offset, true_pose=truth)
    >>> bound = posterior_crb(survey, seabed, NavigationModel(tide_std=0.0), kind="filter")
    >>> np.sqrt(np.diag(bound.position_cov[-1])).round(2).tolist()  # north, east std (m)
    [0.66, 10.82]

    A map error of 0.2 m correlated over 100 m: the 200 m of slope sounded share much of one
    error, which a north offset of 0.2 / 0.05 = 4 m would explain as well.

    >>> model = NavigationModel(tide_std=0.0, map_std=0.2, map_correlation_length=100.0)
    >>> bound = posterior_crb(survey, seabed, model, kind="filter")
    >>> np.sqrt(np.diag(bound.position_cov[-1])).round(2).tolist(), bound.map_error
    ([2.68, 11.64], True)
    """
    _check_arguments(survey, bathymetry, model, kind)
    model = model.with_map(bathymetry)  # NavigationModel.with_map
    layout = _Layout.of(model)
    scale, f, q, p0 = _scaled_model(survey, model, layout)
    features, n_soundings = _sounding_features(survey, bathymetry, order)
    error = map_error(bathymetry, model)
    fields = not error.is_zero or min(model.map_offset_std, model.map_offset_length) > 0
    solve = _field_bound if fields and n_soundings > 0 else _plain_bound
    position, constants, extra = solve(survey, model, error, kind, layout, scale, f, q, p0, features)
    cal, tide = constants[np.ix_(layout.calibration, layout.calibration)], layout.tide
    tide_std = float(np.sqrt(max(constants[tide, tide], 0.0))) if tide is not None else 0.0
    logger.debug("posterior_crb: %s bound over %d pings and %d soundings%s", kind, survey.n_pings,
                 n_soundings, f", a map error field of {extra['field_nodes']} nodes" if extra else "")
    return CramerRaoBound(position_cov=position, calibration_cov=cal, tide_std=tide_std, kind=kind,
                          n_soundings=n_soundings, **extra)


# -- the linearised model ------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class _Layout:
    """Indices of the error state: ``dp`` (0, 1), then walk, white, scale, bias, tide, the tide's
    drift, the map's horizontal offset (one for the survey) if present."""

    n: int
    walk: int | None
    white: int | None
    speed_scale: int
    heading_bias: int
    tide: int | None
    drift: int | None = None
    offset: int | None = None  # the first of two (north, east)

    @classmethod
    def of(cls, model: NavigationModel) -> _Layout:
        names = ["north", "east"]
        if model.heading_walk > 0 or model.heading_turn_std > 0:
            names.append("walk")
        if model.heading_noise > 0:
            names.append("white")
        names += ["scale", "bias"]
        if model.tide_std > 0:
            names.append("tide")
        if model.tide_drift is not None:
            names.append("drift")
        if model.map_offset_std > 0 and model.map_offset_length == 0:  # a field's is the map field's
            names += ["offset", "offset_east"]
        where = {name: i for i, name in enumerate(names)}
        return cls(n=len(names), walk=where.get("walk"), white=where.get("white"),
                   speed_scale=where["scale"], heading_bias=where["bias"], tide=where.get("tide"),
                   drift=where.get("drift"), offset=where.get("offset"))

    @property
    def constants(self) -> list[int]:
        """The states that hold for the whole survey: the calibration, the tide, the map's offset."""
        out = [*self.calibration, *([self.tide] if self.tide is not None else [])]
        return out + ([self.offset, self.offset + 1] if self.offset is not None else [])

    @property
    def calibration(self) -> list[int]:
        return [self.speed_scale, self.heading_bias]

    @property
    def heading(self) -> list[int]:
        """States that add to the DR heading error: bias, walk, white."""
        return [i for i in (self.walk, self.white, self.heading_bias) if i is not None]

    def prior_variance(self, model: NavigationModel) -> np.ndarray:
        v = np.zeros(self.n)
        v[:2] = model.initial_position_std**2
        if self.white is not None:
            v[self.white] = model.heading_noise**2
        v[self.speed_scale] = max(model.speed_scale_std, KNOWN_STD) ** 2  # a known one: as the graph holds it
        v[self.heading_bias] = max(model.heading_bias_std, KNOWN_STD) ** 2
        if self.tide is not None:
            v[self.tide] = model.tide_std**2
        if self.drift is not None:
            v[self.drift] = (model.tide_drift_std or 0.0) ** 2
        if self.offset is not None:
            v[self.offset:self.offset + 2] = model.map_offset_std**2
        return v

    def scale(self, model: NavigationModel, walk: np.ndarray) -> np.ndarray:
        """A natural unit of every state (its prior std, or the walk's std at the end, from the
        walk's variances ``walk`` of every step)."""
        s = np.sqrt(self.prior_variance(model))
        if self.walk is not None:
            s[self.walk] = np.sqrt(max(float(np.sum(walk)), 1e-18))
        return s


def _transitions(survey: Survey, model: NavigationModel, layout: _Layout) -> tuple[np.ndarray, np.ndarray]:
    """Transition matrices ``F_k`` and process noise ``Q_k`` (K-1, n, n) from ping k to k+1."""
    truth = survey.true_pose
    assert truth is not None
    d = np.diff(truth[:, :2], axis=0)
    jd = np.column_stack([-d[:, 1], d[:, 0]])
    dt = np.diff(survey.time)
    m, n = d.shape[0], layout.n
    f = np.tile(np.eye(n), (m, 1, 1))
    f[:, :2, layout.speed_scale] = d
    for i in layout.heading:
        f[:, :2, i] = jd
    q = np.zeros((m, n, n))
    q[:, 0, 0] = q[:, 1, 1] = (model.speed_noise * dt) ** 2
    if layout.walk is not None:
        turned = wrap_angle(np.diff(truth[:, 2]))
        q[:, layout.walk, layout.walk] = walk_variance(model.heading_walk, model.heading_turn_std, dt, turned)
    if layout.white is not None:
        f[:, layout.white, layout.white] = 0.0
        q[:, layout.white, layout.white] = model.heading_noise**2
    if layout.drift is not None:
        keep = model.tide_memory(dt)
        f[:, layout.drift, layout.drift] = keep
        q[:, layout.drift, layout.drift] = (1.0 - keep**2) * (model.tide_drift_std or 0.0) ** 2
    return f, q


def _sounding_features(survey: Survey, bathymetry: BathymetryMap, order) -> tuple[np.ndarray, int]:
    """Features ``(g_n, g_e, g . J r, 1)`` (K, B, 4) of every sounding, zero where it is left out."""
    truth = survey.true_pose
    assert truth is not None
    north, east = survey.footprints(truth)
    has = np.isfinite(survey.beam_depth)
    grad = np.full((*has.shape, 2), np.nan)
    if has.any():
        grad[has] = bathymetry.gradient_at(north[has], east[has], order=order)
    used = has & np.all(np.isfinite(grad), axis=-1)
    r_n = np.where(used, north - truth[:, :1], 0.0)
    r_e = np.where(used, east - truth[:, 1:2], 0.0)
    g = np.where(used[..., None], grad, 0.0)
    turn = g[..., 1] * r_n - g[..., 0] * r_e  # g . J r, J r = (-r_e, r_n)
    features = np.stack([g[..., 0], g[..., 1], turn, used.astype(np.float64)], axis=-1)
    return features, int(used.sum())


def _sounding_jacobian(layout: _Layout) -> np.ndarray:
    """``(n, 4)``: a sounding's Jacobian on the state is ``jacobian @ features``."""
    jacobian = np.zeros((layout.n, 4))
    jacobian[0, 0] = jacobian[1, 1] = -1.0
    jacobian[layout.heading, 2] = -1.0
    for i in (layout.tide, layout.drift):
        if i is not None:
            jacobian[i, 3] = 1.0
    if layout.offset is not None:  # the map where it lies: seen as the vehicle's position is
        jacobian[layout.offset, 0] = jacobian[layout.offset + 1, 1] = -1.0
    return jacobian


def _information_factor(features: np.ndarray, sigma: float, layout: _Layout) -> np.ndarray:
    """``L_k`` (K, n, 4) with ``L_k L_k^T`` the information of ping k's soundings on the state."""
    info = np.swapaxes(features, 1, 2) @ features / sigma**2
    value, vector = np.linalg.eigh(info)
    root = vector * np.sqrt(np.maximum(value, 0.0))[:, None, :]
    return _sounding_jacobian(layout) @ root


# -- the bound with the map's error field -------------------------------------------------------
def _check_arguments(survey: Survey, bathymetry: BathymetryMap, model: NavigationModel, kind: str) -> None:
    """Refuse arguments of the wrong type, a survey without truth and an unknown ``kind``."""
    if not isinstance(survey, Survey):
        raise TangraphError(f"posterior_crb: survey must be a Survey, got {type(survey).__name__}")
    if survey.true_pose is None:
        raise TangraphError("posterior_crb: the survey has no true_pose; the bound is linearised at "
                            "the truth")
    if not isinstance(bathymetry, BathymetryMap):
        raise TangraphError(f"posterior_crb: bathymetry must be a BathymetryMap, got "
                            f"{type(bathymetry).__name__}")
    if not isinstance(model, NavigationModel):
        raise TangraphError(f"posterior_crb: model must be a NavigationModel, got {type(model).__name__}")
    if kind not in _KINDS:
        raise TangraphError(f"posterior_crb: kind must be one of {_KINDS}, got {kind!r}")
    if model.dropout_speed_noise > 0:
        logger.info("posterior_crb: DVL dropouts are not modelled (the survey does not record them)")


def _scaled_model(survey: Survey, model: NavigationModel,
                  layout: _Layout) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The linearised model's ``(scale, f, q, p0)`` in units of each state's natural spread
    (``dp`` over the start's std, ``s`` over its prior std, ...): ``scale (n,)`` the units, ``f``
    and ``q (K, n, n)`` the transitions and their noise, ``p0 (n, n)`` the prior."""
    f, q = _transitions(survey, model, layout)
    scale = layout.scale(model, q[:, layout.walk, layout.walk] if layout.walk is not None else np.zeros(0))
    f = f / scale[:, None] * scale[None, :]
    q = q / np.outer(scale, scale)
    p0 = np.diag(layout.prior_variance(model)) / np.outer(scale, scale)
    return scale, f, q, p0


def _plain_bound(survey: Survey, model: NavigationModel, error: MapError, kind: BoundKind, layout: _Layout,
                 scale: np.ndarray, f: np.ndarray, q: np.ndarray, p0: np.ndarray,
                 features: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict]:
    """The bound with no map error (every sounding's error its own): a Kalman filter over the
    linearised model, smoothed by RTS for ``"smoother"``; called and returning as
    :func:`_field_bound` (``survey`` and ``error`` unused)."""
    factor = _information_factor(features, model.sounding_std, layout) * scale[:, None]
    filtered, predicted = covariance_filter(p0, f, q, factor)
    p = filtered if kind == "filter" else covariance_smoother(filtered, predicted, f)
    p = p * np.outer(scale, scale)
    return p[:, :2, :2], p[-1], dict[str, Any]()


def _field_bound(survey: Survey, model: NavigationModel, error: MapError, kind: BoundKind,
                 layout: _Layout, scale: np.ndarray, f: np.ndarray, q: np.ndarray, p0: np.ndarray,
                 features: np.ndarray) -> tuple[np.ndarray, np.ndarray, dict]:
    """The bound with the map's error as a field of nodes (``f, q, p0`` in the scaled units of
    ``scale``): position covariances (K, 2, 2) in m^2, the constants' covariance (n, n; only the
    calibration and tide entries are set) and the bound's fields that describe the field."""
    from tangraph.eval import field_bound, map_field  # numba loads here, not with tangraph.eval

    truth = survey.true_pose
    assert truth is not None
    north, east = survey.footprints(truth)
    used = features[..., 3] > 0
    fine = kind == "smoother"  # the filter bound's, solved 60 times, no finer than the map's cell
    most = map_field.BOUND_MAX_NODES if fine else map_field.MAX_NODES
    field = map_field.map_error_field(north[used], east[used], error, finer_than_cell=fine, max_nodes=most,
                                      offset=(model.map_offset_std, model.map_offset_length), trim=True)
    node, weight = field.weights(north[used], east[used])
    std = np.ones(used.shape)  # each sounding's noise: its own and the field's nugget
    std[used] = np.sqrt(model.sounding_std**2 + field.nugget(node, weight))
    known = None
    if kind == "filter":  # the filter bound were the map error known, at every ping
        factor = _information_factor(features / std[..., None], 1.0, layout) * scale[:, None]
        known = covariance_filter(p0, f, q, factor)[0][:, :2, :2]
    constant = np.zeros(layout.n, dtype=bool)
    constant[layout.constants] = True
    state = field_bound.ErrorState(f=f, q=q, p0=np.diag(p0), constant=constant, ping=np.nonzero(used)[0],
                                 jacobian=features[used] @ _sounding_jacobian(layout).T * scale)
    position, constants = field_bound.field_bound(state, field, node, weight, std[used], known_filter=known)
    extra = {"map_error": True, "field_nodes": field.n_nodes, "field_spacing": field.spacing}
    return position * np.outer(scale[:2], scale[:2]), constants * np.outer(scale, scale), extra
