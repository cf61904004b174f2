"""The state-space model every particle filter shares: motion between pings and terrain likelihood.

It is built from a :class:`~tangraph.sensors.NavigationModel` (the one model of the survey's dead
reckoning and terrain measurements every estimator shares) as a run's :class:`FilterModel`: the
filter configs hold only algorithm settings.

State of a particle: horizontal position ``x = (north, east)``, the constant dead-reckoning errors
``c = (k, b)`` (``k`` the DVL speed scale: the DVL reads ``1 + k`` times the true speed; ``b`` the
total heading error, DR minus true: the constant bias plus its random walk) and, when the tide is
uncertain, the mean of its Gaussian tide posterior (Rao-Blackwellised).

**Motion**: ``x_k = x_{k-1} + R(-b_{k-1}) u_k / (1 + k) + v_k`` and ``b_k = b_{k-1} + w_k``,
``u_k`` the dead-reckoned (world-frame) displacement between pings ``k-1`` and ``k`` (the DR
integrates ``(1 + k)`` times the true body velocity with the heading ``psi + b``, so this is the
true displacement up to the white errors), ``R(a)`` the rotation by ``a`` clockwise from north,
``v_k ~ N(0, Q_k)`` with ``Q_k = (speed_noise dt)^2 I + heading_noise^2 u_k^perp u_k^perp^T +
floor^2 I`` (the white DVL noise over the interval ``dt``, the white heading error turning the
step, and the config's optional floor) and ``w_k ~ N(0, heading_walk^2 dt + heading_turn_std^2
|dpsi_k| / pi)``, ``dpsi_k`` the DR heading's turn over the step
(:func:`~tangraph.sensors.walk_variance`).

**Measurement**: the ``B`` soundings of ping ``k`` (offsets ``o_b`` from the vehicle,
world-aligned by the dead-reckoned heading: ``R(-b) o_b`` are the true offsets) measure
``z_b = h(x + R(-b) o_b) + t + e_b``, ``h`` the map's bilinear depth, ``t`` the tide (measured =
map + tide) and ``e_b`` of variance ``v_b``: the terrain measurement model of
:mod:`tangraph.sensors.terrain` (the sounding noise plus the map error the sounding shares with
the survey's other soundings), carried by the ping (:func:`survey_pings`); without a map error,
``v_b = sounding_std^2``. The likelihood (:mod:`tangraph.filters.likelihood`) leaves out, per
particle, the soundings with no map under it (they take the sub-cloud's mean likelihood: no
data is no evidence) and raises each sounding's term to MBARI's exponent (little information
where the cloud's predicted depths do not spread beyond the map's error). With ``tide_std = 0``
the tide is known; with ``tide_std > 0`` the tide has a Gaussian prior ``N(tide, tide_std^2)``
and each particle carries its conjugate posterior ``N(m, v)`` (Rao-Blackwellised): the weight is
the predictive density of the ping and the posterior is updated in closed form; with a
drifting tide the posterior is of the datum and the drift together (:mod:`tangraph.filters.tide`).
The white
heading error of a ping's own DR heading stays in its soundings' offsets (not modelled: a few
centimetres across a swath for a tenth of a degree). Constants shared by all particles are
dropped: weights are normalised.
"""

from __future__ import annotations

import dataclasses
import operator

import numpy as np

from tangraph.errors import TangraphError
from tangraph.filters.config import ParticleConfig
from tangraph.filters.likelihood import TerrainLikelihood
from tangraph.geometry import rotate, wrap_angle
from tangraph.maps.grid import BathymetryMap
from tangraph.sensors import NavigationModel
from tangraph.sensors.dead_reckoning import walk_variance
from tangraph.sensors.misfit import MisfitScale, misfit_counts
from tangraph.sensors.terrain import map_error_grids
from tangraph.survey import Survey

__all__ = ["FilterModel", "MotionModel", "Ping", "TerrainModel", "TerrainUpdate", "survey_pings"]


