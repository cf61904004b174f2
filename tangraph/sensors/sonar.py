"""Multibeam and single-beam echo sounders: beam geometry, ray-cast soundings and their errors.

Frames: the map is NED ``(north, east, down)``; the body frame is x forward, y starboard,
z down, with roll ``phi`` (starboard down positive) and pitch ``theta`` (nose up positive) as
``R = Rz(psi) Ry(theta) Rx(phi)``. Soundings are reported in the *levelled* vehicle frame:
``beam_forward`` and ``beam_starboard`` are horizontal offsets of the footprint along and across
the heading (turned by the heading alone), ``beam_depth`` the seafloor depth below the sea
surface. Use :func:`tangraph.survey.footprints` to place them on the map with a pose.

Tide: the sea surface lies ``tide`` metres above the map's vertical datum, so a measured depth
is ``true (map) depth + tide``. The vehicle depth (pressure) is below the sea surface, so the
sonar sits at map depth ``vehicle_depth - tide``. Wang et al.'s tide estimate
``t = mean(map - measured)`` is therefore ``-tide``.
"""

from __future__ import annotations

import dataclasses
from typing import cast

import numpy as np

from tangraph.errors import TangraphError
from tangraph.geometry import rotate
from tangraph.maps.mesh import TerrainScene, cast_rays
from tangraph.validation import check_number

__all__ = [
    "MultibeamConfig",
    "Pings",
    "SingleBeamConfig",
    "beam_angles",
    "simulate_pings",
]


@dataclasses.dataclass(frozen=True)
class MultibeamConfig:
    """A multibeam echo sounder.

    Parameters
    ----------
    n_beams : int
        Beams per ping (>= 2), fanned across-track at ``linspace(-swath/2, swath/2, n_beams)``
        from the vertical, positive to starboard.
    swath : float
        Full swath angle, rad, in ``(0, pi)``.
    ping_rate : float
        Pings per second (used by the simulators that pick ping times).
    range_noise : float
        Std of the slant-range error as a fraction of the range (0.002: 0.2 %).
    depth_noise : float
        Std of an extra depth error, m, independent of the range.
    outlier_rate, outlier_std : float
        Fraction of returns with a gross error, and its std (m, added to the depth).
    missing_rate : float
        Fraction of beams that return nothing at random.
    max_range : float
        Slant ranges longer than this give no return, m (``inf``: no limit).
    tide : float
        Height of the sea surface above the map's datum, m: measured = true depth + tide.
    attitude_noise : float
        Std of an unmodelled roll and pitch error per ping, rad: the rays are cast with it,
        the soundings are reduced without it.
    tide_drift_std, tide_drift_time : float
        The tide's drift (m, s): the simulated survey's depths differ from the map's by ``tide``
        plus a Gauss-Markov offset of this std that forgets over this time
        (``NavigationModel.tide_drift_std``); 0: none.

    Examples
    --------
    >>> MultibeamConfig.han2020().n_beams
    60
    >>> MultibeamConfig(missing_rate=2.0)
    Traceback (most recent call last):
    ...
    tangraph.errors.TangraphError: MultibeamConfig.missing_rate must be <= 1, got 2.0
    """

    n_beams: int = 101
    swath: float = float(np.deg2rad(120.0))
    ping_rate: float = 1.0
    range_noise: float = 0.0
    depth_noise: float = 0.0
    outlier_rate: float = 0.0
    outlier_std: float = 0.0
    missing_rate: float = 0.0
    max_range: float = np.inf
    tide: float = 0.0
    attitude_noise: float = 0.0
    tide_drift_std: float = 0.0
    tide_drift_time: float = 0.0

    def __post_init__(self) -> None:
        n = self.n_beams
        if isinstance(n, bool) or not isinstance(n, int | np.integer) or n < 2:
            raise TangraphError(f"MultibeamConfig.n_beams must be an integer >= 2, got {self.n_beams!r}")
        object.__setattr__(self, "n_beams", int(self.n_beams))
        if check_number(self, "swath", open_low=True) >= np.pi:
            raise TangraphError(f"MultibeamConfig.swath must be < pi rad, got {self.swath!r}")
        check_number(self, "ping_rate", open_low=True)
        check_number(self, "max_range", open_low=True, allow_inf=True)
        check_number(self, "tide", low=None)
        for name in ("range_noise", "depth_noise", "outlier_std", "attitude_noise"):
            check_number(self, name)
        _check_drift(self)
        for name in ("outlier_rate", "missing_rate"):
            check_number(self, name, high=1.0)

    @classmethod
    def wang2019(cls) -> MultibeamConfig:
        """Wang et al. (2019): a ship multibeam in Jiaozhou Bay, read as 101 beams over 120 deg
        at 1 Hz, 0.2 % range noise and 0.2 m depth noise (their sounding std, Table 1:
        0.18-0.23 m), tide -2.55 m (their ``t = mean(map - measured)`` = 2.55 m)."""
        return cls(n_beams=101, swath=float(np.deg2rad(120.0)), ping_rate=1.0, range_noise=0.002,
                   depth_noise=0.2, tide=-2.55)

    @classmethod
    def han2020(cls) -> MultibeamConfig:
        """Han et al. (2020): 60 beams; swath 120 deg, 0.2 Hz (10 m between pings at 2 m/s) and
        0.5 m depth noise are choices, the paper only says "noise added"."""
        return cls(n_beams=60, swath=float(np.deg2rad(120.0)), ping_rate=0.2, depth_noise=0.5)


