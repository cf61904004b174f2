"""The one terrain likelihood every particle filter shares, in a compiled kernel.

``log p(z | x) = -1/2 sum_b (h(x + o_b) - (z_b - tide))^2 / sigma^2`` (up to a constant) over a
ping's soundings, with ``h`` the map's bilinear depth (the rules of
:mod:`tangraph.maps._interp`). A particle for which any sounding falls off the map or next to a
NaN cell gets ``-inf``: zero weight. One compiled kernel serves the known tide and the
Gaussian tide posterior of :mod:`tangraph.filters.model` (:meth:`TerrainLikelihood.tide_update`);
each particle's grid coordinates are computed once. A particle may turn its soundings' world
offsets about the vehicle by its own angle (``turn``: a filter's particle turns them by minus its
heading error, :mod:`tangraph.filters.model`).
"""

from __future__ import annotations

import dataclasses

import numba
import numpy as np

from tangraph.errors import TangraphError
from tangraph.maps._interp import _FASTMATH, _bilinear
from tangraph.maps.grid import BathymetryMap

__all__ = ["FilterDivergence", "OffMap", "TerrainLikelihood", "effective_sample_size", "log_normalise"]


class FilterDivergence(TangraphError):
    """Every particle has zero likelihood: the filter has lost the vehicle."""


class OffMap(FilterDivergence):
    """No particle has the map under every sounding of a ping: the ping says nothing about where
    the vehicle is (it is not evidence against any particle)."""


@numba.njit(cache=True, nogil=True, fastmath=_FASTMATH, inline="always")
def _particle_sums(depth, pn, pe, offsets, inv_dn, inv_de, c, s, measured, shift):
    """``(sum r, sum r^2)`` of ``r = z - shift - h`` for one particle at grid coordinates
    ``(pn, pe)`` whose soundings' world offsets ``(B, 2)`` (metres) are turned by the angle of
    cosine ``c`` and sine ``s`` (``R(a) o``, ``a`` clockwise from north); NaN if a sounding falls
    off the map or by a NaN cell (``_interp._locate``)."""
    ny, nx = depth.shape
    s1 = 0.0
    s2 = 0.0
    for b in range(offsets.shape[0]):
        on = c * offsets[b, 0] - s * offsets[b, 1]
        oe = s * offsets[b, 0] + c * offsets[b, 1]
        fy = pn + on * inv_dn
        fx = pe + oe * inv_de
        if not (fy >= 0.0 and fy <= ny - 1 and fx >= 0.0 and fx <= nx - 1):
            return np.nan, np.nan
        i = min(int(fy), ny - 2)
        j = min(int(fx), nx - 2)
        r = measured[b] - shift - _bilinear(depth, i, j, fy - i, fx - j)[0]
        s1 += r
        s2 += r * r
    return s1, s2


@numba.njit(cache=True, nogil=True, fastmath=_FASTMATH)
def _residual_sums_kernel(
    depth, north0, east0, inv_dn, inv_de, particles, turn, offsets, measured, out
):  # fmt: skip
    """``out[p] = (sum r, sum r^2)`` of ``r = z - h(x_p + R(turn_p) o_b)``, NaN rows where a
    sounding has no map depth."""
    for p in range(particles.shape[0]):
        s1, s2 = _particle_sums(
            depth,
            (particles[p, 0] - north0) * inv_dn,
            (particles[p, 1] - east0) * inv_de,
            offsets,
            inv_dn,
            inv_de,
            np.cos(turn[p]),
            np.sin(turn[p]),
            measured,
            0.0,
        )
        out[p, 0] = s1
        out[p, 1] = s2 if s1 == s1 else np.nan


@numba.njit(cache=True, nogil=True, fastmath=_FASTMATH)
def _tide_update_kernel(
    depth, north0, east0, inv_dn, inv_de, particles, turn, offsets, measured, tide, tide_var, noise_var,
    log_likelihood, new_tide, predicted,
):  # fmt: skip
    """The ping's log-likelihood with a Gaussian tide posterior ``N(tide[p], tide_var)``, the
    updated tide means and the mean predicted depth, per particle whose soundings' offsets are
    turned by ``turn[p]`` (see ``filters.model``)."""
    nb = offsets.shape[0]
    gain = tide_var / (noise_var + nb * tide_var)
    sum_z = 0.0
    for b in range(nb):
        sum_z += measured[b]
    for p in range(particles.shape[0]):
        se, se2 = _particle_sums(
            depth,
            (particles[p, 0] - north0) * inv_dn,
            (particles[p, 1] - east0) * inv_de,
            offsets,
            inv_dn,
            inv_de,
            np.cos(turn[p]),
            np.sin(turn[p]),
            measured,
            tide[p],
        )
        m = tide[p]
        if se != se:
            log_likelihood[p] = -np.inf
            new_tide[p] = m
            predicted[p] = np.nan
            continue
        log_likelihood[p] = -0.5 * (se2 - gain * se * se) / noise_var
        new_tide[p] = m + gain * se
        predicted[p] = (sum_z - se) / nb  # mean of h + m: sum h = sum z - se - nb m


