"""`Track`: what every estimator returns, and its files (CSV with latitude/longitude, and TUM).

Every filter and the factor graph return a :class:`Track`: poses with their covariances at the
survey's ping times. Writers never overwrite an existing file unless asked and write atomically.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any

import numpy as np

from tangraph.errors import TangraphError

__all__ = ["Track", "position_errors", "write_track_csv", "write_track_tum"]


@dataclasses.dataclass(frozen=True, eq=False)
class Track:
    """Estimated poses of a run.

    Parameters
    ----------
    time : ndarray (K,)
        Seconds from the survey start, strictly increasing.
    pose : ndarray (K, 3)
        ``(north, east, psi)`` in the map's local frame, metres and radians.
    covariance : ndarray (K, 3, 3), optional
        Covariance of each pose (north, east, psi); NaN where the estimator does not know it.
        Default: all NaN.
    method : str
        Which estimator made the track (``"pf"``, ``"isam2"``, ...).
    timings : dict
        Run-time figures (seconds), e.g. ``{"total": 1.2, "per_step_p99": 0.004}``.
    meta : dict
        Anything else worth keeping (counts of rejected fixes, divergences, seeds).
    """

    time: np.ndarray
    pose: np.ndarray
    covariance: np.ndarray | None = None
    method: str = "unknown"
    timings: dict[str, float] = dataclasses.field(default_factory=dict)
    meta: dict[str, Any] = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        time = np.array(self.time, dtype=np.float64)
        pose = np.array(self.pose, dtype=np.float64)
        k = time.size
        if time.ndim != 1 or k < 1:
            raise TangraphError(
                f"track {self.method!r}: time must be 1-D and not empty, got shape {time.shape}"
            )
        if not np.all(np.isfinite(time)) or np.any(np.diff(time) <= 0):
            raise TangraphError(f"track {self.method!r}: time must be finite and strictly increasing")
        if pose.shape != (k, 3):
            raise TangraphError(f"track {self.method!r}: pose has shape {pose.shape}, expected ({k}, 3)")
        cov = (
            np.full((k, 3, 3), np.nan)
            if self.covariance is None
            else np.array(self.covariance, dtype=np.float64)
        )
        if cov.shape != (k, 3, 3):
            raise TangraphError(
                f"track {self.method!r}: covariance has shape {cov.shape}, expected ({k}, 3, 3)"
            )
        for a in (time, pose, cov):
            a.setflags(write=False)
        object.__setattr__(self, "time", time)
        object.__setattr__(self, "pose", pose)
        object.__setattr__(self, "covariance", cov)
        object.__setattr__(self, "timings", dict(self.timings))
        object.__setattr__(self, "meta", dict(self.meta))

    @property
    def n_poses(self) -> int:
        return int(self.time.size)


def position_errors(track: Track, true_pose: np.ndarray) -> np.ndarray:
    """Horizontal error (m) of each pose against the truth at the same times, shape (K,)."""
    true_pose = np.asarray(true_pose, float)
    if true_pose.shape != track.pose.shape:
        raise TangraphError(f"truth has shape {true_pose.shape}, the track {track.pose.shape}")
    return np.hypot(*(track.pose[:, :2] - true_pose[:, :2]).T)


def _columns(track: Track, crs: str | None, origin, reference=None) -> tuple[list[str], np.ndarray]:
    names = ["time", "north", "east", "heading_deg", "var_north", "cov_north_east", "var_east", "var_heading"]
    c = track.covariance
    columns = [
        track.time,
        track.pose[:, 0],
        track.pose[:, 1],
        np.degrees(np.mod(track.pose[:, 2], 2 * np.pi)),
        c[:, 0, 0],
        c[:, 0, 1],
        c[:, 1, 1],
        c[:, 2, 2],
    ]
    if crs is not None:
        import pyproj

        t = pyproj.Transformer.from_crs(crs, "EPSG:4326", always_xy=True)
        lon, lat = t.transform(track.pose[:, 1] + origin[1], track.pose[:, 0] + origin[0])
        names[1:1] = ["lat", "lon"]
        columns[1:1] = [lat, lon]
    if reference is not None:
        reference = np.asarray(reference, float)
        if reference.shape[0] != track.n_poses or reference.ndim != 2 or reference.shape[1] < 2:
            raise TangraphError(
                f"reference track has shape {reference.shape}, the track {track.n_poses} poses"
            )
        names += ["ref_north", "ref_east"]
        columns += [reference[:, 0], reference[:, 1]]
    return names, np.column_stack(columns)


def write_track_csv(
    track: Track,
    path: str | os.PathLike,
    *,
    crs: str | None = None,
    origin=(0.0, 0.0),
    reference: np.ndarray | None = None,
    overwrite: bool = False,
) -> Path:
    """CSV with time, latitude/longitude (when ``crs`` is given: the map's), north, east, heading
    (degrees clockwise from north), the covariance terms and, given the survey's ``reference``
    track (K, 2 or 3: GPS or the truth, in the frame of ``north``, ``east``), ``ref_north`` and
    ``ref_east``."""
    from tangraph.maps.io import write_atomically

    names, data = _columns(track, crs, origin, reference)
    header = ",".join(names)
    p = Path(path)
    write_atomically(
        p,
        overwrite,
        lambda tmp: np.savetxt(tmp, data, delimiter=",", header=header, comments="", fmt="%.10g"),
    )
    return p


def write_track_tum(track: Track, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """TUM trajectory format (``time x y z qx qy qz qw``), readable by evo and other tools.

    The local NED pose maps to x = north, y = east, z = 0 (depth is not estimated here) and the
    heading to a rotation about the down axis (quaternion ``(0, 0, sin(psi/2), cos(psi/2))``).
    """
    from tangraph.maps.io import write_atomically

    half = track.pose[:, 2] / 2
    zeros = np.zeros(track.n_poses)
    data = np.column_stack(
        [track.time, track.pose[:, 0], track.pose[:, 1], zeros, zeros, zeros, np.sin(half), np.cos(half)]
    )
    p = Path(path)
    write_atomically(p, overwrite, lambda tmp: np.savetxt(tmp, data, fmt="%.9f"))
    return p
