"""The point-mass filter's density: the members' position grids, their moments, the DR noise
convolved in, and re-gridding (:class:`PointMass`, :class:`_Grid`, :func:`_regrid`).

See :mod:`tangraph.filters.pmf`.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
import scipy.fft
from scipy import ndimage

from tangraph.filters.likelihood import log_normalise
from tangraph.filters.pmf_bank import _evidence_fit, _log_gaussian, _place_nodes
from tangraph.filters.tide import TideDrift
from tangraph.sensors.misfit import MisfitScale

if TYPE_CHECKING:
    from tangraph.filters.config import PMFConfig

__all__ = ["PointMass"]


# a member's density reaching this share of its mass in its grid's outer ring triggers a re-grid
_EDGE_MASS = 1e-3
# the density's std in grid spacings may drift this factor from the target before a re-grid
_SPREAD_RATIO = 1.6


# the fields each of PointMass's cached values is derived from
_DEPENDS = {
    "offsets": ("axes",),  # and the grid's size: in its key
    "masses": ("log_density",),
    "member_moments": ("log_density", "nodes", "axes", "centres", "shift"),
    "member_log_mass": ("log_density", "nodes", "axes"),
}


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
    its log mass at placement; ``placed (mean, std)`` is the Gaussian the nodes were placed on;
    ``misfit`` the local misfit scale the density shares (:mod:`tangraph.sensors.misfit`; None:
    the stated errors trusted); ``tide_drift`` the drifting part of the points' tide posteriors
    (:mod:`tangraph.filters.tide`, its mean ``(M, n, n)``; None: a constant tide). With the
    calibration held per point (:mod:`tangraph.filters.pmf_points`; one member) ``point_cal (n *
    n, 2)`` is each point's calibration mean, ``shift (n * n, 2)`` its move since the grid was
    laid and ``joint (4, 4)`` the covariance of the position's deviation since then and the
    calibration's, which the points share (None, None, None with the bank)."""

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
    misfit: MisfitScale | None = None
    tide_drift: TideDrift | None = None
    point_cal: np.ndarray | None = None
    shift: np.ndarray | None = None
    joint: np.ndarray | None = None
    # what the methods below derive from the fields (read-only arrays), each dropped when a field
    # it depends on (_DEPENDS) is set: the fields are replaced, never changed in place
    _cache: dict[str, np.ndarray | tuple[np.ndarray, ...]] = dataclasses.field(
        default_factory=dict, init=False, repr=False)

    def __setattr__(self, name: str, value) -> None:
        object.__setattr__(self, name, value)
        cache = self.__dict__.get("_cache")
        if cache:
            for key in [key for key in cache if name in _DEPENDS[key.partition(":")[0]]]:
                del cache[key]

    def _cached(self, key: str, compute: Callable[[], Any]) -> Any:
        if key not in self._cache:
            value = compute()
            for a in value if isinstance(value, tuple) else (value,):
                a.setflags(write=False)
            self._cache[key] = value
        return self._cache[key]

    def copy(self) -> PointMass:
        """A copy whose fields can be replaced without changing this state."""
        out = dataclasses.replace(self)
        out._cache.update(self._cache)
        return out

    @property
    def n(self) -> int:
        return int(self.log_density.shape[1])

    def offsets(self) -> np.ndarray:
        """The grid's points relative to a member's centre, ``(n * n, 2)`` (row-major)."""
        return self._cached(f"offsets:{self.n}", lambda: _offsets(self.n, self.axes))

    def points(self) -> np.ndarray:
        """Every member's points, ``(M * n * n, 2)``."""
        offsets = self.offsets()  # (the same sums as broadcasting, a faster layout)
        points = np.tile(offsets, (len(self.centres), 1)) + np.repeat(self.centres, len(offsets), axis=0)
        return points if self.shift is None else points + self.shift

    @property
    def cell_area(self) -> float:
        return float(abs(np.linalg.det(self.axes)))

    def masses(self) -> np.ndarray:
        """Each point's probability, ``(M, n, n)`` (sums to 1)."""
        return self._cached("masses", self._masses)

    def _masses(self) -> np.ndarray:
        w = np.exp(self.log_density - np.max(self.log_density))
        return w / w.sum()

    def member_moments(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Each member's mass ``(M,)``, mean ``(M, 2)`` and covariance ``(M, 2, 2)`` (of its
        points; zero-mass members: their centre and a zero covariance)."""
        return self._cached("member_moments", self._member_moments)

    def _member_moments(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        # numpy's sums, not a compiled pass: the start's isotropic density has a covariance whose
        # principal axes (the grid's, at a re-grid) are chosen by its round-off
        mass = self.masses().reshape(len(self.nodes), -1)
        weight = mass.sum(axis=1)
        offsets = self.offsets() if self.shift is None else self.offsets() + self.shift
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
        return total, pooled + (self.pending if self.joint is None else self.joint[:2, :2])

    def member_log_mass(self) -> np.ndarray:
        """Each member's log mass ``(M,)`` (computed in logs: no underflow however unlikely)."""
        return self._cached("member_log_mass", self._member_log_mass)

    def _member_log_mass(self) -> np.ndarray:
        flat = self.log_density.reshape(len(self.nodes), -1)
        top = np.max(flat, axis=1)
        safe = np.where(np.isfinite(top), top, 0.0)
        with np.errstate(divide="ignore"):
            return safe + np.log(np.sum(np.exp(flat - safe[:, None]), axis=1)) + np.log(self.cell_area)

    def heading_errors(self) -> np.ndarray:
        """Every point's heading error ``(M * n * n,)`` (its member's node's, or its own)."""
        if self.point_cal is not None:
            return self.point_cal[:, 1]
        return np.repeat(self.nodes[:, 1], self.n * self.n)

    def calibration(self) -> tuple[np.ndarray, np.ndarray]:
        """The calibration's posterior mean ``(2,)`` and covariance ``(2, 2)``: the prior at
        placement times the evidence since, fitted at the nodes (:func:`_evidence_fit`); with
        the calibration per point, the points' mixture."""
        if self.point_cal is not None and self.joint is not None:
            w = self.masses().ravel()
            mean = w @ self.point_cal
            d = self.point_cal - mean
            return mean, self.joint[2:, 2:] + (d * w[:, None]).T @ d
        return _evidence_fit(self.nodes, self.member_log_mass() - self.node_base, *self.prior)[:2]


