"""The point-mass filter: the position density on a grid that moves with the estimate.

No particles: the density of the vehicle's position is held as its values on a regular
``n x n`` grid (Bergman's point-mass filter), every grid point weighed by the same terrain
likelihood as the particle filters (:mod:`tangraph.filters.likelihood`: the map's error, no map
is no evidence, MBARI's exponents, the tide marginalised exactly: each point carries its
Gaussian tide posterior). It is deterministic and keeps a multimodal density as it is.

**The DR's constant errors** ``(k, b)`` (speed scale, heading error) are handled by a bank: the
joint density of ``(position, k, b)`` is held at the nodes of a product Gauss-Hermite rule of a
Gaussian in the calibration (``calibration_points`` per principal axis), each node a member with
its own position grid and a mass. Between pings a member's grid moves by its own calibrated
increment ``R(-b) u / (1 + k)`` (the Lagrangian form: moving the points is exact); the white DR
noise accumulates and is convolved in (FFT, in the grid's coordinates) once its std reaches half
a grid spacing. A ping weighs every point of every member. The calibration's posterior is the
Gaussian the nodes were placed with times the evidence since (each member's mass over its mass
at placement), fitted as a quadratic at the nodes whose curvature is made a likelihood's
(positive semi-definite): exact for a Gaussian evidence however narrow against the nodes, never
wider than the prior, its mean kept among the nodes.

**Re-gridding**: when a member's density reaches its grid's edge, or the density has grown or
shrunk well away from its grid, every member is re-sampled (bilinear) onto a grid centred on its
own mean, aligned with the principal axes of the members' mean covariance, spanning
``grid_sigmas`` standard deviations and at least the points that hold all but ``1e-4`` of the
mass (so a second mode is not cut off). The calibration's nodes are re-placed then, and whenever
its posterior has moved from their placement: the Gauss-Hermite rule of the posterior (its
heading error grown by the heading walk since the last placement), each new node given the
position density of the nearest old member shifted by the regression of the members' mean
positions on their nodes (the posterior's position sensitivity to the calibration). When one
ping's evidence differs by more than ``_SHARP`` nats between the nodes and is Gaussian in the
calibration, the predicted state's nodes are first re-placed at the posterior it gives and the
ping weighed again (adaptive Gauss-Hermite quadrature). The tide posteriors of points mixed by
the convolution are moment-matched (the spread of the mixed means joins the variance);
re-sampling interpolates them.

**Resolution**: a grid point stands for its cell, so each sounding's variance is raised by the
variance of the map's depth across a cell, ``sum_i a_i^T G a_i / 12`` for the grid's steps
``a_i`` and the map's mean outer product of depth gradients ``G``: a coarse grid does not claim a
sharp likelihood it cannot resolve (negligible once the grid is finer than the likelihood).

The track is the density's mean and covariance (with the white noise not yet convolved in), the
heading the dead-reckoned one; ``meta["calibration"]`` is the bank's mean and std of ``(k, b)``.
A ping whose mean sounding's innovation is inconsistent with the density's predictive spread
(:class:`~tangraph.filters.core.Innovation`'s ``nis``) for ``lost_pings`` pings in a row is
flagged lost with them (``meta["lost_steps"]``) and, with ``relocalise`` set, the filter starts
afresh from a uniform density on a global grid over the map's data (or ``relocalise_radius``
around its estimate; ``relocalise_points`` per axis), with one calibration node at the
calibration's prior, which the bank grows back from at its next re-grid, and the tide at its
prior (what a lost filter believes of them is suspect too). The density then holds every place
the soundings could have come from, and its covariance says so until the terrain has chosen
(``meta["relocalisation_steps"]``).
"""

from __future__ import annotations

import dataclasses
import logging
import time as _time
from typing import Any

import numpy as np
import scipy.fft
from scipy import ndimage

from tangraph.filters.config import check_count, check_number
from tangraph.filters.core import (
    Belief,
    FilterModel,
    _chi2_quantile,
    check_run_inputs,
    innovation,
    step_timings,
)
from tangraph.filters.likelihood import FilterDivergence, log_normalise
from tangraph.filters.model import Ping, rotate, survey_pings
from tangraph.maps.grid import BathymetryMap
from tangraph.sensors import NavigationModel, slope_moment, survey_navigation_model
from tangraph.survey import Survey
from tangraph.track import Track

__all__ = ["PMFConfig", "PointMass", "point_mass_filter"]

_log = logging.getLogger(__name__)

# a member's density reaching this share of its mass in its grid's outer ring triggers a re-grid
_EDGE_MASS = 1e-3
# the density's std in grid spacings may drift this factor from the target before a re-grid
_SPREAD_RATIO = 1.6
# the calibration's nodes are re-placed when its posterior std leaves [r, 1 / r] times the
# placement's, or its mean moves by this many placement stds
_NODE_RATIO = 0.7
_NODE_SHIFT = 0.5


