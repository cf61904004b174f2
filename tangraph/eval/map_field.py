"""The map's error as a Gaussian-Markov random field on a grid of nodes (the bound's sparse joint
solve with it is :mod:`tangraph.eval.field_bound`; the model and its approximations are in the
notes of :mod:`tangraph.eval.crb`).

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
bound is solved at ``L / 3`` (on at most :data:`BOUND_MAX_NODES` nodes a field, those within
the margin of a footprint: at ``L / 5`` the simulated realistic maps' bounds move by 1 %, at
``L / 2`` the long strip of ``han2020-map-error`` by less than 0.01 %), while a solve that
estimates the field may keep its nodes no finer than the map's cell (``finer_than_cell=False``),
where the map says nothing of its error, and share the nugget among the soundings of a cell instead
(:func:`tangraph.graph.field_solve.shared_nugget`).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from scipy import sparse

from tangraph.errors import TangraphError
from tangraph.sensors.terrain import MapError

__all__ = [
    "BOUND_MAX_NODES",
    "MARGIN_LENGTHS",
    "MAX_NODES",
    "CombinedField",
    "MapErrorField",
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
#: most nodes of each of the bound's grids
BOUND_MAX_NODES = 50_000


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
    kept : ndarray of int, optional
        The lattice indices (ascending) of the nodes the field holds, when it holds only those
        near its points (``map_error_field(..., trim=True)``); ``std``, ``precision`` and the
        node indices of :meth:`weights` are then over these nodes, in this order.
    """

    origin: tuple[float, float]
    spacing: float
    shape: tuple[int, int]
    std: np.ndarray
    precision: sparse.csc_array
    correlation: np.ndarray
    correlation_length: float
    through: tuple[Any, int] | None = None
    kept: np.ndarray | None = None

    @property
    def n_nodes(self) -> int:
        return int(self.shape[0] * self.shape[1]) if self.kept is None else int(self.kept.size)

    def nodes(self) -> tuple[np.ndarray, np.ndarray]:
        """``(north, east)`` of every node (n_nodes,), in index order."""
        lattice = np.arange(self.n_nodes) if self.kept is None else self.kept
        i, j = np.divmod(lattice, self.shape[1])
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
        if self.kept is not None:
            slot = np.searchsorted(self.kept, index)
            if np.any(self.kept[np.minimum(slot, self.kept.size - 1)] != index):
                raise TangraphError("map_error_field: a point lies beyond the nodes the field keeps")
            index = slot
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


def spde_precision(shape: tuple[int, int], c: float, kept: np.ndarray | None = None) -> sparse.csc_array:
    """The unit-variance SPDE precision ``Q = v M^2`` on a ``(ny, nx)`` grid, ``M = c^2 I +
    Lap`` (``Lap`` the graph Laplacian: free edges), ``v`` the infinite lattice's variance of
    ``M^2`` (:func:`lattice_correlation`); ``c = kappa h = sqrt(8) h / L``. With ``kept``
    (lattice indices, ascending) on those nodes alone, ``Lap`` the Laplacian of the lattice's
    edges between them (free edges where the others were left out)."""
    ny, nx = shape

    def path(n: int) -> sparse.csr_array:
        degree = np.full(n, 2.0)
        degree[[0, -1]] = 1.0
        return sparse.diags_array([degree, -np.ones(n - 1), -np.ones(n - 1)], offsets=[0, -1, 1]).tocsr()

    lap = sparse.csr_array(sparse.kron(sparse.eye_array(ny), path(nx))
                           + sparse.kron(path(ny), sparse.eye_array(nx)))
    if kept is not None:
        edges = lap[kept][:, kept]
        edges.setdiag(0.0)
        lap = sparse.csr_array(edges - sparse.diags_array(np.asarray(edges.sum(axis=1)).ravel()))
    m = sparse.eye_array(lap.shape[0]) * c**2 + lap
    variance, _ = lattice_correlation(c)
    return sparse.csc_array(m @ m * variance)


