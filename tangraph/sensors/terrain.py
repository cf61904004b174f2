"""The terrain measurement model every estimator shares: sounding noise plus the map's error.

A sounding of the seafloor at ``p`` measures ``z = h(p) + d(p) + t + e``: ``h`` the prior map's
(bilinear) depth, ``d`` the map's error (the true seafloor minus the map), ``t`` the tide and
``e ~ N(0, sounding_std^2)`` the sounding's own noise, independent between soundings. A map is
gridded from earlier surveys, so ``d`` is a zero-mean Gaussian random field, **correlated in
space**, at two scales. With ``s`` the map's per-cell standard deviation
(``BathymetryMap.depth_std``, else the navigation model's ``map_std`` everywhere) and ``L`` its
correlation length (``BathymetryMap.correlation_length``, else
``NavigationModel.map_correlation_length``, else one map cell), ``d`` is the sum of two
independent Matérn (nu = 1) fields (:meth:`MapError.components`):

- the **cell-scale** error, every cell's own (how well a surveyed cell's depth is known: the
  noise averaged in it, the relief within it), at the level of the map's well-surveyed cells
  (``s_c = min(s, s_25)``, ``s_25`` the lower quartile of ``s`` over the map), of range one cell;
- the **excess** over that level, ``sqrt(s^2 - s_c^2)``, where the map was interpolated (gaps
  between lines, filled cells), of range ``L``.

A field of std ``a(p)`` and range ``L`` has ``cov(d(p), d(q)) = a(p) a(q) rho(|p - q|)`` with

    ``rho(r) = (k r) K_1(k r)``, ``k = sqrt(8) / L``  (``rho(L)`` is about 0.14),

the field a second-order SPDE on the plane gives (Lindgren, Rue & Lindström 2011), so the same
field can be simulated (:func:`tangraph.sensors.matern.matern_field`) and carried as a sparse
Gaussian-Markov prior by the bound. A map with ``L`` of one cell or less, or a uniform std (a
navigation model's ``map_std``), has one field of range ``L``.

**What the estimators use: the row-sum bound.** The exact likelihood of a survey's soundings has
the dense covariance ``C = sounding_std^2 I + S R S`` (``R_ij = rho(|p_i - p_j|)``, ``S`` the
diagonal of ``s``). A filter or a fix that treated the soundings as independent with variance
``sounding_std^2 + s^2`` would count the same map error once for every sounding that sees it,
and converge on the map's noise. Every estimator here instead gives sounding ``b`` the variance

    ``v_b = sounding_std^2 + sum_fields a_b sum_j a_j rho(|p_b - p_j|)``

(the sum over the survey's soundings, ``b`` itself included: one over the soundings that share
its map error, weighted by how much they share it). Since ``S R S`` has non-negative entries,
``diag(row sums) - S R S`` is a graph Laplacian and positive semi-definite, so
``diag(v) >= C``: the independent-sounding likelihood with these variances never claims more
information than the exact one, in any direction. It is exact for the common part of
soundings that share one error (the information of a patch's mean residual is
``1 / (sounding_std^2 / n + s^2)``); what it gives up is the information in the pattern of
soundings within one correlation length beyond their common part, which is small where the map
holds no structure finer than its error's range (a gridded map holds none finer than its cell)
and large for a long-range error over fine terrain. Sums are evaluated on the dead-reckoned
footprints (:func:`sounding_variances`).

**The change since the map.** A map states how well the earlier surveys knew the seafloor
*then*; a seafloor that has changed since (sediment moved, weed grown, a datum that drifted
patch by patch) errs by more, everywhere, and no check among the map's own surveys can see it.
The navigation model states it (``map_change_std``, ``map_change_length``; a later survey's
check lines measure it, :mod:`tangraph.eval.map_change`): a field of its own, the same std
everywhere the map has data, added to the map's statement in quadrature
(``MapError.change_std``) and carried by every estimator and the bound like the map's own
fields.

**Where the soundings are.** The row sums above need the map error's std where each sounding
lies. The filters, the graph's tracking factors and point-mass windows and the smoother's
terrain solve read it where their estimate puts each sounding, in the bound's form ``a_b^2
n_b``, which needs the std at the sounding's own footprint only (:func:`sounding_map_counts`,
:func:`placed_map_variances`), so that a sounding the dead reckoning puts on one of the map's
lines, but the estimate in a filled gap between them, counts as little as the gap is known.
TAP fixes still read it at the dead-reckoned footprints (:func:`survey_map_error`): read where
the fix puts its window (or averaged over the window's likelihood) the simulated surveys gained,
but on Lake Caputh's long run the graph's fixes became over-confident (the lake's map errs
beyond its statement where its fixes land, on the flat shelf); the map's statement, not the
placing, is what is wrong there.

A TAP fix, which weighs one window's soundings together, is widened by the map error they share
among themselves exactly (:func:`shared_quadratic`, the double sum over pairs on the map
gradients): there the row-sum bound would count the shared error of soundings whose gradients
differ in sign as if it added up, where it cancels in the fix, and on rough terrain it made a
window's likelihood tens of times flatter than the map's error does.

**No data is no information.** A sounding that falls on no map data (off the grid, or by a NaN
cell) says nothing about a candidate position, for or against: estimators leave it out of the
comparison instead of giving the candidate zero weight.

**Little information where the terrain does not rise above the map's noise.** Where the depths
that a belief predicts for a sounding spread no more than the map's error, the sounding cannot
tell the belief's positions apart, and its small differences are the map's noise: the
likelihood is raised to the exponent :func:`information_exponent` (MBARI's modified weighting).

**Patches that err beyond the statement.** A real map errs as it states over most of its area
and by several times that in patches (the check lines of :mod:`tangraph.eval.map_check`). The
filters hold that excess as a scale on the variances above, shared along the track and
integrated out (:mod:`tangraph.sensors.misfit`; ``NavigationModel.misfit_dof``).
"""

