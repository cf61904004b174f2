"""The point-mass filter's calibration held per point (``PMFConfig.calibration = "points"``).

Instead of a bank of calibration nodes, each with its own position grid
(:mod:`tangraph.filters.pmf_bank`), one grid whose every point carries the Gaussian posterior of
the DR's constant errors ``c = (k, b)`` (speed scale, heading error) given that the vehicle is
there: the Rao-Blackwellised point-mass filter (Šmídl and Gašperin, "Rao-Blackwellized point
mass filter for reliable state estimation", FUSION 2013), the position's density non-parametric
and the calibration, which only moves the position linearly over a short stretch, Gaussian.

- **Between convolutions** each point moves by the DR increment calibrated with its own mean,
  ``R(-b_i) u / (1 + k_i)`` (the points part as their calibrations differ: the grid shears), and
  one joint covariance of the position's deviation since the last and the calibration's,
  ``[[S_xx, S_xc], [S_cx, S_cc]]``, shared by the points, grows as a Kalman prediction: the
  white DR noise into ``S_xx``, the heading walk into ``S_cc``, and the calibration's effect
  ``J c`` (``J`` the increment's derivative at the mean calibration) into both and their
  correlation.
- **A convolution** (once ``S_xx`` reaches half a grid step, checked before a ping weighs the
  density and after, and before every new lattice; a spread wider than the lattice holds
  after the new lattice, laid for it) fits the lattice to the points as they have moved
  (:func:`refit`) and spreads every point's mass over its neighbours by a lattice kernel of
  covariance ``S_xx`` exactly (:func:`_kernel`; at least ``CELL`` each way), each arrival's
  calibration conditioned on where it arrives,
  ``c_i + S_cx S_xx^-1 (x_j - x_i)`` with ``S_cc - S_cx S_xx^-1 S_xc``; a point's calibration is
  the moment match of what arrives (the spread of the arriving means joins the shared ``S_cc``,
  so the calibration's variance is kept), as are its tide means (their spread joins the tide's
  variance). Points of negligible mass hold the mixture's mean calibration (``NEGLIGIBLE``).
- **A ping of a swath** tells each point's heading error too (it turns the soundings about the
  point; :func:`swath_heading`): the ping's log-likelihood at the point's heading mean and one
  shared std either side, fitted by a quadratic, conditions the point's Gaussian (a Kalman
  update of its mean, the shared covariance by the points' mean curvature), and the point is
  weighed by its likelihood with the heading error integrated out. The bank's nodes get this
  evidence by being weighed at their different headings; without it the points learnt the
  heading error from the motion alone (15 % less accurate on ``wang2019``'s swath).
- **A new lattice** (when the density needs one, as the bank's) reads the density by cubic
  splines and the calibration and tide means as ratios of bilinear ones.

A heading error that may change at every turn only widens ``S_cc``: the points it moves apart
stay one continuous density, which the terrain weighs, where the bank's nodes parted into
separate grids with nothing between them. Weighing a ping costs one grid of points, not one per
node.
"""

from __future__ import annotations

import dataclasses

import numba
import numpy as np
from scipy import ndimage

from tangraph.filters.likelihood import FilterDivergence, log_normalise
from tangraph.filters.pmf_grid import PointMass, _Grid, _offsets, _point_means, _support
from tangraph.filters.tide import TideDrift
from tangraph.geometry import rotate

__all__: list[str] = []

