"""The point-mass front end of the online graph: a window's terrain information from its posterior.

TAP summarises a window's likelihood by a confidence region found without the graph's belief,
so its covariance must be conservative, and windows that share pings are discounted by how many
do. This front end instead weighs the window's soundings where the graph believes the vehicle is
and hands the graph exactly what they add to that belief:

1. **Prior**: the graph's prediction of the window end's world position and of the tide,
   ``N(m, P)`` over (north, east, tide) (its marginal, the calibration's uncertainty included;
   a graph that does not hold the tide gives the model's tide prior, apart from the position).
2. **Posterior on a grid**: the window's soundings are laid with the calibrated DR from the end
   ping, as TAP lays them (:func:`~tangraph.matching.window_patch`), and weighed at every point
   of a ``GRID_POINTS x GRID_POINTS`` grid aligned with ``P``'s principal axes and spanning
   ``GRID_SIGMAS`` of its stds, with the filters' terrain likelihood
   (:meth:`~tangraph.filters.likelihood.TerrainLikelihood.ping_update`: each sounding's variance
   and map error from the terrain measurement model, no map is no evidence, the tide
   marginalised exactly from the prior's conditional on the point). A grid point stands for
   its cell, so each sounding's variance is raised by the depth variance a shift within the
   cell gives it, shared by every sounding of the window (the row-sum bound of the map error's
   model): a likelihood sharper than the grid is not lost between its points. The posterior
   is the prior times the likelihood. The multimodality and edge tests below are made on this
   grid.
3. **Refinement**: the posterior is weighed again without the resolution term, on the same
   grid when its std along every axis is at least ``REFINE_SPACINGS`` grid spacings (the grid
   resolves it), else on a new grid laid on it (aligned with its covariance grown by a third
   of a cell, so that a posterior sitting between two points is covered, ``GRID_SIGMAS`` stds
   each side); a refined grid whose outer ring holds more than ``EDGE_MASS`` is laid twice as
   wide; at most ``MAX_REFINE`` times.
   Its mean and covariance are ``mu`` and ``S`` (at least a twelfth of a cell's variance along
   each grid axis: a posterior on one point stands for its cell).
4. **Prior removed**: the likelihood's information is the posterior's less the prior's,
   ``L = S^-1 - P^-1``, and its mean ``L^-1 (S^-1 mu - P^-1 m)``; the graph receives the fix
   ``N(L^-1 (S^-1 mu - P^-1 m), L^-1)``, so nothing it already knew is counted again. On a
   linear-Gaussian model this is the window's likelihood factor exactly. Along a principal axis
   (of ``L`` in the prior's whitened coordinates) where the window adds less than ``MIN_GAIN``
   of the prior's information, the fix keeps the prior's mean and ``MIN_AXIS_GAIN`` of its
   information: its mean there would be the posterior's small shift divided by a small gain.
   When the graph holds the tide (``tide_factor``), the tide's posterior joins the grid's
   moments, the prior is removed over (north, east, tide) and the factor is on both: what one
   window learnt of the tide sharpens the absolute depths of the next, which a window that
   marginalises the tide afresh from its prior cannot use.

The window is refused, never given as one Gaussian, when the posterior on the prior-wide grid
has a second part (``multimodal``: a connected region above ``exp(-MODE_LEVEL)`` of the peak
holding at least ``MODE_MASS`` of the mass away from the main one), or the soundings alone (the
likelihood over the same grid) do (a second place they fit as well within the prediction's
reach: a window that follows a wrong prediction would choose the mode near it), when ``L`` has an axis
along which the posterior is wider than the prior by more than ``MAX_LOSS`` of its information
(the likelihood is not a Gaussian's there: the terrain's curvature spreads the posterior) or
adds less than ``MIN_GAIN`` of the prior's information along its best axis (``uninformative``),
and when more than ``EDGE_MASS`` of the posterior lies in the grid's outer ring
(``best_on_edge``: the truth may lie beyond, which is evidence that the prediction is wrong).
The windows of this front end share no ping (:class:`~tangraph.graph.GraphNavigator`).

**A depth fault** (when the graph holds the tide): the window's soundings are weighed over the
prior's grid once with the held tide and once with a free depth offset on top of it (prior std
``FAULT_STD``, marginalised); when the free offset's evidence wins at the prior odds
``FAULT_PRIOR``, the window's depths are wrong, not the place (a draft, a tide step, a block of
bad pings). It is refused as ``"depth fault"`` with its offset (``WindowFix.depth_offset``),
which the graph judges ``MISFIT``: no evidence that the prediction is wrong. Weighed with the
held tide it would move the position to where the map is as deep, or say the vehicle is lost.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import ndimage, special, stats

from tangraph.filters.likelihood import TerrainLikelihood
from tangraph.geometry import mahalanobis2
from tangraph.matching import FixQuality, MatchingError, Patch

__all__ = ["WindowFix", "posterior_fix"]

GRID_POINTS = 31  #: points per axis of the window's grid
GRID_SIGMAS = 5.0  #: the grid spans this many stds of the density it is laid on, each side
REFINE_SPACINGS = 2.5  #: a posterior std below this many grid spacings is re-gridded
MAX_REFINE = 4  #: re-griddings at most
MIN_SPACING = 0.01  #: m, the finest grid spacing
MODE_LEVEL = 0.5 * stats.chi2.ppf(0.999, 2)  #: nats below the peak that bound a part of the posterior
MODE_MASS = 0.01  #: share of the mass a second part must hold to make the window multimodal
EDGE_MASS = 1e-3  #: share of the posterior in the grid's outer ring that says the truth may lie beyond
#: least information the window must add along its best axis, as a share of the prior's
MIN_GAIN = 1e-3
#: an axis along which the posterior is wider than the prior by more than this share refuses it
MAX_LOSS = 0.1
#: A window's depths may carry a fault the tide does not (a draft or a tide step, a bad block):
#: its offset's prior std (m) and the prior probability of a window with one (see ``_depth_fault``)
FAULT_STD = 10.0
FAULT_PRIOR = 1e-3
#: information given along an axis the window adds less than MIN_GAIN to, as a share of the prior's
MIN_AXIS_GAIN = 1e-4


@dataclasses.dataclass(frozen=True, eq=False)
class WindowFix:
    """The terrain information of the window of pings ``first`` to ``index``: the likelihood's
    ``position (2,)`` and ``covariance (2, 2)`` (world, north/east; a refused window's are its
    posterior's), the posterior tide mean ``tide`` and the soundings' residual std ``sigma`` at
    the posterior mean, their number, the ``quality`` flags the graph judges (as a TAP fix's),
    the posterior's mean and covariance, the prior's (north, east, tide), and the grid
    (``points (n*n, 2)`` and the normalised ``log_density``) it was last weighed on, the
    ``n_grids``-th; ``joint_mean (3,)`` and ``joint_covariance (3, 3)``: the likelihood factor
    on (north, east, tide) when the tide was uncertain (NaN otherwise, or when refused);
    ``depth_offset``: a depth fault's offset from the held tide (m; NaN without one)."""

    index: int
    first: int
    position: np.ndarray
    covariance: np.ndarray
    tide: float
    sigma: float
    n_soundings: int
    quality: FixQuality
    posterior_mean: np.ndarray
    posterior_covariance: np.ndarray
    prior_mean: np.ndarray
    prior_covariance: np.ndarray
    points: np.ndarray
    log_density: np.ndarray
    n_grids: int
    joint_mean: np.ndarray
    joint_covariance: np.ndarray
    depth_offset: float = float("nan")

    @property
    def accepted(self) -> bool:
        """Informative, unimodal and inside its grid."""
        q = self.quality
        return q.informative and not q.multimodal and not q.outside


def _axes(cov: np.ndarray) -> np.ndarray:
    """Grid axes ``(2, 2)`` (columns: one grid step along each principal axis of ``cov``)."""
    values, vectors = np.linalg.eigh(0.5 * (cov + cov.T))
    std = np.sqrt(np.maximum(values, 0.0))
    spacing = np.maximum(2.0 * GRID_SIGMAS * std / (GRID_POINTS - 1), MIN_SPACING)
    return vectors * spacing


def _grid(centre: np.ndarray, axes: np.ndarray) -> np.ndarray:
    half = (GRID_POINTS - 1) / 2
    u = np.arange(GRID_POINTS) - half
    a, b = np.meshgrid(u, u, indexing="ij")
    return centre + np.column_stack([a.ravel(), b.ravel()]) @ axes.T


def _log_gaussian(points: np.ndarray, mean: np.ndarray, cov: np.ndarray) -> np.ndarray:
    return -0.5 * mahalanobis2(points - mean, cov)


def _moments(points: np.ndarray, log_density: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Normalised masses, mean and covariance of a density at ``points``."""
    mass = np.exp(log_density - np.max(log_density))
    mass /= mass.sum()
    mean = mass @ points
    d = points - mean
    return mass, mean, (d * mass[:, None]).T @ d


def _floored(cov: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """``cov`` with its variance along every axis of the grid's coordinates at least a twelfth
    of a cell's (a point stands for its cell): a density on one point is not a singular one."""
    inv = np.linalg.inv(axes)
    values, vectors = np.linalg.eigh(inv @ cov @ inv.T)
    grid = (vectors * np.maximum(values, 1.0 / 12.0)) @ vectors.T
    return axes @ grid @ axes.T


def _parts(log_density: np.ndarray, mass: np.ndarray) -> tuple[int, float]:
    """Connected parts of a density on the grid (posterior or likelihood) above
    ``exp(-MODE_LEVEL)`` of its peak, and the share of the mass in the parts other than the
    heaviest (each point counted with the part nearest to it)."""
    image = log_density.reshape(GRID_POINTS, GRID_POINTS)
    labels, n = ndimage.label(image > np.max(image) - MODE_LEVEL)
    if n < 2:
        return n, 0.0
    # the mass of each part: the points closer (by label propagation) to it than to another
    _, (rows, cols) = ndimage.distance_transform_edt(labels == 0, return_indices=True)
    nearest = labels[rows, cols].ravel()
    held = np.bincount(nearest, weights=mass, minlength=n + 1)[1:]
    return n, float(held.sum() - held.max())


def _edge(mass: np.ndarray) -> float:
    image = mass.reshape(GRID_POINTS, GRID_POINTS)
    inner = image[1:-1, 1:-1].sum()
    return float(image.sum() - inner)


def _resolution(bathymetry, footprints: np.ndarray, axes: np.ndarray, slope: np.ndarray) -> np.ndarray:
    """Each sounding's variance from the grid's resolution. A grid point stands for its cell:
    the vehicle may be anywhere in it, a shift ``u`` uniform over the cell of ``axes`` (``A``)
    that every sounding of the window shares, so sounding ``b`` errs by ``g_b . u`` with its
    footprint's depth gradient ``g_b``, and ``cov(b, c) = sum_i (g_b . a_i)(g_c . a_i) / 12``.
    As for the map's error (:mod:`tangraph.sensors.terrain`), each sounding's variance grows by
    the row sum of these: ``sum_i |g_b . a_i| sum_c |g_c . a_i| / 12``, at least the map-wide
    mean of one sounding's own, ``sum_i a_i^T G a_i / 12`` (``slope``: G), which also stands for
    a footprint off the map. On a grid much coarser than the likelihood the window is then
    weighed as a whole, not as many independent soundings that each miss by the same shift."""
    mean = float(np.trace(axes.T @ slope @ axes)) / 12.0
    gradient = bathymetry.gradient_at(footprints[:, 0], footprints[:, 1])
    reach = np.abs(np.nan_to_num(gradient @ axes))  # (N, 2): |g_b . a_i|
    shared = reach @ reach.sum(axis=0) / 12.0
    return np.maximum(shared, mean)


def _remove_prior(mean, cov, m, p, reasons: list[str]) -> tuple[np.ndarray, np.ndarray] | None:
    """The Gaussian likelihood factor ``N(L^-1 (S^-1 mu - P^-1 m), L^-1)``, ``L = S^-1 - P^-1``,
    of a posterior ``N(mean, cov)`` under the prior ``N(m, p)`` (any dimension), computed in the
    prior's whitened coordinates; None (and a reason appended) when it is refused (module
    docstring)."""
    # y = R^-1 (x - m), R R^T = P: the prior is N(0, I), the posterior N(a, B), and the
    # likelihood's information G = B^-1 - I = V diag(g) V^T
    root = np.linalg.cholesky(p)
    inv_root = np.linalg.inv(root)
    a = inv_root @ (mean - m)
    b = inv_root @ cov @ inv_root.T
    gain, vectors = np.linalg.eigh(np.linalg.inv(0.5 * (b + b.T)) - np.eye(len(m)))
    if gain.min() < -MAX_LOSS:
        reasons.append(f"uninformative: the posterior is wider than the prior (gain {gain.min():.2f})")
        return None
    if gain.max() < MIN_GAIN:
        reasons.append(f"uninformative: the window adds {gain.max():.1%} of the prior's information")
        return None
    # the likelihood's mean along each axis, (1 + g) / g times the posterior's shift; an axis the
    # window hardly sees keeps the prior's mean and almost no information
    seen = gain >= MIN_GAIN
    z = np.where(seen, (1.0 + gain) * (vectors.T @ a) / np.where(seen, gain, 1.0), 0.0)
    g = np.where(seen, gain, MIN_AXIS_GAIN)
    covariance = root @ (vectors / g) @ vectors.T @ root.T
    return m + root @ vectors @ z, 0.5 * (covariance + covariance.T)


def _depth_fault(likelihood: TerrainLikelihood, patch: Patch, variance, map_variance, variance_extra,
                 points: np.ndarray, log_post: np.ndarray, log_lik: np.ndarray, tide: np.ndarray,
                 tide_var: float) -> tuple[str, float] | None:
    """Whether the window's depths carry an offset of their own: the evidence of its soundings
    over the prior's grid with a free offset on top of the held tide (``N(0, FAULT_STD^2)``,
    marginalised) against the evidence with the held tide alone. A depth-biased block of pings
    fits the held tide nowhere, and weighed as if it did it moves the position to where the map
    is as deep (or says the prediction is wrong); its offset is told apart by the Bayes factor,
    at the prior odds ``FAULT_PRIOR``. None, or the reason (``"depth fault: ..."``) and the
    offset (the free offset's posterior mean). The held tide's evidence is the prior-wide grid's
    (``log_post``, ``log_lik``: weighed with the soundings' variances plus ``variance_extra``, the
    grid's resolution term); the free one is weighed on the same grid with the same variances."""
    log_prior = log_post - log_lik
    held = special.logsumexp(log_post)
    update = likelihood.ping_update(points, patch.offsets, patch.depths, tide, tide_var + FAULT_STD**2,
                                    weights=np.exp(log_prior - log_prior.max()),
                                    variance=variance + variance_extra, map_variance=map_variance)
    log_w = log_prior + update.log_likelihood
    free = special.logsumexp(log_w)
    if not (np.isfinite(free) and free - held > np.log((1.0 - FAULT_PRIOR) / FAULT_PRIOR)):
        return None
    offset = float(np.exp(log_w - free) @ (update.tide - tide))
    return f"depth fault: the soundings sit {offset:+.2f} m off the held tide (log Bayes factor " \
        f"{free - held:.0f})", offset


def _first_reasons(fault: tuple[str, float] | None, n_parts: int, other: float, n_fits: int,
                   elsewhere: float) -> list[str]:
    """Why a window is refused on the prior-wide grid: a depth fault, a second part of the
    posterior, or a second place its soundings fit as well (none: an empty list)."""
    if fault:
        return [fault[0]]
    if other >= MODE_MASS:
        return [f"multimodal: {n_parts} parts, {other:.0%} of the mass away from the main one"]
    if elsewhere >= MODE_MASS:
        return [f"multimodal: the soundings fit {n_fits} places within the prediction's reach, "
                f"{elsewhere:.0%} of their likelihood away from the best"]
    return []


def _checked_prior(patch: Patch, prior_mean, prior_cov) -> tuple[np.ndarray, np.ndarray]:
    """The prior's mean ``(3,)`` and covariance ``(3, 3)`` as arrays, refused unless finite with a
    positive definite position part and a tide variance >= 0."""
    m3 = np.asarray(prior_mean, float)
    p3 = np.asarray(prior_cov, float)
    if m3.shape != (3,) or p3.shape != (3, 3) or not (np.all(np.isfinite(p3)) and np.all(np.isfinite(m3))) \
            or np.linalg.eigvalsh(p3[:2, :2]).min() <= 0 or p3[2, 2] < 0:
        raise MatchingError(f"window {patch.first}..{patch.reference}: the prior covariance is not finite "
                            "and positive definite")
    return m3, p3


def _refined(weigh, weighed: tuple, centre: np.ndarray, lay: np.ndarray) -> tuple[tuple, int]:
    """The window weighed at the grid's resolution, from ``weighed``, the result of the first,
    blurred, ``weigh(centre, lay, True)``: a posterior narrower than ``REFINE_SPACINGS`` spacings
    is weighed again on a grid laid over it, one that spills over the grid's edge on a grid four
    times as wide, up to ``MAX_REFINE`` more grids; one resolved on a blurred grid is weighed
    again on it unblurred. Returns the last weighing and how many grids were laid."""
    grids, blurred = 1, True
    while True:
        mass, mean, cov = weighed[3:]
        axes = _axes(lay)
        inv = np.linalg.inv(axes)
        narrow = np.linalg.eigvalsh(inv @ cov @ inv.T).min() < REFINE_SPACINGS**2
        spilled = grids > 1 and _edge(mass) > EDGE_MASS
        if not (narrow or spilled) or grids > MAX_REFINE:
            if not blurred:
                return weighed, grids
            weighed = weigh(centre, lay, False)  # resolved on this grid: weigh it again as it is
            blurred = False
            continue
        # a narrow posterior may sit between the points: lay the next grid over the cells around it
        lay = 4.0 * lay if spilled else cov + axes @ axes.T / 3.0
        centre = mean
        weighed = weigh(centre, lay, False)
        blurred = False
        grids += 1


def _residual_std(likelihood: TerrainLikelihood, patch: Patch, position: np.ndarray, tide: float) -> float:
    """The RMS residual of the window's soundings at ``position`` with ``tide`` (NaN with none on
    the map)."""
    residual = likelihood.residuals(position[None, :], patch.offsets, patch.depths, np.array([tide]))[:, 0]
    ok = np.isfinite(residual)
    return float(np.sqrt(np.mean(residual[ok] ** 2))) if ok.any() else float("nan")


def _factor(weighed: tuple, joint: bool, m3: np.ndarray, p3: np.ndarray,
            reasons: list[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The window's factor from its last weighing: ``(position, covariance, joint_mean,
    joint_cov)``, the posterior less the prior ``N(m3, p3)``, in (north, east, tide) when
    ``joint`` (the tide's posterior joined to the grid's moments), else in (north, east); a
    refused window (``reasons``, which the removal may add to) keeps its posterior as its
    record and NaN joint moments."""
    points, _, update, mass, mean, cov = weighed
    position, covariance = mean, cov  # a refused window's record shows its posterior
    joint_mean, joint_cov = np.full(3, np.nan), np.full((3, 3), np.nan)
    if reasons:
        return position, covariance, joint_mean, joint_cov
    if joint:
        factor = _remove_prior(*_joint_moments(points, update, mass, mean, cov), m3, p3, reasons)
        if factor is not None:
            joint_mean, joint_cov = factor
            position, covariance = joint_mean[:2], joint_cov[:2, :2]
    else:
        factor = _remove_prior(mean, cov, m3[:2], p3[:2, :2], reasons)
        if factor is not None:
            position, covariance = factor
    return position, covariance, joint_mean, joint_cov


def _joint_moments(points: np.ndarray, update, mass: np.ndarray, mean: np.ndarray,
                   cov: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The posterior's mean and covariance of (north, east, tide): the grid's moments joined by
    each point's tide posterior."""
    tide_mean = float(mass @ update.tide)
    spread = update.tide - tide_mean
    post3 = np.zeros((3, 3))
    post3[:2, :2] = cov
    post3[:2, 2] = post3[2, :2] = (mass * spread) @ (points - mean)
    post3[2, 2] = update.tide_var + mass @ spread**2
    return np.append(mean, tide_mean), post3


def posterior_fix(patch: Patch, likelihood: TerrainLikelihood, variance: np.ndarray,
                  map_variance: np.ndarray | None, slope: np.ndarray, prior_mean, prior_cov, *,
                  tide_factor: bool = False) -> WindowFix:
    """The window's terrain information (module docstring) from ``patch`` (laid from the end
    ping's position, the prior's mean standing for it), each sounding's ``variance (N,)`` and map
    error ``map_variance (N,)`` (None: a perfect map), the map's mean outer product of depth
    gradients ``slope (2, 2)``, and the prior ``N(prior_mean (3,), prior_cov (3, 3))`` of the
    end ping's (north, east) and the tide (``measured = map + tide``).

    Each grid point's tide prior is the prior's conditional on the point. With ``tide_factor``
    (a graph that holds the tide as a variable, whose belief the prior's tide is) and a tide of
    positive prior variance, the posterior's mean and covariance are those of (north, east,
    tide) (each point's tide posterior joins the grid's moments), the prior removed from them in
    three dimensions gives ``joint_mean`` and ``joint_covariance``, and ``position`` and
    ``covariance`` are their (north, east) part. Without it the tide's prior is part of the
    window's evidence (nothing else holds the tide) and only the position's prior is removed.

    Raises
    ------
    MatchingError
        The prior covariance is not finite, symmetric and positive semi-definite with a positive
        definite position part, or no sounding of the window has the map under it anywhere on
        the grid.
    """
    m3, p3 = _checked_prior(patch, prior_mean, prior_cov)
    where = f"window {patch.first}..{patch.reference}"
    m, p = m3[:2], p3[:2, :2]
    gain_t = np.linalg.solve(p, p3[:2, 2])  # the tide's prior regression on the position
    tide_var = max(float(p3[2, 2] - p3[:2, 2] @ gain_t), 0.0)  # given the position
    joint = tide_factor and tide_var > 1e-12

    def weigh(centre, cov, blur):
        axes = _axes(cov)
        points = _grid(centre, axes)
        prior = _log_gaussian(points, m, p)
        extra = _resolution(likelihood.bathymetry, patch.offsets + centre, axes, slope) if blur else 0.0
        update = likelihood.ping_update(points, patch.offsets, patch.depths, m3[2] + (points - m) @ gain_t,
                                        tide_var, weights=np.exp(prior - prior.max()),
                                        variance=variance + extra, map_variance=map_variance)
        if np.all(np.isneginf(update.log_likelihood)):
            raise MatchingError(f"{where}: no sounding has the map under it anywhere near the prediction")
        log_post = prior + update.log_likelihood
        mass, mean, cov = _moments(points, log_post)
        return points, log_post, update, mass, mean, _floored(cov, axes)

    weighed = weigh(m, p, True)
    points, log_post, update, mass = weighed[:4]
    log_lik = update.log_likelihood
    fault = _depth_fault(likelihood, patch, variance, map_variance, _resolution(
        likelihood.bathymetry, patch.offsets + m, _axes(p), slope), points, log_post, log_lik,
        m3[2] + (points - m) @ gain_t, tide_var) if joint else None
    n_parts, other = _parts(log_post, mass)
    # the soundings alone over the prior's reach: a second place they fit as well is a
    # prediction's word against theirs, which a window that follows a wrong one would lose
    n_fits, elsewhere = _parts(log_lik, _moments(points, log_lik)[0])
    edge = _edge(mass)
    reasons = _first_reasons(fault, n_parts, other, n_fits, elsewhere)
    grids = 1
    if not reasons:
        weighed, grids = _refined(weigh, weighed, m, p)
    points, log_post, update, mass, mean, cov = weighed
    position, covariance, joint_mean, joint_cov = _factor(weighed, joint, m3, p3, reasons)
    tide_best = float(update.tide[int(np.argmax(log_post))])
    sigma = _residual_std(likelihood, patch, mean, tide_best)
    quality = FixQuality(peak_ratio=float("inf") if n_parts < 2 else other, n_basins=max(n_parts, n_fits, 1),
                         area_fraction=float(np.sqrt(np.linalg.det(cov) / np.linalg.det(p))),
                         touches_edge=edge > EDGE_MASS, reasons=tuple(reasons),
                         best_on_edge=edge > EDGE_MASS)
    log_density = log_post - special.logsumexp(log_post)
    return WindowFix(int(patch.reference), int(patch.first), position, covariance, tide_best, sigma,
                     patch.n_soundings, quality, mean, cov, m3, p3, points, log_density, grids,
                     joint_mean, joint_cov, fault[1] if fault else float("nan"))
