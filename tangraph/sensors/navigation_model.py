"""`NavigationModel`: what every estimator believes about the vehicle, its DR and its sonar.

One frozen object per survey, passed to the factor graph and to every particle filter (their
configs hold only algorithm settings). It holds

- the dead-reckoning error model: the white errors (DVL speed noise, white heading noise, heading
  random walk, the INS velocity walk during DVL dropouts) and the **constant** errors every real
  DVL and compass has, the speed scale factor ``k`` (the DVL reads ``1 + k`` times the true speed)
  and the heading bias ``b`` (the DR heading is the true one plus ``b``), each with a prior mean
  and std. The constant errors are estimated by the graph (calibration variables) and the filters
  (particle states), never treated as white noise;
- the initial uncertainty of the start position, the same for every estimator;
- the terrain measurement model: sounding noise, map error and the tide prior, with one sign
  convention everywhere: a residual is ``measured - map``, and the tide is what a measured depth
  has on top of the map's (``measured = map + tide + noise``);
- the factor graph's model of its terrain fixes' errors (their tail and what neighbouring fixes
  share) and the floors of its odometry noise.
"""

from __future__ import annotations

import dataclasses
import math
import os
from typing import Any

import numpy as np

from tangraph.errors import TangraphError
from tangraph.sensors.dead_reckoning import DeadReckoningModel
from tangraph.tomlfile import read_table
from tangraph.validation import check_number as _number

__all__ = ["KNOWN_STD", "NavigationModel", "load_navigation_model", "survey_navigation_model"]

#: The prior std at which an estimator (or the bound) that needs a Gaussian holds a constant
#: error the model knows exactly (``speed_scale_std`` or ``heading_bias_std`` of 0): it then
#: stays at its prior mean to a millionth.
KNOWN_STD = 1e-6

_KERNELS = ("huber", "cauchy", "none")
_ANGLES = ("heading_bias", "heading_bias_std", "heading_noise", "heading_walk", "heading_turn_std")