# the shared spread, in grid steps squared, at which it is convolved in (as the bank's white noise)
SPREAD = 0.25
# points of less than this share of the largest point's mass hold the calibration's mean: the
# conditional means of the far tails, extrapolated at each convolution from the few neighbours
# that reach them, would otherwise run away, and what the tails hold does not count
NEGLIGIBLE = 1e-10
# the narrowest spread (grid steps^2) convolved in, each way: a narrower one would send a little
# mass a whole step, and an arrival that far on a spread that small implies an extreme calibration
CELL = 1.0 / 48.0
# a swath's evidence on the heading error (:func:`swath_heading`): only the points that hold all
# but exp(-REACH) of a ping's posterior are weighed again; a Newton step moves a point's heading
# error by at most MAX_MOVE of the std it was fitted over (one std each way), and a point is
# fitted at most ITERATIONS times; below MIN_HEADING_VAR (rad^2) the heading error is known
REACH = 20.0
MAX_MOVE = 2.0
ITERATIONS = 3
MIN_HEADING_VAR = 1e-10


def start_joint(cal_cov: np.ndarray) -> np.ndarray:
    """The joint covariance ``(4, 4)`` at a (re-)grid: no position deviation yet, the
    calibration's ``cal_cov (2, 2)``."""
    joint = np.zeros((4, 4))
    joint[2:, 2:] = cal_cov
    return joint


def predict(state, ping, motion) -> None:
    """Move every point by its own calibrated increment and grow the joint covariance by the
    ping's step (``motion``: the filter model's motion, :class:`~tangraph.filters.model.FilterModel`)."""
    cal = state.point_cal
    u = np.broadcast_to(ping.increment, cal.shape)
    state.shift = state.shift + rotate(-cal[:, 1], u) / (1.0 + cal[:, 0])[:, None]
    w = state.masses().ravel()
    k, b = w @ cal if w.sum() > 0 else cal.mean(axis=0)
    v = rotate(-b, np.asarray(ping.increment, float))
    jac = np.column_stack([-v / (1.0 + k) ** 2, np.array([v[1], -v[0]]) / (1.0 + k)])
    f = np.eye(4)
    f[:2, 2:] = jac
    noise = np.zeros((4, 4))
    noise[:2, :2] = motion.noise_covariance(ping)
    noise[3, 3] = motion.walk_variance(ping)
    state.joint = f @ state.joint @ f.T + noise