def _check_drift(config) -> None:
    """The tide's drift of a sonar config: both >= 0, its time > 0 where it has a std."""
    check_number(config, "tide_drift_std")
    check_number(config, "tide_drift_time")
    if config.tide_drift_std > 0 and not config.tide_drift_time > 0:
        raise TangraphError(f"{type(config).__name__}.tide_drift_time must be > 0 s with tide_drift_std = "
                            f"{config.tide_drift_std:g} m, got {config.tide_drift_time!r}")


@dataclasses.dataclass(frozen=True)
class SingleBeamConfig:
    """A single vertical beam (altimeter / echo sounder): ``ping_rate`` (Hz), ``depth_noise``
    (m std), ``tide`` (m, as in :class:`MultibeamConfig`), ``max_range`` (m), ``tide_drift_std``
    (m) and ``tide_drift_time`` (s, as in :class:`MultibeamConfig`).

    Examples
    --------
    >>> SingleBeamConfig.chen2022().depth_noise
    5.0
    """

    ping_rate: float = 1.0
    depth_noise: float = 0.0
    tide: float = 0.0
    max_range: float = np.inf
    tide_drift_std: float = 0.0
    tide_drift_time: float = 0.0

    def __post_init__(self) -> None:
        check_number(self, "ping_rate", open_low=True)
        check_number(self, "depth_noise")
        _check_drift(self)
        check_number(self, "tide", low=None)
        check_number(self, "max_range", open_low=True, allow_inf=True)

    @classmethod
    def chen2022(cls) -> SingleBeamConfig:
        """Chen & Che (2022), Table 1: depth variance 25 m^2 (std 5 m), one sounding per 100 s."""
        return cls(ping_rate=0.01, depth_noise=5.0)


SonarConfig = MultibeamConfig | SingleBeamConfig


def beam_angles(config: SonarConfig) -> np.ndarray:
    """Nominal across-track beam angles ``(B,)``, rad from the vertical, positive to starboard.

    >>> np.rad2deg(beam_angles(MultibeamConfig(n_beams=3, swath=np.pi / 2))).tolist()
    [-45.0, 0.0, 45.0]
    """
    if isinstance(config, SingleBeamConfig):
        return np.zeros(1)
    return np.linspace(-config.swath / 2, config.swath / 2, config.n_beams)


@dataclasses.dataclass(frozen=True, eq=False)
class Pings:
    """Soundings of K pings of B beams: ``beam_forward, beam_starboard`` (m, levelled vehicle
    frame) and ``beam_depth`` (m below the sea surface), each ``(K, B)`` and NaN where a beam
    has no return; ``n_off_map`` beams missed the map or exceeded ``max_range``,
    ``n_missing`` returns were dropped at random, ``n_outliers`` of the soundings are gross."""

    beam_forward: np.ndarray
    beam_starboard: np.ndarray
    beam_depth: np.ndarray
    n_missing: int = 0
    n_outliers: int = 0
    n_off_map: int = 0

    def __post_init__(self) -> None:
        arrays = [np.array(getattr(self, n), dtype=np.float64)
                  for n in ("beam_forward", "beam_starboard", "beam_depth")]
        if arrays[0].ndim != 2 or any(a.shape != arrays[0].shape for a in arrays):
            raise TangraphError(f"Pings: beam arrays must share one (K, B) shape, got "
                                f"{[a.shape for a in arrays]}")
        for name, a in zip(("beam_forward", "beam_starboard", "beam_depth"), arrays, strict=True):
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        for name in ("n_missing", "n_outliers", "n_off_map"):
            object.__setattr__(self, name, int(getattr(self, name)))