@dataclasses.dataclass(frozen=True)
class NavigationModel:
    """The estimators' model of a survey's dead reckoning and terrain measurements.

    Parameters
    ----------
    speed_noise : float
        White DVL velocity error, m/s (std per axis and interval).
    heading_noise : float
        White heading error of each sample, rad.
    heading_walk : float
        Random walk of the heading error, rad/sqrt(s).
    heading_turn_std : float
        Std (rad) of the heading error's change over a turn of 180 deg: the part of the heading
        error that depends on the heading (a magnetic compass's deviation ``A sin(psi + phi)``
        gives ``sqrt(2) A``; the crab angle a current gives a DR that runs along the heading
        does the same), walked with the angle turned
        (:func:`~tangraph.sensors.walk_variance`). 0 (default): a heading error
        that does not depend on the heading (a gyrocompass, an INS).
    dropout_speed_noise : float
        INS velocity random walk while the DVL has lost bottom lock, m/s/sqrt(s).
    speed_scale, speed_scale_std : float
        Prior mean and std of the constant DVL scale-factor error ``k`` (0.01: reads 1 % fast).
        A std of 0: ``k`` is known, its prior mean (the graph does not estimate it; with both
        stds 0 and both means 0 it holds no calibration variable and trusts the DR's shape).
    heading_bias, heading_bias_std : float
        Prior mean and std of the constant heading error ``b`` (DR minus true), rad; it includes
        the INS alignment error of the start heading. A std of 0: ``b`` is known.
    initial_position_std : float
        Std (m, per axis) of the start position around the first DR position: every estimator
        starts from this uncertainty.
    sounding_std : float
        Std (m) of a sounding's error (noise, attitude, map interpolation).
    map_std : float
        Std (m) of the map's own depth error where the map carries none (a map gridded by
        ``tangraph maps grid``, a BAG or an S-102 file carries its own, per cell); 0: the map is
        the truth. See :mod:`tangraph.sensors.terrain` for how every estimator uses it.
    map_correlation_length : float
        Range (m) of the map error's spatial correlation where the map states none; 0: one
        cell of the map. Soundings closer than this share their map error, so they count as
        fewer independent ones (:func:`~tangraph.sensors.terrain.sounding_variances`).
    map_change_std, map_change_length : float
        The seafloor's change since the map was surveyed (m; 0, the default: none): a field of
        this std everywhere the map has data, of range ``map_change_length`` (m; 0: the map error's
        correlation length), added to the map's own stated error (which can only say how well the
        earlier surveys knew the seafloor then). A later survey's check lines against the map
        measure both (:func:`tangraph.eval.map_change.measure_change`, ``tangraph maps change``).
    misfit_dof, misfit_length : float
        The local misfit scale (:mod:`tangraph.sensors.misfit`): the filters hold how far the
        soundings err beyond the stated sounding and map errors as a variable shared along the
        track, with the tail of a Student-t of ``misfit_dof`` degrees of freedom, forgotten over
        ``misfit_length`` m (a patch of the map that errs beyond its statement). A map that
        states its tail (``BathymetryMap.error_dof``, from its check lines, which ``tangraph maps
        grid`` makes by default) gives its own; ``misfit_dof`` is the default for a map that states
        none; at 0 (the default) the stated errors are trusted everywhere (a Gaussian likelihood).
        The factor graph's fixes are not affected: each TAP window scales its fix by its own
        residual variance.
    tide, tide_std : float
        Prior mean and std (m) of the tide, ``measured = map + tide``.
    tide_drift_std, tide_drift_time : float
        The drift of the tide (m, s; ``tide_drift_std`` None by default: the drift the map states,
        else none, :meth:`with_map`; 0: a constant tide whatever the map states): the offset between
        the survey's depths and the map's wanders about its prior by a Gauss-Markov process of this
        std, forgetting over this time (the map's error that holds over a stretch of track, the
        water level between gauge readings, the sound speed). A drifting offset is estimated with
        the position instead of taken for the map's error, which would count an error that holds for
        hundreds of metres once per correlation length. The check lines of a map measure both
        (``tangraph maps grid``; :meth:`tangraph.eval.MapCheck.drift`), and a map that states its
        drift gives it to a model that states none (:meth:`with_map`). The filters hold the datum
        and the drift about it together (:mod:`tangraph.filters.tide`): a datum known only to metres
        is learnt once and kept while the drift is followed. The factor graph's fixes then take each
        window's tide from its soundings (criterion ``mle``) and are widened by the drift along
        their window; the bound (:func:`~tangraph.eval.posterior_crb`) holds the drift exactly,
        beside the constant tide.
    map_offset_std : float
        Std (m, per axis) of the map's horizontal offset against the survey's frame, one for the
        whole survey: the earlier surveys' position error that their runs share (a DGPS of a
        few metres wanders slowly), which moves the map as a whole where a correlated depth
        error cannot say it. 0 (default): the map lies where its coordinates say. Solved for by
        the batch smoother with ``smoother_terrain = "field"``, whose track then stays in the
        survey's frame while the soundings are matched to the map at the offset.
    map_offset_length : float
        How the map's horizontal offset varies over the map (m): 0 (default) one offset for the
        whole survey; > 0 a 2-D field of offsets, each axis a Matérn (nu = 1) field of std
        ``map_offset_std`` and this range (the earlier surveys' positioning error drifts, so the
        map is displaced patch by patch: about twice their speed times the time their GPS error
        takes to forget). A sounding sees the offset through the map's slope, ``g . o``, which
        no track can tell from its own position over one patch: the bound
        (:func:`~tangraph.eval.posterior_crb`) and the batch smoother's field solve
        (``smoother_terrain = "field"``) hold the offset as unknowns, and the part of the map's
        stated depth error that the offset explains through the slope is taken out of the depth
        field (:meth:`tangraph.sensors.MapError.without_offset`).
    robust_kernel : {"huber", "cauchy", "none"}
        The tail of a terrain fix's error in the factor graph: the M-estimator on each position
        fix's whitened error (a fix from a window whose map or pings err beyond their model is
        down-weighted instead of trusted).
    robust_parameter : float
        Its threshold on the whitened error norm (default 2.45, the 95 % point of a 2-D
        Gaussian's norm).
    fix_inflation : float
        A further factor (>= 1) on every fix's TAP covariance, for errors that neighbouring fixes
        share beyond their common pings (map error, patch shape); 1 by default.
    odometry_min_std, odometry_min_heading_std : float
        Floors (m, rad) added as variances to every odometry covariance of the factor graph, so
        it stays positive definite (a model without heading noise gives a singular one).

    Examples
    --------
    >>> import numpy as np
    >>> model = NavigationModel(speed_scale_std=0.02, heading_bias_std=np.deg2rad(2.0))
    >>> round(float(model.calibration_std[1]), 4)
    0.0349
    >>> NavigationModel(sounding_std=-1.0)
    Traceback (most recent call last):
    ...
    tangraph.errors.TangraphError: NavigationModel.sounding_std must be > 0, got -1.0
    """

    speed_noise: float = 0.05
    heading_noise: float = 0.0
    heading_walk: float = 0.0
    heading_turn_std: float = 0.0
    dropout_speed_noise: float = 0.0
    speed_scale: float = 0.0
    speed_scale_std: float = 0.02
    heading_bias: float = 0.0
    heading_bias_std: float = float(np.deg2rad(2.0))
    initial_position_std: float = 10.0
    sounding_std: float = 0.5
    map_std: float = 0.0
    map_correlation_length: float = 0.0
    map_change_std: float = 0.0
    map_change_length: float = 0.0
    misfit_dof: float = 0.0
    misfit_length: float = 200.0
    tide: float = 0.0
    tide_std: float = 3.0
    tide_drift_std: float | None = None
    tide_drift_time: float = 0.0
    map_offset_std: float = 0.0
    map_offset_length: float = 0.0
    robust_kernel: str = "huber"
    robust_parameter: float = 2.45
    fix_inflation: float = 1.0
    odometry_min_std: float = 0.01
    odometry_min_heading_std: float = 1e-4

    def __post_init__(self) -> None:
        for name in ("speed_noise", "heading_noise", "heading_walk", "heading_turn_std",
                     "dropout_speed_noise", "map_std", "map_correlation_length", "tide_std",
                     "map_change_std", "map_change_length",
                     "tide_drift_time",
                     "map_offset_std", "map_offset_length", "speed_scale_std", "heading_bias_std"):
            _number(self, name, low=0.0)
        _number(self, "misfit_dof", low=0.0)
        if self.tide_drift_std is not None:
            _number(self, "tide_drift_std", low=0.0)
        for name in ("initial_position_std", "sounding_std", "misfit_length"):
            _number(self, name, low=0.0, open_low=True)
        _number(self, "speed_scale", low=-0.5, high=0.5)
        _number(self, "heading_bias", low=-math.pi, high=math.pi)
        _number(self, "tide", low=None)
        for name in ("robust_parameter", "odometry_min_std", "odometry_min_heading_std"):
            _number(self, name, low=0.0, open_low=True)
        _number(self, "fix_inflation", low=1.0)
        if (self.tide_drift_std or 0.0) > 0 and not self.tide_drift_time > 0:
            raise TangraphError(f"NavigationModel.tide_drift_time must be > 0 s with tide_drift_std = "
                                f"{self.tide_drift_std:g} m (how long the tide's drift takes to forget), "
                                f"got {self.tide_drift_time!r}")
        if self.robust_kernel not in _KERNELS:
            raise TangraphError(f"NavigationModel.robust_kernel must be one of {', '.join(_KERNELS)}, "
                                f"got {self.robust_kernel!r}")

    # -- parts ---------------------------------------------------------------------------------
    @property
    def dead_reckoning(self) -> DeadReckoningModel:
        """The white part of the DR error model (constant errors zero): the noise of an increment
        of the *calibrated* dead reckoning (:func:`~tangraph.sensors.increment_covariance`)."""
        return DeadReckoningModel(heading_walk=self.heading_walk, heading_turn_std=self.heading_turn_std,
                                  heading_noise=self.heading_noise, speed_noise=self.speed_noise,
                                  dropout_speed_noise=self.dropout_speed_noise)

    @property
    def calibration_prior(self) -> np.ndarray:
        """Prior mean ``(k, b)`` of the constant DR errors."""
        return np.array([self.speed_scale, self.heading_bias])

    @property
    def calibration_std(self) -> np.ndarray:
        """Prior std ``(k, b)`` of the constant DR errors."""
        return np.array([self.speed_scale_std, self.heading_bias_std])

    @property
    def tide_variance(self) -> float:
        """Variance (m^2) of the tide about its prior mean at any time: the prior's and the
        drift's."""
        return self.tide_std**2 + (self.tide_drift_std or 0.0) ** 2

    @property
    def tide_drift(self) -> tuple[float, float] | None:
        """``(tide_drift_std, tide_drift_time)``, or None for a constant tide."""
        std = self.tide_drift_std or 0.0
        return (std, self.tide_drift_time) if std > 0 else None

    def tide_memory(self, dt: Any) -> Any:
        """How much of the tide's departure from its prior mean is kept after ``dt`` s (a number or
        an array) of drift, ``exp(-dt / tide_drift_time)`` (1 without a drift)."""
        if self.tide_drift is None:
            return np.ones_like(dt, dtype=np.float64) if np.ndim(dt) else 1.0
        keep = np.exp(-np.asarray(dt, dtype=np.float64) / self.tide_drift_time)
        return keep if np.ndim(dt) else float(keep)

    @property
    def measurement_std(self) -> float:
        """Std (m) of one sounding's residual against the map: sounding and map errors, and the
        seafloor's change since the map."""
        return float(np.sqrt(self.sounding_std**2 + self.map_std**2 + self.map_change_std**2))

    def replace(self, **changes: Any) -> NavigationModel:
        """A copy with some fields changed (checked again)."""
        return dataclasses.replace(self, **changes)

    def with_map(self, bathymetry: Any) -> NavigationModel:
        """The model an estimator navigates ``bathymetry`` with: its own tide drift where it states
        one (``tide_drift_std`` not None; 0: a constant tide), else the drift the map states
        (``BathymetryMap.error_drift``, which ``tangraph maps grid`` measures on its check
        lines), else a constant tide."""
        drift = getattr(bathymetry, "error_drift", None)
        if self.tide_drift_std is not None or drift is None:
            return self
        return self.replace(tide_drift_std=float(drift[0]), tide_drift_time=float(drift[1]))

    def as_dict(self) -> dict[str, float | str | None]:
        """JSON-ready form, kept in a track's metadata."""
        return {k: v if v is None or isinstance(v, str) else float(v)
                for k, v in dataclasses.asdict(self).items()}

    # -- construction --------------------------------------------------------------------------
    @classmethod
    def from_dead_reckoning(cls, dr: DeadReckoningModel, **overrides: Any) -> NavigationModel:
        """The model of a :class:`DeadReckoningModel` (a simulated DR's settings): its white errors
        as they are, its constant errors as priors of mean zero whose std is the larger of the
        stated default and the magnitude of the simulated error (the simulated values are the
        unknown truth, not the estimators' knowledge), a compass deviation curve as the walk
        with the angle turned it gives (``heading_turn_std = sqrt(2) heading_deviation``: the
        estimators know its size, not its curve), and the start uncertainty its
        ``start_position_std`` (at least 0.1 m). ``overrides`` replace any field."""
        if not isinstance(dr, DeadReckoningModel):
            raise TangraphError(f"dead-reckoning model must be a DeadReckoningModel, got {type(dr).__name__}")
        default = cls()
        fields = {
            "speed_noise": dr.speed_noise, "heading_noise": dr.heading_noise,
            "heading_walk": dr.heading_walk,
            "heading_turn_std": max(dr.heading_turn_std, math.sqrt(2.0) * dr.heading_deviation),
            "dropout_speed_noise": dr.dropout_speed_noise,
            "speed_scale_std": max(default.speed_scale_std, abs(dr.speed_scale)),
            "heading_bias_std": max(default.heading_bias_std, abs(dr.heading_bias)),
            "initial_position_std": max(dr.start_position_std, 0.1),
        }
        return cls(**(fields | overrides))

    @classmethod
    def from_survey(cls, survey: Any, **overrides: Any) -> NavigationModel:
        """The model of a simulated survey, from the settings it records (``meta["settings"]``):
        the DR as :meth:`from_dead_reckoning`; ``sounding_std`` 1.5 times the sonar's
        ``depth_noise`` (the margin covers map interpolation and attitude errors), at least 0.2 m;
        the tide prior of mean zero and std 3 m, drifting as the sonar's ``tide_drift_std``
        and ``tide_drift_time`` say; with a prior map gridded from an earlier survey (a
        ``[prior_map]``, :mod:`tangraph.sim.seafloor`), the map's horizontal offset that its
        gridding kept of that survey's GPS error (``meta["seafloor"]``'s ``map_offset_std``
        and ``map_offset_length``) and the seafloor's change since (``map_change_std`` and
        ``map_change_length``: the RMS and range of the change the world drew).
        ``overrides`` replace any field.

        Raises
        ------
        TangraphError
            The survey records no dead-reckoning settings (a recorded survey: use
            :func:`load_navigation_model` or the constructor with the instrument's figures).
        """
        settings: Any = survey.meta.get("settings") if isinstance(survey.meta, dict) else None
        try:
            table = dict(settings["dead_reckoning"])
        except (KeyError, TypeError):
            raise TangraphError(
                "this survey does not record its dead-reckoning error model (meta['settings']"
                "['dead_reckoning']): give a NavigationModel (a TOML file with --dr-model on the "
                "command line) with the INS/DVL's errors"
            ) from None
        try:
            dr = DeadReckoningModel(**table)
        except TypeError as exc:
            raise TangraphError(
                f"survey meta['settings']['dead_reckoning'] is not a DR model: {exc}"
            ) from None
        terrain: dict[str, Any] = {}
        try:
            noise = float(settings["sonar"]["depth_noise"])
            if np.isfinite(noise) and noise >= 0:
                terrain["sounding_std"] = max(1.5 * noise, 0.2)
        except (KeyError, TypeError, ValueError):
            pass
        sonar = settings.get("sonar")
        drift = [sonar.get(k, 0.0) if isinstance(sonar, dict) else 0.0
                 for k in ("tide_drift_std", "tide_drift_time")]
        if all(isinstance(v, (int, float)) and np.isfinite(v) and v > 0 for v in drift):
            terrain["tide_drift_std"], terrain["tide_drift_time"] = float(drift[0]), float(drift[1])
        world = survey.meta.get("seafloor")  # the offset a prior map's gridding kept, the change since
        for keys in (("map_offset_std", "map_offset_length"), ("map_change_std", "map_change_length")):
            values = [world.get(k, 0.0) if isinstance(world, dict) else 0.0 for k in keys]
            if all(isinstance(v, (int, float)) and np.isfinite(v) and v > 0 for v in values):
                terrain |= {k: float(v) for k, v in zip(keys, values, strict=True)}
        return cls.from_dead_reckoning(dr, **(terrain | overrides))

    @classmethod
    def from_mapping(cls, table: dict, where: str = "navigation model") -> NavigationModel:
        """The model of a table of field names (an angle field may be given in degrees as
        ``NAME_deg``); an unknown key or a bad value is refused, naming it and ``where``."""
        fields = {f.name for f in dataclasses.fields(cls)}
        values: dict[str, Any] = {}
        for key, value in table.items():
            if key == "map_error_shared":
                raise TangraphError(
                    f"{where}: map_error_shared is no longer a setting: every estimator counts the "
                    "soundings that share a map error (set map_std and map_correlation_length, or use "
                    "a map that carries its depth_std)"
                )
            name = key[:-4] if key.endswith("_deg") else key
            if name not in fields or (key.endswith("_deg") and name not in _ANGLES):
                allowed = sorted(fields | {f"{a}_deg" for a in _ANGLES})
                raise TangraphError(f"{where}: unknown key {key!r}; allowed: {', '.join(allowed)}")
            if name in values:
                raise TangraphError(f"{where}: {name} is given twice (as {name} and {name}_deg)")
            if key.endswith("_deg"):
                try:
                    value = math.radians(float(value))
                except (TypeError, ValueError):
                    raise TangraphError(f"{where}: {key} must be a number, got {value!r}") from None
            values[name] = value
        try:
            return cls(**values)
        except TangraphError as exc:
            raise TangraphError(f"{where}: {exc}") from None