@dataclasses.dataclass(frozen=True)
class PMFConfig:
    """Settings of the point-mass filter.

    Parameters
    ----------
    grid_points : int
        Points per axis of a member's position grid (odd, >= 5).
    grid_sigmas : float
        Half-width of the grid in standard deviations of the density along each principal axis.
    min_spacing : float
        Smallest grid spacing (m): the floor a grid shrinks to around a density narrower than
        its points (a coarser floor gives up precision: each sounding's variance grows with the
        spacing, see the module docstring).
    calibration_points : tuple of int
        Gauss-Hermite nodes of the calibration bank along the principal axes of the
        calibration's covariance (first: the speed scale's, second: the heading error's; 1 on an
        axis whose std is 0, whatever is asked).
    lost_alpha, lost_pings : float, int
        A ping is inconsistent when its innovation is beyond the ``1 - lost_alpha`` chi-square
        quantile; ``lost_pings`` in a row flag the filter lost.
    relocalise : bool
        When lost, start afresh from a uniform density on the global grid (off by default: on
        a map whose error the model under-states, as on a flat lake gridded from an earlier
        survey, the lost test fires where the filter is not lost, and a global restart there
        chose a wrong place in most runs; use it where the terrain is distinctive).
    relocalise_points : int
        Points per axis of the global grid (odd, >= 5).
    relocalise_radius : float or None
        Half-width (m) of the global grid around the estimate; None: the map's data extent.

    Examples
    --------
    >>> PMFConfig().grid_points
    31
    >>> PMFConfig(grid_points=4)
    Traceback (most recent call last):
    ...
    tangraph.errors.TangraphError: PMFConfig: grid_points must be an odd integer >= 5, got 4
    """

    grid_points: int = 31
    grid_sigmas: float = 5.0
    min_spacing: float = 0.01
    calibration_points: tuple[int, int] = (3, 3)
    lost_alpha: float = 1e-3
    lost_pings: int = 5
    relocalise: bool = False
    relocalise_points: int = 201
    relocalise_radius: float | None = None

    def __post_init__(self) -> None:
        from tangraph.errors import TangraphError

        n = self.grid_points
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 5 or n % 2 == 0:
            raise TangraphError(f"PMFConfig: grid_points must be an odd integer >= 5, got {n!r}")
        object.__setattr__(self, "grid_points", int(n))
        check_number(self, "grid_sigmas", low=1.0)
        check_number(self, "min_spacing", low=0.0, open_low=True)
        points = self.calibration_points
        if (not isinstance(points, (tuple, list)) or len(points) != 2
                or any(isinstance(p, bool) or not isinstance(p, (int, np.integer)) or p < 1 for p in points)):
            raise TangraphError(f"PMFConfig: calibration_points must be two integers >= 1, got {points!r}")
        object.__setattr__(self, "calibration_points", (int(points[0]), int(points[1])))
        check_number(self, "lost_alpha", low=0.0, open_low=True, high=0.5)
        check_count(self, "lost_pings", low=1)
        object.__setattr__(self, "relocalise", bool(self.relocalise))
        n = self.relocalise_points
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 5 or n % 2 == 0:
            raise TangraphError(f"PMFConfig: relocalise_points must be an odd integer >= 5, got {n!r}")
        object.__setattr__(self, "relocalise_points", int(n))
        if self.relocalise_radius is not None:
            check_number(self, "relocalise_radius", low=0.0, open_low=True)

    def as_dict(self) -> dict[str, Any]:
        return dataclasses.asdict(self)