def map_error_field(north: np.ndarray, east: np.ndarray, error: MapError, *, max_nodes: int = MAX_NODES,
                    finer_than_cell: bool = False, offset: tuple[float, float] | None = None,
                    trim: bool = False) -> MapErrorField | CombinedField:
    """The map error's field on a grid of nodes over the points ``north, east`` (the soundings'
    true footprints), one grid per independent field of the error
    (:meth:`~tangraph.sensors.MapError.components`: the cell-scale error and the excess of the
    interpolated parts, each with its own range), each with a margin of
    :data:`MARGIN_LENGTHS` ranges and at most ``max_nodes`` nodes, its spacing a third of its
    range, but never finer than the map's cell unless ``finer_than_cell`` (module docstring).
    ``trim``: only the nodes within the margin of some point (``MapErrorField.kept``; the count
    ``max_nodes`` is of those), the grid's edges being as far from every point as the bounding
    box's: the bound is the same, on fewer nodes where the points do not fill their box (a
    survey's lines, a loop).

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
    fields = [_one_field(north, east, part, max_nodes, finer_than_cell, trim) for part in error.components()]
    if std > 0:  # its std at every node (off the map's data a field's nodes take its median)
        base = _one_field(north, east, MapError(error.bathymetry, np.full(error.std.shape, std), length),
                          max_nodes, True, trim)
        fields += [dataclasses.replace(base, through=(error.bathymetry, axis)) for axis in (0, 1)]
    return fields[0] if len(fields) == 1 else CombinedField(tuple(fields))


def _one_field(north: np.ndarray, east: np.ndarray, error: MapError, max_nodes: int,
               finer_than_cell: bool, trim: bool) -> MapErrorField:
    length = error.correlation_length
    spacing = length / NODES_PER_LENGTH
    if not finer_than_cell:
        spacing = max(spacing, float(max(error.bathymetry.cell_size)))
    margin = MARGIN_LENGTHS * length
    low = np.array([np.min(north), np.min(east)]) - margin
    extent = np.array([np.max(north), np.max(east)]) + margin - low
    while True:
        shape = (int(np.ceil(extent[0] / spacing)) + 1, int(np.ceil(extent[1] / spacing)) + 1)
        kept = _near(north, east, low, spacing, shape, margin) if trim else None
        if (shape[0] * shape[1] if kept is None else kept.size) <= max_nodes:
            break
        spacing *= max(np.sqrt((shape[0] * shape[1] if kept is None else kept.size) / max_nodes), 1.01)
    c = np.sqrt(8.0) * spacing / length
    i, j = np.divmod(np.arange(shape[0] * shape[1]) if kept is None else kept, shape[1])
    std = error.std_at(low[0] + i * spacing, low[1] + j * spacing)
    return MapErrorField(origin=(float(low[0]), float(low[1])), spacing=float(spacing), shape=shape,
                         std=np.where(np.isfinite(std), std, error.typical_std),
                         precision=spde_precision(shape, c, kept), correlation=lattice_correlation(c)[1],
                         correlation_length=length, kept=kept)


def _near(north: np.ndarray, east: np.ndarray, low: np.ndarray, spacing: float, shape: tuple[int, int],
          margin: float) -> np.ndarray:
    """Lattice indices (ascending) of the nodes of a ``shape`` grid from ``low`` within ``margin``
    of a point (a superset: within ``margin`` plus a node spacing of the nodes around a point)."""
    from scipy.ndimage import distance_transform_edt

    i = np.clip(np.floor((np.asarray(north) - low[0]) / spacing).astype(np.int64), 0, shape[0] - 2)
    j = np.clip(np.floor((np.asarray(east) - low[1]) / spacing).astype(np.int64), 0, shape[1] - 2)
    empty = np.ones(shape, dtype=bool)
    for di in (0, 1):
        for dj in (0, 1):
            empty[i + di, j + dj] = False
    return np.flatnonzero(distance_transform_edt(empty, sampling=spacing) <= margin + spacing)


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
def sparse_sum(*terms) -> sparse.csc_array:
    """The sum of sparse matrices keeping every stored entry, explicit zeros too (``+`` drops
    them, and with them the entries the bound reads)."""
    parts = [sparse.coo_array(t) for t in terms]
    data = np.concatenate([p.data for p in parts])
    index = (np.concatenate([p.row for p in parts]), np.concatenate([p.col for p in parts]))
    return sparse.csc_array(sparse.coo_array((data, index), shape=parts[0].shape))
