"""The map's error as unknowns of the terrain solve: a correction field estimated with the track.

A map gridded from earlier surveys errs by a correlated field ``d(p)``
(:mod:`tangraph.sensors.terrain`). The terrain solve on every sounding
(:mod:`tangraph.graph.terrain_factors`) can only widen each sounding's variance for it (the
row-sum bound), which leaves the errors' correlation out: a patch of map a metre too deep pulls
every ping over it the same way. Here the field is a set of unknowns instead, on the nodes of
:func:`tangraph.eval.map_field.map_error_field` (the field the map-aware bound is solved with):
``d = S u``, ``S`` the node stds, ``u`` of Gaussian-Markov prior precision ``Q`` (the SPDE's,
Matérn of the map's correlation length). A sounding then measures

    ``z = t + h(f) + w(f)^T S u + e``,    ``var e = sounding_std^2 + nugget(f) * shared``

(``w`` the bilinear weights of its footprint on the nodes, the nugget the variance the nodes
miss between them; the soundings within one cell of nodes share it, so each is given it as
many times as they share it, :func:`shared_nugget`: the bound of the same model takes it as
independent, which claims more than it is, so the solve's covariance is at or above the
bound's), and the track, the calibration, the tide and ``u`` are solved together:
Gauss-Newton on the odometry and priors (GTSAM's linearisation), the soundings and
``1/2 u^T Q u``, assembled as one sparse system.

Each sounding's weights are those of its footprint where the solve starts (:class:`FieldSoundings`),
held while the track moves, as the bound holds them at the true footprints
(:mod:`tangraph.eval.map_field`): the field is the error of the map *under the soundings*, and
its own slope is no evidence of where they lie. The track moves by metres, the field varies over
its correlation length (tens of metres); and an estimated field's texture, fitted to the same
soundings, would otherwise be taken for terrain (measured: on a simulated survey trapped 13 m off
the truth, the field's slope made it claim 0.6 m).

A map's error is heavy-tailed in patches: check lines find most of a map erring as it says and
patches of it off by several times that. After each converged solve the field's std is grown,
a patch of a few correlation ranges at a time, by the variance factor that patch's part of the
field shows, weighed against the survey's (:func:`patch_factors`), so a patch that is far off
is given the error it shows instead of pulling the track to where the wrong map fits.

The marginal covariances of the key poses, the calibration and the nodes come from the selected
inverse of the system at the solution (:mod:`tangraph.eval.selected_inverse`), and the refined
map (:func:`refined_map`) is the map plus the field, with its posterior std.
"""

from __future__ import annotations

import dataclasses

import gtsam
import numpy as np
from scipy import sparse
from scipy.sparse.linalg import splu

from tangraph.errors import TangraphError
from tangraph.eval import selected_inverse as si
from tangraph.eval.map_field import CombinedField, MapErrorField, sparse_sum
from tangraph.graph import terrain_factors
from tangraph.graph.calibration import CALIBRATION, MAP_OFFSET, TIDE
from tangraph.graph.terrain_factors import PingTerrain
from tangraph.maps.grid import BathymetryMap
from tangraph.sensors.terrain import MapError

__all__ = ["PATCH_LENGTHS", "PATCH_PRIOR_DOF", "FieldSolution", "FieldSoundings", "field_variance",
           "marginals", "offset_estimate", "patch_factors", "patches", "refined_map", "scaled_error",
           "shared_nugget", "solve", "variance_components", "variance_ratio"]