def swath_heading(state, live: np.ndarray, log_mass: np.ndarray, log_likelihood: np.ndarray,
                  evaluate, offsets: np.ndarray) -> np.ndarray:
    """A ping's evidence on every point's heading error: at a point the heading error turns the
    swath's soundings about it, so a swath beside the track tells it (a single beam does not).

    The log-likelihood ``log_likelihood (L,)`` of the points ``live (L,)`` (their prior
    ``log_mass``) is evaluated again at ``b -+ d`` by ``evaluate(sub, heading_error (len(sub),),
    move (len(sub), 2))`` for the points ``live[sub]`` (the position moved with the heading by
    the joint's regression, ``S_xb / S_bb``), starting at the point's mean ``b_i`` with ``d``
    the shared std, and fitted by a quadratic in ``b`` (its curvature ``h`` made a
    likelihood's, at least 0). A Newton step on the log-posterior (the prior ``N(b_i, S_bb)``)
    follows, at most ``MAX_MOVE`` ``d``; a point whose step leaves the fitted range on evidence
    sharper than the prior (``h S_bb > 1``; not a quadratic there, as a first ping's can be) is
    weighed where it went: if its log-posterior rose, it is fitted again there, with ``d`` its
    posterior std (or what is left of the step over ``MAX_MOVE``, never wider), up to
    ``ITERATIONS`` times (a Laplace approximation); if not, the step is cut to the fitted
    range. Each point's Gaussian (position deviation, calibration) moves by the regression on
    its heading's move, the shared joint covariance is conditioned by the points' mean
    curvature, and the points' likelihoods with the heading error integrated out
    are returned. Only the points that hold all but ``exp(-REACH)`` of the ping's posterior are
    weighed again. Replaces ``state.point_cal``, ``shift`` and ``joint`` (never in place)."""
    joint = state.joint
    s_bb = float(joint[3, 3])
    if s_bb <= MIN_HEADING_VAR or not np.any(np.abs(offsets) > 1e-6):
        return log_likelihood
    post = log_mass + log_likelihood
    sub = np.flatnonzero(post > np.max(post) - REACH)
    b0 = state.point_cal[live[sub], 1]
    regress = joint[:2, 3] / s_bb  # the position's deviation per unit of heading error
    at = np.zeros(sub.size)  # each point's heading offset from b_i
    centre = np.zeros(sub.size)  # where mid, g and h were fitted
    mid = log_likelihood[sub].copy()
    d = np.full(sub.size, np.sqrt(s_bb))
    g, h = np.zeros(sub.size), np.zeros(sub.size)
    todo = np.arange(sub.size)
    for iteration in range(ITERATIONS):
        c, dt = centre[todo], d[todo]
        lo = evaluate(sub[todo], b0[todo] + c - dt, (c - dt)[:, None] * regress)
        hi = evaluate(sub[todo], b0[todo] + c + dt, (c + dt)[:, None] * regress)
        ok = np.isfinite(lo) & np.isfinite(hi)
        lo, hi = np.where(ok, lo, 0.0), np.where(ok, hi, 0.0)
        g[todo] = np.where(ok, (hi - lo) / (2.0 * dt), 0.0)
        h[todo] = np.where(ok, np.maximum((2.0 * mid[todo] - lo - hi) / dt**2, 0.0), 0.0)
        newton = (g[todo] - c / s_bb) / (h[todo] + 1.0 / s_bb)
        step = np.clip(newton, -MAX_MOVE * dt, MAX_MOVE * dt)
        at[todo] = c + step
        # fitted next over the posterior's std, or over what is left of the step (never wider)
        d[todo] = np.maximum(1.0 / np.sqrt(h[todo] + 1.0 / s_bb),
                             np.minimum(dt, np.abs(newton - step) / MAX_MOVE))
        # beyond the range it was fitted over, on evidence sharper than the prior (a weak
        # evidence, the map's noise seen through a short lever arm, is not followed further)
        far = ok & (np.abs(step) > dt) & (h[todo] * s_bb > 1.0)
        if iteration == ITERATIONS - 1 or not far.any():
            break
        todo, c, step, dt = todo[far], c[far], step[far], dt[far]
        there = evaluate(sub[todo], b0[todo] + at[todo], at[todo][:, None] * regress)
        # a step the log-posterior does not rise by is cut back to the fitted range
        better = np.isfinite(there) & (there - 0.5 * at[todo] ** 2 / s_bb > mid[todo] - 0.5 * c**2 / s_bb)
        at[todo[~better]] = c[~better] + np.clip(step[~better], -dt[~better], dt[~better])
        todo, there = todo[better], there[better]
        if not todo.size:
            break
        centre[todo], mid[todo] = at[todo], there
    step = at - centre
    evidence = mid - log_likelihood[sub] + g * step - 0.5 * h * step**2 - 0.5 * at**2 / s_bb \
        - 0.5 * np.log1p(h * s_bb)
    out = log_likelihood.copy()
    out[sub] += evidence
    move = (at / s_bb)[:, None] * joint[:, 3][None, :]  # (position deviation, k, b) of each point
    cal, shift = state.point_cal.copy(), state.shift.copy()
    cal[live[sub]] += move[:, 2:]
    shift[live[sub]] += move[:, :2]
    w = np.exp(post[sub] + evidence - np.max(post[sub] + evidence))
    h_bar = float(w @ h / w.sum())
    column = joint[:, 3]
    state.joint = joint - np.outer(column, column) * h_bar / (1.0 + h_bar * s_bb)
    state.point_cal, state.shift = cal, shift
    return out


