"""`GraphConfig`: the algorithm settings of the factor-graph navigators (online iSAM2 and batch
smoother). Their model (the tail of the fixes' errors, the odometry's floors) is the navigation
model's (:class:`~tangraph.sensors.NavigationModel`)."""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Mapping
from typing import Any, Literal

import numpy as np

from tangraph.errors import TangraphError
from tangraph.matching import TapConfig
from tangraph.validation import check_number

__all__ = ["GraphConfig", "load_graph_config"]

_TAP_DEFAULT = TapConfig()
_STEP_CELLS = 0.5  # GraphConfig.tap_step_cells' default
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


def _number(config: GraphConfig, name: str, *, allow_zero: bool = False) -> None:
    check_number(config, name, open_low=not allow_zero)


@dataclasses.dataclass(frozen=True)
class GraphConfig:
    """Settings of :class:`~tangraph.graph.GraphNavigator`, :func:`~tangraph.graph.navigate_online`
    and :func:`~tangraph.graph.smooth_survey`.

    Parameters
    ----------
    key_interval : float
        Seconds: a key pose at least this often; there is also one at every TAP window end, at the
        first and at the last ping.
    front_end : {"tap", "pmf"}
        What turns a window's soundings into the online graph's terrain factor. ``"tap"``
        (default): a TAP fix (:mod:`tangraph.graph.fixes`) searched around the prediction.
        ``"pmf"``: the window's posterior on a point-mass grid laid on the prediction, with the
        prediction's information removed (:mod:`tangraph.graph.posterior_fix`); its windows
        end every ``front_end_pings`` pings and share no ping (``fix_spacing`` and
        ``ramp_pings`` are TAP's); a multimodal window is never given as one Gaussian: like an
        uninformative one it is held and grown by the next ``front_end_pings`` pings, up to
        ``n_pings`` pings, before it is given up. With the
        calibration estimated and an uncertain tide (``NavigationModel.tide_std > 0``) the
        online graph holds the tide as a variable, and each window's factor is on its end
        position and the tide (``Track.meta["tide"]``). It is the online graph's only: the batch
        smoother always weighs TAP fixes (it re-matches its windows around the smoothed track
        with TAP, and on the front end's short windows it was 1.5-2.2 x less accurate in the
        graph_vs_filters study). A window whose depths fit a depth offset of their own far
        better than the held tide is a depth fault (``MISFIT``), and when the windows find one
        offset over 40 pings the tide steps (:mod:`tangraph.graph.posterior_fix`,
        :func:`tangraph.graph.online_fixes.tide_step`). It is for clean simulated data: shifted
        footprints and a wrong start make it fail where TAP holds (the robustness study), and
        on a recorded lake survey it converged on the map's noise (the caputh_replay study).
    front_end_pings : int
        Pings per window of the point-mass front end (default 3: on three seeds each of
        ``demo``, ``wang2019`` and ``han2020`` windows of 2 and 3 pings gave the lowest online
        RMSE, 5, 10 and 20 pings more, a single ping much more; see the graph_vs_filters study).
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
    lost_windows : int or None
        Lost and relocalisation of the online navigator (:mod:`tangraph.graph.policy`). After this
        many TAP windows since the last *trusted* fix (one a later fix from a disjoint window
        agreed with) whose precise fix says the prediction is wrong (its best match on the edge
        of the search, ``FixStatus.OUTSIDE_SEARCH``, or beyond the gate, ``GATE``), the navigator
        is *lost*: it gives up the fixes used since the last trusted one, widens its belief by a
        *break* (the start's prior when no fix was ever trusted, else the odometry into that
        key gets an extra position std of the search's half-width, so the next searches are
        four times as wide, up to ``max_half_width_cells``, and the covariance it reports says
        how little it knows), searches that window again, and widens again after every further
        ``lost_windows`` such windows. It relocalises on ``relocalise_fixes`` precise fixes that
        agree with each other through the DR (informative, unimodal, inside the search) from
        windows that share no ping (which one block of bad pings cannot fake), or ends the
        episode when a precise fix agrees with the belief it gave up. Fixes refused only by the
        gate while tracking are weighed the same way: when enough of them agree, the prediction
        was the wrong one, and the navigator breaks its odometry by their distance from it and
        adds them. The pings from the last trusted fix to the end of the episode are flagged
        lost (``Track.meta["lost_steps"]``). None: never lost (default 4).
    relocalise_fixes : int
        Agreeing fixes, from windows that share no ping, that end a lost episode (default 2).
    confirm_probability : float or None
        The online navigator uses a fix at once when its NIS against the prediction is below
        the ``chi2(2)`` quantile of this probability; one between that and the gate waits for the
        next accepted fix, as surprising, to agree with it through the DR (it is used then, late,
        or dropped as ``UNCONFIRMED``): a fix from a window spoiled by a few bad pings is seldom
        confirmed, and a vague fix, which agrees with the prediction as well, confirms nothing.
        None: every fix within the gate is used at once (default 0.9).
    misfit_ratio : float or None
        A fix whose residual std at its best match exceeds this many times the navigation
        model's ``measurement_std``, and (from the survey's third window) as many times the
        median of the last ten windows' (a patch laid with DR whose constant errors are not yet
        known fits the map worse, window after window), is refused as ``MISFIT`` (the window's
        soundings fit the map nowhere: part of its pings in error) and is no evidence of being
        lost; None: no such test (default 3).
    robust_solve : {"gnc", "none"}
        Batch smoother: ``"gnc"`` decides which fixes (those the online pass accepted, gated or
        held as relocalisation candidates) and whether the start position prior are inliers by
        graduated non-convexity with a truncated least-squares loss (Yang et al. 2020, the rules
        of GTSAM's ``GncOptimizer``; see :mod:`tangraph.graph.robust`), then solves with the
        inliers only, so the covariances are those of the fixes kept; ``"none"``: the fixes the
        online pass accepted, under ``NavigationModel.robust_kernel``.
    gnc_probability : float
        A GNC candidate is an inlier while its whitened squared error is below the
        ``chi2(dim)`` quantile of this probability (default 0.99).
    smoother_terrain : {"fixes", "soundings", "field"}
        What the batch smoother's final solve sees of the terrain: ``"fixes"``, one TAP fix per
        window (default); ``"soundings"``, every sounding as its own factor on a key pose at its
        ping (:mod:`tangraph.graph.terrain_factors`), iterated from the fixes' solution, which
        the soundings then replace (the same soundings are not counted twice), the map's error
        widening each sounding's variance; ``"field"``, every sounding with the map's error as
        a field of unknowns solved with the track (:mod:`tangraph.graph.field_solve`: its
        covariance is the map-aware bound's, and the track carries the refined map in
        ``meta["refined_map"]``; as ``"soundings"`` on a map that states no error). On
        simulated surveys whose map errs as it states, ``"soundings"`` is at the Cramér-Rao
        bound; both trust the stated map error far more than the fixes do, so on a recorded
        survey use them only with a map whose error check lines confirm (``tangraph maps
        check``): on Lake Caputh's map, whose error is heavy-tailed, the track ANEES with
        ``"soundings"`` was 3-160 (fixes: 0-6).

    Examples
    --------
    >>> config = GraphConfig(n_pings=20, fix_spacing=None)
    >>> config.spacing, config.gate_probability
    (20, 0.999)
    >>> GraphConfig(front_end="ekf")
    Traceback (most recent call last):
    ...
    tangraph.errors.TangraphError: GraphConfig.front_end must be one of tap, pmf, got 'ekf'
    """

    key_interval: float = 60.0
    front_end: Literal["tap", "pmf"] = "tap"
    front_end_pings: int = 3
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
    relinearize_threshold: float = 0.005
    relinearize_position: float = 1.0
    relinearize_skip: int = 1
    isam_window: int | None = 100
    max_iterations: int = 100
    smoother_covariance: Literal["all", "none"] = "all"
    rematch_iterations: int = 2
    rematch_tolerance: float = 0.5
    lost_windows: int | None = 4
    relocalise_fixes: int = 2
    confirm_probability: float | None = 0.9
    misfit_ratio: float | None = 3.0
    robust_solve: Literal["gnc", "none"] = "gnc"
    gnc_probability: float = 0.99
    smoother_terrain: Literal["fixes", "soundings", "field"] = "fixes"

    @classmethod
    def from_mapping(cls, fields: Mapping[str, Any], where: str = "GraphConfig") -> GraphConfig:
        """A config from a mapping of its fields (a TOML table, ``--graph`` options); ``tap``
        may be a mapping of :class:`~tangraph.matching.TapConfig` fields. Unknown names are
        refused, naming ``where``.

        >>> GraphConfig.from_mapping({"n_pings": 60, "tap": {"criterion": "msd"}}).tap.criterion.value
        'msd'
        >>> GraphConfig.from_mapping({"fix_inflation": 2.0}, "a.toml")  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        tangraph.errors.TangraphError: a.toml: GraphConfig.fix_inflation is no longer a setting: moved to ...
        >>> GraphConfig.from_mapping({"n_ping": 60}, "--graph")
        Traceback (most recent call last):
        ...
        tangraph.errors.TangraphError: --graph: unknown GraphConfig field 'n_ping'
        """
        fields = dict(fields)
        for name in sorted(set(fields) & set(_REMOVED)):
            raise TangraphError(f"{where}: GraphConfig.{name} is no longer a setting: {_REMOVED[name]}")
        kinds: tuple[tuple[str | None, type], ...] = (("tap", TapConfig), (None, cls))
        for part, kind in kinds:
            table = fields.get(part, {}) if part else fields
            known = {f.name for f in dataclasses.fields(kind)}
            unknown = sorted(set(table) - known) if isinstance(table, dict) else []
            if unknown:
                raise TangraphError(f"{where}: unknown {kind.__name__} field {unknown[0]!r}")
        if isinstance(fields.get("tap"), dict):
            fields["tap"] = TapConfig(**fields["tap"])
        return cls(**fields)

    def __post_init__(self) -> None:
        for name in ("key_interval", "tap_step_cells", "half_width_sigmas",
                     "min_half_width_cells", "max_half_width_cells", "relinearize_threshold",
                     "relinearize_position"):
            _number(self, name)
        _number(self, "rematch_tolerance", allow_zero=True)
        if self.max_half_width_cells < self.min_half_width_cells:
            raise TangraphError(
                f"GraphConfig: max_half_width_cells ({self.max_half_width_cells}) is below "
                f"min_half_width_cells ({self.min_half_width_cells})"
            )
        for name, low in (("n_pings", 1), ("front_end_pings", 1), ("relinearize_skip", 1),
                          ("max_iterations", 1), ("rematch_iterations", 0), ("relocalise_fixes", 1)):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | np.integer) or value < low:
                raise TangraphError(f"GraphConfig.{name} must be an integer >= {low}, got {value!r}")
            object.__setattr__(self, name, int(value))
        if self.fix_spacing is not None:
            if isinstance(self.fix_spacing, bool) or not isinstance(self.fix_spacing, int | np.integer) \
                    or self.fix_spacing < 1:
                raise TangraphError(
                    f"GraphConfig.fix_spacing must be None or an integer >= 1, got {self.fix_spacing!r}"
                )
            object.__setattr__(self, "fix_spacing", int(self.fix_spacing))
        if self.ramp_pings is not None:
            if isinstance(self.ramp_pings, bool) or not isinstance(self.ramp_pings, int | np.integer) \
                    or self.ramp_pings < 1:
                raise TangraphError(
                    f"GraphConfig.ramp_pings must be None or an integer >= 1, got {self.ramp_pings!r}"
                )
            object.__setattr__(self, "ramp_pings", int(self.ramp_pings))
        if self.isam_window is not None and (isinstance(self.isam_window, bool) or not isinstance(
                self.isam_window, int | np.integer) or self.isam_window < 2):
            raise TangraphError(
                f"GraphConfig.isam_window must be None or an integer >= 2, got {self.isam_window!r}"
            )
        if self.lost_windows is not None and (isinstance(self.lost_windows, bool) or not isinstance(
                self.lost_windows, int | np.integer) or self.lost_windows < 1):
            raise TangraphError(
                f"GraphConfig.lost_windows must be None or an integer >= 1, got {self.lost_windows!r}"
            )
        if not 0.0 < float(self.gnc_probability) < 1.0:
            raise TangraphError(
                f"GraphConfig.gnc_probability must lie in (0, 1), got {self.gnc_probability!r}")
        if self.misfit_ratio is not None:
            _number(self, "misfit_ratio")
        if self.confirm_probability is not None and not 0.0 < float(self.confirm_probability) < 1.0:
            raise TangraphError("GraphConfig.confirm_probability must be None or lie in (0, 1), "
                                f"got {self.confirm_probability!r}")
        if self.gate_probability is not None and not 0.0 < float(self.gate_probability) < 1.0:
            raise TangraphError(
                f"GraphConfig.gate_probability must be None or lie in (0, 1), got {self.gate_probability!r}"
            )
        if not isinstance(self.tap, TapConfig):
            raise TangraphError(f"GraphConfig.tap must be a TapConfig, got {type(self.tap).__name__}")
        if self.half_width_rule == "marginal" and self.tap.half_width != _TAP_DEFAULT.half_width:
            raise TangraphError(
                f"GraphConfig: tap.half_width = {self.tap.half_width!r} is not used with half_width_rule "
                "= 'marginal' (the half-width comes from the predicted covariance): set half_width_rule "
                "= 'fixed' to use it, or leave it out"
            )
        if self.tap.step is not None and self.tap_step_cells != _STEP_CELLS:
            raise TangraphError(
                f"GraphConfig: tap.step ({self.tap.step!r} m) and tap_step_cells ({self.tap_step_cells!r} "
                "cells) both set the search step: give one"
            )
        for name, allowed in (("front_end", ("tap", "pmf")),
                              ("half_width_rule", ("marginal", "fixed")),
                              ("smoother_covariance", ("all", "none")),
                              ("robust_solve", ("gnc", "none")),
                              ("smoother_terrain", ("fixes", "soundings", "field"))):
            if getattr(self, name) not in allowed:
                raise TangraphError(
                    f"GraphConfig.{name} must be one of {', '.join(allowed)}, got {getattr(self, name)!r}"
                )

    @property
    def spacing(self) -> int:
        """Pings between consecutive window ends (the front end's)."""
        if self.front_end == "pmf":
            return self.front_end_pings
        return self.n_pings if self.fix_spacing is None else self.fix_spacing

    @property
    def window(self) -> int:
        """Pings per window (the front end's)."""
        return self.front_end_pings if self.front_end == "pmf" else self.n_pings

    def as_dict(self) -> dict:
        """JSON-ready form, kept in a track's metadata."""
        out = dataclasses.asdict(self)
        out["tap"] = {k: (v.value if hasattr(v, "value") else v) for k, v in out["tap"].items()}
        out["tap"]["headings"] = list(out["tap"]["headings"])
        return out


def load_graph_config(path: str | os.PathLike) -> GraphConfig:
    """A :class:`GraphConfig` from a TOML file: its fields at the top level or in a ``[graph]``
    table, TapConfig fields in ``[graph.tap]`` (or ``[tap]``); fields not given keep their
    defaults (CLI: ``--graph-config``)."""
    from tangraph.tomlfile import read_table

    table = read_table(path, "graph", "graph config file")
    return GraphConfig.from_mapping(table, str(path))