@dataclasses.dataclass(frozen=True, eq=False)
class TerrainLikelihood:
    """Gaussian sounding errors of std ``sigma`` (m) around the map depth plus ``tide``."""

    bathymetry: BathymetryMap
    sigma: float
    tide: float = 0.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.sigma) and self.sigma > 0):
            raise TangraphError(f"TerrainLikelihood: sigma must be positive, got {self.sigma!r}")

    def log_likelihood(self, particles, offsets, depths, turn=None) -> np.ndarray:
        """Log-likelihood (N,) of particles (N, 2) for soundings at ``offsets`` (B, 2) (world
        north/east from the vehicle) with measured ``depths`` (B,); NaN depths are skipped.

        ``-1/2 sum_b (z_b - tide - h(x + R(turn) o_b))^2 / sigma^2``; ``-inf`` where a sounding has
        no map depth. ``turn (N,)`` (rad, clockwise from north; None: 0) turns each particle's
        offsets about the vehicle (a filter passes ``-b``, minus its heading error). One compiled
        pass (the known-tide case of :meth:`tide_update`).
        """
        particles = np.asarray(particles, dtype=np.float64)
        tide = np.full(particles.shape[0] if particles.ndim else 0, float(self.tide))
        return self.tide_update(particles, offsets, depths, tide, 0.0, turn=turn)[0]

    def _checked(self, particles, offsets, depths, turn) -> tuple[np.ndarray, ...]:
        particles = np.ascontiguousarray(particles, dtype=np.float64)
        offsets = np.ascontiguousarray(offsets, dtype=np.float64)
        depths = np.asarray(depths, dtype=np.float64)
        if particles.ndim != 2 or particles.shape[1] != 2:
            raise TangraphError(f"particles must have shape (N, 2), got {particles.shape}")
        if offsets.ndim != 2 or offsets.shape[1] != 2 or depths.shape != (offsets.shape[0],):
            raise TangraphError(
                f"offsets (B, 2) and depths (B,) do not match: {offsets.shape}, {depths.shape}"
            )
        n = particles.shape[0]
        if turn is None:
            turn = np.zeros(n)
        turn = np.ascontiguousarray(turn, dtype=np.float64)
        if turn.shape != (n,):
            raise TangraphError(f"turn must have shape ({n},) as particles, got {turn.shape}")
        keep = np.isfinite(depths)
        if not keep.all():
            offsets, depths = np.ascontiguousarray(offsets[keep]), depths[keep]
        return particles, offsets, np.ascontiguousarray(depths), turn

    def residual_sums(self, particles, offsets, depths, turn=None) -> np.ndarray:
        """``(N, 2)``: per particle the sum and the sum of squares of the residuals
        ``r = z - h(x + R(turn) o)`` (measured minus map depth, ``tide`` not removed) of the
        finite soundings; NaN rows for particles with a sounding off the map or by a NaN cell.
        ``turn (N,)``: see :meth:`log_likelihood`.

        One compiled pass over particles x soundings; the filters build their likelihood (with
        a known or an estimated tide) from these sums.
        """
        particles, offsets, depths, turn = self._checked(particles, offsets, depths, turn)
        out = np.empty((particles.shape[0], 2))
        n0, e0, dn, de = self.bathymetry._grid  # type: ignore[attr-defined]
        _residual_sums_kernel(
            self.bathymetry.depth, n0, e0, 1.0 / dn, 1.0 / de, particles, turn, offsets, depths, out
        )
        return out

    def tide_update(
        self, particles, offsets, depths, tide, tide_var: float, *, turn=None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """With finite soundings only, in one compiled pass: per particle the log-likelihood
        (up to a constant) of the soundings under a Gaussian tide posterior ``N(tide (N,),
        tide_var)`` (``tide_var = 0``: a known tide, the plain Gaussian likelihood), the
        posterior tide mean after them and the mean predicted depth (map plus tide); ``-inf``,
        the old tide and NaN for particles with a sounding off the map. See
        :mod:`tangraph.filters.model` for the algebra; ``self.tide`` is not used. NaN depths are
        skipped (with their offsets), as in :meth:`log_likelihood`. ``turn (N,)`` turns each
        particle's offsets about the vehicle (rad; None: 0).

        Raises
        ------
        TangraphError
            ``particles`` not ``(N, 2)``, ``offsets`` and ``depths`` not ``(B, 2)`` and ``(B,)``,
            ``tide`` or ``turn`` not ``(N,)``, ``tide_var`` negative or not finite.
        """
        particles, offsets, depths, turn = self._checked(particles, offsets, depths, turn)
        n = particles.shape[0]
        tide = np.ascontiguousarray(tide, dtype=np.float64)
        if tide.shape != (n,):
            raise TangraphError(f"tide must have shape ({n},) as particles, got {tide.shape}")
        try:
            variance = float(tide_var)
        except (TypeError, ValueError):
            variance = np.nan
        if not (np.isfinite(variance) and variance >= 0):
            raise TangraphError(f"tide_var must be a finite number >= 0, got {tide_var!r}")
        if depths.size == 0:  # nothing measured: no information
            return np.zeros(n), tide.copy(), np.full(n, np.nan)
        log_likelihood, new_tide, predicted = np.empty(n), np.empty(n), np.empty(n)
        n0, e0, dn, de = self.bathymetry._grid  # type: ignore[attr-defined]
        _tide_update_kernel(
            self.bathymetry.depth, n0, e0, 1.0 / dn, 1.0 / de, particles, turn, offsets, depths, tide,
            variance, self.sigma**2, log_likelihood, new_tide, predicted,
        )  # fmt: skip
        return log_likelihood, new_tide, predicted


def log_normalise(logw: np.ndarray, *, where: str = "") -> tuple[np.ndarray, float]:
    """Normalised weights and the log of their sum, computed stably.

    Raises
    ------
    FilterDivergence
        Every weight is zero (all ``-inf``), naming ``where``.
    """
    top = np.max(logw)
    if not np.isfinite(top):
        raise FilterDivergence(f"{where}: all {logw.size} particles have zero likelihood (filter diverged)")
    w = np.exp(logw - top)
    total = w.sum()
    return w / total, float(top + np.log(total))


def effective_sample_size(weights: np.ndarray) -> float:
    """``1 / sum(w^2)`` of normalised weights."""
    return float(1.0 / np.sum(np.square(weights)))