@numba.njit(cache=True, nogil=True)
def _spread(weight, cal, means, table, gain, n):  # pragma: no cover - compiled
    """Every point's mass (``weight (n * n,)``, calibration ``cal (n * n, 2)``, tide-like means
    ``means (n * n, T)``) spread over its neighbours by the discrete kernel ``table (2R + 1, 2R +
    1)`` (offsets ``-R..R`` in grid steps; renormalised over the grid), each arrival's calibration
    conditioned by ``gain (2, 2)`` per step. Returns the points' mass ``(n * n,)``, mass-weighted
    calibration ``(n * n, 2)``, its second moments ``(n * n, 3)`` (kk, kb, bb) and mass-weighted
    means ``(n * n, T)``."""
    t = means.shape[1]
    reach = (table.shape[0] - 1) // 2
    mass = np.zeros(n * n)
    c1 = np.zeros((n * n, 2))
    c2 = np.zeros((n * n, 3))
    m1 = np.zeros((n * n, t))
    for i in range(n * n):
        if weight[i] <= 0.0:
            continue
        r0, s0 = i // n, i % n
        lo0, hi0 = max(r0 - reach, 0), min(r0 + reach, n - 1)
        lo1, hi1 = max(s0 - reach, 0), min(s0 + reach, n - 1)
        total = 0.0
        for r in range(lo0, hi0 + 1):
            for s in range(lo1, hi1 + 1):
                total += table[r - r0 + reach, s - s0 + reach]
        if total <= 0.0:
            continue
        for r in range(lo0, hi0 + 1):
            for s in range(lo1, hi1 + 1):
                wk = weight[i] * table[r - r0 + reach, s - s0 + reach] / total
                if wk <= 0.0:
                    continue
                x, y = r - r0, s - s0
                j = r * n + s
                ck = cal[i, 0] + gain[0, 0] * x + gain[0, 1] * y
                cb = cal[i, 1] + gain[1, 0] * x + gain[1, 1] * y
                mass[j] += wk
                c1[j, 0] += wk * ck
                c1[j, 1] += wk * cb
                c2[j, 0] += wk * ck * ck
                c2[j, 1] += wk * ck * cb
                c2[j, 2] += wk * cb * cb
                for m in range(t):
                    m1[j, m] += wk * means[i, m]
    return mass, c1, c2, m1


def held(cov: np.ndarray) -> np.ndarray:
    """The covariance ``(2, 2)`` (grid steps^2) of :func:`_kernel`'s table for ``cov``: ``cov``,
    its smaller variance raised to the correlation where a 3 x 3 step cannot hold it
    (``|cov_xy| > min(cov_xx, cov_yy)``); what is added is white, so conditioning on the
    table's covariance stays exact."""
    out = 0.5 * (cov + cov.T)
    out[0, 0], out[1, 1] = max(out[0, 0], abs(out[0, 1])), max(out[1, 1], abs(out[0, 1]))
    return out


def _kernel(cov: np.ndarray) -> np.ndarray:
    """A lattice kernel of mean zero and covariance ``cov (2, 2)`` (grid steps^2, as
    :func:`held` holds it), however narrow against a step: ``m`` steps of a 3 x 3 random walk of
    covariance ``cov / m`` (``m`` keeps its centre weight non-negative), whose moments add (its
    table from the ``m``-th power of the step's transform)."""
    cov = held(cov)
    m = max(1, int(np.ceil(2.0 * np.trace(cov))))
    kxx, kyy, kxy = cov[0, 0] / m, cov[1, 1] / m, cov[0, 1] / m
    c = min(abs(kxy), kxx, kyy) / 2.0  # the diagonal neighbours' weight
    a, b = kxx / 2.0 - c, kyy / 2.0 - c
    reach = int(np.ceil(6.0 * np.sqrt(max(float(np.max(np.linalg.eigvalsh(cov))), 0.0)))) + 1
    size = 2 * reach + 1
    wi = 2.0 * np.pi * np.fft.fftfreq(size)[:, None]
    wj = 2.0 * np.pi * np.fft.fftfreq(size)[None, :]
    diagonal = wi + wj if kxy >= 0 else wi - wj
    step = 1.0 - 2.0 * (a + b + c) + 2.0 * a * np.cos(wi) + 2.0 * b * np.cos(wj) + 2.0 * c * np.cos(diagonal)
    table = np.maximum(np.fft.fftshift(np.real(np.fft.ifft2(step**m))), 0.0)  # (round-off below zero)
    return table / table.sum()