def _offsets(n: int, axes: np.ndarray) -> np.ndarray:
    """The points of an ``n x n`` grid of steps ``axes (2, 2)`` relative to its centre, ``(n * n,
    2)`` (row-major)."""
    h = (n - 1) / 2.0
    i, j = np.meshgrid(np.arange(n) - h, np.arange(n) - h, indexing="ij")
    return np.column_stack([i.ravel(), j.ravel()]) @ axes.T


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


def _point_means(state: PointMass) -> list[np.ndarray]:
    """The per-point means of the tide posterior: the tide's (and its drifting part's)."""
    return [state.tide] + ([] if state.tide_drift is None else [state.tide_drift.mean])


def _mixed_tide(mass: np.ndarray, firsts: list[np.ndarray], seconds: dict) -> tuple[list, dict]:
    """The tide posterior of points whose density ``mass`` mixes points of tide means whose
    mass-weighted first moments are ``firsts`` and second moments ``seconds[(a, b)]`` (same
    shape): each point's means and what the one covariance of the filter gains (the
    mass-weighted spread between the mixed means, ``[(a, b)]``)."""
    live = mass > 1e-300
    total = mass.sum()
    with np.errstate(divide="ignore", invalid="ignore"):
        means = [np.where(live, f / mass, 0.0) for f in firsts]
        spread = {}
        for (a, b), second in seconds.items():
            s = np.where(live, second / mass - means[a] * means[b], 0.0)
            s = np.maximum(s, 0.0) if a == b else s
            spread[a, b] = float(np.sum(mass * s) / total) if total > 0 else 0.0
    return means, spread


def _diffuse(state: PointMass) -> None:
    """Convolve the pending white DR noise into every member's density (and tide posteriors)."""
    inv = np.linalg.inv(state.axes)
    cov = inv @ state.pending @ inv.T
    top = np.max(state.log_density)
    p = np.exp(state.log_density - top)
    if state.tide_var > 0:  # one transform of the density and its tide moments (the same values)
        means = _point_means(state)
        pairs = [(a, b) for a in range(len(means)) for b in range(a, len(means))]
        out = _gaussian_convolve(np.concatenate([p, *(p * t for t in means),
                                                 *(p * means[a] * means[b] for a, b in pairs)]), cov)
        out = out.reshape(1 + len(means) + len(pairs), *p.shape)
        smoothed = np.maximum(out[0], 0.0)  # less round-off below zero
        mixed, spread = _mixed_tide(smoothed, list(out[1:1 + len(means)]),
                                    dict(zip(pairs, out[1 + len(means):], strict=True)))
        state.tide, state.tide_var = mixed[0], state.tide_var + spread[0, 0]
        if state.tide_drift is not None:
            drift = state.tide_drift
            state.tide_drift = TideDrift(mixed[1], drift.cross + spread[0, 1], drift.var + spread[1, 1])
    else:
        smoothed = np.maximum(_gaussian_convolve(p, cov), 0.0)
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

    def axes(self, cov: np.ndarray, support: Callable[[np.ndarray], np.ndarray] | None = None) -> np.ndarray:
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


def _held(size: np.ndarray, mass: np.ndarray, total: float) -> float:
    """The smallest of ``size (P,)`` whose points of ``mass (P,)`` at that size or less hold all
    but ``_SUPPORT_MASS`` of ``total``."""
    order = np.argsort(size)
    held = np.cumsum(mass[order])
    at = min(int(np.searchsorted(held, (1.0 - _SUPPORT_MASS) * total)), size.size - 1)
    return float(size[order][at])