@dataclasses.dataclass(frozen=True, eq=False)
class FieldSoundings:
    """The soundings' hold on the field: per sounding ``(K, B)`` its nodes and weights
    ``(K, B, m)`` (zero weight where it has no footprint on the map) and the variance its
    nugget is given (:func:`shared_nugget` among the soundings seen; m^2, NaN where none)."""

    field: MapErrorField | CombinedField
    node: np.ndarray
    weight: np.ndarray
    nugget: np.ndarray

    @classmethod
    def at(cls, field, north: np.ndarray, east: np.ndarray, seen: np.ndarray) -> FieldSoundings:
        """The field's hold on soundings at footprints ``north, east (K, B)``, those ``seen``."""
        node, weight = field.weights(north[seen], east[seen])
        m = node.shape[1]
        nodes = np.zeros((*seen.shape, m), dtype=np.int64)
        weights = np.zeros((*seen.shape, m))
        nugget = np.full(seen.shape, np.nan)
        nodes[seen], weights[seen], nugget[seen] = node, weight, shared_nugget(field, node, weight)
        return cls(field, nodes, weights, nugget)

    def scaled(self, factor) -> FieldSoundings:
        """The hold of the field whose stds are ``factor`` (a number, or one per node) times
        these, the nugget shared with them."""
        factor = np.broadcast_to(np.asarray(factor, float), (self.field.n_nodes,))
        fields = self.field.fields if isinstance(self.field, CombinedField) else (self.field,)
        offsets = np.cumsum([0, *(f.n_nodes for f in fields)])
        scaled = tuple(dataclasses.replace(f, std=f.std * factor[start:start + f.n_nodes])
                       for f, start in zip(fields, offsets, strict=False))
        field = CombinedField(scaled) if isinstance(self.field, CombinedField) else scaled[0]
        seen = np.isfinite(self.nugget)
        nugget = np.full(self.nugget.shape, np.nan)
        nugget[seen] = shared_nugget(field, self.node[seen], self.weight[seen])
        return dataclasses.replace(self, field=field, nugget=nugget)

    def variance_ratio(self, factor: np.ndarray) -> np.ndarray:
        """``(K, B)``: the map error's variance under each sounding with the node stds times
        ``factor`` over that as held (:func:`variance_ratio`; 1 where it has no footprint)."""
        out = np.ones(self.nugget.shape)
        seen = np.isfinite(self.nugget)
        out[seen] = variance_ratio(self.field, self.node[seen], self.weight[seen], factor)
        return out

    def offset(self, u: np.ndarray) -> np.ndarray:
        """The field ``S u`` under every sounding ``(K, B)`` (0 where it has no footprint)."""
        return np.sum(self.weight * (self.field.std * np.asarray(u, float))[self.node], axis=-1)


Field = MapErrorField | CombinedField

#: A patch of map whose error's scale is estimated on its own (:func:`patch_factors`) is this many
#: of its field's correlation ranges wide.
PATCH_LENGTHS = 4.0
#: The weight, in degrees of freedom, of the scale the whole survey shows in a patch's own
#: (the scaled inverse chi-square prior of its variance, a Student-t patch error: Lange, Little &
#: Taylor 1989 take 4 as the robust default).
PATCH_PRIOR_DOF = 4.0


def variance_ratio(field: Field, index: np.ndarray, weight: np.ndarray, factor: np.ndarray) -> np.ndarray:
    """(M,) the map error's variance at points (``index, weight`` their interpolation on the
    nodes) with the node stds times ``factor`` over that as stated: each field's nodes'
    variances blended with its interpolation weights, times the square of what the weights sum
    to (1 for a depth field; the slope for a field of the map's offset, whose weights carry it)."""
    size = np.abs(weight)
    parts = np.sum(size.reshape(*size.shape[:-1], -1, 4), axis=-1)  # each field's four nodes
    variance = size * np.repeat(parts, 4, axis=-1) * field.std[index] ** 2
    total = np.sum(variance, axis=-1)
    return np.divide(np.sum(variance * np.asarray(factor)[index] ** 2, axis=-1), total,
                     out=np.ones(total.shape), where=total > 0)


