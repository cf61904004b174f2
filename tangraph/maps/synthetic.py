"""Seeded synthetic seafloors: fractal, seamounts, ridges, flat with noise, and two test charts.

Every generator takes ``rng: numpy.random.Generator`` (keyword-only) and returns a
:class:`~tangraph.maps.BathymetryMap` with ``crs=None``, ``north`` and ``east`` starting at 0
and square cells of ``cell`` metres. Depth is positive down. The same generator state gives
the same map, bit for bit.

The random surfaces are spectral: white noise is Fourier-transformed, shaped by an amplitude
``A(|k|)`` (``k`` in cycles per metre) and transformed back, so they are periodic over the map
(the north edge continues into the south edge, the east edge into the west edge).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Literal

import numpy as np

from tangraph.errors import TangraphError
from tangraph.maps.grid import BathymetryMap
from tangraph.validation import number

__all__ = [
    "HAN2020_AREAS",
    "flat_with_noise",
    "fractal",
    "han2020_chart",
    "polar_chart",
    "ridges",
    "seamounts",
]

Shape = tuple[int, int]

#: The five matching areas of :func:`han2020_chart`, ``((north_lo, north_hi), (east_lo, east_hi))``
#: in metres, west to east along the path ``north = 2500``; their terrain entropy increases.
HAN2020_AREAS: tuple[tuple[tuple[float, float], tuple[float, float]], ...] = tuple(
    ((2300.0, 2700.0), (e - 200.0, e + 200.0)) for e in (500.0, 1500.0, 2500.0, 3500.0, 4500.0)
)


# -- shared pieces ---------------------------------------------------------------------------
def _positive(value: float | np.ndarray, name: str, where: str, *, allow_zero: bool = False) -> float:
    """``value`` as a float, or raise naming it if it is not finite and positive."""
    return number(value, f"{where}: {name}", open_low=not allow_zero)


def _axes(shape: Sequence[int], cell: float, where: str) -> tuple[np.ndarray, np.ndarray]:
    """Cell-centre coordinates ``north (ny,)``, ``east (nx,)`` from 0, after checking both."""
    cell = _positive(cell, "cell", where)
    if len(shape) != 2 or not all(isinstance(n, int | np.integer) and n >= 2 for n in shape):
        raise TangraphError(f"{where}: shape must be two integers >= 2, got {shape!r}")
    ny, nx = (int(n) for n in shape)
    return cell * np.arange(ny, dtype=np.float64), cell * np.arange(nx, dtype=np.float64)


def _spectral_field(
    shape: Shape,
    cell: float,
    rng: np.random.Generator,
    amplitude: Callable[[np.ndarray], np.ndarray],
) -> np.ndarray:
    """White noise shaped in the Fourier domain by ``amplitude(|k|)``; mean 0, std 1 exactly.

    ``k`` is in cycles per metre; the mean (``k = 0``) term is removed.
    """
    k = np.hypot(np.fft.fftfreq(shape[0], d=cell)[:, None], np.fft.rfftfreq(shape[1], d=cell))
    k[0, 0] = 1.0  # placeholder so that power laws stay finite; the term is zeroed below
    spectrum = np.fft.rfft2(rng.standard_normal(shape)) * amplitude(k)
    spectrum[0, 0] = 0.0
    field = np.fft.irfft2(spectrum, s=shape)
    return (field - field.mean()) / field.std()


def _power_law(beta: float) -> Callable[[np.ndarray], np.ndarray]:
    """Amplitude of a power spectrum ``P(k) ~ |k|^-beta``."""
    return lambda k: k ** (-0.5 * beta)


def _gaussian_smoothing(length: float) -> Callable[[np.ndarray], np.ndarray]:
    """Transfer function of a Gaussian filter of standard deviation ``length`` metres."""
    return lambda k: np.exp(-2.0 * (np.pi * k * length) ** 2)


def _bumps(
    north: np.ndarray, east: np.ndarray, centres: np.ndarray, heights: np.ndarray, radii: np.ndarray
) -> np.ndarray:
    """Sum of Gaussian bumps ``h exp(-r^2 / (2 R^2))`` on the grid (one pass per bump)."""
    total = np.zeros((north.size, east.size))
    for (cn, ce), h, r in zip(centres, heights, radii, strict=True):
        along_north = np.exp(-0.5 * ((north - cn) / r) ** 2)
        along_east = np.exp(-0.5 * ((east - ce) / r) ** 2)
        total += h * np.outer(along_north, along_east)
    return total


def _draw(value, count: int, rng: np.random.Generator, name: str, where: str) -> np.ndarray:
    """``count`` positive values: a number repeated, a tuple ``(lo, hi)`` drawn uniformly,
    or a list/array with one value per feature."""
    if isinstance(value, tuple):
        if len(value) != 2:
            raise TangraphError(
                f"{where}: {name} as a tuple must be a range (lo, hi), got {value!r}"
            )
        lo, hi = (_positive(v, name, where) for v in value)
        if hi < lo:
            raise TangraphError(f"{where}: {name} range must have lo <= hi, got {value!r}")
        return rng.uniform(lo, hi, size=count)
    values = np.asarray(value, dtype=np.float64)
    if values.ndim == 0:
        return np.full(count, _positive(values, name, where))
    if values.shape != (count,) or not np.all(np.isfinite(values) & (values > 0)):
        raise TangraphError(
            f"{where}: {name} must be a positive number, a range (lo, hi) or {count} positive "
            f"values, got {value!r}"
        )
    return values


# -- generators ------------------------------------------------------------------------------
def fractal(
    shape: Shape = (256, 256),
    cell: float = 10.0,
    *,
    rng: np.random.Generator,
    beta: float = 3.0,
    relief: float = 10.0,
    mean_depth: float = 100.0,
    name: str = "fractal",
) -> BathymetryMap:
    """A random surface with a power-law spectrum, ``P(k) ~ |k|^-beta``.

    Parameters
    ----------
    shape : (int, int)
        ``(ny, nx)``, each at least 2.
    cell : float
        Cell size in metres.
    rng : numpy.random.Generator
        Source of the white noise.
    beta : float
        Spectral exponent, >= 0. 0 is white noise; larger is smoother (more of the relief in long
        wavelengths). For ``2 < beta < 4`` the surface is fractional Brownian with fractal
        dimension ``(8 - beta) / 2``; 3 is a common fit to real seafloor.
    relief : float
        Standard deviation of the depth over the map, metres (met exactly).
    mean_depth : float
        Mean depth, metres (met exactly).
    name : str
        Name of the map.

    Returns
    -------
    BathymetryMap

    Examples
    --------
    >>> import numpy as np
    >>> m = fractal((64, 64), 5.0, rng=np.random.default_rng(1), relief=4.0, mean_depth=50.0)
    >>> m.shape, round(float(m.depth.std()), 6), round(float(m.depth.mean()), 6)
    ((64, 64), 4.0, 50.0)
    """
    where = "fractal"
    north, east = _axes(shape, cell, where)
    beta = _positive(beta, "beta", where, allow_zero=True)
    relief = _positive(relief, "relief", where, allow_zero=True)
    mean_depth = _positive(mean_depth, "mean_depth", where)
    field = _spectral_field((north.size, east.size), cell, rng, _power_law(beta))
    return BathymetryMap(north=north, east=east, depth=mean_depth + relief * field, name=name)


def seamounts(
    shape: Shape = (256, 256),
    cell: float = 10.0,
    *,
    rng: np.random.Generator,
    count: int = 5,
    height: float | tuple[float, float] | Sequence[float] = (50.0, 300.0),
    radius: float | tuple[float, float] | Sequence[float] = (100.0, 400.0),
    centres: np.ndarray | None = None,
    base_depth: float = 1000.0,
    name: str = "seamounts",
) -> BathymetryMap:
    """A flat seafloor at ``base_depth`` with Gaussian seamounts ``h exp(-r^2 / (2 R^2))``.

    Parameters
    ----------
    shape, cell, rng, name
        As in :func:`fractal`.
    count : int
        Number of seamounts (>= 0); ignored when ``centres`` is given.
    height, radius : float, tuple or sequence
        Height above the floor and radius ``R`` (standard deviation of the Gaussian), metres.
        A number is used for every seamount, a tuple ``(lo, hi)`` is a range to draw from
        uniformly, a list or array gives one value per seamount.
    centres : ndarray, shape (count, 2), optional
        ``(north, east)`` of each summit; drawn uniformly over the map if omitted.
    base_depth : float
        Depth of the flat floor, metres.

    Returns
    -------
    BathymetryMap
        Seamounts may overlap (their heights add); a summit above the sea surface gives a
        negative depth.

    Examples
    --------
    >>> import numpy as np
    >>> m = seamounts((50, 50), 10.0, rng=np.random.default_rng(0), centres=[[250.0, 250.0]],
    ...               height=[100.0], radius=[50.0], base_depth=500.0)
    >>> float(m.depth_at(250.0, 250.0))
    400.0
    """
    where = "seamounts"
    north, east = _axes(shape, cell, where)
    base_depth = _positive(base_depth, "base_depth", where)
    if centres is None:
        if not isinstance(count, int | np.integer) or count < 0:
            raise TangraphError(f"{where}: count must be a non-negative integer, got {count!r}")
        centres = np.column_stack(
            [rng.uniform(north[0], north[-1], count), rng.uniform(east[0], east[-1], count)]
        )
    centres = np.asarray(centres, dtype=np.float64)
    if centres.ndim != 2 or centres.shape[1] != 2 or not np.all(np.isfinite(centres)):
        raise TangraphError(
            f"{where}: centres must be finite (north, east) rows, got shape {centres.shape}"
        )
    count = centres.shape[0]
    heights = _draw(height, count, rng, "height", where)
    radii = _draw(radius, count, rng, "radius", where)
    depth = base_depth - _bumps(north, east, centres, heights, radii)
    return BathymetryMap(north=north, east=east, depth=depth, name=name)


def ridges(
    shape: Shape = (256, 256),
    cell: float = 10.0,
    *,
    rng: np.random.Generator,
    orientation: float = 0.0,
    spacing: float = 500.0,
    height: float = 50.0,
    profile: Literal["sine", "gaussian"] = "sine",
    width: float | None = None,
    base_depth: float = 1000.0,
    name: str = "ridges",
) -> BathymetryMap:
    """Parallel ridges whose crests run along ``orientation``, ``spacing`` metres apart.

    Parameters
    ----------
    shape, cell, rng, name
        As in :func:`fractal`; ``rng`` draws the across-ridge position of the crests.
    orientation : float
        Direction of the crests in degrees, clockwise from north (0: crests run north-south,
        depth varies with east only).
    spacing : float
        Distance between neighbouring crests, metres.
    height : float
        Height of a crest above the troughs, metres.
    profile : {"sine", "gaussian"}
        ``"sine"``: a raised cosine across the ridges; ``"gaussian"``: Gaussian crests of
        standard deviation ``width`` on a flat floor (each point feels its nearest crest).
    width : float, optional
        Width of the Gaussian crests, metres; default ``spacing / 6``. Not used by ``"sine"``.
    base_depth : float
        Depth of the troughs, metres.

    Returns
    -------
    BathymetryMap

    Examples
    --------
    >>> import numpy as np
    >>> m = ridges((40, 40), 10.0, rng=np.random.default_rng(0), orientation=0.0, height=20.0)
    >>> bool(np.all(m.depth == m.depth[0]))  # crests along north: every row is the same
    True
    """
    where = "ridges"
    north, east = _axes(shape, cell, where)
    spacing = _positive(spacing, "spacing", where)
    height = _positive(height, "height", where, allow_zero=True)
    if profile not in ("sine", "gaussian"):
        raise TangraphError(f"{where}: profile must be 'sine' or 'gaussian', got {profile!r}")
    width = spacing / 6.0 if width is None else _positive(width, "width", where)
    theta = np.deg2rad(float(orientation))
    # Across-ridge coordinate: distance along the normal (-sin, cos) of the crest direction.
    across = -np.sin(theta) * north[:, None] + np.cos(theta) * east[None, :]
    phase = (across - rng.uniform(0.0, spacing)) % spacing
    if profile == "sine":
        crest = 0.5 * (1.0 + np.cos(2.0 * np.pi * phase / spacing))
    else:
        nearest = np.minimum(phase, spacing - phase)
        crest = np.exp(-0.5 * (nearest / width) ** 2)
    return BathymetryMap(north=north, east=east, depth=base_depth - height * crest, name=name)


def flat_with_noise(
    shape: Shape = (256, 256),
    cell: float = 10.0,
    *,
    rng: np.random.Generator,
    depth: float = 100.0,
    gradient: tuple[float, float] = (0.0, 0.0),
    noise_std: float = 0.5,
    correlation_length: float = 0.0,
    name: str = "flat",
) -> BathymetryMap:
    """A flat (or uniformly sloped) seabed plus random noise.

    Parameters
    ----------
    shape, cell, rng, name
        As in :func:`fractal`.
    depth : float
        Depth at ``north = east = 0``, metres.
    gradient : (float, float)
        Slope of the plane, ``(d depth / d north, d depth / d east)`` in m/m.
    noise_std : float
        Standard deviation of the noise over the map, metres (met exactly; 0 for a plane).
    correlation_length : float
        0 for white noise, else the standard deviation (metres) of the Gaussian filter that
        smooths it.

    Returns
    -------
    BathymetryMap

    Examples
    --------
    >>> import numpy as np
    >>> m = flat_with_noise((32, 32), 2.0, rng=np.random.default_rng(0), noise_std=0.0,
    ...                     gradient=(0.1, 0.0))
    >>> round(float(m.depth[1, 0] - m.depth[0, 0]), 9)
    0.2
    """
    where = "flat_with_noise"
    north, east = _axes(shape, cell, where)
    depth = _positive(depth, "depth", where)
    noise_std = _positive(noise_std, "noise_std", where, allow_zero=True)
    length = _positive(correlation_length, "correlation_length", where, allow_zero=True)
    g_north, g_east = (float(g) for g in gradient)
    plane = depth + g_north * north[:, None] + g_east * east[None, :]
    noise = _spectral_field((north.size, east.size), cell, rng, _gaussian_smoothing(length))
    return BathymetryMap(north=north, east=east, depth=plane + noise_std * noise, name=name)


def han2020_chart(*, rng: np.random.Generator, name: str = "han2020") -> BathymetryMap:
    """A stand-in for the electronic-chart DTM of Han, Chen & Shen (2020).

    5 km x 5 km at 1000 x 1000 cells of 5 m. The depth is
    ``100 m + a(east) F + 0.05 m W``: ``F`` a fractal surface (``beta = 2.5``, unit std), ``W``
    white noise (the chart's quantisation), and the relief ``a`` falls geometrically from 30 m on
    the west edge to 0.03 m on the east edge. Travelling east along ``north = 2500`` the terrain
    goes from rugged to flat, so the five areas of :data:`HAN2020_AREAS` (400 m x 400 m, centred
    at east = 500, 1500, ..., 4500 m) have increasing terrain entropy (the literal definition,
    :func:`tangraph.maps.statistics.region_entropy` with ``relative=False``; each area's deficit
    ``ln N - H`` is typically ten times the next one's), as the paper's five matching areas
    (2.12 ... 4.09) do. The paper's values themselves are not reproduced: they depend on its
    chart and on how it normalised the entropy. The relative entropy does not follow the
    relief here: it ignores the scale of the relief, which is what changes along the path.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of both random surfaces.
    name : str
        Name of the map.

    Returns
    -------
    BathymetryMap

    Examples
    --------
    >>> import numpy as np
    >>> m = han2020_chart(rng=np.random.default_rng(0))
    >>> m.shape, m.cell_size
    ((1000, 1000), (5.0, 5.0))
    """
    shape, cell = (1000, 1000), 5.0
    north, east = _axes(shape, cell, "han2020_chart")
    relief = 30.0 * 0.001 ** (east / east[-1])
    rugged = _spectral_field(shape, cell, rng, _power_law(2.5))
    floor_noise = _spectral_field(shape, cell, rng, _gaussian_smoothing(0.0))
    depth = 100.0 + relief[None, :] * rugged + 0.05 * floor_noise
    return BathymetryMap(north=north, east=east, depth=depth, name=name)


def polar_chart(
    *,
    rng: np.random.Generator,
    size: float = 150_000.0,
    cell: float = 500.0,
    depth_range: tuple[float, float] = (300.0, 2000.0),
    flat_fraction: float = 0.4,
    n_seamounts: int = 4,
    name: str = "polar",
) -> BathymetryMap:
    """A coarse polar-like chart in the setting of Chen & Che (2022): sparse features, flat plains.

    A smooth large-scale surface (power law, ``beta = 4``) is mapped onto ``depth_range`` and
    its deepest ``flat_fraction`` of the area is levelled to the deepest depth (a sediment-filled
    abyssal plain, exactly flat). A few Gaussian seamounts (heights 300-1000 m, radii 2-5 km)
    rise from it; summits are cut at half the shallowest depth (flat-topped guyots). Depths are
    rounded to whole metres, as in a chart (so the seamounts' Gaussian tails end and the plain
    stays flat). The default 150 km x 150 km at 500 m cells (300 x 300) holds a 100 km
    trajectory.

    Parameters
    ----------
    rng : numpy.random.Generator
        Source of the surface and the seamounts.
    size : float
        Side of the square chart, metres.
    cell : float
        Cell size, metres.
    depth_range : (float, float)
        Shallowest and deepest depth of the background surface, metres.
    flat_fraction : float
        Fraction of the chart levelled to the plain, in [0, 1).
    n_seamounts : int
        Number of seamounts.
    name : str
        Name of the map.

    Returns
    -------
    BathymetryMap

    Examples
    --------
    >>> import numpy as np
    >>> m = polar_chart(rng=np.random.default_rng(0))
    >>> m.shape, m.cell_size, float(m.depth.max())
    ((300, 300), (500.0, 500.0), 2000.0)
    """
    where = "polar_chart"
    cell = _positive(cell, "cell", where)
    n = round(_positive(size, "size", where) / cell)
    north, east = _axes((n, n), cell, where)
    shallow, deep = (_positive(d, "depth_range", where) for d in depth_range)
    if not shallow < deep:
        raise TangraphError(f"{where}: depth_range must be (shallow, deep) with shallow < deep, "
                            f"got {depth_range!r}")
    if not 0.0 <= flat_fraction < 1.0:
        raise TangraphError(f"{where}: flat_fraction must be in [0, 1), got {flat_fraction!r}")
    field = _spectral_field((n, n), cell, rng, _power_law(4.0))
    plain_level = np.quantile(field, 1.0 - flat_fraction)
    scaled = (plain_level - np.minimum(field, plain_level)) / (plain_level - field.min())
    background = deep - (deep - shallow) * scaled
    mounts = seamounts(
        (n, n), cell, rng=rng, count=n_seamounts, height=(300.0, 1000.0),
        radius=(2000.0, 5000.0), base_depth=deep,
    )
    depth = np.round(np.maximum(background - (deep - mounts.depth), 0.5 * shallow))
    return BathymetryMap(north=north, east=east, depth=depth, name=name)