from __future__ import annotations

import weakref

import numpy as np

from tangraph.maps.grid import BathymetryMap
from tangraph.sensors.map_error_model import MapError, map_error
from tangraph.sensors.matern import _correlation_quadratic, _weighted_correlation_sums

__all__ = [
    "MapError",
    "information_exponent",
    "map_error",
    "map_error_grids",
    "placed_map_variances",
    "shared_among",
    "shared_map_variances",
    "slope_moment",
    "sounding_map_counts",
    "sounding_map_variances",
    "sounding_variances",
    "survey_map_error",
]

def sounding_variances(survey, bathymetry: BathymetryMap, model, *, poses=None) -> np.ndarray:
    """Per sounding ``(K, B)`` the variance every estimator gives its residual (m^2): the
    sounding noise plus its map error times the map error it shares with the survey's soundings
    (the row-sum bound of the module docstring), at the footprints seen from ``poses``
    (default: the dead reckoning). NaN where a beam has no depth. It is ``sounding_std^2 + s_b^2
    +`` :func:`shared_map_variances`.

    A footprint off the map's data takes the map's median error std (its soundings are left
    out where they have no map under a candidate, but may have one under another). With no map
    error it is ``sounding_std^2`` everywhere.

    Examples
    --------
    Nine soundings in one spot share one map error: each counts as a ninth of a sounding with
    the map's error, ``0.1^2 + 9 * 0.2^2 = 0.37``:

    >>> import numpy as np
    >>> from tangraph.maps import BathymetryMap
    >>> from tangraph.sensors import NavigationModel
    >>> from tangraph.survey import Survey
    >>> flat = BathymetryMap(np.arange(0.0, 200, 10), np.arange(0.0, 200, 10), np.full((20, 20), 30.0))
    >>> t = np.arange(9.0)
    >>> pose = np.column_stack([100 + 0 * t, 100 + 0 * t, 0 * t])
    >>> s = Survey(time=t, dr_pose=pose, vehicle_depth=0 * t, beam_forward=np.zeros((9, 1)),
    ...            beam_starboard=np.zeros((9, 1)), beam_depth=np.full((9, 1), 30.0))
    >>> model = NavigationModel(sounding_std=0.1, map_std=0.2, map_correlation_length=20.0)
    >>> sounding_variances(s, flat, model)[:, 0].round(3).tolist()[:3]
    [0.37, 0.37, 0.37]
    """
    own, shared = _map_variances(survey, bathymetry, model, poses)
    return float(model.sounding_std) ** 2 + own + shared


def shared_map_variances(survey, bathymetry: BathymetryMap, model, *, poses=None) -> np.ndarray:
    """Per sounding ``(K, B)`` the map error variance it shares with the survey's other
    soundings, ``s_b sum_(j != b) s_j rho(|p_b - p_j|)`` (m^2; the row-sum bound's off-diagonal
    part, :func:`sounding_variances`); 0 with no map error, NaN where a beam has no depth.

    A fix's covariance is widened by it (:func:`tangraph.matching.tap_fix`): the residual scatter
    a window shows holds the map error its soundings do not share, not the part they share
    with each other and with the survey's other soundings."""
    return _map_variances(survey, bathymetry, model, poses)[1]