@dataclasses.dataclass(frozen=True, eq=False)
class Ping:
    """What a filter step needs of ping ``index``: the dead-reckoned ``increment (2,)`` from the
    previous ping (zero and ``first`` True at ping 0), the world-aligned ``offsets (B, 2)`` of
    its finite soundings from the dead-reckoned position, their ``depths (B,)``, the time
    ``dt`` (s) since the previous ping (its white DR errors grow with it; 0 at ping 0), the DR
    heading's ``turn`` (rad, wrapped) since the previous ping, and the terrain measurement
    model's ``variance (B,)`` of each sounding and ``map_variance (B,)`` of
    the map's error under it (:func:`tangraph.sensors.sounding_variances`; None: the filter
    model's sounding std and a perfect map), and ``map_counts (B, F)``, how many of the survey's
    soundings share each field of its map error (:func:`tangraph.sensors.sounding_map_counts`;
    None: its variance is judged at the dead-reckoned footprint).

    Checked on construction: ``index`` an integer >= 0, ``dt`` finite >= 0, ``increment`` finite
    ``(2,)``, ``offsets`` finite ``(B, 2)``, ``depths`` ``(B,)``. A NaN depth (no return) is
    dropped with its offset, as :func:`survey_pings` does, so a step never mistakes a missing
    sounding for a divergence; an infinite depth is refused.

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
    dt: float = 1.0
    variance: np.ndarray | None = None
    map_variance: np.ndarray | None = None
    turn: float = 0.0
    map_counts: np.ndarray | None = None

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
            first_bad = int(np.flatnonzero(np.isinf(depths))[0])
            raise TangraphError(
                f"Ping {index}: depths must be finite or NaN, got {float(depths[first_bad])!r} "
                f"at sounding {first_bad}"
            )
        keep = ~np.isnan(depths)
        extra = {}
        for name in ("variance", "map_variance", "map_counts"):
            value = getattr(self, name)
            if value is None:
                continue
            value = np.asarray(value, dtype=np.float64)
            if value.shape[:1] != depths.shape or value.ndim != (2 if name == "map_counts" else 1):
                raise TangraphError(f"Ping {index}: {name} must have shape {depths.shape} as depths"
                                    f"{' by fields' if name == 'map_counts' else ''}, got {value.shape}")
            if not np.all((value[keep] >= 0) & np.isfinite(value[keep])):
                raise TangraphError(f"Ping {index}: {name} must be finite and >= 0")
            extra[name] = value[keep]
        if not keep.all():
            offsets, depths = offsets[keep], depths[keep]
        object.__setattr__(self, "index", int(index))
        object.__setattr__(self, "increment", increment)
        object.__setattr__(self, "offsets", offsets)
        object.__setattr__(self, "depths", depths)
        object.__setattr__(self, "first", bool(self.first))
        for name, value in extra.items():
            object.__setattr__(self, name, value)
        try:
            dt = float(self.dt)
        except (TypeError, ValueError):
            dt = np.nan
        if not (np.isfinite(dt) and dt >= 0):
            raise TangraphError(f"Ping {index}: dt must be a finite number >= 0, got {self.dt!r}")
        object.__setattr__(self, "dt", dt)
        try:
            turn = float(self.turn)
        except (TypeError, ValueError):
            turn = np.nan
        if not (np.isfinite(turn) and abs(turn) <= np.pi):
            raise TangraphError(f"Ping {index}: turn must be a finite angle in [-pi, pi] rad, "
                                f"got {self.turn!r}")
        object.__setattr__(self, "turn", turn)

    @property
    def n_soundings(self) -> int:
        return int(self.depths.size)


def survey_pings(survey: Survey, bathymetry=None, model: NavigationModel | None = None) -> list[Ping]:
    """The pings of a survey as filter inputs (NaN soundings dropped). Given the map and the
    navigation model, each sounding carries the terrain measurement model's variance and its
    map error variance (:func:`tangraph.sensors.sounding_variances`, at the dead-reckoned
    footprints)."""
    from tangraph.sensors.terrain import sounding_map_counts, sounding_map_variances, sounding_variances

    north, east = survey.footprints()
    dr = survey.dr_pose
    valid = np.isfinite(survey.beam_depth)
    variance = map_variance = counts = None
    if bathymetry is not None and model is not None:
        variance = sounding_variances(survey, bathymetry, model)
        map_variance = sounding_map_variances(survey, bathymetry, model)
        counts = sounding_map_counts(survey, bathymetry, model)
        if map_variance is None:
            map_variance = np.zeros(north.shape)
    turned = wrap_angle(np.diff(dr[:, 2]))
    pings = []
    for k in range(survey.n_pings):
        keep = valid[k]
        offsets = np.column_stack([north[k, keep] - dr[k, 0], east[k, keep] - dr[k, 1]])
        increment = dr[k, :2] - dr[k - 1, :2] if k > 0 else np.zeros(2)
        dt = float(survey.time[k] - survey.time[k - 1]) if k > 0 else 0.0
        pings.append(Ping(k, increment, offsets, survey.beam_depth[k, keep].copy(), first=k == 0, dt=dt,
                          turn=float(turned[k - 1]) if k > 0 else 0.0,
                          variance=None if variance is None else variance[k, keep],
                          map_variance=None if map_variance is None else map_variance[k, keep],
                          map_counts=None if counts is None else counts[k, keep]))
    return pings


@dataclasses.dataclass(frozen=True)
class MotionModel:
    """Calibrated dead-reckoned displacement plus the white DR errors (see the module docstring).

    Parameters
    ----------
    speed_noise : float
        White DVL velocity error, m/s per axis (``NavigationModel.speed_noise``).
    heading_noise : float
        White heading error of each DR sample, rad: turns the step it starts.
    heading_walk : float
        Random walk of the heading error, rad/sqrt(s): the particles' ``b`` walks with it.
    floor : float
        Extra white noise (m per ping and axis): an algorithm setting (a roughening floor), 0 by
        default.
    heading_turn_std : float
        Std of the heading error's change over a turn of 180 deg, rad: ``b`` walks with the
        angle the DR heading turns too (:meth:`walk_variance`).

    Examples
    --------
    >>> model = MotionModel(speed_noise=0.1)
    >>> model.noise_covariance(Ping(1, np.array([30.0, 40.0]), np.zeros((0, 2)), np.zeros(0), dt=5.0))
    array([[0.25, 0.  ],
           [0.  , 0.25]])
    """

    speed_noise: float = 0.05
    heading_noise: float = 0.0
    heading_walk: float = 0.0
    floor: float = 0.0
    heading_turn_std: float = 0.0

    @classmethod
    def from_model(cls, model: NavigationModel, floor: float = 0.0) -> MotionModel:
        """The white DR errors of a navigation model (plus a floor)."""
        return cls(model.speed_noise, model.heading_noise, model.heading_walk, float(floor),
                   model.heading_turn_std)

    def walk_variance(self, ping: Ping) -> float:
        """Variance (rad^2) the heading error's walk gains over the ping's step."""
        return float(walk_variance(self.heading_walk, self.heading_turn_std, ping.dt, ping.turn))

    def noise_covariance(self, ping: Ping, extra_std: float = 0.0) -> np.ndarray:
        """World-frame covariance ``(2, 2)`` of the white position error over the ping's step
        (plus ``extra_std^2 I``)."""
        across = np.array([-ping.increment[1], ping.increment[0]])
        isotropic = (self.speed_noise * ping.dt) ** 2 + self.floor**2 + extra_std**2
        return isotropic * np.eye(2) + self.heading_noise**2 * np.outer(across, across)

    def predict(
        self,
        particles: np.ndarray,
        calibration: np.ndarray,
        ping: Ping,
        *,
        rng: np.random.Generator,
        extra_std: float = 0.0,
    ) -> tuple[np.ndarray, np.ndarray]:
        """New particles ``(N, 2)`` and calibrations ``(N, 2)`` (``k``, ``b``): every particle
        moved by its calibrated increment ``R(-b) u / (1 + k)`` plus the white noise (and
        ``extra_std`` of independent jitter), then its ``b`` walked; unchanged at the first ping.
        The draws: ``N x 2`` normals for the position, then ``N`` for the walk if any."""
        if ping.first:
            return particles, calibration
        k, b = calibration[:, 0], calibration[:, 1]
        step = rotate(-b, np.broadcast_to(ping.increment, particles.shape)) / (1.0 + k)[:, None]
        cov = self.noise_covariance(ping, extra_std)
        noise = rng.standard_normal(particles.shape)
        if cov[0, 1] == 0.0:
            noise = noise * np.sqrt(np.diag(cov))
        else:
            noise = noise @ np.linalg.cholesky(cov + 1e-12 * np.eye(2)).T
        moved = particles + step + noise
        variance = self.walk_variance(ping)
        if variance > 0:
            # (the time walk's std written as it always was: seeded runs without a turn walk draw
            # the same numbers to the last bit)
            std = np.sqrt(variance) if self.heading_turn_std > 0 else self.heading_walk * np.sqrt(ping.dt)
            walk = std * rng.standard_normal(particles.shape[0])
            calibration = np.column_stack([k, b + walk])
        return moved, calibration


@dataclasses.dataclass(frozen=True, eq=False)
class TerrainUpdate:
    """The terrain measurement of one ping for every particle: ``log_likelihood (N,)`` (up to a
    constant), the tide posterior ``tide (N,)``, ``tide_var``, the mean predicted depth of the
    ping's soundings ``predicted (N,)`` (map depth plus tide; NaN with no map under any), the
    soundings' information exponents ``exponent (B,)`` (reused by later evaluations of the same
    ping), the share of the ping's soundings with the map under each particle
    ``mapped (N,)``, with a misfit scale the ``scale`` the ping was weighed with and each
    particle's ``quadratic`` and ``count`` (:meth:`tangraph.sensors.MisfitScale.after`), and the
    soundings' ``variance (B,)`` and expected whitened squares ``counts (B,)`` the ping was
    weighed with (reused, with the exponents, by a later evaluation of the same ping)."""

    log_likelihood: np.ndarray
    tide: np.ndarray
    tide_var: float
    predicted: np.ndarray
    exponent: np.ndarray | None = None
    mapped: np.ndarray | None = None
    scale: MisfitScale | None = None
    quadratic: np.ndarray | None = None
    count: np.ndarray | None = None
    variance: np.ndarray | None = None
    counts: np.ndarray | None = None

    def scale_after(self, weights: np.ndarray) -> MisfitScale | None:
        """The misfit scale after this ping for the posterior ``weights (N,)`` (None without
        one)."""
        if self.scale is None or self.quadratic is None or self.count is None:
            return self.scale
        return self.scale.after(self.quadratic, self.count, weights)


@dataclasses.dataclass(frozen=True, eq=False)
class TerrainModel:
    """The terrain likelihood of a ping with a known (``tide_std = 0``) or uncertain tide;
    ``sounding_std`` is the std of one sounding's residual for pings that carry no variances
    (a navigation model's ``measurement_std``: sounding and map errors); ``noise_std`` the
    sounding's own noise (a navigation model's ``sounding_std``; None: ``sounding_std``), from
    which a misfit scale counts each sounding (:func:`tangraph.sensors.misfit_counts`)."""

    bathymetry: BathymetryMap
    sounding_std: float
    tide_std: float = 0.0
    noise_std: float | None = None
    error_grids: np.ndarray | None = dataclasses.field(default=None, repr=False)
    likelihood: TerrainLikelihood = dataclasses.field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "likelihood", TerrainLikelihood(self.bathymetry, self.sounding_std,
                                                                 error_grids=self.error_grids))

    def evaluate(
        self, particles: np.ndarray, tide: np.ndarray, tide_var: float, ping: Ping, heading_error=None,
        *, weights=None, earlier: TerrainUpdate | None = None, scale: MisfitScale | None = None,
        extra_variance: float = 0.0,
    ) -> TerrainUpdate:  # fmt: skip
        """Likelihood of ``ping`` at ``particles (N, 2)`` whose tide posteriors are ``N(tide (N,),
        tide_var)``, whose heading errors are ``heading_error (N,)`` (rad, DR minus true; None:
        0: each particle's soundings are turned by ``-heading_error`` about it) and whose weights
        are ``weights (N,)`` (None: equal); ``earlier``: an earlier evaluation of the same ping,
        whose information exponents and soundings' variances are reused (None: judged from this
        cloud); ``scale``: the local misfit scale before the ping (forgotten here over the ping's
        step and integrated out; None: the variances as stated); ``extra_variance`` (m^2) is
        added to every sounding's variance (a grid's resolution). A ping that carries its map
        error counts (``map_counts``) on a model that holds the map's error grids has its
        soundings' map error read where the cloud puts them
        (:func:`tangraph.sensors.sounding_map_counts`). See the module docstring."""
        turn = None if heading_error is None else -np.asarray(heading_error, dtype=np.float64)
        noise = self.sounding_std if self.noise_std is None else self.noise_std
        if scale is not None:
            scale = scale.forget(float(np.hypot(*ping.increment)))
        map_counts = counts = None
        if earlier is not None and earlier.variance is not None:  # as judged for this ping before
            variance, counts = earlier.variance, earlier.counts
        elif ping.map_counts is not None and self.error_grids is not None:
            # the sounding's own noise here; its map error where the cloud puts it
            variance, map_counts = np.full(ping.n_soundings, noise**2 + extra_variance), ping.map_counts
            counts = None if scale is None else np.ones(ping.n_soundings)
        else:
            variance = ping.variance if ping.variance is not None else np.full(ping.n_soundings,
                                                                              self.sounding_std**2)
            variance = variance + extra_variance
            if scale is not None:
                counts = misfit_counts(variance, ping.map_variance, noise**2 + extra_variance)
        update = self.likelihood.ping_update(
            particles, ping.offsets, ping.depths, tide, tide_var, turn=turn, weights=weights,
            variance=variance, map_variance=ping.map_variance,
            exponent=None if earlier is None else earlier.exponent, scale=scale, counts=counts,
            map_counts=map_counts,
        )  # fmt: skip
        return TerrainUpdate(update.log_likelihood, update.tide, update.tide_var, update.predicted,
                             update.exponent, update.mapped, scale, update.quadratic, update.count,
                             update.variance, None if scale is None else update.counts)


@dataclasses.dataclass(frozen=True, eq=False)
class FilterModel:
    """The state-space model of a run (apart from the algorithm): motion, terrain measurement and
    the navigation model they come from (start uncertainty, calibration and tide priors)."""

    motion: MotionModel
    terrain: TerrainModel
    navigation: NavigationModel = dataclasses.field(default_factory=NavigationModel)

    @classmethod
    def from_model(
        cls, navigation: NavigationModel, bathymetry: BathymetryMap, config: ParticleConfig | None = None
    ) -> FilterModel:
        """The filter model of a navigation model on a map; ``config`` adds its
        ``process_floor`` (if any) to the motion noise.

        Examples
        --------
        >>> from tangraph.maps import fractal
        >>> chart = fractal((20, 20), 5.0, rng=np.random.default_rng(0))
        >>> model = FilterModel.from_model(NavigationModel(sounding_std=0.3, map_std=0.4), chart)
        >>> round(model.terrain.sounding_std, 6)  # the map error inflates the likelihood
        0.5
        """
        if not isinstance(navigation, NavigationModel):
            raise TangraphError(
                f"model must be a tangraph.sensors.NavigationModel, got {type(navigation).__name__}"
            )
        floor = getattr(config, "process_floor", 0.0) if config is not None else 0.0
        return cls(
            MotionModel.from_model(navigation, floor),
            TerrainModel(bathymetry, navigation.measurement_std, navigation.tide_std,
                         navigation.sounding_std, map_error_grids(bathymetry, navigation)),
            navigation,
        )

    def misfit_prior(self) -> MisfitScale | None:
        """The local misfit scale a run starts from: the Student-t tail the map states (its
        ``error_dof``), else the navigation model's ``misfit_dof``, forgotten over its
        ``misfit_length``; None when neither gives one (the stated errors trusted)."""
        nav = self.navigation
        stated = self.terrain.bathymetry.error_dof
        dof = nav.misfit_dof if stated is None else stated
        return MisfitScale.prior(dof, nav.misfit_length) if dof > 0 else None