@dataclasses.dataclass(eq=False)
class PointMass:
    """The filter's state: ``M`` members (calibration ``nodes (M, 2)``: ``k``, ``b``), each a
    position grid of ``n x n`` points ``centres[m] + axes @ (i - h, j - h)`` (``h = (n - 1) / 2``;
    ``axes (2, 2)``'s columns the grid's steps in metres, shared by the members), the log density
    ``log_density (M, n, n)`` (per square metre, normalised over all members), each point's tide
    posterior mean ``tide (M, n, n)`` and variance ``tide_var``; ``pending (2, 2)`` the white DR
    noise not yet convolved in; ``walk`` the heading error's variance grown since the nodes were
    placed. The calibration's posterior is ``prior (mean, cov)`` (the Gaussian it had when the
    nodes were placed) times the evidence since: each member's log mass less ``node_base (M,)``,
    its log mass at placement; ``placed (mean, std)`` is the Gaussian the nodes were placed on."""

    nodes: np.ndarray
    node_base: np.ndarray
    centres: np.ndarray
    axes: np.ndarray
    log_density: np.ndarray
    tide: np.ndarray
    tide_var: float
    pending: np.ndarray
    walk: float
    prior: tuple[np.ndarray, np.ndarray]
    placed: tuple[np.ndarray, np.ndarray]

    @property
    def n(self) -> int:
        return int(self.log_density.shape[1])

    def offsets(self) -> np.ndarray:
        """The grid's points relative to a member's centre, ``(n * n, 2)`` (row-major)."""
        h = (self.n - 1) / 2.0
        i, j = np.meshgrid(np.arange(self.n) - h, np.arange(self.n) - h, indexing="ij")
        return np.column_stack([i.ravel(), j.ravel()]) @ self.axes.T

    def points(self) -> np.ndarray:
        """Every member's points, ``(M * n * n, 2)``."""
        return (self.centres[:, None, :] + self.offsets()[None]).reshape(-1, 2)

    @property
    def cell_area(self) -> float:
        return float(abs(np.linalg.det(self.axes)))

    def masses(self) -> np.ndarray:
        """Each point's probability, ``(M, n, n)`` (sums to 1)."""
        w = np.exp(self.log_density - np.max(self.log_density))
        return w / w.sum()

    def member_moments(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Each member's mass ``(M,)``, mean ``(M, 2)`` and covariance ``(M, 2, 2)`` (of its
        points; zero-mass members: their centre and a zero covariance)."""
        mass = self.masses().reshape(len(self.nodes), -1)
        weight = mass.sum(axis=1)
        offsets = self.offsets()
        with np.errstate(invalid="ignore", divide="ignore"):
            w = np.where(weight[:, None] > 0, mass / weight[:, None], 0.0)
        local = w @ offsets
        d = offsets[None] - local[:, None]
        cov = np.einsum("mp,mpi,mpj->mij", w, d, d)
        return weight, self.centres + local, cov

    def within(self) -> np.ndarray:
        """The members' mass-weighted mean covariance ``(2, 2)`` (the spread a grid must hold)."""
        weight, _, cov = self.member_moments()
        return np.einsum("m,mij->ij", weight, cov) / weight.sum()

    def moments(self) -> tuple[np.ndarray, np.ndarray]:
        """The position's mean ``(2,)`` and covariance ``(2, 2)`` (with the white noise not yet
        convolved in)."""
        weight, mean, cov = self.member_moments()
        total = weight @ mean
        d = mean - total
        pooled = np.einsum("m,mij->ij", weight, cov) + (d * weight[:, None]).T @ d
        return total, pooled + self.pending

    def member_log_mass(self) -> np.ndarray:
        """Each member's log mass ``(M,)`` (computed in logs: no underflow however unlikely)."""
        flat = self.log_density.reshape(len(self.nodes), -1)
        top = np.max(flat, axis=1)
        safe = np.where(np.isfinite(top), top, 0.0)
        with np.errstate(divide="ignore"):
            return safe + np.log(np.sum(np.exp(flat - safe[:, None]), axis=1)) + np.log(self.cell_area)

    def calibration(self) -> tuple[np.ndarray, np.ndarray]:
        """The calibration's posterior mean ``(2,)`` and covariance ``(2, 2)``: the prior at
        placement times the evidence since, fitted at the nodes (:func:`_evidence_fit`)."""
        return _evidence_fit(self.nodes, self.member_log_mass() - self.node_base, *self.prior)[:2]


def _evidence_fit(nodes: np.ndarray, evidence: np.ndarray, mean: np.ndarray, cov: np.ndarray):
    """The Gaussian ``N(mean, cov)`` times the exponential of the least-squares quadratic through
    the log ``evidence (M,)`` at ``nodes (M, 2)``, its curvature made positive semi-definite (a
    likelihood's): the posterior is never wider than the prior, exact when the evidence is
    Gaussian in the calibration however narrow it is against the nodes' spacing. The mean is
    kept inside the nodes' bounding box (the fit does not extrapolate). Axes of prior variance
    0, or on which the nodes do not vary, keep the prior; without enough finite evidence for a
    quadratic, the prior is returned. Returns the mean, the covariance and whether the fitted
    evidence was concave (a Gaussian likelihood)."""
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    live = np.flatnonzero((std > 0) & (np.ptp(nodes, axis=0) > 0))
    pairs = [(i, j) for i in range(live.size) for j in range(i, live.size)]
    keep = np.isfinite(evidence)
    if live.size == 0 or keep.sum() < 1 + live.size + len(pairs):
        return mean.copy(), cov.copy(), False
    x = (nodes[keep][:, live] - mean[live]) / std[live]
    columns = [np.ones(len(x)), *x.T, *(x[:, i] * x[:, j] for i, j in pairs)]
    coef = np.linalg.lstsq(np.column_stack(columns), evidence[keep], rcond=None)[0]
    g = coef[1:1 + live.size]
    h = np.zeros((live.size, live.size))
    for c, (i, j) in zip(coef[1 + live.size:], pairs, strict=True):
        h[i, j] = h[j, i] = -c if i != j else -2.0 * c
    values, vectors = np.linalg.eigh(h)
    h = (vectors * np.maximum(values, 0.0)) @ vectors.T  # a likelihood's curvature
    correlation = cov[np.ix_(live, live)] / np.outer(std[live], std[live])
    posterior = np.linalg.inv(np.linalg.inv(correlation) + h)
    out_mean, out_cov = mean.copy(), cov.copy()
    box = nodes[:, live]
    out_mean[live] = np.clip(mean[live] + std[live] * (posterior @ g), box.min(axis=0), box.max(axis=0))
    out_cov[np.ix_(live, live)] = posterior * np.outer(std[live], std[live])
    return out_mean, out_cov, bool(np.all(values > 0))


