"""The map's error as a Gaussian-Markov random field on a grid of nodes, for the bound.

:func:`map_error_field` lays a regular grid of nodes over the soundings' footprints and gives
the map's error ``d`` (:mod:`tangraph.sensors.terrain`: zero mean, ``cov(d(p), d(q)) = s(p)
s(q) rho(|p - q|)``, ``rho`` the Matérn nu = 1 correlation of range ``L``) as ``d = S u`` on
the nodes: ``u`` a unit-variance field with the sparse precision of the SPDE of Lindgren, Rue &
Lindström (2011) with alpha = 2 in the plane (the Matérn nu = 1 field),

    ``Q = c0 M^2``,  ``M = c^2 I + Lap``,  ``c = kappa h``,  ``kappa = sqrt(8) / L``,

(``Lap`` the 5-point graph Laplacian of the grid, with free, Neumann, edges; ``h`` the node
spacing), which is ``tau^2 h^2 (kappa^2 I - Laplacian_h)^2`` with ``tau^2 = c0 / h^2``, and
``S`` the diagonal of the per-node std ``s`` (:meth:`~tangraph.sensors.terrain.MapError.std_at`
at the node, the map's median std where it has none). ``c0`` is the variance of the field of
precision ``M^2`` on the infinite lattice (a Fourier sum), so that ``u`` has unit variance away
from the edges; the edges inflate it (to about twice at an edge), so the grid reaches
``2 L`` (:data:`MARGIN_LENGTHS`) beyond every footprint, where the inflation is about 1 %.

A sounding at ``p`` sees ``w^T S u``, ``w`` its bilinear weights on the 4 nodes around ``p``.
Between nodes that interpolation has less variance than the field (its nodes are not
perfectly correlated), so each sounding also gets the independent variance it misses, its
*nugget* ``sum_ab w_a w_b s_a s_b (1 - R_ab)`` (``R`` the lattice correlation of the nodes):
its map error then has the variance ``s^2`` of the model (``s`` interpolated), and soundings
in one cell share the interpolated part only.

Node spacing ``h = max(L / 3, map cell)`` (L / 3: the lattice correlation at ``L`` is 0.126
against Matérn's 0.140), made coarser (the nugget taking more) when the grid would exceed
:data:`MAX_NODES` nodes.
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import sparse

from tangraph.sensors.terrain import MapError

__all__ = ["MARGIN_LENGTHS", "MAX_NODES", "MapErrorField", "lattice_correlation", "map_error_field",
           "spde_precision"]

#: nodes per correlation length (at most: never finer than the map's cell)
NODES_PER_LENGTH = 3
#: the grid reaches this many correlation lengths beyond every footprint
MARGIN_LENGTHS = 2.0
#: most nodes of a grid (the spacing grows beyond it)
MAX_NODES = 40_000


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
    """

    origin: tuple[float, float]
    spacing: float
    shape: tuple[int, int]
    std: np.ndarray
    precision: sparse.csc_array
    correlation: np.ndarray
    correlation_length: float

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
        return index, weight

    def nugget(self, index: np.ndarray, weight: np.ndarray) -> np.ndarray:
        """The variance (M,) of the map error at points that their interpolation on the nodes
        misses: ``sum_ab w_a w_b s_a s_b (1 - R_ab)`` (m^2)."""
        ws = weight * self.std[index]
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


def map_error_field(north: np.ndarray, east: np.ndarray, error: MapError, *,
                    max_nodes: int = MAX_NODES) -> MapErrorField:
    """The map error's field on a grid of nodes over the points ``north, east`` (the soundings'
    true footprints) with a margin of :data:`MARGIN_LENGTHS` ranges.

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
    """
    length = error.correlation_length
    cell = float(max(error.bathymetry.cell_size))
    spacing = max(length / NODES_PER_LENGTH, cell)
    margin = MARGIN_LENGTHS * length
    low = np.array([np.min(north), np.min(east)]) - margin
    extent = np.array([np.max(north), np.max(east)]) + margin - low
    while True:
        shape = tuple(int(n) for n in np.ceil(extent / spacing).astype(np.int64) + 1)
        if shape[0] * shape[1] <= max_nodes:
            break
        spacing *= max(np.sqrt(shape[0] * shape[1] / max_nodes), 1.01)
    c = np.sqrt(8.0) * spacing / length
    origin = (float(low[0]), float(low[1]))
    placeholder = np.zeros(shape[0] * shape[1])
    field = MapErrorField(origin, float(spacing), (shape[0], shape[1]), placeholder,
                          spde_precision((shape[0], shape[1]), c), lattice_correlation(c)[1], length)
    std = error.std_at(*field.nodes())
    std = np.where(np.isfinite(std), std, error.typical_std)
    return dataclasses.replace(field, std=std)
