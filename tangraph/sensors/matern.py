"""The Matérn correlation of the map's error (:mod:`tangraph.sensors.terrain`): the function
``rho(r) = (k r) K_1(k r)``, a seeded field of it on a grid, and its sums over scattered points
(one window's or a survey's soundings) on a grid of a sixth of its range: the row sums
``sum_j w_j rho_bj`` and the quadratic form ``sum_(b != j) w_b w_j^T rho_bj``."""

from __future__ import annotations

import functools

import numpy as np
from scipy import special

from tangraph.errors import TangraphError

__all__ = ["matern_correlation", "matern_field"]

# Grid of the row sums: at least this many cells per correlation length, at most this many cells.
_CELLS_PER_LENGTH = 6
_MAX_CELLS = 4_000_000



def matern_correlation(distance, length: float) -> np.ndarray:
    """The map error's correlation ``rho(r) = (k r) K_1(k r)``, ``k = sqrt(8) / length`` (1 at 0).

    Examples
    --------
    >>> matern_correlation([0.0, 10.0], 10.0).round(3).tolist()
    [1.0, 0.14]
    """
    r = np.sqrt(8.0) * np.abs(np.asarray(distance, dtype=np.float64)) / float(length)
    with np.errstate(invalid="ignore"):
        out = r * special.kv(1, r)
    return np.where(r > 0, out, 1.0)


def matern_field(north, east, std: float, length: float, *, rng: np.random.Generator) -> np.ndarray:
    """A zero-mean Gaussian random field with the Matérn (nu = 1) covariance of range ``length``
    and std ``std`` on the regular grid ``north (ny,) x east (nx,)``: white noise filtered in
    the Fourier domain by the square root of the spectral density ``(k^2 + |w|^2)^-2``, on a grid
    padded by two ranges so the periodic wrap does not correlate opposite edges.

    Examples
    --------
    >>> axis = np.arange(0.0, 1000.0, 5.0)
    >>> f = matern_field(axis, axis, 0.3, 50.0, rng=np.random.default_rng(0))
    >>> f.shape, bool(0.2 < f.std() < 0.4)
    ((200, 200), True)
    """
    north = np.asarray(north, dtype=np.float64)
    east = np.asarray(east, dtype=np.float64)
    if not (np.isfinite(std) and std >= 0 and np.isfinite(length) and length > 0):
        raise TangraphError(f"matern_field: std must be >= 0 and length > 0, got {std!r}, {length!r}")
    dn = float(north[1] - north[0]) if north.size > 1 else 1.0
    de = float(east[1] - east[0]) if east.size > 1 else 1.0
    pad_n, pad_e = int(np.ceil(2 * length / dn)), int(np.ceil(2 * length / de))
    shape = (north.size + 2 * pad_n, east.size + 2 * pad_e)
    noise = rng.standard_normal(shape)
    kappa = np.sqrt(8.0) / length
    wn = 2 * np.pi * np.fft.fftfreq(shape[0], dn)[:, None]
    we = 2 * np.pi * np.fft.rfftfreq(shape[1], de)[None, :]
    amplitude = 1.0 / (kappa**2 + wn**2 + we**2)  # sqrt of the spectral density
    field = np.fft.irfft2(np.fft.rfft2(noise) * amplitude, s=shape)
    # normalise to the stationary variance: the filter's variance per unit white noise
    variance = np.sum(amplitude**2 * np.where(we == 0, 1.0, 2.0)) / (shape[0] * shape[1])
    variance -= np.sum(amplitude[:, -1] ** 2) / (shape[0] * shape[1]) if shape[1] % 2 == 0 else 0.0
    field = field[pad_n : pad_n + north.size, pad_e : pad_e + east.size] / np.sqrt(variance)
    return std * field


def _weighted_correlation_sums(north, east, weight, length: float) -> np.ndarray:
    """``sum_j w_j rho(|p_b - p_j|)`` for every point ``b`` and non-negative weights
    (:func:`_correlation_sums`), never below the point's own term."""
    return np.maximum(_correlation_sums(north, east, weight, length), weight)


def _correlation_sums(north, east, weight, length: float) -> np.ndarray:
    """``sum_j w_j rho(|p_b - p_j|)`` for every point ``b`` (weights ``(N,)`` or ``(N, k)``, of
    any sign), on a grid: the weights splatted bilinearly onto cells of a sixth of the range,
    convolved (FFT) with the Matérn correlation sampled on the cells out to four ranges, and
    read back bilinearly; each point's own term is then made exact (``rho(0) = 1``)."""
    from scipy.signal import fftconvolve

    weight = np.asarray(weight, dtype=np.float64)
    grid = _Splat(north, east, length)
    density = grid.density(weight.reshape(weight.shape[0], -1))
    kernel = _matern_kernel(float(length), grid.cell, grid.half)
    smooth = fftconvolve(density, kernel[:, :, None], mode="same", axes=(0, 1))
    sums = sum(beta[:, None] * smooth[grid.i + a, grid.j + b] for a, b, beta in grid.corners)
    return (sums - weight.reshape(sums.shape) * grid.self_term()[:, None]).reshape(weight.shape) + weight