def refit(state) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The lattice that fits the points as they have moved: ``(centre (2,), axes (2, 2), shift
    (n * n, 2))``, the affine map of the grid's indices that is closest to the points where the
    mass is (least squares weighted by it: points of the tails, however far their calibration
    took them, do not bend the lattice) and what is left of each point's move."""
    n = state.n
    h = (n - 1) / 2.0
    i, j = np.meshgrid(np.arange(n) - h, np.arange(n) - h, indexing="ij")
    index = np.column_stack([i.ravel(), j.ravel()])
    points = state.points()
    w = state.masses().ravel()
    if np.count_nonzero(w > 1e-9 * w.max()) < 3:  # (too few points hold the mass to fit by)
        w = np.ones_like(w)
    w = w / w.sum()
    mean_index = w @ index
    d_i, d_p = index - mean_index, points - w @ points
    axes = np.linalg.solve((d_i * w[:, None]).T @ d_i, (d_i * w[:, None]).T @ d_p).T
    centre = w @ points - axes @ mean_index
    return centre, axes, points - centre - index @ axes.T


def convolve(state, carried: list[np.ndarray]) -> dict:
    """The shared spread ``S_xx`` convolved into the density on its own (re-fitted) lattice,
    each arrival's calibration conditioned on where it arrives; the fields of the new state
    (``centres``, ``axes``, ``shift``, ``log_density``, ``point_cal``, ``joint``) and the
    arrivals' mean of each of the per-point values ``carried`` (each ``(n * n,)``), as
    ``means``."""
    centre, axes, shift = refit(state)
    n = state.n
    inv = np.linalg.inv(axes)
    # at least CELL each way (what is added is white: the conditioning stays exact)
    values, vectors = np.linalg.eigh(held(inv @ state.joint[:2, :2] @ inv.T))
    cov = held((vectors * np.maximum(values, CELL)) @ vectors.T)
    table = _kernel(cov)
    s_xx, s_cx = axes @ cov @ axes.T, state.joint[2:, :2]
    a = s_cx @ np.linalg.inv(s_xx)
    gain = a @ axes  # the calibration per step of the lattice
    conditional = state.joint[2:, 2:] - a @ s_cx.T
    weight = state.masses().ravel()
    stacked = np.column_stack(carried) if carried else np.zeros((weight.size, 0))
    # about the mixture's mean: the arrivals' spread is then not the difference of two large
    # second moments (a known calibration, all points alike, keeps a spread of exactly 0)
    ref = weight @ state.point_cal / weight.sum()
    mass, c1, c2, m1 = _spread(weight, np.ascontiguousarray(state.point_cal - ref, dtype=np.float64),
                               np.ascontiguousarray(stacked, dtype=np.float64), table,
                               np.ascontiguousarray(gain), n)
    total = mass.sum()
    live = mass > 0.0
    safe = np.where(live, mass, 1.0)
    mean_cal = c1.sum(axis=0) / total
    cal = np.where((mass > NEGLIGIBLE * mass.max())[:, None], c1 / safe[:, None], mean_cal)
    second = c2 / safe[:, None]
    spread = np.stack([second[:, 0] - cal[:, 0] ** 2, second[:, 1] - cal[:, 0] * cal[:, 1],
                       second[:, 2] - cal[:, 1] ** 2])
    cal = cal + ref
    within = np.where(live, spread, 0.0) @ mass / total  # kk, kb, bb
    within = np.array([[within[0], within[1]], [within[1], within[2]]])
    values, vectors = np.linalg.eigh(within)
    conditional = 0.5 * (conditional + conditional.T) + (vectors * np.maximum(values, 0.0)) @ vectors.T
    means = [np.where(live, m1[:, t] / safe, float(weight @ carried[t])) for t in range(len(carried))]
    with np.errstate(divide="ignore"):
        density = np.where(live, np.log(safe), -np.inf)
    _, log_total = log_normalise(density, where="pmf")
    area = float(abs(np.linalg.det(axes)))
    return {"centres": centre[None, :], "axes": axes, "shift": shift,
            "log_density": (density - log_total - np.log(area)).reshape(1, n, n), "point_cal": cal,
            "joint": start_joint(conditional), "means": means}