# survey -> map -> {model: (shared variances, error)}: weak keys, so nothing outlives its survey or
# map and a new map never meets an old one's entry (surveys and maps hash by identity)
_SURVEY_MAP_ERRORS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def survey_map_error(survey, bathymetry: BathymetryMap, model) -> tuple[np.ndarray | None, MapError | None]:
    """The survey's :func:`shared_map_variances` at its dead-reckoned footprints and the map's
    error (:func:`map_error`), computed once per survey, map and model; ``(None, None)`` with a
    perfect map. What every fix of a run is widened by (TAP in the graph, MLE, TERCOM-PF): read
    at the dead-reckoned footprints, not where the fix puts the window (the module docstring
    says why)."""
    per_map = _SURVEY_MAP_ERRORS.setdefault(survey, weakref.WeakKeyDictionary())
    per_model = per_map.setdefault(bathymetry, {})
    if model not in per_model:
        error = map_error(bathymetry, model)
        per_model[model] = (None, None) if error.is_zero else \
            (shared_map_variances(survey, bathymetry, model), error)
    return per_model[model]


def shared_among(north, east, error: MapError) -> np.ndarray:
    """For points ``(N,)`` (the soundings of one window) the map error each shares with the
    others of them alone, ``sum_fields a_b sum_(j != b) a_j rho(|p_b - p_j|)`` (m^2): the part of
    :func:`shared_map_variances` that shapes one window's own likelihood. A point off the map's
    data takes the field's median std."""
    north = np.asarray(north, dtype=np.float64)
    east = np.asarray(east, dtype=np.float64)
    out = np.zeros(north.shape)
    if north.size == 0:
        return out
    for part in error.components():
        a = part.std_at(north, east)
        a = np.where(np.isfinite(a), a, part.typical_std)
        out += a * (_weighted_correlation_sums(north, east, a, part.correlation_length) - a)
    return out


def _map_variances(survey, bathymetry, model, poses) -> tuple[np.ndarray, np.ndarray]:
    """``(s_b^2, s_b sum_(j != b) s_j rho_bj)`` per sounding (K, B), NaN where no depth."""
    north, east = survey.footprints(poses)
    has = np.isfinite(survey.beam_depth) & np.isfinite(north) & np.isfinite(east)
    own = np.full(north.shape, np.nan)
    shared = np.full(north.shape, np.nan)
    own[has] = shared[has] = 0.0
    for part in map_error(bathymetry, model).components():
        a = part.std_at(north[has], east[has])
        a = np.where(np.isfinite(a), a, part.typical_std)
        sums = _weighted_correlation_sums(north[has], east[has], a, part.correlation_length)
        own[has] += a * a
        shared[has] += a * (sums - a)
    return own, shared


def shared_quadratic(north, east, vectors, error: MapError) -> np.ndarray:
    """For points ``(N,)`` (one window's soundings) and a vector ``v_b (N, k)`` per point, the
    covariance that the map error they share among themselves gives ``sum_b v_b d(p_b)``:
    ``sum_fields sum_(b != j) a_b a_j rho(|p_b - p_j|) v_b v_j^T`` ``(k, k)`` (m^2 times the
    vectors' units squared). With the map gradients at the soundings as ``v`` it is the map
    error's part of a least-squares fix's score covariance: exact where :func:`shared_among`'s
    row sums bound it from above by counting every pair as if their gradients were alike
    (soundings whose gradients differ in sign share map error that cancels in the fix). A
    point off the map's data takes the field's median std.

    Examples
    --------
    Two points one range apart, unit std: ``2 rho(L) v v^T`` for equal vectors, the negative
    of it for opposite ones:

    >>> import numpy as np
    >>> from tangraph.maps import BathymetryMap
    >>> from tangraph.sensors import matern_correlation
    >>> axis = np.arange(0.0, 200.0, 1.0)
    >>> flat = BathymetryMap(axis, axis, np.full((200, 200), 10.0), depth_std=np.ones((200, 200)),
    ...                      correlation_length=20.0)
    >>> error = map_error(flat, None)
    >>> north, east = np.array([100.0, 120.0]), np.array([100.0, 100.0])
    >>> same = shared_quadratic(north, east, np.array([[1.0], [1.0]]), error)[0, 0]
    >>> opposite = shared_quadratic(north, east, np.array([[1.0], [-1.0]]), error)[0, 0]
    >>> bool(abs(same - 2 * matern_correlation(20.0, 20.0)) < 0.01), bool(abs(same + opposite) < 1e-9)
    (True, True)
    """
    north = np.asarray(north, dtype=np.float64)
    east = np.asarray(east, dtype=np.float64)
    vectors = np.asarray(vectors, dtype=np.float64).reshape(north.size, -1)
    out = np.zeros((vectors.shape[1], vectors.shape[1]))
    if north.size < 2:
        return out
    for part in error.components():
        a = part.std_at(north, east)
        w = np.where(np.isfinite(a), a, part.typical_std)[:, None] * vectors
        out += _correlation_quadratic(north, east, w, part.correlation_length)
    return 0.5 * (out + out.T)


