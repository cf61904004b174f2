"""`GraphConfig`: the algorithm settings of the factor-graph navigators (online iSAM2 and batch
smoother), in three parts by role: :class:`FixConfig` (what a TAP window is, how its fix is
searched and accepted), :class:`OnlineConfig` (iSAM2, the online front end and fix policy) and
:class:`BatchConfig` (the batch smoother's solve). Their model (the tail of the fixes' errors, the
odometry's floors) is the navigation model's (:class:`~tangraph.sensors.NavigationModel`)."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping
from typing import Any, Literal

import numpy as np

from tangraph.errors import TangraphError
from tangraph.matching import TapConfig
from tangraph.validation import check_number

__all__ = ["BatchConfig", "FixConfig", "GraphConfig", "OnlineConfig", "load_graph_config"]

_TAP_DEFAULT = TapConfig()
_STEP_CELLS = 0.5  # FixConfig.tap_step_cells' default
_FRONT_END_PINGS = 3  # OnlineConfig.front_end_pings' default
# Settings that were removed, with where their job went (an old config naming one is refused).
_MOVED = "moved to NavigationModel.{0} (a model file's [navigation] table)"
_REMOVED = {
    **{name: _MOVED.format(name) for name in ("robust_kernel", "robust_parameter", "fix_inflation",
                                                "odometry_min_std", "odometry_min_heading_std")},
    "estimate_calibration": "a model whose speed_scale_std and heading_bias_std are 0 keeps the DR's "
                            "constant errors at their prior mean (NavigationModel)",
    "optimizer": "the batch solve is Gauss-Newton with step halving for every graph "
                 "(tangraph.graph.batch.gauss_newton): remove the key",
}


def _integer(config: Any, name: str, low: int, *, optional: bool = False) -> None:
    """``config.name`` an integer >= ``low`` (or None when ``optional``), stored as ``int``."""
    value = getattr(config, name)
    if optional and value is None:
        return
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < low:
        kind = f"None or an integer >= {low}" if optional else f"an integer >= {low}"
        raise TangraphError(f"{type(config).__name__}.{name} must be {kind}, got {value!r}")
    object.__setattr__(config, name, int(value))


def _probability(config: Any, name: str, *, optional: bool = False) -> None:
    """``config.name`` in (0, 1) (or None when ``optional``)."""
    value = getattr(config, name)
    if optional and value is None:
        return
    if isinstance(value, bool) or not isinstance(value, int | float | np.floating) or not 0.0 < value < 1.0:
        kind = "None or lie in (0, 1)" if optional else "lie in (0, 1)"
        raise TangraphError(f"{type(config).__name__}.{name} must {kind}, got {value!r}")


def _choice(config: Any, name: str, allowed: tuple[str, ...]) -> None:
    if getattr(config, name) not in allowed:
        raise TangraphError(f"{type(config).__name__}.{name} must be one of {', '.join(allowed)}, "
                            f"got {getattr(config, name)!r}")


@dataclasses.dataclass(frozen=True)
class FixConfig:
    """What a TAP window is, and how its fix is searched and accepted (``GraphConfig.fixes``;
    ``[graph.fixes]`` in a file, its TapConfig in ``[graph.fixes.tap]``).

    Parameters
    ----------
    n_pings : int
        Pings per TAP window (default 20).
    fix_spacing : int or None
        Pings between consecutive window ends (default 10: windows overlap by half, which on the
        shipped scenarios gave the lowest smoother RMSE; see the graph_vs_filters study); None:
        ``n_pings`` (windows that do not overlap).
    ramp_pings : int or None
        Before the first full window, windows of this many pings every this many pings (default
        5), so the first fix comes after 5 pings instead of ``n_pings``; None waits for a full
        window. A window's TAP covariance is multiplied by how many windows hold its pings on
        average (:func:`~tangraph.graph.keyposes.fix_windows`), so overlapping windows count
        every sounding once.
    tap : TapConfig
        Settings of each fix. Its ``half_width`` is used only with ``half_width_rule =
        "fixed"`` (a ``half_width`` other than TapConfig's default with the ``"marginal"`` rule
        is refused: it would not be used); its ``step``, when given, is the search step in
        metres (then ``tap_step_cells`` must keep its default).
    tap_step_cells : float
        Without ``tap.step``, the search step in map cells (default half a cell: on whole-cell
        steps a fix is quantised to the grid around its prior and follows the prior by up to
        half a cell, which the graph would then count twice).
    accept_multimodal : bool
        Use a fix whose calibrated region has several parts (two places fit), with the
        covariance of its normalised likelihood over the whole search (``TapConfig.covariance
        = "region"``), which spans every part; it still passes the gate and the robust kernel
        (default: on the shipped scenarios with drifting DR it lowered the online graph's RMSE
        by 10-25 % and kept the fix coverage at 0.96-1.00; see the graph_vs_filters study).
        False refuses such fixes.
    gate_probability : float or None
        A fix is refused when its NIS ``e^T (P_fix + P_pred)^-1 e`` against the predicted
        marginal exceeds the ``chi2(2)`` quantile of this probability; None: no gate.
    half_width_rule : {"marginal", "fixed"}
        ``"marginal"``: the search half-width of each fix is ``half_width_sigmas`` times the
        square root of the largest eigenvalue of the predicted position covariance, clipped to
        ``[min_half_width_cells, max_half_width_cells]`` map cells; ``"fixed"``: ``tap.half_width``.
    half_width_sigmas, min_half_width_cells, max_half_width_cells : float
    misfit_ratio : float or None
        A fix whose residual std at its best match exceeds this many times the navigation
        model's ``measurement_std``, and (from the survey's third window) as many times the
        median of the last ten windows' (a patch laid with DR whose constant errors are not yet
        known fits the map worse, window after window), is refused as ``MISFIT`` (the window's
        soundings fit the map nowhere: part of its pings in error) and is no evidence of being
        lost; None: no such test (default 3).
    """

    n_pings: int = 20
    fix_spacing: int | None = 10
    ramp_pings: int | None = 5
    tap: TapConfig = dataclasses.field(default_factory=TapConfig)
    tap_step_cells: float = _STEP_CELLS
    accept_multimodal: bool = True
    gate_probability: float | None = 0.999
    half_width_rule: Literal["marginal", "fixed"] = "marginal"
    half_width_sigmas: float = 4.0
    min_half_width_cells: float = 5.0
    max_half_width_cells: float = 200.0
    misfit_ratio: float | None = 3.0

    def __post_init__(self) -> None:
        if isinstance(self.tap, Mapping):  # a table of its fields (TOML, JSON)
            object.__setattr__(self, "tap", TapConfig(**self.tap))
        if not isinstance(self.tap, TapConfig):
            raise TangraphError(f"FixConfig.tap must be a TapConfig, got {type(self.tap).__name__}")
        for name in ("tap_step_cells", "half_width_sigmas", "min_half_width_cells", "max_half_width_cells"):
            check_number(self, name, open_low=True)
        if self.misfit_ratio is not None:
            check_number(self, "misfit_ratio", open_low=True)
        if self.max_half_width_cells < self.min_half_width_cells:
            raise TangraphError(
                f"FixConfig: max_half_width_cells ({self.max_half_width_cells}) is below "
                f"min_half_width_cells ({self.min_half_width_cells})"
            )
        _integer(self, "n_pings", 1)
        _integer(self, "fix_spacing", 1, optional=True)
        _integer(self, "ramp_pings", 1, optional=True)
        _probability(self, "gate_probability", optional=True)
        object.__setattr__(self, "accept_multimodal", bool(self.accept_multimodal))
        _choice(self, "half_width_rule", ("marginal", "fixed"))
        if self.half_width_rule == "marginal" and self.tap.half_width != _TAP_DEFAULT.half_width:
            raise TangraphError(
                f"FixConfig: tap.half_width = {self.tap.half_width!r} is not used with half_width_rule "
                "= 'marginal' (the half-width comes from the predicted covariance): set half_width_rule "
                "= 'fixed' to use it, or leave it out"
            )
        if self.tap.step is not None and self.tap_step_cells != _STEP_CELLS:
            raise TangraphError(
                f"FixConfig: tap.step ({self.tap.step!r} m) and tap_step_cells ({self.tap_step_cells!r} "
                "cells) both set the search step: give one"
            )

    @property
    def spacing(self) -> int:
        """Pings between consecutive TAP window ends."""
        return self.n_pings if self.fix_spacing is None else self.fix_spacing


@dataclasses.dataclass(frozen=True)
class OnlineConfig:
    """The online navigator's settings: iSAM2, its terrain front end and its fix policy
    (``GraphConfig.online``; ``[graph.online]`` in a file).

    Parameters
    ----------
    front_end : {"tap", "pmf"}
        What turns a window's soundings into the online graph's terrain factor. ``"tap"``
        (default): a TAP fix (:mod:`tangraph.graph.fixes`) searched around the prediction.
        ``"pmf"``: the window's posterior on a point-mass grid laid on the prediction, with the
        prediction's information removed (:mod:`tangraph.graph.posterior_fix`); its windows
        end every ``front_end_pings`` pings and share no ping (``FixConfig.fix_spacing`` and
        ``ramp_pings`` are TAP's); a multimodal window is never given as one Gaussian: like an
        uninformative one it is held and grown by the next ``front_end_pings`` pings, up to
        ``FixConfig.n_pings`` pings, before it is given up. With the calibration estimated and
        an uncertain tide (``NavigationModel.tide_std > 0``) the online graph holds the tide as
        a variable, and each window's factor is on its end position and the tide
        (``Track.meta["tide"]``). It is the online graph's only: the batch smoother always
        weighs TAP fixes (it re-matches its windows around the smoothed track with TAP, and on
        the front end's short windows it was 1.5-2.2 x less accurate in the graph_vs_filters
        study). A window whose depths fit a depth offset of their own far better than the held
        tide is a depth fault (``MISFIT``), and when the windows find one offset over 40 pings
        the tide steps (:mod:`tangraph.graph.posterior_fix`,
        :func:`tangraph.graph.online_fixes.tide_step`). It is for clean simulated data: shifted
        footprints and a wrong start make it fail where TAP holds (the robustness study), and
        on a recorded lake survey it converged on the map's noise (the caputh_replay study).
    terrain : {"fixes", "soundings"}
        What the online graph weighs of the terrain once it has found the vehicle: ``"fixes"``,
        a window's fix (``front_end``) at every window end (default); ``"soundings"``, every
        sounding (:mod:`tangraph.graph.online_terrain`). Once the vehicle is found (``acquire``),
        and while the map is near its tangent plane over the belief, the soundings of each key's
        pings enter iSAM2 as one terrain factor on that key, the calibration and the tide (a
        variable then). The windows are then searched as checks only (``FixStatus.CHECKED``),
        and take over again when a check says the prediction is wrong, the belief grows too wide
        for the linearisation, or most pings stop fitting the map. Only with ``front_end =
        "tap"``; the batch smoother's forward pass weighs fixes (``BatchConfig.smoother_terrain``).
    acquire : {"windows", "pmf"}
        How the online graph finds the vehicle to track on soundings: TAP windows and the fix policy
        (default) or a point-mass filter (:mod:`tangraph.graph.acquisition`; only with soundings).
    front_end_pings : int
        Pings per window of the point-mass front end, so only with ``front_end = "pmf"`` (another
        value with ``"tap"`` is refused: it would not be used; default 3: on three seeds each of
        ``demo``, ``wang2019`` and ``han2020`` windows of 2 and 3 pings gave the lowest online
        RMSE, 5, 10 and 20 pings more, a single ping much more; see the graph_vs_filters study).
    relinearize_threshold, relinearize_position : float
        iSAM2 relinearises a pose whose update exceeds this in heading (rad) or in position (m);
        a Pose2 chain is nonlinear in the heading only.
    relinearize_skip : int
        iSAM2 checks for relinearisation every this many updates.
    isam_window : int or None
        Key poses kept in iSAM2: once there are twice as many, the oldest are marginalised (their
        information stays as a linear marginal factor), so the time per update does not grow
        with the mission; None keeps all (the update then slows as the chain grows, since every
        new fix moves the whole past). The batch smoother always uses every key pose.
    confirm_probability : float or None
        The online navigator uses a fix at once when its NIS against the prediction is below
        the ``chi2(2)`` quantile of this probability; one between that and the gate waits for the
        next accepted fix, as surprising, to agree with it through the DR (it is used then, late,
        or dropped as ``UNCONFIRMED``): a fix from a window spoiled by a few bad pings is seldom
        confirmed, and a vague fix, which agrees with the prediction as well, confirms nothing.
        None: every fix within the gate is used at once (default 0.9).
    lost_windows : int or None
        Lost and relocalisation of the online navigator (:mod:`tangraph.graph.policy`). After this
        many TAP windows since the last *trusted* fix (one a later fix from a disjoint window
        agreed with) whose precise fix says the prediction is wrong (its best match on the edge
        of the search, ``FixStatus.OUTSIDE_SEARCH``, or beyond the gate, ``GATE``), the navigator
        is *lost*: it gives up the fixes used since the last trusted one, widens its belief by a
        *break* (the start's prior when no fix was ever trusted, else the odometry into that
        key gets an extra position std of the search's half-width, so the next searches are
        four times as wide, up to ``FixConfig.max_half_width_cells``, and the covariance it
        reports says how little it knows), searches that window again, and widens again after
        every further ``lost_windows`` such windows. It relocalises on ``relocalise_fixes``
        precise fixes that agree with each other through the DR (informative, unimodal, inside
        the search) from windows that share no ping (which one block of bad pings cannot fake),
        or ends the episode when a precise fix agrees with the belief it gave up. Fixes refused
        only by the gate while tracking are weighed the same way: when enough of them agree,
        the prediction was the wrong one, and the navigator breaks its odometry by their
        distance from it and adds them. The pings from the last trusted fix to the end of the
        episode are flagged lost (``Track.meta["lost_steps"]``). None: never lost (default 4).
    relocalise_fixes : int
        Agreeing fixes, from windows that share no ping, that end a lost episode (default 2).
    """

    front_end: Literal["tap", "pmf"] = "tap"
    terrain: Literal["fixes", "soundings"] = "fixes"
    acquire: Literal["windows", "pmf"] = "windows"
    front_end_pings: int = _FRONT_END_PINGS
    relinearize_threshold: float = 0.005
    relinearize_position: float = 1.0
    relinearize_skip: int = 1
    isam_window: int | None = 100
    confirm_probability: float | None = 0.9
    lost_windows: int | None = 4
    relocalise_fixes: int = 2

    def __post_init__(self) -> None:
        _choice(self, "front_end", ("tap", "pmf"))
        _choice(self, "terrain", ("fixes", "soundings"))
        _choice(self, "acquire", ("windows", "pmf"))
        if self.acquire == "pmf" and self.terrain != "soundings":
            raise TangraphError("OnlineConfig.acquire = 'pmf' tracks on soundings: set terrain = 'soundings'")
        if self.terrain == "soundings" and self.front_end != "tap":
            raise TangraphError("OnlineConfig: terrain = 'soundings' takes over from TAP windows once the "
                                f"vehicle is found, not from front_end = {self.front_end!r}: set "
                                "front_end = 'tap' or terrain = 'fixes'")
        _integer(self, "front_end_pings", 1)
        if self.front_end == "tap" and self.front_end_pings != _FRONT_END_PINGS:
            raise TangraphError(f"OnlineConfig: front_end_pings = {self.front_end_pings} is the point-mass "
                                "front end's and is not used with front_end = 'tap': set front_end = 'pmf' "
                                "to use it, or leave it out")
        check_number(self, "relinearize_threshold", open_low=True)
        check_number(self, "relinearize_position", open_low=True)
        _integer(self, "relinearize_skip", 1)
        _integer(self, "isam_window", 2, optional=True)
        _probability(self, "confirm_probability", optional=True)
        _integer(self, "lost_windows", 1, optional=True)
        _integer(self, "relocalise_fixes", 1)

    @property
    def learns_tide(self) -> bool:
        """Whether the online graph's terrain tells the tide (the point-mass front end's windows,
        the soundings while tracking): it then holds the tide as a variable."""
        return self.front_end == "pmf" or self.terrain == "soundings"


@dataclasses.dataclass(frozen=True)
class BatchConfig:
    """The batch smoother's solve (``GraphConfig.batch``; ``[graph.batch]`` in a file).

    Parameters
    ----------
    max_iterations : int
        Of the batch solve (Gauss-Newton with step halving on a METIS ordering,
        :func:`tangraph.graph.batch.gauss_newton`, for every graph).
    smoother_covariance : {"all", "none"}
        Marginal covariances of every key pose after the batch solve (about 3 s per 100 000
        key poses), or none (the track's covariance is NaN).
    rematch_iterations : int
        After the batch solve, re-run TAP around the smoothed track (patches laid with the
        smoothed poses, search half-widths from the smoothed marginals) and re-solve, at most
        this many times, until no fix moves by more than ``rematch_tolerance`` metres and the
        set of accepted fixes stays the same.
    rematch_tolerance : float
        Metres (see ``rematch_iterations``).
    robust_solve : {"gnc", "none"}
        ``"gnc"`` decides which fixes (those the online pass accepted, gated or held as
        relocalisation candidates) and whether the start position prior are inliers by
        graduated non-convexity with a truncated least-squares loss (Yang et al. 2020, the rules
        of GTSAM's ``GncOptimizer``; see :mod:`tangraph.graph.robust`), then solves with the
        inliers only, so the covariances are those of the fixes kept; ``"none"``: the fixes the
        online pass accepted, under ``NavigationModel.robust_kernel``.
    gnc_probability : float
        A GNC candidate is an inlier while its whitened squared error is below the
        ``chi2(dim)`` quantile of this probability (default 0.99).
    smoother_terrain : {"fixes", "soundings", "field"}
        What the final solve sees of the terrain: ``"fixes"``, one TAP fix per window
        (default); ``"soundings"``, every sounding as its own factor on a key pose at its ping
        (:mod:`tangraph.graph.terrain_factors`), iterated from the fixes' solution, which the
        soundings then replace (the same soundings are not counted twice), the map's error
        widening each sounding's variance; ``"field"``, every sounding with the map's error as
        a field of unknowns solved with the track (:mod:`tangraph.graph.field_solve`: its
        covariance is the map-aware bound's, and the track carries the refined map in
        ``meta["refined_map"]``; as ``"soundings"`` on a map that states no error). On
        simulated surveys whose map errs as it states, ``"soundings"`` is at the Cramér-Rao
        bound; both trust the stated map error far more than the fixes do, so on a recorded
        survey use them only with a map whose error check lines confirm (``tangraph maps
        check``): on Lake Caputh's map, whose error is heavy-tailed, the track ANEES with
        ``"soundings"`` was 3-160 (fixes: 0-6).
    """

    max_iterations: int = 100
    smoother_covariance: Literal["all", "none"] = "all"
    rematch_iterations: int = 2
    rematch_tolerance: float = 0.5
    robust_solve: Literal["gnc", "none"] = "gnc"
    gnc_probability: float = 0.99
    smoother_terrain: Literal["fixes", "soundings", "field"] = "fixes"

    def __post_init__(self) -> None:
        _integer(self, "max_iterations", 1)
        _choice(self, "smoother_covariance", ("all", "none"))
        _integer(self, "rematch_iterations", 0)
        check_number(self, "rematch_tolerance")
        _choice(self, "robust_solve", ("gnc", "none"))
        _probability(self, "gnc_probability")
        _choice(self, "smoother_terrain", ("fixes", "soundings", "field"))


_PARTS: dict[str, type] = {"fixes": FixConfig, "online": OnlineConfig, "batch": BatchConfig}
# which part holds each of the parts' fields (their names are unique across the parts)
_PART_OF = {f.name: part for part, kind in _PARTS.items() for f in dataclasses.fields(kind)}


@dataclasses.dataclass(frozen=True)
class GraphConfig:
    """Settings of :class:`~tangraph.graph.GraphNavigator`, :func:`~tangraph.graph.navigate_online`
    and :func:`~tangraph.graph.smooth_survey`: the key-pose interval and three parts by role.

    Parameters
    ----------
    key_interval : float
        Seconds: a key pose at least this often; there is also one at every window end, at the
        first and at the last ping.
    fixes : FixConfig
        The TAP windows and their fixes, online and in the batch smoother.
    online : OnlineConfig
        iSAM2, the online front end and fix policy.
    batch : BatchConfig
        The batch smoother's solve.

    :meth:`replace` changes fields of any part by name.

    Examples
    --------
    >>> config = GraphConfig().replace(n_pings=20, fix_spacing=None)
    >>> config.spacing, config.fixes.gate_probability
    (20, 0.999)
    >>> GraphConfig().replace(front_end="ekf")
    Traceback (most recent call last):
    ...
    tangraph.errors.TangraphError: OnlineConfig.front_end must be one of tap, pmf, got 'ekf'
    """

    key_interval: float = 60.0
    fixes: FixConfig = dataclasses.field(default_factory=FixConfig)
    online: OnlineConfig = dataclasses.field(default_factory=OnlineConfig)
    batch: BatchConfig = dataclasses.field(default_factory=BatchConfig)

    def __post_init__(self) -> None:
        check_number(self, "key_interval", open_low=True)
        for part, kind in _PARTS.items():
            value = getattr(self, part)
            if isinstance(value, Mapping):  # a table of its fields (TOML, JSON)
                object.__setattr__(self, part, kind(**value))
            elif not isinstance(value, kind):
                raise TangraphError(f"GraphConfig.{part} must be a {kind.__name__}, "
                                    f"got {type(value).__name__}")

    @classmethod
    def from_mapping(cls, fields: Mapping[str, Any], where: str = "GraphConfig") -> GraphConfig:
        """A config from a mapping as a file holds it: ``key_interval`` and the tables
        ``fixes`` (with ``tap``), ``online`` and ``batch`` of their parts' fields. Unknown names
        are refused, naming ``where``; so is a part's field at the top level, naming its table.

        >>> config = GraphConfig.from_mapping({"fixes": {"n_pings": 60, "tap": {"criterion": "msd"}}})
        >>> config.fixes.tap.criterion.value
        'msd'
        >>> GraphConfig.from_mapping({"n_pings": 60}, "a.toml")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        tangraph.errors.TangraphError: a.toml: GraphConfig.n_pings is now in the fixes part ([graph.fixes] ...
        >>> GraphConfig.from_mapping({"fix_inflation": 2.0}, "a.toml")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        tangraph.errors.TangraphError: a.toml: GraphConfig.fix_inflation is no longer a setting: moved to ...
        """
        fields = dict(fields)
        for name in sorted(fields):
            if name in _REMOVED or name in _PART_OF or name == "tap":
                raise TangraphError(f"{where}: {_moved(name)}")
        unknown = sorted(set(fields) - {f.name for f in dataclasses.fields(cls)})
        if unknown:
            raise TangraphError(f"{where}: unknown GraphConfig field {unknown[0]!r}")
        for part, kind in _PARTS.items():
            table = fields.get(part, {})
            if not isinstance(table, Mapping):
                raise TangraphError(f"{where}: GraphConfig.{part} must be a table of {kind.__name__} fields")
            _check_names(table, kind, where)
            if part == "fixes" and isinstance(table.get("tap"), Mapping):
                _check_names(table["tap"], TapConfig, where)
        return cls(**fields)

    def replace(self, **changes: Any) -> GraphConfig:
        """A copy with fields changed by name, whichever part holds them (``n_pings=60``,
        ``front_end="pmf"``, ``smoother_terrain="soundings"``; ``tap`` a TapConfig or a mapping
        of its fields); checked again. A study's ``--graph FIELD=VALUE`` options come here.

        >>> GraphConfig().replace(n_pings=60, smoother_terrain="soundings").batch.smoother_terrain
        'soundings'
        """
        for name in sorted(changes):
            if name in _REMOVED:
                raise TangraphError(_moved(name))
            if name not in _PART_OF and name not in {f.name for f in dataclasses.fields(self)}:
                raise TangraphError(f"unknown GraphConfig field {name!r}")
        own = {k: v for k, v in changes.items() if k not in _PART_OF}
        for part in _PARTS:
            mine = {k: v for k, v in changes.items() if _PART_OF.get(k) == part}
            if mine:
                own[part] = dataclasses.replace(own.get(part, getattr(self, part)), **mine)
        return dataclasses.replace(self, **own)

    @property
    def spacing(self) -> int:
        """Pings between consecutive window ends (the front end's)."""
        return self.online.front_end_pings if self.online.front_end == "pmf" else self.fixes.spacing

    @property
    def window(self) -> int:
        """Pings per window (the front end's)."""
        return self.online.front_end_pings if self.online.front_end == "pmf" else self.fixes.n_pings

    def as_dict(self) -> dict:
        """JSON-ready form (the parts as tables), kept in a track's metadata."""
        out = dataclasses.asdict(self)
        tap = out["fixes"]["tap"]
        out["fixes"]["tap"] = {k: (v.value if hasattr(v, "value") else v) for k, v in tap.items()}
        out["fixes"]["tap"]["headings"] = list(tap["headings"])
        return out


def _moved(name: str) -> str:
    if name in _REMOVED:
        return f"GraphConfig.{name} is no longer a setting: {_REMOVED[name]}"
    part = _PART_OF.get(name, "fixes")
    return f"GraphConfig.{name} is now in the {part} part ([graph.{part}] in a file)"


def _check_names(table: Mapping[str, Any], kind: type, where: str) -> None:
    unknown = sorted(set(table) - {f.name for f in dataclasses.fields(kind)})
    if unknown:
        raise TangraphError(f"{where}: unknown {kind.__name__} field {unknown[0]!r}")


def load_graph_config(path: str | os.PathLike) -> GraphConfig:
    """A :class:`GraphConfig` from a TOML file: ``key_interval`` at the top level or in a
    ``[graph]`` table, the parts' fields in ``[graph.fixes]`` (TapConfig's in
    ``[graph.fixes.tap]``), ``[graph.online]`` and ``[graph.batch]``; fields not given keep their
    defaults (CLI: ``--graph-config``)."""
    from tangraph.tomlfile import read_table

    table = read_table(path, "graph", "graph config file")
    return GraphConfig.from_mapping(table, str(path))
