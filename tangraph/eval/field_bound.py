"""The map-aware bound's sparse joint solve: the survey's linearised error state at every ping,
the DR's constants and the map error's field (:mod:`tangraph.eval.map_field`) as one sparse
information matrix, its inverse read on the factor's pattern (:mod:`tangraph.eval.selected_inverse`)
for the smoother bound, and the survey cut after a subset of its pings for the filter bound
(:func:`field_bound`; the model and its approximations are in the notes of :mod:`tangraph.eval.crb`).
"""

from __future__ import annotations

import dataclasses

import numpy as np
from scipy import sparse

from tangraph.eval import selected_inverse as si
from tangraph.eval.map_field import CombinedField, MapErrorField, sparse_sum

__all__ = ["FILTER_PINGS", "ZERO_VARIANCE", "ErrorState", "field_bound"]

#: the filter bound is solved at this many pings at most (interpolated in between)
FILTER_PINGS = 60
#: the variance (in units of the state's natural spread squared) given to a step of the error
#: state whose variance is zero (a DR without speed noise): an information matrix cannot hold
#: an exact constraint. It moves the bound by about this much times the pings (relative); the
#: rounding of the stiffer system grows as it shrinks.
ZERO_VARIANCE = 1e-8


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
    gained = sparse.csc_array((var.n, var.n))
    added = np.empty((pings.size, 2, 2))
    start = 0
    for t, (ping, end) in enumerate(zip(pings, ends, strict=True)):
        new = rows[start:end]
        # + drops the exact zeros of terms that cancel across cuts (they would fill the factor)
        gained = sparse.csc_array(gained + new.T @ new)
        information = sparse_sum(base, gained)
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