def survey_navigation_model(survey: Any, model: NavigationModel | None, *, where: str = "",
                            bathymetry: Any = None) -> NavigationModel:
    """``model``, or if None the model of a simulated survey (:meth:`NavigationModel.from_survey`),
    with the tide drift ``bathymetry`` states if it states none (:meth:`NavigationModel.with_map`):
    the one place every estimator resolves its model.

    Raises
    ------
    TangraphError
        ``model`` is not a NavigationModel, or is None for a survey that records no DR model;
        the message starts with ``where`` when given.
    """
    prefix = f"{where}: " if where else ""
    if model is None:
        try:
            model = NavigationModel.from_survey(survey)
        except TangraphError as exc:
            raise TangraphError(f"{prefix}{exc}") from None
    if not isinstance(model, NavigationModel):
        raise TangraphError(
            f"{prefix}model must be a tangraph.sensors.NavigationModel (or None), got {type(model).__name__}"
        )
    return model.with_map(bathymetry)


def load_navigation_model(path: str | os.PathLike) -> NavigationModel:
    """A :class:`NavigationModel` from a TOML file: its fields at the top level or in a
    ``[navigation]`` table; angles in radians, or in degrees as ``NAME_deg``. Fields not given
    keep their stated defaults.

    Examples
    --------
    The file of a recorded survey's INS/DVL might read::

        speed_noise = 0.05           # m/s
        heading_walk_deg = 0.01      # deg / sqrt(s)
        speed_scale_std = 0.02       # 2 % scale-factor uncertainty
        heading_bias_std_deg = 2.0
        initial_position_std = 5.0   # m
        sounding_std = 0.3           # m
    """
    table = read_table(path, "navigation", "navigation model file")
    return NavigationModel.from_mapping(table, str(path))