def regrid(state: PointMass, grid: _Grid, keep: bool = False) -> PointMass:
    """The state with its calibration per point: its shared spread convolved in on its own
    lattice (:func:`_convolved`), then, unless ``keep``, re-sampled onto the grid rule's new
    lattice about its mean (:func:`_relattice`). A spread wider than the density's target on
    its lattice (``(n - 1) / 2 / sigmas`` steps std: a kernel that would reach past the lattice's
    edges) is convolved in after the new lattice, laid for the density with the spread."""
    assert state.joint is not None and state.point_cal is not None  # (calibration per point)
    inv = np.linalg.inv(state.axes)
    target = (state.n - 1) / 2.0 / grid.sigmas
    wide = np.max(np.linalg.eigvalsh(inv @ state.joint[:2, :2] @ inv.T)) > target**2
    if wide and not keep:
        return _convolved(_relattice(state, grid))
    state = _convolved(state)
    return state if keep else _relattice(state, grid)


def _convolved(state: PointMass) -> PointMass:
    """``state`` with its shared spread convolved in on its lattice (:func:`convolve`; the tide
    means mixed as the density is)."""
    joint = state.joint
    assert joint is not None
    if np.any(joint[:2, :2]):
        # the tide means mix as the density does; the spread of the mixed means joins the
        # variance (as :func:`_diffuse`)
        carried = [t.ravel() for t in _point_means(state)]
        pairs = [(a, b) for a in range(len(carried)) for b in range(a, len(carried))]
        fields = convolve(state, carried + [carried[a] * carried[b] for a, b in pairs])
        means = fields.pop("means")
        mass = np.exp(fields["log_density"].ravel() - np.max(fields["log_density"]))
        mass = mass / mass.sum()
        spread = {pair: float(mass @ (means[len(carried) + i] - means[pair[0]] * means[pair[1]]))
                  for i, pair in enumerate(pairs)}
        drift = state.tide_drift
        state = dataclasses.replace(
            state, **fields, tide=means[0].reshape(1, state.n, state.n),
            tide_var=state.tide_var + max(spread[0, 0], 0.0),
            tide_drift=None if drift is None else
            TideDrift(means[1].reshape(1, state.n, state.n), drift.cross + spread[0, 1],
                      drift.var + max(spread[1, 1], 0.0)))
    return state


def _splat(index: np.ndarray, values: list[np.ndarray], n: int) -> list[np.ndarray]:
    """Each of ``values`` (``(P,)`` each) of points at fractional lattice ``index (P, 2)``
    spread to the four lattice points around it by bilinear weights and summed, on an ``n x n``
    lattice (flat, ``(n * n,)`` each; what falls outside is dropped)."""
    low = np.floor(index).astype(np.int64)
    t = index - low
    out = [np.zeros(n * n) for _ in values]
    for di in (0, 1):
        for dj in (0, 1):
            i, j = low[:, 0] + di, low[:, 1] + dj
            w = (t[:, 0] if di else 1.0 - t[:, 0]) * (t[:, 1] if dj else 1.0 - t[:, 1])
            inside = (i >= 0) & (i < n) & (j >= 0) & (j < n)
            for o, v in zip(out, values, strict=True):
                np.add.at(o, i[inside] * n + j[inside], w[inside] * v[inside])
    return out