def information_exponent(predicted: np.ndarray, weights: np.ndarray, map_variance) -> np.ndarray:
    """MBARI's modified weighting: per sounding, the exponent in [0, 1] of its likelihood from
    how much the depths a belief predicts for it spread beyond the map's noise.

    ``predicted (N, B)`` are the depths (or residuals) that the belief's ``N`` weighted
    particles (``weights (N,)``, normalised) predict for each of ``B`` soundings (NaN: no map
    there, left out); ``map_variance (B,)`` the map's error variance at each. With ``D^2`` the
    weighted spread of the predictions less what the map's noise alone gives a weighted
    spread (``(1 - sum w^2) s^2``), the exponent is ``D^2 / (D^2 + 2 s^2)``: 1 with a perfect
    map, near 0 where the belief's predictions differ by no more than the map's noise.

    Examples
    --------
    >>> w = np.full(4, 0.25)
    >>> predicted = np.array([[10.0, 10.0], [10.01, 12.0], [9.99, 8.0], [10.0, 10.0]])
    >>> information_exponent(predicted, w, np.array([0.01, 0.01])).round(3).tolist()
    [0.0, 0.99]
    """
    predicted = np.asarray(predicted, dtype=np.float64)
    w = np.asarray(weights, dtype=np.float64)[:, None] * np.isfinite(predicted)
    total = w.sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        w = w / total
        x = np.nan_to_num(predicted)
        mean = np.sum(w * x, axis=0)
        spread = np.sum(w * (x - mean) ** 2, axis=0) - (1.0 - np.sum(w * w, axis=0)) * map_variance
        spread = np.maximum(spread, 0.0)
        alpha = np.where(map_variance > 0, spread / (spread + 2.0 * map_variance), 1.0)
    return np.where(total >= 1e-3, alpha, 0.0)  # a sub-cloud of under 0.1 % of the weight: left out


def slope_moment(bathymetry: BathymetryMap) -> np.ndarray:
    """The map's mean outer product of its depth gradients over its data, ``(2, 2)`` (north,
    east; dimensionless): a grid estimator whose point stands for a cell ``a`` raises each
    sounding's variance by the map's depth variance across the cell, ``a^T G a / 12``."""
    _, _, dn, de = bathymetry._grid  # type: ignore[attr-defined]
    gn, ge = np.gradient(bathymetry.depth, dn, de)
    ok = np.isfinite(gn) & np.isfinite(ge)
    if not ok.any():
        return np.zeros((2, 2))
    g = np.column_stack([gn[ok], ge[ok]])
    return g.T @ g / g.shape[0]


def sounding_map_variances(survey, bathymetry: BathymetryMap, model) -> np.ndarray | None:
    """Per sounding ``(K, B)`` the variance of the map's own error under it (m^2) at the
    dead-reckoned footprints, the map's median error where a footprint is off its data, NaN
    where a beam has no depth; None for a perfect map. What the likelihood's information
    exponents are made of (:meth:`tangraph.filters.likelihood.TerrainLikelihood.ping_update`)."""
    error = map_error(bathymetry, model)
    if error.is_zero:
        return None
    north, east = survey.footprints()
    valid = np.isfinite(survey.beam_depth)
    out = np.full(north.shape, np.nan)
    s = error.std_at(north[valid], east[valid])
    out[valid] = np.where(np.isfinite(s), s, error.typical_std) ** 2
    return out