def _gaussian_convolve(values: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """``values (M, n, n)`` convolved with the Gaussian of covariance ``cov (2, 2)`` in grid
    coordinates (zero padded, so nothing wraps around)."""
    n = values.shape[1]
    pad = int(np.ceil(5.0 * np.sqrt(max(np.max(np.linalg.eigvalsh(cov)), 0.0)))) + 1
    size = scipy.fft.next_fast_len(n + 2 * pad)
    f = scipy.fft.rfft2(values, s=(size, size), axes=(1, 2))
    wi = 2.0 * np.pi * scipy.fft.fftfreq(size)[:, None]
    wj = 2.0 * np.pi * scipy.fft.rfftfreq(size)[None, :]
    kernel = np.exp(-0.5 * (cov[0, 0] * wi**2 + 2.0 * cov[0, 1] * wi * wj + cov[1, 1] * wj**2))
    return scipy.fft.irfft2(f * kernel, s=(size, size), axes=(1, 2))[:, :n, :n]


def _mixed_tide(mass: np.ndarray, first: np.ndarray, second: np.ndarray, tide_var: float):
    """The tide posterior of points whose density ``mass`` mixes points of tide means whose
    mass-weighted first and second moments are ``first``, ``second`` (same shape): each point's
    mean and the one variance of the filter (the variance within plus the mass-weighted spread
    between the mixed means)."""
    live = mass > 1e-300
    with np.errstate(divide="ignore", invalid="ignore"):
        tide = np.where(live, first / mass, 0.0)
        spread = np.where(live, np.maximum(second / mass - tide**2, 0.0), 0.0)
    total = mass.sum()
    return tide, tide_var + (float(np.sum(mass * spread) / total) if total > 0 else 0.0)


def _diffuse(state: PointMass) -> None:
    """Convolve the pending white DR noise into every member's density (and tide posteriors)."""
    inv = np.linalg.inv(state.axes)
    cov = inv @ state.pending @ inv.T
    top = np.max(state.log_density)
    p = np.exp(state.log_density - top)
    smoothed = np.maximum(_gaussian_convolve(p, cov), 0.0)  # less round-off below zero
    if state.tide_var > 0:
        state.tide, state.tide_var = _mixed_tide(
            smoothed, _gaussian_convolve(p * state.tide, cov), _gaussian_convolve(p * state.tide**2, cov),
            state.tide_var,
        )  # fmt: skip
    with np.errstate(divide="ignore"):
        state.log_density = np.where(smoothed > 1e-300, np.log(smoothed), -np.inf) + top
    state.pending = np.zeros((2, 2))


def _edge_mass(state: PointMass) -> float:
    """The largest share of a member's mass in its grid's outer ring."""
    mass = state.masses()
    total = mass.sum(axis=(1, 2))
    inner = mass[:, 1:-1, 1:-1].sum(axis=(1, 2))
    live = total > 1e-9 * total.max()
    return float(np.max((total[live] - inner[live]) / total[live]))


class _Grid:
    """The grid rule of a run: points, half-width in standard deviations, smallest spacing."""

    def __init__(self, config: PMFConfig, min_spacing: float):
        self.n = config.grid_points
        self.sigmas = config.grid_sigmas
        self.min_spacing = min_spacing

    def axes(self, cov: np.ndarray, support: np.ndarray | None = None) -> np.ndarray:
        """Grid steps ``(2, 2)`` (columns) for a density of covariance ``cov``: along its principal
        axes, spanning ``sigmas`` standard deviations each side, and at least its ``support``
        (a function of the axes ``(2, 2) -> (2,)``: the half-widths holding every point of
        the density above ``_SUPPORT`` nats below its peak, so no mode is cut off)."""
        values, vectors = np.linalg.eigh(0.5 * (cov + cov.T))
        half = self.sigmas * np.sqrt(np.maximum(values, 0.0))
        if support is not None:
            half = np.maximum(half, support(vectors))
        spacing = np.maximum(half / ((self.n - 1) / 2.0), self.min_spacing)
        return vectors * spacing

    def needs_regrid(self, state: PointMass, cov: np.ndarray) -> bool:
        """Whether the density has reached the edge, its spread (in grid coordinates) has grown
        beyond ``_SPREAD_RATIO`` times the target, or its support has shrunk within ``1 /
        _SPREAD_RATIO`` of the grid on an axis that can be made finer. A global grid (more points
        than the rule's) is kept until its support fits the rule's grid at no coarser spacing."""
        h = (self.n - 1) / 2.0
        if state.n > self.n:
            return bool(np.all(_significant(state) < h))
        if _edge_mass(state) > _EDGE_MASS:
            return True
        inv = np.linalg.inv(state.axes)
        spread = np.sqrt(np.maximum(np.linalg.eigvalsh(inv @ cov @ inv.T), 0.0))
        if np.max(spread) > _SPREAD_RATIO * h / self.sigmas:
            return True
        extent = _significant(state)
        spacing = np.linalg.norm(state.axes, axis=0)
        return bool(np.any((extent < h / _SPREAD_RATIO) & (spacing > 1.01 * self.min_spacing)))


# the density's support: the points that hold all but this share of its mass, whatever their
# shape (a second mode included; what bilinear re-sampling adds to the tails is not)
_SUPPORT_MASS = 1e-4


def _extent(offsets: np.ndarray, mass: np.ndarray) -> np.ndarray:
    """Per column of ``offsets (P, A)`` the smallest half-width holding all but
    ``_SUPPORT_MASS`` of ``mass (P,)``."""
    out = np.empty(offsets.shape[1])
    total = mass.sum()
    for a in range(offsets.shape[1]):
        size = np.abs(offsets[:, a])
        order = np.argsort(size)
        held = np.cumsum(mass[order])
        out[a] = size[order][min(np.searchsorted(held, (1.0 - _SUPPORT_MASS) * total), size.size - 1)]
    return out


def _significant(state: PointMass) -> np.ndarray:
    """The half-widths in grid steps, per grid axis, that hold the density's support about
    each member's mean."""
    i, j = np.meshgrid(np.arange(state.n), np.arange(state.n), indexing="ij")
    index = np.column_stack([i.ravel(), j.ravel()]).astype(np.float64)
    mass = state.masses().reshape(len(state.nodes), -1)
    weight = mass.sum(axis=1, keepdims=True)
    centre = (mass @ index) / np.where(weight > 0, weight, 1.0)
    offsets = (index[None, :, :] - centre[:, None, :]).reshape(-1, 2)
    return _extent(offsets, mass.ravel())


def _support(state: PointMass, centres: np.ndarray):
    """The half-widths along unit ``vectors (2, 2)`` (columns) from each member's ``centres``
    that hold the density's support (plus one old grid step), as :meth:`_Grid.axes` takes
    them."""
    points = state.points() - np.repeat(centres, state.n * state.n, axis=0)
    mass = state.masses().ravel()
    return lambda vectors: _extent(points @ vectors, mass) \
        + np.max(np.abs(state.axes.T @ vectors), axis=0)  # one old step along each


def _sample(state: PointMass, member: int, points: np.ndarray) -> tuple[np.ndarray, ...]:
    """Member ``member``'s density (relative to the state's largest value) at world ``points
    (P, 2)`` and its mass-weighted tide mean there (bilinear; zero outside its grid)."""
    inv = np.linalg.inv(state.axes)
    h = (state.n - 1) / 2.0
    q = ((points - state.centres[member]) @ inv.T + h).T
    p = np.exp(state.log_density[member] - np.max(state.log_density))
    t = state.tide[member]
    return tuple(ndimage.map_coordinates(v, q, order=1, mode="constant", cval=0.0) for v in (p, p * t))


def _place_nodes(mean: np.ndarray, cov: np.ndarray, counts: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Calibration nodes ``(M, 2)`` of the product Gauss-Hermite rule of ``counts`` points along
    the principal axes of ``N(mean, cov)`` (one node on an axis of variance 0) and their log
    weights ``(M,)`` (summing to 1)."""
    values, vectors = np.linalg.eigh(0.5 * (cov + cov.T))
    order = np.argsort(np.argmax(np.abs(vectors), axis=0))  # principal axis nearest k first, then b
    values, vectors = values[order], vectors[:, order]
    rules = []
    for c, v in zip(counts, values, strict=True):
        if c == 1 or v <= 0:
            rules.append((np.zeros(1), np.ones(1)))
        else:
            x, w = np.polynomial.hermite_e.hermegauss(c)
            rules.append((x, w / w.sum()))
    (x0, w0), (x1, w1) = rules
    xi = np.stack(np.meshgrid(x0, x1, indexing="ij"), axis=-1).reshape(-1, 2)
    nodes = mean + xi * np.sqrt(np.maximum(values, 0.0)) @ vectors.T
    return nodes, np.log(np.outer(w0, w1).ravel())


def _log_gaussian(nodes: np.ndarray, mean: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """``log N(nodes; mean, cov)`` up to a constant (axes of variance 0 left out)."""
    live = np.diag(cov) > 0
    if not live.any():
        return np.zeros(len(nodes))
    d = (nodes - mean)[:, live]
    return -0.5 * np.einsum("mi,ij,mj->m", d, np.linalg.inv(cov[np.ix_(live, live)]), d)


def _regrid(state: PointMass, grid: _Grid, config: PMFConfig, estimate: bool, target=None) -> PointMass:
    """The state re-sampled onto new grids (and, with the calibration estimated, new nodes: the
    Gauss-Hermite rule of the state's calibration posterior, or of ``target`` ``(mean, cov)``,
    the members' masses then carrying the state's posterior over the target)."""
    if np.any(state.pending):
        _diffuse(state)
    weight, means, _ = state.member_moments()
    live = weight > 0
    axes = grid.axes(state.within(), _support(state, means))
    nodes, prior, placed = state.nodes, state.prior, state.placed
    source = np.arange(len(nodes))
    shift = np.zeros((len(nodes), 2))
    log_weight = np.log(np.maximum(weight, 1e-300))
    node_base = state.node_base  # the nodes stay: so does the evidence since their placement
    if estimate:
        own_mean, own_cov = state.calibration()
        own_cov = own_cov.copy()
        own_cov[1, 1] += state.walk
        cal_mean, cal_cov = (own_mean, own_cov) if target is None else target
        nodes, log_weight = _place_nodes(cal_mean, cal_cov, config.calibration_points)
        if target is not None:  # mass = weight x own posterior / target's at each node
            log_weight = log_weight + _log_gaussian(nodes, own_mean, own_cov) \
                - _log_gaussian(nodes, cal_mean, cal_cov)
        node_base = log_weight
        prior = (own_mean, own_cov)
        placed = (cal_mean, np.sqrt(np.maximum(np.diag(cal_cov), 0.0)))
        # the members' mean positions regressed on their nodes: the position's sensitivity
        d_theta = state.nodes - own_mean
        d_x = means - weight @ means
        c_xt = (d_x * weight[:, None]).T @ d_theta
        gain = c_xt @ np.linalg.pinv(own_cov - np.diag([0.0, state.walk]), rcond=1e-9)
        live_var = np.maximum(np.diag(cal_cov), 1e-30)
        distance = ((nodes[:, None, :] - state.nodes[None]) ** 2 / live_var).sum(axis=2)
        distance[:, ~live] = np.inf
        source = np.argmin(distance, axis=1)
        shift = (nodes - state.nodes[source]) @ gain.T
    new_centres = means[source] + shift
    h = (grid.n - 1) / 2.0
    i, j = np.meshgrid(np.arange(grid.n) - h, np.arange(grid.n) - h, indexing="ij")
    offsets = np.column_stack([i.ravel(), j.ravel()]) @ axes.T
    shape = (len(nodes), grid.n, grid.n)
    mass, first = np.empty(shape), np.empty(shape)
    for m, src in enumerate(source):
        value, t1 = _sample(state, src, new_centres[m] - shift[m] + offsets)
        total = value.sum()
        if total <= 0:  # a member whose density missed its new grid: its mean point
            value, t1 = np.zeros_like(value), np.zeros_like(value)
            value[value.size // 2], t1[value.size // 2] = 1.0, state.tide[src].mean()
            total = 1.0
        scale = np.exp(log_weight[m] - np.max(log_weight)) / total
        mass[m], first[m] = value.reshape(shape[1:]) * scale, t1.reshape(shape[1:]) * scale
    # re-sampling only reads the density between points: the tide means are interpolated (their
    # spread between neighbours is not a mixture: it would widen the tide at every re-grid)
    with np.errstate(divide="ignore", invalid="ignore"):
        tide = np.where(mass > 1e-300, first / mass, 0.0)
        density = np.log(mass)
    area = float(abs(np.linalg.det(axes)))
    _, log_total = log_normalise(density.ravel(), where="pmf")
    return PointMass(nodes, node_base, new_centres, axes, density - log_total - np.log(area), tide,
                     state.tide_var, np.zeros((2, 2)), 0.0 if estimate else state.walk, prior, placed)


def _calibration_moved(state: PointMass) -> bool:
    """Whether the calibration's posterior has left the nodes' placement: its std out of
    ``[_NODE_RATIO, 1 / _NODE_RATIO]`` times the placement's on an axis, or its mean moved by
    more than ``_NODE_SHIFT`` placement stds."""
    mean, cov = state.calibration()
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    placed_mean, placed_std = state.placed
    live = (placed_std > 0) & (np.ptp(state.nodes, axis=0) > 0)
    if not live.any():
        return False
    grown = np.sqrt(placed_std[live] ** 2 + np.array([0.0, state.walk])[live])
    ratio = std[live] / grown
    return bool(np.any(ratio < _NODE_RATIO) or np.any(ratio > 1.0 / _NODE_RATIO)
                or np.any(np.abs(mean - placed_mean)[live] > _NODE_SHIFT * placed_std[live]))


def _start(navigation: NavigationModel, centre: np.ndarray, grid: _Grid, config: PMFConfig) -> PointMass:
    cal_mean = np.asarray(navigation.calibration_prior, dtype=np.float64)
    cal_std = np.asarray(navigation.calibration_std, dtype=np.float64)
    nodes, log_weight = _place_nodes(cal_mean, np.diag(cal_std**2), config.calibration_points)
    s = navigation.initial_position_std
    axes = grid.axes(np.eye(2) * s**2)
    h = (grid.n - 1) / 2.0
    i, j = np.meshgrid(np.arange(grid.n) - h, np.arange(grid.n) - h, indexing="ij")
    offsets = np.column_stack([i.ravel(), j.ravel()]) @ axes.T
    log_p = -0.5 * np.sum(offsets**2, axis=1) / max(s, 1e-9) ** 2
    density = (log_weight[:, None] + log_p[None]).reshape(len(nodes), grid.n, grid.n)
    _, log_total = log_normalise(density.ravel(), where="pmf")
    area = float(abs(np.linalg.det(axes)))
    return PointMass(nodes, log_weight, np.tile(centre, (len(nodes), 1)), axes,
                     density - log_total - np.log(area), np.full(density.shape, navigation.tide),
                     navigation.tide_std**2, np.zeros((2, 2)), 0.0, (cal_mean, np.diag(cal_std**2)),
                     (cal_mean, cal_std))


def _predict(state: PointMass, ping: Ping, model: FilterModel) -> None:
    if ping.first:
        return
    step = rotate(-state.nodes[:, 1], np.broadcast_to(ping.increment, state.centres.shape))
    state.centres = state.centres + step / (1.0 + state.nodes[:, 0])[:, None]
    state.pending = state.pending + model.motion.noise_covariance(ping)
    state.walk += model.motion.heading_walk**2 * ping.dt
    inv = np.linalg.inv(state.axes)
    if np.max(np.linalg.eigvalsh(inv @ state.pending @ inv.T)) >= 0.25:
        _diffuse(state)


def _update(state: PointMass, ping: Ping, model: FilterModel, slope: np.ndarray):
    """Weigh every point by the ping; returns the predicted state's belief view, the update and
    whether any point had the map under it."""
    if ping.n_soundings == 0:
        return None, None
    points = state.points()
    n_points = state.n * state.n
    turn = np.repeat(-state.nodes[:, 1], n_points)
    log_mass = (state.log_density - np.max(state.log_density)).ravel()
    weights = np.exp(log_mass)
    resolution = float(np.trace(state.axes.T @ slope @ state.axes)) / 12.0
    variance = ping.variance if ping.variance is not None else np.full(ping.n_soundings,
                                                                      model.terrain.sounding_std**2)
    update = model.terrain.likelihood.ping_update(
        points, ping.offsets, ping.depths, state.tide.ravel(), state.tide_var, turn=turn, weights=weights,
        variance=variance + resolution, map_variance=ping.map_variance,
    )  # fmt: skip
    if np.all(np.isneginf(update.log_likelihood)):
        return None, None  # no point has the map under any sounding: no information
    view = Belief(points, log_mass - np.log(weights.sum()), state.tide.ravel(), state.tide_var,
                  np.empty((points.shape[0], 0)), np.empty(0))
    check = innovation(view, update, ping, model)
    posterior = state.log_density + update.log_likelihood.reshape(state.log_density.shape)
    _, log_total = log_normalise(posterior.ravel(), where=f"pmf ping {ping.index}")
    state.log_density = posterior - log_total - np.log(state.cell_area)
    state.tide = update.tide.reshape(state.tide.shape)
    state.tide_var = update.tide_var
    return check, update


# A ping whose evidence differs by more than this (nats) between calibration nodes tells the
# calibration more sharply than the nodes can hold: they are re-placed at its posterior first.
_SHARP = 8.0
_MAX_REFINE = 2


def _measure(state: PointMass, ping: Ping, model: FilterModel, slope: np.ndarray, grid: _Grid,
             config: PMFConfig, estimate: bool):
    """The ping's update (:func:`_update`) as a new state. With the calibration estimated, when
    the ping's evidence is too sharp across the nodes, the predicted state's nodes are re-placed
    at the posterior the ping gives (adaptive Gauss-Hermite quadrature) and the ping weighed
    again, at most ``_MAX_REFINE`` times."""
    for attempt in range(_MAX_REFINE + 1):
        trial = dataclasses.replace(state)  # fields are replaced, never changed in place
        check, update = _update(trial, ping, model, slope)
        if update is None or attempt == _MAX_REFINE:
            return trial, check, update
        if not estimate:
            return trial, check, update
        prior = state.member_log_mass()
        evidence = trial.member_log_mass() - prior
        live = np.isfinite(evidence) & (prior > np.max(prior) - 20.0)
        if not live.any() or np.ptp(evidence[live]) <= _SHARP:
            return trial, check, update
        mean, cov, concave = _evidence_fit(trial.nodes, trial.member_log_mass() - trial.node_base,
                                           *trial.prior)
        if not concave:  # not a Gaussian in the calibration: the nodes cannot be aimed by it
            return trial, check, update
        cov[1, 1] += state.walk
        state = _regrid(state, grid, config, True, target=(mean, cov))
    return trial, check, update  # not reached


def _inconsistent(check, alpha: float) -> bool:
    """The lost test of one ping: its mean sounding's innovation against the density's own
    predictive spread (:class:`~tangraph.filters.core.Innovation`'s ``nis``, chi-square(1)).
    The best point's chi-square is not used: the calibration's few nodes need not hold a point
    that fits every sounding of a wide swath while the heading error is still uncertain."""
    return bool(check.nis > _chi2_quantile(alpha, 1))


def _relocalised(state: PointMass, bathymetry: BathymetryMap, navigation: NavigationModel,
                  config: PMFConfig, centre: np.ndarray) -> PointMass:
    """A uniform density on the global grid (see the module docstring)."""
    rows, cols = np.nonzero(np.isfinite(bathymetry.depth))
    low = np.array([bathymetry.north[rows.min()], bathymetry.east[cols.min()]])
    high = np.array([bathymetry.north[rows.max()], bathymetry.east[cols.max()]])
    if config.relocalise_radius is not None:
        low = np.maximum(low, centre - config.relocalise_radius)
        high = np.minimum(high, centre + config.relocalise_radius)
        if np.any(high <= low):  # the estimate is far off the map's data: around it then
            low, high = centre - config.relocalise_radius, centre + config.relocalise_radius
    n = config.relocalise_points
    axes = np.diag(np.maximum((high - low) / (n - 1), config.min_spacing))
    cal_mean = np.asarray(navigation.calibration_prior, dtype=np.float64)  # a lost filter's: suspect
    cal_cov = np.diag(np.asarray(navigation.calibration_std, dtype=np.float64) ** 2)
    area = float(abs(np.linalg.det(axes))) * n * n
    return PointMass(cal_mean[None, :], np.zeros(1), (0.5 * (low + high))[None, :], axes,
                     np.full((1, n, n), -np.log(area)), np.full((1, n, n), navigation.tide),
                     navigation.tide_std**2, np.zeros((2, 2)), 0.0, (cal_mean, cal_cov),
                     (cal_mean, np.sqrt(np.maximum(np.diag(cal_cov), 0.0))))


def point_mass_filter(
    survey: Survey,
    bathymetry: BathymetryMap,
    config: PMFConfig | None = None,
    *,
    model: NavigationModel | None = None,
    rng: np.random.Generator | None = None,
    progress: bool = False,
) -> Track:
    """Run the point-mass filter over a survey (deterministic: ``rng`` is not used); ``model``
    is the navigation model (None: ``NavigationModel.from_survey(survey)``). See the module
    docstring.

    Returns
    -------
    Track
        The density's mean track and covariance (heading: dead reckoning, its variance NaN);
        ``meta``: ``calibration`` (the bank's mean and std), ``n_lost``, ``lost_steps``,
        ``n_off_map``, ``off_map_steps`` (pings no point had the map under),
        ``relocalisation_steps`` (pings after which it started afresh on the global grid),
        ``n_regrids``,
        ``n_points`` (grid points per ping: members times ``grid_points^2``),
        ``navigation_model``, ``config``; ``timings``.
    """
    from tqdm.auto import tqdm

    check_run_inputs(survey, bathymetry, rng, where="pmf", rng_optional=True)
    config = config or PMFConfig()
    navigation = survey_navigation_model(survey, model, where="pmf")
    filter_model = FilterModel.from_model(navigation, bathymetry)
    grid = _Grid(config, config.min_spacing)
    slope = slope_moment(bathymetry)
    estimate = any(c > 1 and s > 0
                   for c, s in zip(config.calibration_points, navigation.calibration_std, strict=True))
    state = _start(navigation, survey.dr_pose[0, :2].astype(np.float64), grid, config)
    k_total = survey.n_pings
    mean = np.empty((k_total, 2))
    cov = np.full((k_total, 3, 3), np.nan)
    seconds = np.empty(k_total)
    lost_steps: list[int] = []
    off_map_steps: list[int] = []
    divergence_steps: list[int] = []
    relocalisation_steps: list[int] = []
    streak = n_regrids = 0
    started = _time.perf_counter()
    pings = survey_pings(survey, bathymetry, navigation)
    for ping in tqdm(pings, disable=not progress, desc="pmf", unit="ping", leave=False):
        t0 = _time.perf_counter()
        _predict(state, ping, filter_model)
        try:
            state, check, update = _measure(state, ping, filter_model, slope, grid, config, estimate)
        except FilterDivergence:  # no point of positive density explains the ping: keep the prior
            divergence_steps.append(ping.index)
            check, update = None, False
        if update is None and ping.n_soundings:
            off_map_steps.append(ping.index)
        if check is not None or update is False:
            streak = streak + 1 if update is False or _inconsistent(check, config.lost_alpha) else 0
            if streak == config.lost_pings:  # the streak's pings all said so
                lost_steps.extend(range(ping.index - streak + 1, ping.index))
            if streak >= config.lost_pings:
                lost_steps.append(ping.index)
                if config.relocalise and state.n <= grid.n:  # not while searching the global grid
                    _log.warning("pmf: lost at ping %d; relocalising on the global grid", ping.index)
                    state = _relocalised(state, bathymetry, navigation, config, state.moments()[0])
                    relocalisation_steps.append(ping.index)
                    streak = 0
        if grid.needs_regrid(state, state.within()) or (estimate and _calibration_moved(state)):
            state = _regrid(state, grid, config, estimate)
            n_regrids += 1
        m, c = state.moments()
        mean[ping.index], cov[ping.index, :2, :2] = m, c
        seconds[ping.index] = _time.perf_counter() - t0
    elapsed = _time.perf_counter() - started
    cal_mean, cal_cov = state.calibration()
    cal_std = np.sqrt(np.maximum(np.diag(cal_cov), 0.0))
    meta: dict[str, Any] = {
        "calibration": {
            "speed_scale": float(cal_mean[0]),
            "speed_scale_std": float(cal_std[0]),
            "heading_error": float(cal_mean[1]),
            "heading_error_std": float(np.sqrt(cal_std[1] ** 2 + state.walk)),
        },
        "ess": [float("nan")] * k_total,
        "n_resampled": 0,
        "n_divergences": len(divergence_steps),
        "divergence_steps": divergence_steps,
        "n_lost": len(lost_steps),
        "lost_steps": lost_steps,
        "n_off_map": len(off_map_steps),
        "off_map_steps": off_map_steps,
        "relocalisation_steps": relocalisation_steps,
        "n_regrids": n_regrids,
        "n_points": int(len(state.nodes) * grid.n**2),
        "sounding_std": filter_model.terrain.sounding_std,
        "navigation_model": navigation.as_dict(),
        "config": config.as_dict(),
        "seed": None,
    }
    return Track(
        time=survey.time,
        pose=np.column_stack([mean, survey.dr_pose[:, 2]]),
        covariance=cov,
        method="pmf",
        timings=step_timings(elapsed, seconds),
        meta=meta,
    )