def _relattice(state: PointMass, grid: _Grid) -> PointMass:
    """``state`` re-sampled onto the grid rule's new lattice about its mean, sized for its
    density with the shared spread convolved in (the density by cubic splines, its calibration
    and tide means as the bank's re-grid reads them; the joint covariance kept)."""
    joint, point_cal, shift = state.joint, state.point_cal, state.shift
    assert joint is not None and point_cal is not None and shift is not None
    _, centres, _ = state.member_moments()
    axes = grid.axes(state.within() + joint[:2, :2], _support(state, centres))
    inv = np.linalg.inv(state.axes)
    h, n = (state.n - 1) / 2.0, grid.n
    q = ((centres[0] + _offsets(n, axes) - state.centres[0]) @ inv.T + h).T
    if np.any(shift):  # each new point read where it lies among the old points as they moved
        sheared = shift.reshape(state.n, state.n, 2)
        back = np.column_stack([ndimage.map_coordinates(sheared[..., a], q, order=1, mode="nearest")
                                for a in range(2)])
        q = q - (back @ inv.T).T
    p = state.masses()[0]
    sampled = [p, *(p * c for c in point_cal.reshape(state.n, state.n, 2).transpose(2, 0, 1)),
               *(p * t[0] for t in _point_means(state))]
    new_inv = np.linalg.inv(axes)
    if (abs(np.linalg.det(axes)) > abs(np.linalg.det(state.axes))
            and np.min(np.linalg.eigvalsh(new_inv @ state.within() @ new_inv.T)) < 1.0):
        # a coarser lattice than a density narrower than its step (a wide spread still to
        # come): each old point's mass and what it carries go to its four new neighbours
        # (bilinear weights), so nothing falls between the new points
        f = (state.points() - centres[0]) @ new_inv.T + (n - 1) / 2.0
        value, k, b, *tides = _splat(f, [v.ravel() for v in sampled], n)
        linear = value
    else:
        # the density by cubic splines (bilinear re-sampling would widen it by up to a quarter
        # of a step squared each time), the means it carries as ratios of bilinear ones (each
        # new point's a mean of its old neighbours')
        value = np.maximum(ndimage.map_coordinates(p, q, order=3, mode="constant", cval=0.0), 0.0)
        linear, k, b, *tides = (ndimage.map_coordinates(v, q, order=1, mode="constant", cval=0.0)
                                for v in sampled)
    total = value.sum()
    if total <= 0:  # (the new lattice is laid about the density's mean: not reached)
        raise FilterDivergence("pmf: the density missed its new grid")
    live = value > 1e-300 * total
    read = linear > 1e-300 * linear.max()
    safe = np.where(read, linear, 1.0)
    mean_cal = state.calibration()[0]
    cal = np.where((read & (value > NEGLIGIBLE * value.max()))[:, None],
                   np.column_stack([k, b]) / safe[:, None], mean_cal)
    moved = [np.where(read, t / safe, float(np.sum(t) / np.sum(linear))).reshape(1, n, n) for t in tides]
    safe = np.where(live, value, 1.0)
    with np.errstate(divide="ignore"):
        density = np.where(live, np.log(safe), -np.inf)
    _, log_total = log_normalise(density, where="pmf")
    area = float(abs(np.linalg.det(axes)))
    cal_cov = joint[2:, 2:]
    return PointMass(mean_cal[None, :], np.zeros(1), centres[:1], axes,
                     (density - log_total - np.log(area)).reshape(1, n, n), moved[0], state.tide_var,
                     np.zeros((2, 2)), 0.0, (mean_cal, cal_cov),
                     (mean_cal, np.sqrt(np.maximum(np.diag(cal_cov), 0.0))), state.misfit,
                     None if state.tide_drift is None else
                     dataclasses.replace(state.tide_drift, mean=moved[1]),
                     cal, np.zeros((n * n, 2)), joint)