def patches(field: Field) -> np.ndarray:
    """(n_nodes,) the patch of every node: squares of :data:`PATCH_LENGTHS` ranges of each field,
    numbered across the fields."""
    fields = field.fields if isinstance(field, CombinedField) else (field,)
    out, first = [], 0
    for f in fields:
        side = max(1, round(float(PATCH_LENGTHS * f.correlation_length / f.spacing)))
        i, j = np.divmod(np.arange(f.n_nodes), f.shape[1])
        across = -(-f.shape[1] // side)
        out.append(first + (i // side) * across + j // side)
        first += across * -(-f.shape[0] // side)
    return np.concatenate(out)


def patch_factors(found: dict, factor: np.ndarray, patch: np.ndarray) -> np.ndarray:
    """The node stds' factors (over the stated) that the solution's field shows, a patch at a
    time: with ``factor`` the current ones (constant within a patch) and ``found`` the solve's
    :func:`variance_components`, a patch ``P``'s variance factor is

        ``f_P^2 = (nu g^2 + f_P^2 s_P) / (nu + r_P)``,   ``g^2 = sum_P f_P^2 s_P / sum_P r_P``,

    ``s_P`` the sum of ``u_k (Q u)_k`` over its nodes, ``r_P`` their redundancy, ``nu``
    :data:`PATCH_PRIOR_DOF`: each patch's own evidence weighed against the survey's. A map's
    error is heavy-tailed in patches (check lines find patches off by several times the stated
    std where the bulk fits it), and a patch off by metres then gives its soundings the variance
    it shows instead of pulling the track to where the wrong map fits. Never below 1: the map is
    never taken as better than stated."""
    n = int(patch.max()) + 1
    square = np.bincount(patch, found["field_nodes"] * factor**2, minlength=n)
    redundancy = np.bincount(patch, found["field_node_redundancy"], minlength=n)
    overall = float(square.sum() / redundancy.sum()) if redundancy.sum() > 0 else 1.0
    own = (PATCH_PRIOR_DOF * overall + square) / (PATCH_PRIOR_DOF + redundancy)
    return np.sqrt(np.maximum(own, 1.0))[patch]


def shared_nugget(field: Field, index: np.ndarray, weight: np.ndarray) -> np.ndarray:
    """The variance (M,) each point's nugget is given: its own nugget ``n_b`` (the variance its
    field's nodes miss, :meth:`~tangraph.eval.map_field.MapErrorField.nugget`) times what the
    points in its cell of nodes share of it, ``sqrt(n_b) sum_j sqrt(n_j)`` over the points ``j``
    in the same cell of each field's nodes (``index, weight`` their interpolation on the nodes).

    The part of the map's error that its nodes miss varies within about a node spacing, so the
    soundings of one cell share it (a multibeam's beams lie a fraction of a metre apart); taken
    as independent, every sounding would count it once more and the solve would converge on the
    map's noise. Within a cell this is the row-sum bound of :mod:`tangraph.sensors.terrain`:
    never more information than if they shared it wholly."""
    fields = field.fields if isinstance(field, CombinedField) else (field,)
    offsets = np.cumsum([0, *(f.n_nodes for f in fields)])
    out = np.zeros(index.shape[0])
    for n, (f, start) in enumerate(zip(fields, offsets, strict=False)):
        node, w = index[:, 4 * n:4 * n + 4] - start, weight[:, 4 * n:4 * n + 4]
        root = np.sqrt(f.nugget(node, w))
        cell = node[:, 0]  # a cell is named by its first corner
        out += root * np.bincount(cell, weights=root, minlength=f.n_nodes)[cell]
    return out


_VECTORS = (CALIBRATION, TIDE, MAP_OFFSET)  # the solve's variables that are vectors, not poses


@dataclasses.dataclass(frozen=True, eq=False)
class _Layout:
    """Columns of the joint unknowns: GTSAM's variables in key order (its sparse Jacobian's),
    then the field's nodes."""

    keys: np.ndarray  # sorted GTSAM keys
    start: np.ndarray  # first column of each
    dims: np.ndarray
    n_gtsam: int
    n_field: int

    @classmethod
    def of(cls, values, n_field: int) -> _Layout:
        keys = np.array(sorted(int(k) for k in values.keys()), dtype=np.uint64)
        dims = np.array([values.atVector(int(k)).size if int(k) in _VECTORS else 3 for k in keys])
        start = np.concatenate([[0], np.cumsum(dims)[:-1]])
        return cls(keys, start, dims, int(dims.sum()), int(n_field))

    @property
    def n(self) -> int:
        return self.n_gtsam + self.n_field

    def pattern(self) -> sparse.coo_array:
        """Explicit zeros on every variable's own block and between each and the calibration
        and the tide (the entries the marginals read, which an exact zero of a Jacobian would
        leave out of the factor's pattern)."""
        blocks = [np.arange(d) + s for s, d, k in zip(self.start, self.dims, self.keys, strict=True)
                  if int(k) in _VECTORS]
        shared = np.concatenate([*blocks, np.zeros(0, np.int64)]).astype(np.int64)
        own = self.start[:, None] + np.arange(3)  # a pose's columns (a shorter vector: its own, repeated)
        own = np.minimum(own, (self.start + self.dims - 1)[:, None])
        joined = np.concatenate([own, np.broadcast_to(shared, (own.shape[0], shared.size))], axis=1)
        rows = np.repeat(joined, joined.shape[1], axis=1).ravel()
        cols = np.tile(joined, (1, joined.shape[1])).ravel()
        return sparse.coo_array((np.zeros(rows.size), (rows, cols)), shape=(self.n, self.n))

    def column(self, key: int) -> int:
        return int(self.start[np.searchsorted(self.keys, np.uint64(key))])

    def pose_columns(self, keys) -> np.ndarray:
        """First column of each pose key (ascending ping keys come first)."""
        return self.start[np.searchsorted(self.keys, np.asarray(keys, dtype=np.uint64))]


@dataclasses.dataclass(frozen=True, eq=False)
class FieldSolution:
    """A converged joint solve: the GTSAM ``values`` (poses, ``c``, tide), the field's unit
    nodes ``u``, the iterations run and the system's information matrix at the solution."""

    values: gtsam.Values
    u: np.ndarray
    iterations: int
    information: sparse.csc_array
    layout: _Layout


def solve(factors, values, terrain: PingTerrain, bathymetry: BathymetryMap, hold: FieldSoundings,
          used: np.ndarray, unpack, *, u=None, max_iterations: int = 50,
          tolerance: float = 1e-6) -> FieldSolution:  # fmt: skip
    """Gauss-Newton with step halving on the odometry and priors ``factors`` (a GTSAM nonlinear
    graph), the soundings ``used`` of ``terrain`` (their variances the noise and nugget alone)
    holding the field as ``hold`` says, and the field's prior, from ``values`` and ``u``
    (default zero). ``unpack(values)`` gives the key poses, ``c``, the tide and the map's
    offset (None when it is not a variable)."""
    field = hold.field
    layout = _Layout.of(values, field.n_nodes)
    prior = sparse.csc_array(field.precision)
    u = np.zeros(field.n_nodes) if u is None else np.asarray(u, float)

    def cost(v, x) -> float:
        pose, calibration, tide, shift = unpack(v)
        return (factors.error(v) + 0.5 * float(x @ (prior @ x))
                + terrain_factors.terrain_cost(terrain, bathymetry, pose, calibration, tide, used,
                                               hold.offset(x), shift))

    def system(v, x):
        return _normal_equations(factors, v, x, terrain, bathymetry, hold, used, unpack, layout, prior)

    error, iterations = cost(values, u), 0
    while iterations < max_iterations:
        iterations += 1
        information, gradient = system(values, u)
        try:
            delta = splu(information, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                         options={"SymmetricMode": True}).solve(gradient)
        except RuntimeError as exc:
            raise TangraphError(f"terrain solve with the map's error: {exc}") from None
        step = 1.0
        while True:
            trial = _retract(values, layout, step * delta[:layout.n_gtsam])
            trial_u = u + step * delta[layout.n_gtsam:]
            new = cost(trial, trial_u)
            if new <= error or step < 1e-3:
                break
            step *= 0.5
        if new > error:
            break
        converged = error - new <= tolerance * max(error, 1e-12)
        values, u, error = trial, trial_u, new
        if converged:
            break
    return FieldSolution(values, u, iterations, system(values, u)[0], layout)


def _normal_equations(factors, values, u, terrain, bathymetry, hold: FieldSoundings, used, unpack,
                      layout: _Layout, prior):
    """``A^T A + Q`` and ``A^T b - Q u`` of the linearised problem at ``values, u``."""
    triplets = np.asarray(factors.linearize(values).sparseJacobian_())
    rows, cols, vals = triplets[0].astype(np.int64) - 1, triplets[1].astype(np.int64) - 1, triplets[2]
    rhs_col = cols == layout.n_gtsam  # the augmented column holds b
    n_rows = int(rows.max()) + 1 if rows.size else 0
    b0 = np.zeros(n_rows)
    np.add.at(b0, rows[rhs_col], vals[rhs_col])
    a0 = sparse.csr_array((vals[~rhs_col], (rows[~rhs_col], cols[~rhs_col])), shape=(n_rows, layout.n))
    a1, b1 = _sounding_rows(values, u, terrain, bathymetry, hold, used, unpack, layout)
    a = sparse.vstack([a0, a1], format="csr")
    b = np.concatenate([b0, b1])
    embedded = sparse.block_diag([sparse.csc_array((layout.n_gtsam, layout.n_gtsam)), prior], format="csc")
    information = sparse_sum(a.T @ a, embedded, layout.pattern())
    gradient = a.T @ b
    gradient[layout.n_gtsam:] -= prior @ u
    return information, gradient


def _sounding_rows(values, u, terrain: PingTerrain, bathymetry, hold: FieldSoundings, used, unpack,
                   layout: _Layout):
    """The whitened rows ``(A, b)`` of the soundings ``used``: key pose, ``c``, tide, nodes."""
    pose, calibration, tide, shift = unpack(values)
    residual, jac, dr_variance = terrain_factors.sounding_jacobians(terrain, bathymetry, pose, calibration,
                                                                    tide, hold.offset(u), shift)
    ok = used & np.isfinite(residual) & np.all(np.isfinite(jac), axis=-1)
    ping = np.nonzero(ok)[0]
    sigma = np.sqrt(terrain.variance[ok] + dr_variance[ok])
    j = jac[ok] / sigma[:, None]
    m = ping.size
    columns = [layout.pose_columns(terrain.keys[terrain.key_index[ping]])[:, None] + np.arange(3)]
    blocks = [j[:, :3]]
    at = 3
    if terrain.calibrated:
        columns.append(np.broadcast_to(layout.column(CALIBRATION) + np.arange(2), (m, 2)))
        blocks.append(j[:, at:at + 2])
        at += 2
    if terrain.estimates_tide:
        columns.append(np.full((m, 1), layout.column(TIDE)))
        blocks.append(j[:, at:at + 1])
        at += 1
    if terrain.estimates_offset:
        columns.append(np.broadcast_to(layout.column(MAP_OFFSET) + np.arange(2), (m, 2)))
        blocks.append(j[:, at:at + 2])
    node = hold.node[ok]
    columns.append(layout.n_gtsam + node)
    blocks.append(-hold.weight[ok] * hold.field.std[node] / sigma[:, None])
    col = np.concatenate(columns, axis=1)
    val = np.concatenate(blocks, axis=1)
    a = sparse.csr_array((val.ravel(), (np.repeat(np.arange(m), col.shape[1]), col.ravel())),
                         shape=(m, layout.n))
    return a, -residual[ok] / sigma


def _retract(values, layout: _Layout, delta: np.ndarray):
    vector = gtsam.VectorValues()
    for key, start, dim in zip(layout.keys, layout.start, layout.dims, strict=True):
        vector.insert(int(key), delta[start:start + dim])
    return values.retract(vector)


def marginals(solution: FieldSolution, keys, calibrated: bool) -> tuple[np.ndarray, np.ndarray, dict]:
    """Joint covariances ``(n, 5, 5)`` of the key poses (GTSAM's tangent) with ``c``, that of
    ``c`` ``(2, 2)``, and the selected inverse for the field (:func:`refined_map`)."""
    layout = solution.layout
    factor = si.factor(solution.information, si.fill_reducing_order(solution.information))
    z = si.selected_inverse(factor)
    at = layout.pose_columns(keys)[:, None] + np.arange(3)
    out = np.zeros((at.shape[0], 5, 5))
    out[:, :3, :3] = si.inverse_entries(factor, z, at[:, :, None], at[:, None, :])
    calib_cov = np.zeros((2, 2))
    if calibrated:
        c = layout.column(CALIBRATION) + np.arange(2)
        calib_cov = si.inverse_entries(factor, z, c[:, None], c[None, :])
        cross = si.inverse_entries(factor, z, at[:, :, None], np.broadcast_to(c, (at.shape[0], 1, 2)))
        out[:, :3, 3:] = cross
        out[:, 3:, :3] = np.swapaxes(cross, 1, 2)
        out[:, 3:, 3:] = calib_cov
    return out, calib_cov, {"factor": factor, "z": z}


def offset_estimate(solution: FieldSolution, inverse: dict, estimated: bool) -> dict:
    """The map's horizontal offset at the solution and its std (m, north and east;
    ``"map_offset"``, ``"map_offset_std"``), or nothing when it is not a variable."""
    if not estimated:
        return {}
    c = solution.layout.column(MAP_OFFSET) + np.arange(2)
    cov = si.inverse_entries(inverse["factor"], inverse["z"], c[:, None], c[None, :])
    return {"map_offset": [float(x) for x in solution.values.atVector(MAP_OFFSET)],
            "map_offset_std": [float(x) for x in np.sqrt(np.diag(cov))]}


def variance_components(solution: FieldSolution, terrain: PingTerrain, bathymetry: BathymetryMap,
                        hold: FieldSoundings, used: np.ndarray, unpack, inverse: dict) -> dict[str, float]:
    """A posteriori variance factors of the soundings' noise and of the field (Förstner's
    variance component estimates): each component's weighted squares over its redundancy,

        ``f_noise^2 = sum (r / sigma)^2 / (m - tr(H_e Sigma))``,
        ``f_field^2 = u^T Q u / (n - tr(Q Sigma_uu))``,

    ``H_e`` the soundings' information, ``Q`` the field's prior precision, ``Sigma`` the inverse
    of the whole system (on its pattern, ``inverse`` from :func:`marginals`); each 1 when the
    data scatter as the model says. Returns both (squared), with the redundancies, and the
    field's per node: ``u_k (Q u)_k`` and ``1 - (Q Sigma_uu)_kk`` (``"field_nodes"``,
    ``"field_node_redundancy"``, for :func:`patch_factors`)."""
    layout, factor, z = solution.layout, inverse["factor"], inverse["z"]
    a, b = _sounding_rows(solution.values, solution.u, terrain, bathymetry, hold, used, unpack, layout)
    h = sparse.coo_array(a.T @ a)
    redundancy = float(b.size - np.sum(h.data * si.inverse_entries(factor, z, h.row, h.col)))
    q = sparse.coo_array(hold.field.precision)
    at = layout.n_gtsam
    entries = si.inverse_entries(factor, z, q.row + at, q.col + at)
    field_redundancy = float(hold.field.n_nodes - np.sum(q.data * entries))
    u = solution.u
    qu = q.tocsr() @ u
    return {"noise": float(b @ b) / redundancy if redundancy > 0 else 1.0,
            "field": float(u @ qu) / field_redundancy if field_redundancy > 0 else 1.0,
            "noise_redundancy": redundancy, "field_redundancy": field_redundancy,
            "field_nodes": u * qu,
            "field_node_redundancy": 1.0 - np.bincount(q.row, q.data * entries, minlength=hold.field.n_nodes)}


def field_variance(field: Field, inverse: dict, layout: _Layout, north, east) -> np.ndarray:
    """The posterior variance of ``w^T S u`` at points (each field's own part; a combined
    field's parts summed, their posterior correlation left out)."""
    node, weight = field.weights(north, east)
    ws = weight * field.std[node]
    col = layout.n_gtsam + node
    part = np.arange(node.shape[1]) // 4  # a field's four nodes
    same = part[:, None] == part[None, :]
    rows, cols = np.broadcast_arrays(col[:, :, None], col[:, None, :])
    cov = np.zeros(rows.shape)
    cov[:, same] = si.inverse_entries(inverse["factor"], inverse["z"], rows[:, same], cols[:, same])
    return np.einsum("mi,mij,mj->m", ws, cov, ws)


def refined_map(error: MapError, field: Field, solution: FieldSolution, inverse: dict) -> BathymetryMap:
    """The map of ``error`` corrected by the estimated field over the field's grid, with its
    posterior std (the field's posterior variance plus the nugget there, at most the stated std) and
    the error's correlation length; beyond the grid the map and its error's std as they were, and no data
    where the map has none."""
    bathymetry = error.bathymetry
    north, east = np.meshgrid(bathymetry.north, bathymetry.east, indexing="ij")
    inside = np.isfinite(bathymetry.depth) & _inside(field, north, east)
    depth = np.array(bathymetry.depth, float)
    node, weight = field.weights(north[inside], east[inside])
    depth[inside] += np.sum(weight * (field.std * solution.u)[node], axis=-1)
    std = np.where(np.isfinite(depth), np.nan_to_num(error.std), np.nan)
    variance = field_variance(field, inverse, solution.layout, north[inside], east[inside])
    nugget = field.nugget(node, weight)
    # never above the stated std (the field's grid inflates its prior variance towards its edges,
    # beyond the soundings, where the posterior is the prior)
    std[inside] = np.minimum(np.sqrt(np.maximum(variance, 0.0) + nugget), std[inside])
    return bathymetry.replace(depth=depth, depth_std=std, correlation_length=error.correlation_length,
                              name=f"{bathymetry.name} refined")


def scaled_error(error: MapError, field: Field, factor: np.ndarray) -> MapError:
    """``error`` with its std grown over ``field``'s grid as the node factors ``factor`` (of
    the field as stated) say, as it was beyond the grid."""
    north, east = np.meshgrid(error.bathymetry.north, error.bathymetry.east, indexing="ij")
    inside = np.isfinite(error.std) & _inside(field, north, east)
    std = np.array(error.std, float)
    node, weight = field.weights(north[inside], east[inside])
    std[inside] *= np.sqrt(variance_ratio(field, node, weight, factor))
    return dataclasses.replace(error, std=std)


def _inside(field: Field, north, east) -> np.ndarray:
    fields = field.fields if isinstance(field, CombinedField) else (field,)
    ok = np.ones(np.shape(north), dtype=bool)
    for f in fields:
        top = (f.origin[0] + (f.shape[0] - 1) * f.spacing, f.origin[1] + (f.shape[1] - 1) * f.spacing)
        ok &= (north >= f.origin[0]) & (north <= top[0]) & (east >= f.origin[1]) & (east <= top[1])
    return ok