def _extent(offsets: np.ndarray, mass: np.ndarray) -> np.ndarray:
    """Per column of ``offsets (P, A)`` the smallest half-width holding all but
    ``_SUPPORT_MASS`` of ``mass (P,)``."""
    total = mass.sum()
    return np.array([_held(np.abs(offsets[:, a]), mass, total) for a in range(offsets.shape[1])])


@functools.lru_cache(maxsize=8)
def _index(n: int) -> np.ndarray:
    """The ``(i, j)`` of an ``n x n`` grid's points, ``(n * n, 2)`` (row-major; read-only)."""
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    index = np.column_stack([i.ravel(), j.ravel()]).astype(np.float64)
    index.setflags(write=False)
    return index


def _significant(state: PointMass) -> np.ndarray:
    """The half-widths in grid steps, per grid axis, that hold the density's support about
    each member's mean (:func:`_extent` of the grid's rows and columns: a row's points share
    their offset along the first axis, a column's along the second)."""
    index = _index(state.n)
    masses = state.masses()
    mass = masses.reshape(len(state.nodes), -1)
    weight = mass.sum(axis=1, keepdims=True)
    centre = (mass @ index) / np.where(weight > 0, weight, 1.0)
    total = mass.sum()
    line = np.arange(state.n, dtype=np.float64)
    return np.array([_held(np.abs(line[None, :] - centre[:, a, None]).ravel(), held.ravel(), total)
                     for a, held in enumerate((masses.sum(axis=2), masses.sum(axis=1)))])


def _support(state: PointMass, centres: np.ndarray):
    """The half-widths along unit ``vectors (2, 2)`` (columns) from each member's ``centres``
    that hold the density's support (plus one old grid step), as :meth:`_Grid.axes` takes
    them."""
    points = state.points() - np.repeat(centres, state.n * state.n, axis=0)
    mass = state.masses().ravel()
    return lambda vectors: _extent(points @ vectors, mass) \
        + np.max(np.abs(state.axes.T @ vectors), axis=0)  # one old step along each


def _sample(state: PointMass, member: int | np.integer, points: np.ndarray,
            own: bool = False) -> tuple[np.ndarray, ...]:
    """Member ``member``'s density (relative to the state's largest value, or with ``own`` to
    the member's: a member far less likely than the others keeps its shape instead of
    underflowing) at world ``points (P, 2)`` and its mass-weighted tide means there
    (:func:`_point_means`; bilinear; zero outside its grid)."""
    inv = np.linalg.inv(state.axes)
    h = (state.n - 1) / 2.0
    q = ((points - state.centres[member]) @ inv.T + h).T
    top = np.max(state.log_density[member] if own else state.log_density)
    p = np.exp(state.log_density[member] - top) if np.isfinite(top) else np.zeros(state.log_density.shape[1:])
    return tuple(ndimage.map_coordinates(v, q, order=1, mode="constant", cval=0.0)
                 for v in (p, *(p * t[member] for t in _point_means(state))))


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
        # the members' mean positions regressed on the calibration now: their covariance with
        # the nodes over the calibration's variance, the heading walk since the placement
        # included (it has not moved the positions yet, so it dilutes what a node says of them)
        d_theta = state.nodes - own_mean
        d_x = means - weight @ means
        c_xt = (d_x * weight[:, None]).T @ d_theta
        gain = c_xt @ np.linalg.pinv(own_cov, rcond=1e-9)
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
    point_means = _point_means(state)
    mass, firsts = np.empty(shape), [np.empty(shape) for _ in point_means]
    for m, src in enumerate(source):
        value, *moments = _sample(state, src, new_centres[m] - shift[m] + offsets, own=True)
        total = value.sum()
        if total <= 0:  # a member whose density missed its new grid: its mean point
            value, moments = np.zeros_like(value), [np.zeros_like(value) for _ in point_means]
            value[value.size // 2] = 1.0
            for t1, t in zip(moments, point_means, strict=True):
                t1[value.size // 2] = t[src].mean()
            total = 1.0
        share = np.exp(log_weight[m] - np.max(log_weight))  # (each member's shape sums to 1 first)
        mass[m] = value.reshape(shape[1:]) / total * share
        for first, t1 in zip(firsts, moments, strict=True):
            first[m] = t1.reshape(shape[1:]) / total * share
    # re-sampling only reads the density between points: the tide means are interpolated (their
    # spread between neighbours is not a mixture: it would widen the tide at every re-grid)
    with np.errstate(divide="ignore", invalid="ignore"):
        tide, *drift = (np.where(mass > 1e-300, first / mass, 0.0) for first in firsts)
        density = np.log(mass)
    area = float(abs(np.linalg.det(axes)))
    _, log_total = log_normalise(density.ravel(), where="pmf")
    return PointMass(nodes, node_base, new_centres, axes, density - log_total - np.log(area), tide,
                     state.tide_var, np.zeros((2, 2)), 0.0 if estimate else state.walk, prior, placed,
                     state.misfit, None if state.tide_drift is None else
                     dataclasses.replace(state.tide_drift, mean=drift[0]))