def map_error_grids(bathymetry: BathymetryMap, model) -> np.ndarray | None:
    """The variance of each field of the map's error (:meth:`MapError.components`) on the map's
    grid, ``(ny, nx, F)`` (m^2; the field's median where the map has no data, where no residual
    is made), or None for a perfect map: what a filter reads at each candidate's footprints
    (:func:`sounding_map_counts`)."""
    parts = map_error(bathymetry, model).components()
    if not parts:
        return None
    grids = [np.where(np.isfinite(part.std), part.std, part.typical_std) ** 2 for part in parts]
    return np.ascontiguousarray(np.stack(grids, axis=-1))


def sounding_map_counts(survey, bathymetry: BathymetryMap, model, *, poses=None) -> np.ndarray | None:
    """Per sounding and field of the map's error, ``(K, B, F)``: how many of the survey's
    soundings share its error, ``n_fb = sum_j rho_f(|p_b - p_j|)`` (``b`` itself included; NaN
    where a beam has no depth), at the footprints seen from ``poses`` (default: the dead
    reckoning, whose footprints are placed well relative to each other); None for a perfect map.

    **The bound at any footprint.** For any positive weights ``u``, ``diag(sum_j C_bj u_j /
    u_b) - C`` is positive semi-definite where ``C`` has non-negative entries (scaled by ``u``,
    it is a graph Laplacian). With ``u = 1 / a`` the map error's covariance ``a_b a_j rho_bj``
    is bounded by ``a_b^2 n_b``, which needs the error's std only at the sounding's own
    footprint. A filter therefore gives sounding ``b`` at candidate ``x`` the variance
    ``sounding_std^2 + sum_f a_f(x + o_b)^2 n_fb``, read where that candidate puts the
    sounding: a sounding the candidate places in a filled gap between the map's lines counts
    as little as the gap is known, though the dead reckoning (tens of metres off) put it on a
    line.

    Examples
    --------
    Nine soundings in one spot share one error: each is counted nine times.

    >>> import numpy as np
    >>> from tangraph.maps import BathymetryMap
    >>> from tangraph.sensors import NavigationModel
    >>> from tangraph.survey import Survey
    >>> flat = BathymetryMap(np.arange(0.0, 200, 10), np.arange(0.0, 200, 10), np.full((20, 20), 30.0))
    >>> t = np.arange(9.0)
    >>> pose = np.column_stack([100 + 0 * t, 100 + 0 * t, 0 * t])
    >>> s = Survey(time=t, dr_pose=pose, vehicle_depth=0 * t, beam_forward=np.zeros((9, 1)),
    ...            beam_starboard=np.zeros((9, 1)), beam_depth=np.full((9, 1), 30.0))
    >>> model = NavigationModel(sounding_std=0.1, map_std=0.2, map_correlation_length=20.0)
    >>> sounding_map_counts(s, flat, model)[:3, 0, 0].round(3).tolist()
    [9.0, 9.0, 9.0]
    """
    parts = map_error(bathymetry, model).components()
    if not parts:
        return None
    north, east = survey.footprints(poses)
    has = np.isfinite(survey.beam_depth) & np.isfinite(north) & np.isfinite(east)
    out = np.full((*north.shape, len(parts)), np.nan)
    ones = np.ones(int(has.sum()))
    for f, part in enumerate(parts):
        out[has, f] = _weighted_correlation_sums(north[has], east[has], ones, part.correlation_length)
    return out


def placed_map_variances(error: MapError, counts, north, east) -> tuple[np.ndarray, np.ndarray]:
    """The map error of soundings placed at ``north, east`` (any shape ``S``; an estimate's
    footprints, not the dead reckoning's) with their counts ``counts (*S, F)``
    (:func:`sounding_map_counts`): the variance the row-sum bound gives each, ``sum_f a_f^2
    n_fb``, and the map's own error variance under it, ``sum_f a_f^2`` (the fields' stds ``a_f``
    read there, their median off the map's data). What a graph weighs a sounding by where its
    belief puts it, as a filter does where its cloud does (:func:`sounding_map_counts`)."""
    north, east = np.asarray(north, float), np.asarray(east, float)
    counts = np.asarray(counts, float)
    shared, own = np.zeros(north.shape), np.zeros(north.shape)
    for f, part in enumerate(error.components()):
        s = part.std_at(north, east)
        a2 = np.where(np.isfinite(s), s, part.typical_std) ** 2
        shared += a2 * counts[..., f]
        own += a2
    return shared, own
