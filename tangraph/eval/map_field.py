"""The map's error as a Gaussian-Markov random field on a grid of nodes, and the bound's sparse
joint solve with it (:func:`field_bound`; the model and its approximations are in the notes of
:mod:`tangraph.eval.crb`).

:func:`map_error_field` lays a regular grid of nodes over the soundings' footprints and writes
the map's error ``d`` (:mod:`tangraph.sensors.terrain`: zero mean, ``cov(d(p), d(q)) = s(p)
s(q) rho(|p - q|)``, ``rho`` the Matérn nu = 1 correlation of range ``L``) as ``d = S u`` on the
nodes: ``S`` the diagonal of the per-node std ``s`` (:meth:`~tangraph.sensors.terrain.MapError.std_at`
at the node, the map's median std where it has no data) and ``u`` a unit-variance field with
the sparse precision of the SPDE of Lindgren, Rue & Lindström (2011) with alpha = 2 in the plane
(whose solution is the Matérn nu = 1 field)::

    Q = c0 M^2,   M = c^2 I + Lap,   c = kappa h,   kappa = sqrt(8) / L

(``Lap`` the 5-point graph Laplacian of the grid, with free (Neumann) edges; ``h`` the node
spacing). That is ``tau^2 h^2 (kappa^2 I - Laplacian_h)^2`` with ``tau^2 = c0 h^2``. ``c0`` is
the variance of the field of precision ``M^2`` on the infinite lattice (a Fourier sum,
:func:`lattice_correlation`), so ``u`` has unit variance away from the grid's edges. The edges
inflate it (about 1.6 times at an edge and 2.5 at a corner for ``h = L / 3``), so the grid
reaches :data:`MARGIN_LENGTHS` ranges beyond every footprint, where the excess is below 1e-4.

A sounding at ``p`` sees ``w^T S u``, ``w`` its bilinear weights on the 4 nodes around ``p``.
Between nodes that interpolation has less variance than the field (neighbouring nodes are not
perfectly correlated), so each sounding is also given the variance it misses, its *nugget*
``sum_ab w_a w_b s_a s_b (1 - R_ab)`` (``R`` the lattice correlation of the nodes), as
independent noise: its map error then has the model's variance ``s(p)^2`` (``s`` interpolated),
and soundings in one cell share the interpolated part only.

The node spacing is ``h = L / 3`` (at ``L / 3`` the lattice's correlation at ``L`` is 0.126
against Matérn's 0.140), made coarser (the nugget then takes more) where the grid would pass
``max_nodes`` nodes. The nugget is the error's variation within a node cell, which the
soundings there share (a multibeam's beams lie a fraction of a metre apart): taken as
independent it claims more than there is, and at ``h = L`` (a cell-scale error on the map's
own cells) it is two thirds of the variance at a node cell's centre, at ``L / 3`` a third. So the
bound is solved at ``L / 3`` (:data:`BOUND_MAX_NODES`; at ``L / 5`` the simulated realistic
maps' bounds move by 1 %), while a solve that estimates the field may keep its nodes no finer
than the map's cell (``finer_than_cell=False``), where the map says nothing of its error, and
share the nugget among the soundings of a cell instead
(:func:`tangraph.graph.field_solve.shared_nugget`).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from scipy import sparse

from tangraph.eval import selected_inverse as si
from tangraph.sensors.terrain import MapError

__all__ = [
    "BOUND_MAX_NODES",
    "FILTER_PINGS",
    "MARGIN_LENGTHS",
    "MAX_NODES",
    "ZERO_VARIANCE",
    "CombinedField",
    "ErrorState",
    "MapErrorField",
    "field_bound",
    "lattice_correlation",
    "map_error_field",
    "sparse_sum",
    "spde_precision",
]

#: nodes per correlation length (at most)
NODES_PER_LENGTH = 3
#: the grid reaches this many correlation lengths beyond every footprint
MARGIN_LENGTHS = 2.0
#: most nodes of a grid (the spacing grows beyond it)
MAX_NODES = 40_000
#: most nodes of the bound's grid
BOUND_MAX_NODES = 100_000
#: the filter bound is solved at this many pings at most (interpolated in between)
FILTER_PINGS = 60
#: the variance (in units of the state's natural spread squared) given to a step of the error
#: state whose variance is zero (a DR without speed noise): an information matrix cannot hold
#: an exact constraint. It moves the bound by about this much times the pings (relative); the
#: rounding of the stiffer system grows as it shrinks.
ZERO_VARIANCE = 1e-8


@dataclasses.dataclass(frozen=True, eq=False)
class MapErrorField:
    """The map's error on a grid of nodes: ``d = S u``, ``u ~ N(0, precision^-1)``.

    Parameters
    ----------
    origin : tuple of float
        ``(north, east)`` of node ``(0, 0)``, m.
    spacing : float
        Node spacing ``h``, m.
    shape : tuple of int
        ``(ny, nx)`` nodes; node ``(i, j)`` is at ``origin + (i h, j h)`` and has index ``i nx + j``.
    std : ndarray, shape (ny * nx,)
        The map error's std ``s`` at every node, m.
    precision : scipy.sparse.csc_array, shape (ny * nx, ny * nx)
        The precision of the unit-variance field ``u``.
    correlation : ndarray, shape (3,)
        The stationary lattice correlation of ``u`` at node offsets (0, 0), (0, 1) and (1, 1).
    correlation_length : float
        The Matérn range ``L``, m.
    through : (BathymetryMap, int), optional
        A field of the map's horizontal offset along axis 0 (north) or 1 (east), seen through
        the map's slope along it: a point's weights are times the gradient (0 where none).
    """

    origin: tuple[float, float]
    spacing: float
    shape: tuple[int, int]
    std: np.ndarray
    precision: sparse.csc_array
    correlation: np.ndarray
    correlation_length: float
    through: tuple[Any, int] | None = None

    @property
    def n_nodes(self) -> int:
        return int(self.shape[0] * self.shape[1])

    def nodes(self) -> tuple[np.ndarray, np.ndarray]:
        """``(north, east)`` of every node (ny * nx,), in index order."""
        i, j = np.divmod(np.arange(self.n_nodes), self.shape[1])
        return self.origin[0] + i * self.spacing, self.origin[1] + j * self.spacing

    def weights(self, north: np.ndarray, east: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bilinear interpolation of points (M,) on the nodes: node indices and weights (M, 4)
        (corners (0, 0), (0, 1), (1, 0), (1, 1)). The points must lie inside the grid."""
        fy = (np.asarray(north, dtype=np.float64) - self.origin[0]) / self.spacing
        fx = (np.asarray(east, dtype=np.float64) - self.origin[1]) / self.spacing
        i = np.clip(np.floor(fy).astype(np.int64), 0, self.shape[0] - 2)
        j = np.clip(np.floor(fx).astype(np.int64), 0, self.shape[1] - 2)
        ty, tx = fy - i, fx - j
        nx = self.shape[1]
        index = np.stack([i * nx + j, i * nx + j + 1, (i + 1) * nx + j, (i + 1) * nx + j + 1], axis=-1)
        weight = np.stack([(1 - ty) * (1 - tx), (1 - ty) * tx, ty * (1 - tx), ty * tx], axis=-1)
        if self.through is not None:  # the offset seen through the slope along its axis
            bathymetry, axis = self.through
            slope = bathymetry.gradient_at(north, east)[..., axis]
            weight = weight * np.nan_to_num(slope)[..., None]
        return index, weight

    def nugget(self, index: np.ndarray, weight: np.ndarray) -> np.ndarray:
        """The variance (M,) of the map error at points that their interpolation on the nodes
        misses: ``sum_ab w_a w_b s_a s_b (1 - R_ab)`` (m^2); none for an offset (``through``),
        its nodes interpolated: a displacement smooth within a node cell."""
        ws = weight * self.std[index] * (self.through is None)
        miss = 1.0 - self.correlation  # offsets (0, 0), (0, 1), (1, 1)
        out = np.zeros(ws.shape[0])
        for a in range(4):
            for b in range(4):
                steps = abs(a // 2 - b // 2) + abs(a % 2 - b % 2)
                out += ws[:, a] * ws[:, b] * miss[steps]
        return np.maximum(out, 0.0)


def lattice_correlation(c: float) -> tuple[float, np.ndarray]:
    """Variance of the field of precision ``M^2`` (``M = c^2 I + Lap``) on the infinite lattice,
    and its correlation at node offsets (0, 0), (0, 1), (1, 1).

    A periodic lattice of ``n`` nodes a side, ``n`` at least 16 correlation lengths (``16
    sqrt(8) / c`` nodes): its covariance is the inverse Fourier transform of the spectrum
    ``(c^2 + 4 sin^2(w1 / 2) + 4 sin^2(w2 / 2))^-2``, the infinite lattice's but for the wrap,
    ``rho(16 L)``, nothing in double precision.

    Examples
    --------
    >>> v, r = lattice_correlation(np.sqrt(8.0) / 3)
    >>> round(v, 4), r.round(3).tolist()
    (0.1015, [1.0, 0.57, 0.394])
    """
    n = int(2 ** np.ceil(np.log2(max(64.0, 16.0 * np.sqrt(8.0) / c))))
    w = 2.0 * np.pi * np.fft.fftfreq(n)
    s2 = 4.0 * np.sin(w / 2.0) ** 2
    spectrum = 1.0 / (c**2 + s2[:, None] + s2[None, :]) ** 2
    cov = np.fft.ifft2(spectrum).real
    return float(cov[0, 0]), np.array([cov[0, 0], cov[0, 1], cov[1, 1]]) / cov[0, 0]


def spde_precision(shape: tuple[int, int], c: float) -> sparse.csc_array:
    """The unit-variance SPDE precision ``Q = v M^2`` on a ``(ny, nx)`` grid, ``M = c^2 I +
    Lap`` (``Lap`` the graph Laplacian: free edges), ``v`` the infinite lattice's variance of
    ``M^2`` (:func:`lattice_correlation`); ``c = kappa h = sqrt(8) h / L``."""
    ny, nx = shape

    def path(n: int) -> sparse.csr_array:
        degree = np.full(n, 2.0)
        degree[[0, -1]] = 1.0
        return sparse.diags_array([degree, -np.ones(n - 1), -np.ones(n - 1)], offsets=[0, -1, 1]).tocsr()

    lap = sparse.kron(sparse.eye_array(ny), path(nx)) + sparse.kron(path(ny), sparse.eye_array(nx))
    m = sparse.eye_array(ny * nx) * c**2 + lap
    variance, _ = lattice_correlation(c)
    return sparse.csc_array(m @ m * variance)


def map_error_field(north: np.ndarray, east: np.ndarray, error: MapError, *, max_nodes: int = MAX_NODES,
                    finer_than_cell: bool = False,
                    offset: tuple[float, float] | None = None) -> MapErrorField | CombinedField:
    """The map error's field on a grid of nodes over the points ``north, east`` (the soundings'
    true footprints), one grid per independent field of the error
    (:meth:`~tangraph.sensors.MapError.components`: the cell-scale error and the excess of the
    interpolated parts, each with its own range), each with a margin of
    :data:`MARGIN_LENGTHS` ranges and at most ``max_nodes`` nodes, its spacing a third of its
    range, but never finer than the map's cell unless ``finer_than_cell`` (module docstring).

    Examples
    --------
    >>> from tangraph.maps import BathymetryMap
    >>> from tangraph.sensors import NavigationModel, map_error
    >>> axis = np.arange(0.0, 500.0, 10.0)
    >>> flat = BathymetryMap(axis, axis, np.full((50, 50), 20.0))
    >>> error = map_error(flat, NavigationModel(map_std=0.3, map_correlation_length=60.0))
    >>> field = map_error_field(np.array([200.0, 300.0]), np.array([250.0, 250.0]), error)
    >>> field.spacing, field.shape, float(field.std[0])
    (20.0, (18, 13), 0.3)

    ``offset = (std, length)``, both > 0 (the navigation model's ``map_offset_std`` and
    ``map_offset_length``): the map's horizontal offset is two more fields of that std and range,
    one per axis, seen through the map's slope (``through``), and the depth error is the part
    the offset leaves (:meth:`~tangraph.sensors.MapError.without_offset`)."""
    std, length = offset if offset is not None and min(offset) > 0 else (0.0, 0.0)
    error = error.without_offset(std)
    fields = [_one_field(north, east, part, max_nodes, finer_than_cell) for part in error.components()]
    if std > 0:  # its std at every node (off the map's data a field's nodes take its median)
        base = _one_field(north, east, MapError(error.bathymetry, np.full(error.std.shape, std), length),
                          max_nodes, True)
        fields += [dataclasses.replace(base, through=(error.bathymetry, axis)) for axis in (0, 1)]
    return fields[0] if len(fields) == 1 else CombinedField(tuple(fields))


def _one_field(north: np.ndarray, east: np.ndarray, error: MapError, max_nodes: int,
               finer_than_cell: bool) -> MapErrorField:
    length = error.correlation_length
    spacing = length / NODES_PER_LENGTH
    if not finer_than_cell:
        spacing = max(spacing, float(max(error.bathymetry.cell_size)))
    margin = MARGIN_LENGTHS * length
    low = np.array([np.min(north), np.min(east)]) - margin
    extent = np.array([np.max(north), np.max(east)]) + margin - low
    while True:
        shape = tuple(int(n) for n in np.ceil(extent / spacing).astype(np.int64) + 1)
        if shape[0] * shape[1] <= max_nodes:
            break
        spacing *= max(np.sqrt(shape[0] * shape[1] / max_nodes), 1.01)
    c = np.sqrt(8.0) * spacing / length
    i, j = np.divmod(np.arange(shape[0] * shape[1]), shape[1])
    std = error.std_at(low[0] + i * spacing, low[1] + j * spacing)
    return MapErrorField(origin=(float(low[0]), float(low[1])), spacing=float(spacing),
                         shape=(shape[0], shape[1]), std=np.where(np.isfinite(std), std, error.typical_std),
                         precision=spde_precision((shape[0], shape[1]), c),
                         correlation=lattice_correlation(c)[1], correlation_length=length)


@dataclasses.dataclass(frozen=True, eq=False)
class CombinedField:
    """Independent fields summed (:meth:`~tangraph.sensors.MapError.components`), with the
    interface of one :class:`MapErrorField`: their nodes one after the other, a block-diagonal
    precision, a point's interpolation weights on every field's nodes, their nuggets summed."""

    fields: tuple[MapErrorField, ...]

    @property
    def n_nodes(self) -> int:
        return int(sum(f.n_nodes for f in self.fields))

    @property
    def spacing(self) -> float:
        """The finest field's node spacing, m."""
        return float(min(f.spacing for f in self.fields))

    @property
    def std(self) -> np.ndarray:
        return np.concatenate([f.std for f in self.fields])

    @property
    def precision(self) -> sparse.csc_array:
        return sparse.csc_array(sparse.block_diag([f.precision for f in self.fields]))

    def weights(self, north: np.ndarray, east: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Node indices and weights (M, 4 per field), indices offset by the fields before."""
        offsets = np.cumsum([0, *(f.n_nodes for f in self.fields)])
        parts = [f.weights(north, east) for f in self.fields]
        return (np.concatenate([index + start for (index, _), start in zip(parts, offsets, strict=False)],
                               axis=-1),
                np.concatenate([weight for _, weight in parts], axis=-1))

    def nugget(self, index: np.ndarray, weight: np.ndarray) -> np.ndarray:
        offsets = np.cumsum([0, *(f.n_nodes for f in self.fields)])
        out = np.zeros(index.shape[0])
        for n, (f, start) in enumerate(zip(self.fields, offsets, strict=False)):
            out += f.nugget(index[:, 4 * n:4 * n + 4] - start, weight[:, 4 * n:4 * n + 4])
        return out


# -- the joint solve: the error state and the field ---------------------------------------------
@dataclasses.dataclass(frozen=True, eq=False)
class ErrorState:
    """The survey's linearised error state, as :mod:`tangraph.eval.crb` writes it (each state
    in units of its natural spread): ``x_{k+1} = F_k x_k + N(0, Q_k)`` with ``f, q`` (K-1, n, n)
    (``Q_k`` diagonal), ``x_0 ~ N(0, diag(p0))``; the states where ``constant`` (n,) is True stay
    constant (one unknown for the survey); sounding ``j`` has the Jacobian ``jacobian[j]`` (n,) on
    the state of ping ``ping[j]`` (pings ascending). States 0 and 1 are the position error."""

    f: np.ndarray
    q: np.ndarray
    p0: np.ndarray
    constant: np.ndarray
    ping: np.ndarray
    jacobian: np.ndarray


def field_bound(state: ErrorState, field: MapErrorField | CombinedField, node: np.ndarray, weight: np.ndarray,
                noise: np.ndarray, *,
                known_filter: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Every ping's position covariance (K, 2, 2) and the constants' covariance (n, n; zero but
    for the constants) in the state's units, with the map's error the field ``field``: sounding
    ``j`` sees the field at its nodes ``node[j]`` (4,) with the weights ``weight[j]`` and has the
    independent noise std ``noise[j]`` (m).

    The smoother bound unless ``known_filter`` is given: the filter bound were the map error
    known (K, 2, 2), around which the filter bound is interpolated between the pings where it
    is solved (:func:`_filter_positions`).
    """
    var = _Variables.of(state.constant, state.f.shape[0] + 1, field.n_nodes)
    relations, relation_ping = _relation_rows(var, state.f, state.q, state.p0)
    soundings = _sounding_rows(var, state, field, node, weight, noise)
    rows = sparse.vstack([relations, soundings], format="csr")
    row_ping = np.concatenate([relation_ping, state.ping])
    sort = np.argsort(row_ping, kind="stable")
    # A state whose prior variance is zero (the walk at the first ping) is zero: it leaves every
    # row and keeps a unit diagonal of its own.
    pinned = var.column(np.flatnonzero(state.p0 == 0), 0)
    keep = np.ones(var.n)
    keep[pinned] = 0.0
    rows, row_ping = sparse.csr_array(rows[sort] @ sparse.diags_array(keep)), row_ping[sort]
    base = sparse_sum(_field_prior(var, field), sparse.coo_array((1.0 - keep[pinned], (pinned, pinned)),
                                                           shape=(var.n, var.n)))
    information = sparse_sum(base, rows.T @ rows)
    order = si.fill_reducing_order(information)
    factor = si.factor(information, order)
    z = si.selected_inverse(factor)
    dp = var.positions(np.arange(var.n_pings))  # (K, 2)
    position = si.inverse_entries(factor, z, dp[:, :, None], dp[:, None, :])
    n = state.p0.size
    constants = np.zeros((n, n))
    held = np.flatnonzero(state.constant)
    at = var.column(held, 0)
    constants[np.ix_(held, held)] = si.inverse_entries(factor, z, at[:, None], at[None, :])
    if known_filter is not None:
        position = _filter_positions(var, rows, row_ping, base, order, position, known_filter)
    return position, constants


@dataclasses.dataclass(frozen=True)
class _Variables:
    """Columns of the joint unknowns: the error states held per ping (``dp``, walk, white),
    ping by ping; then the constants (scale, bias, tide) once; then the field's nodes."""

    where: np.ndarray  # (n,) column of each state at ping 0
    step: np.ndarray  # (n,) columns per ping (0 for a constant)
    n_pings: int
    n_field: int

    @classmethod
    def of(cls, constant: np.ndarray, n_pings: int, n_field: int) -> _Variables:
        per_ping = int(np.sum(~constant))
        where = np.empty(constant.size, dtype=np.int64)
        where[~constant] = np.arange(per_ping)
        where[constant] = n_pings * per_ping + np.arange(int(constant.sum()))
        return cls(where, np.where(constant, 0, per_ping), n_pings, n_field)

    @property
    def per_ping(self) -> int:
        return int(self.step.max())

    @property
    def n_states(self) -> int:
        return self.n_pings * self.per_ping + int(np.sum(self.step == 0))

    @property
    def n(self) -> int:
        return self.n_states + self.n_field

    def column(self, state, ping) -> np.ndarray:
        return self.where[state] + self.step[state] * np.asarray(ping)

    def positions(self, ping: np.ndarray) -> np.ndarray:
        """Columns ``(dp_north, dp_east)`` (len(ping), 2) of the pings."""
        return self.where[:2] + self.per_ping * np.asarray(ping)[:, None]

    def active(self, last: int) -> np.ndarray:
        """Columns of the survey cut after ping ``last``: its pings' states, constants, field."""
        return np.r_[0:(last + 1) * self.per_ping, self.n_pings * self.per_ping:self.n]


def _relation_rows(var: _Variables, f: np.ndarray, q: np.ndarray,
                   p0: np.ndarray) -> tuple[sparse.csr_array, np.ndarray]:
    """The prior ``x_0 ~ N(0, p0)`` and the transitions ``x_{k+1} - F_k x_k ~ N(0, Q_k)`` of the
    states held per ping as rows divided by their std (information ``rows^T rows``), with the
    ping each belongs to (the constants' rows of ``F`` say they stay constant: they are one
    variable)."""
    n = p0.size
    rows, cols, vals, variance = [np.arange(n)], [var.column(np.arange(n), 0)], [np.ones(n)], [p0]
    ping = [np.zeros(n, dtype=np.int64)]
    held = np.flatnonzero(var.step > 0)
    if var.n_pings > 1:
        k, i = np.meshgrid(np.arange(var.n_pings - 1), held, indexing="ij")
        row = n + np.arange(k.size).reshape(k.shape)
        rows.append(row.ravel())
        cols.append(var.column(i, k + 1).ravel())
        vals.append(np.ones(k.size))
        variance.append(q[k, i, i].ravel())
        ping.append((k + 1).ravel())
        a, b, c = np.nonzero(f[:, held, :])
        rows.append(row[a, b])
        cols.append(var.column(c, a))
        vals.append(-f[a, held[b], c])
    variance[0] = np.where(p0 > 0, p0, 1.0)  # a zero prior variance: see the caller
    std = np.sqrt(np.maximum(np.concatenate(variance), ZERO_VARIANCE))
    row_index = np.concatenate(rows)
    out = sparse.csr_array((np.concatenate(vals) / std[row_index], (row_index, np.concatenate(cols))),
                           shape=(std.size, var.n))
    return out, np.concatenate(ping)


def _sounding_rows(var: _Variables, state: ErrorState, field, node: np.ndarray,
                   weight: np.ndarray, noise: np.ndarray) -> sparse.csr_array:
    """Every sounding's row divided by its noise std: its Jacobian on its ping's states and the
    constants, ``s_a w_a`` on the field's nodes ``node`` (M, 4) around its true footprint."""
    m = state.jacobian.shape[0]
    row, i = np.nonzero(state.jacobian)
    rows = np.concatenate([row, np.repeat(np.arange(m), node.shape[1])])
    cols = np.concatenate([var.column(i, state.ping[row]), var.n_states + node.ravel()])
    vals = np.concatenate([state.jacobian[row, i], (weight * field.std[node]).ravel()]) / noise[rows]
    return sparse.csr_array((vals, (rows, cols)), shape=(m, var.n))


def _field_prior(var: _Variables, field) -> sparse.csc_array:
    """The field's precision on its nodes' columns, and explicit zeros where the bound reads the
    inverse (each ping's ``dp_north, dp_east`` and the constants among themselves), so that
    those entries are on the factor's pattern."""
    prior = sparse.coo_array(field.precision)
    dp = var.positions(np.arange(var.n_pings))
    constants = var.column(np.flatnonzero(var.step == 0), 0)
    a, b = np.meshgrid(constants, constants)
    rows = np.concatenate([prior.row + var.n_states, dp[:, 0], dp[:, 1], a.ravel()])
    cols = np.concatenate([prior.col + var.n_states, dp[:, 1], dp[:, 0], b.ravel()])
    vals = np.concatenate([prior.data, np.zeros(2 * var.n_pings + a.size)])
    return sparse.csc_array(sparse.coo_array((vals, (rows, cols)), shape=(var.n, var.n)))


def sparse_sum(*terms) -> sparse.csc_array:
    """The sum of sparse matrices keeping every stored entry, explicit zeros too (``+`` drops
    them, and with them the entries the bound reads)."""
    parts = [sparse.coo_array(t) for t in terms]
    data = np.concatenate([p.data for p in parts])
    index = (np.concatenate([p.row for p in parts]), np.concatenate([p.col for p in parts]))
    return sparse.csc_array(sparse.coo_array((data, index), shape=parts[0].shape))


def _filter_positions(var: _Variables, rows: sparse.csr_array, row_ping: np.ndarray,
                      base: sparse.csc_array, order: np.ndarray, smoother: np.ndarray,
                      known_field: np.ndarray) -> np.ndarray:
    """The filter bound. At the pings of an evenly spaced subset (all of a survey of at most
    ``FILTER_PINGS`` pings; the first and last always), the bound of the survey cut after the
    ping, read at it (its position ordered last: the inverse of the factor's trailing 2 x 2
    block). In between, the filter bound were the field known (``known_field``, a Kalman filter
    at every ping) plus what the field adds to it, interpolated linearly between the subset's
    pings; then never below the smoother bound (the excess over it made positive
    semi-definite)."""
    k = var.n_pings
    pings = np.unique(np.round(np.linspace(0, k - 1, min(k, FILTER_PINGS))).astype(np.int64))
    ends = np.searchsorted(row_ping, pings, side="right")
    rank = np.empty(var.n, dtype=np.int64)
    rank[order] = np.arange(var.n)
    information = base
    added = np.empty((pings.size, 2, 2))
    start = 0
    for t, (ping, end) in enumerate(zip(pings, ends, strict=True)):
        new = rows[start:end]
        information = sparse_sum(information, new.T @ new)
        start = end
        active = var.active(int(ping))
        local = np.argsort(rank[active], kind="stable")
        last = ping * var.per_ping + np.arange(2)  # dp of the ping: local = global index here
        local = np.concatenate([local[~np.isin(local, last)], last])
        factor = si.factor(information[active][:, active], local)
        z = si.selected_inverse(factor, first=active.size - 2)
        added[t] = si.inverse_entries(factor, z, last[:, None], last[None, :]) - known_field[ping]
    out = known_field.copy()
    for a in range(2):
        for b in range(2):
            out[:, a, b] += np.interp(np.arange(k), pings, added[:, a, b])
    value, vector = np.linalg.eigh(out - smoother)
    return smoother + (vector * np.maximum(value, 0.0)[:, None, :]) @ np.swapaxes(vector, 1, 2)