def _levelled(unit: np.ndarray, roll: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    """Body beam vectors ``unit (B, 3)`` turned by ``Ry(pitch) Rx(roll)`` per ping: ``(K, B, 3)``."""
    cr, sr = np.cos(roll)[:, None], np.sin(roll)[:, None]
    cp, sp = np.cos(pitch)[:, None], np.sin(pitch)[:, None]
    x, y, z = unit[:, 0], unit[:, 1] * cr - unit[:, 2] * sr, unit[:, 1] * sr + unit[:, 2] * cr
    return np.stack([cp * x + sp * z, np.broadcast_to(y, z.shape), -sp * x + cp * z], axis=-1)


def _check_ping_inputs(pose, vehicle_depth, roll, pitch):
    p = np.asarray(pose, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise TangraphError(f"pose must have shape (K, 3), got {p.shape}")
    out = [p]
    for name, a in (("vehicle_depth", vehicle_depth), ("roll", roll), ("pitch", pitch)):
        v = np.zeros(p.shape[0]) if a is None else np.asarray(a, dtype=np.float64)
        if v.shape != (p.shape[0],):
            raise TangraphError(f"{name} must have shape ({p.shape[0]},), got {v.shape}")
        out.append(v)
    if not all(np.all(np.isfinite(a)) for a in out):
        raise TangraphError("pose, vehicle_depth, roll and pitch must be finite")
    return out


def simulate_pings(scene: TerrainScene, pose, vehicle_depth, config: SonarConfig, *,
                   rng: np.random.Generator, roll=None, pitch=None) -> Pings:
    """Soundings of a sonar on a true track, by ray casting the seabed mesh.

    Parameters
    ----------
    scene : TerrainScene
        The seabed, from :func:`tangraph.maps.raycasting_scene` (the mesh is linear on each
        triangle, so the soundings differ slightly from the map's bilinear interpolant).
    pose : array_like, shape (K, 3)
        TRUE ``(north, east, psi)`` at each ping.
    vehicle_depth : array_like, shape (K,)
        Depth of the sonar below the sea surface, m (known exactly).
    config : MultibeamConfig or SingleBeamConfig
    rng : numpy.random.Generator
    roll, pitch : array_like, shape (K,), optional
        Known attitude, rad (default level). ``config.attitude_noise`` adds an error on top
        that the soundings do not know of.

    Returns
    -------
    Pings
        With measured range ``r`` and nominal beam direction ``u`` (levelled frame), a
        sounding is ``(r u_x, r u_y, vehicle_depth + r u_z + depth noise [+ outlier])``.

    Examples
    --------
    >>> import numpy as np
    >>> from tangraph.maps import BathymetryMap, raycasting_scene
    >>> flat = BathymetryMap(north=[-500.0, 500], east=[-500.0, 500], depth=np.full((2, 2), 60.0))
    >>> pings = simulate_pings(raycasting_scene(flat), [[0.0, 0.0, 0.0]], [10.0],
    ...                        MultibeamConfig(n_beams=3, swath=np.pi / 2),
    ...                        rng=np.random.default_rng(0))
    >>> pings.beam_starboard.round(6).tolist(), pings.beam_depth.round(6).tolist()
    ([[-50.0, 0.0, 50.0]], [[60.0, 60.0, 60.0]])
    """
    pose, depth0, roll, pitch = _check_ping_inputs(pose, vehicle_depth, roll, pitch)
    single = isinstance(config, SingleBeamConfig)
    multibeam = cast(MultibeamConfig, config)  # read only when not single
    angles = beam_angles(config)
    k, b = pose.shape[0], angles.size
    unit = np.column_stack([np.zeros(b), np.sin(angles), np.cos(angles)])
    sway = 0.0 if single else multibeam.attitude_noise
    nominal = _levelled(unit, roll, pitch)
    actual = _levelled(unit, roll + sway * rng.standard_normal(k), pitch + sway * rng.standard_normal(k))
    world = np.concatenate([rotate(pose[:, 2:3], actual[..., :2]), actual[..., 2:]], axis=-1)
    origin = np.column_stack([pose[:, :2], depth0 - config.tide])[:, None, :]
    true_range = cast_rays(scene, origin, world)  # one call for all pings and beams
    ret = np.isfinite(true_range) & (true_range <= config.max_range)

    range_noise = 0.0 if single else multibeam.range_noise
    r = np.where(ret, true_range, 0.0) * (1.0 + range_noise * rng.standard_normal((k, b)))
    depth = depth0[:, None] + r * nominal[..., 2] + config.depth_noise * rng.standard_normal((k, b))
    if single:
        outlier = missing = np.zeros((k, b), bool)
    else:
        outlier = rng.random((k, b)) < multibeam.outlier_rate
        missing = rng.random((k, b)) < multibeam.missing_rate
        depth = depth + np.where(outlier, multibeam.outlier_std * rng.standard_normal((k, b)), 0.0)
    keep = ret & ~missing
    return Pings(
        beam_forward=np.where(keep, r * nominal[..., 0], np.nan),
        beam_starboard=np.where(keep, r * nominal[..., 1], np.nan),
        beam_depth=np.where(keep, depth, np.nan),
        n_missing=int(np.sum(ret & missing)),
        n_outliers=int(np.sum(keep & outlier)),
        n_off_map=int(np.sum(~ret)),
    )