class _Splat:
    """Points laid on the grid of :func:`_correlation_sums`: cells of a sixth of the range (at most
    ``_MAX_CELLS`` in all) with a margin of five ranges, each point's cell ``(i, j)`` and its
    bilinear shares in the cell's four corners."""

    def __init__(self, north, east, length: float) -> None:
        reach = 4.0 * length
        pad = reach + length
        n0, e0 = north.min() - pad, east.min() - pad
        span = max(north.max() - north.min(), east.max() - east.min()) + 2 * pad
        self.cell = cell = max(length / _CELLS_PER_LENGTH, span / np.sqrt(_MAX_CELLS))
        self.shape = (int((north.max() + pad - n0) / cell) + 2, int((east.max() + pad - e0) / cell) + 2)
        self.half = int(np.ceil(reach / cell))
        fy, fx = (north - n0) / cell, (east - e0) / cell
        self.i, self.j = np.floor(fy).astype(np.int64), np.floor(fx).astype(np.int64)
        ty, tx = fy - self.i, fx - self.j
        self.corners = [(0, 0, (1 - ty) * (1 - tx)), (0, 1, (1 - ty) * tx),
                        (1, 0, ty * (1 - tx)), (1, 1, ty * tx)]
        self.length = float(length)

    def density(self, columns: np.ndarray) -> np.ndarray:
        """The weights ``(N, k)`` splatted: a weighted count per cell and channel ``(ny, nx, k)``."""
        size = self.shape[0] * self.shape[1]
        density = np.zeros((size, columns.shape[1]))
        for a, b, beta in self.corners:
            flat = (self.i + a) * self.shape[1] + (self.j + b)
            for c in range(columns.shape[1]):
                density[:, c] += np.bincount(flat, weights=beta * columns[:, c], minlength=size)
        return density.reshape((*self.shape, columns.shape[1]))

    def self_term(self) -> np.ndarray:
        """Per point, its own weight's share of the gridded sum (``rho(0)`` as the grid sees it)."""
        kernel = _matern_kernel(self.length, self.cell, self.half)
        h = self.half
        near = (kernel[h, h], kernel[h, h + 1], kernel[h + 1, h + 1])  # offsets 0, 1, diagonal
        out = np.zeros(self.i.shape)
        for a, b, beta in self.corners:
            for c, d, gamma in self.corners:
                out += beta * gamma * near[abs(a - c) + abs(b - d)]
        return out


def _correlation_quadratic(north, east, weight: np.ndarray, length: float) -> np.ndarray:
    """``sum_(b != j) w_b w_j^T rho(|p_b - p_j|)`` ``(k, k)`` for weights ``(N, k)``: the quadratic
    form of :func:`_correlation_sums` (``w^T (sums - w)``) without reading the sums back, by
    Parseval on the splatted weights' spectra and the kernel's (circular convolution on a grid
    whose margin is wider than the kernel, so nothing wraps)."""
    from scipy import fft

    grid = _Splat(north, east, length)
    shape = tuple(fft.next_fast_len(n, real=True) for n in grid.shape)
    spectra = fft.rfft2(grid.density(weight), s=shape, axes=(0, 1))
    kernel = _kernel_spectrum(grid.length, grid.cell, grid.half, shape)
    counted = np.full(spectra.shape[1], 2.0)  # the half spectrum: the other half's conjugates
    counted[0] = 1.0
    if shape[1] % 2 == 0:
        counted[-1] = 1.0
    weighted = spectra * (kernel * counted)[:, :, None]
    total = np.einsum("xyc,xyd->cd", spectra.conj(), weighted).real / (shape[0] * shape[1])
    return total - (weight * grid.self_term()[:, None]).T @ weight


@functools.lru_cache(maxsize=64)
def _kernel_spectrum(length: float, cell: float, half: int, shape: tuple[int, int]) -> np.ndarray:
    """The real spectrum (``rfft2``) of the Matérn kernel laid circularly on a grid of ``shape``."""
    from scipy import fft

    kernel = _matern_kernel(length, cell, half)
    laid = np.zeros(shape)
    rows, cols = np.arange(-half, half + 1) % shape[0], np.arange(-half, half + 1) % shape[1]
    laid[np.ix_(rows, cols)] = kernel
    spectrum = fft.rfft2(laid).real  # the kernel is even: its spectrum is real
    spectrum.setflags(write=False)
    return spectrum


@functools.lru_cache(maxsize=32)
def _matern_kernel(length: float, cell: float, half: int) -> np.ndarray:
    """The Matérn correlation sampled on ``(2 half + 1)^2`` cells of side ``cell`` (read-only)."""
    offsets = np.arange(-half, half + 1) * cell
    kernel = matern_correlation(np.hypot(offsets[:, None], offsets[None, :]), length)
    kernel.setflags(write=False)
    return kernel
