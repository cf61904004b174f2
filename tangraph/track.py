"""`Track`: what every estimator returns, and its files (CSV with latitude/longitude, TUM,
GeoJSON and GeoPackage).

Every filter and the factor graph return a :class:`Track`: poses with their covariances at the
survey's ping times. Writers never overwrite an existing file unless asked and write atomically.
"""

from __future__ import annotations

import dataclasses
import os
import struct
from pathlib import Path
from typing import Any, Literal

import numpy as np

from tangraph.errors import TangraphError
from tangraph.fix_records import FixRecord

__all__ = [
    "Track",
    "error_ellipse",
    "position_errors",
    "utc_times",
    "write_track_csv",
    "write_track_geojson",
    "write_track_gpkg",
    "write_track_tum",
]


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
    fixes : tuple of FixRecord, optional
        What became of every position fix the estimator tried (the graph, TERCOM-PF, MLE and
        the particle filters that take fixes), one record per ping it refers to; None for an
        estimator that takes none.
    """

    time: np.ndarray
    pose: np.ndarray
    covariance: np.ndarray | None = None
    method: str = "unknown"
    timings: dict[str, float] = dataclasses.field(default_factory=dict)
    meta: dict[str, Any] = dataclasses.field(default_factory=dict)
    fixes: tuple[FixRecord, ...] | None = None

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
        if self.fixes is not None:
            fixes = tuple(self.fixes)
            wrong = next((f for f in fixes if not isinstance(f, FixRecord)), None)
            if wrong is not None:
                raise TangraphError(f"track {self.method!r}: fixes must be FixRecords, "
                                    f"got {type(wrong).__name__}")
            object.__setattr__(self, "fixes", fixes)

    @property
    def n_poses(self) -> int:
        return int(self.time.size)

    @property
    def lost(self) -> np.ndarray:
        """``(K,)`` bool: the poses the estimator flagged as lost (``meta["lost_steps"]``: it
        knew its position was not what the map said, so the pose is not to be trusted whatever
        its covariance)."""
        flags = np.zeros(self.n_poses, bool)
        steps = np.asarray(self.meta.get("lost_steps", []), np.int64)
        flags[steps[(steps >= 0) & (steps < self.n_poses)]] = True
        return flags


def position_errors(track: Track, true_pose: np.ndarray) -> np.ndarray:
    """Horizontal error (m) of each pose against the truth at the same times, shape (K,)."""
    true_pose = np.asarray(true_pose, float)
    if true_pose.shape != track.pose.shape:
        raise TangraphError(f"truth has shape {true_pose.shape}, the track {track.pose.shape}")
    return np.hypot(*(track.pose[:, :2] - true_pose[:, :2]).T)


def _lonlat(track: Track, crs: str, origin: Any) -> tuple[np.ndarray, np.ndarray]:
    """WGS84 longitude, latitude (degrees) of the track's poses in the map frame (``crs``, ``origin``)."""
    import pyproj

    t = pyproj.Transformer.from_crs(crs, "EPSG:4326", always_xy=True)
    lon, lat = t.transform(track.pose[:, 1] + origin[1], track.pose[:, 0] + origin[0])
    return np.asarray(lon, float), np.asarray(lat, float)


def utc_times(time: np.ndarray, start_time: str) -> list[str]:
    """ISO 8601 UTC stamps (microseconds, ``Z``) of ``time`` seconds after ``start_time``.

    ``start_time`` is an ISO 8601 string (a survey's ``meta["start_time"]``); without a zone it
    is taken as UTC.

    Examples
    --------
    >>> utc_times(np.array([0.0, 1.25]), "2024-05-01T10:00:00Z")
    ['2024-05-01T10:00:00.000000Z', '2024-05-01T10:00:01.250000Z']
    """
    import datetime as dt

    try:
        start = dt.datetime.fromisoformat(str(start_time).strip())
    except ValueError:
        raise TangraphError(f"start time {start_time!r} is not ISO 8601") from None
    if start.tzinfo is not None:
        start = start.astimezone(dt.UTC).replace(tzinfo=None)
    us = np.datetime64(start, "us") + np.round(np.asarray(time, float) * 1e6).astype("timedelta64[us]")
    return [s + "Z" for s in np.datetime_as_string(us, unit="us")]


def _reference(track: Track, reference: Any) -> np.ndarray | None:
    if reference is None:
        return None
    reference = np.asarray(reference, float)
    if reference.ndim != 2 or reference.shape[0] != track.n_poses or reference.shape[1] < 2:
        raise TangraphError(f"reference track has shape {reference.shape}, the track {track.n_poses} poses")
    return reference


def _columns(track: Track, crs: str | None, origin: Any,
             reference: Any = None) -> tuple[list[str], np.ndarray]:
    names = ["time", "north", "east", "heading_deg", "var_north", "cov_north_east", "var_east", "var_heading"]
    c = track.covariance
    assert c is not None  # __post_init__ fills it
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
    if "lost_steps" in track.meta:  # the estimator says which poses not to trust
        names.append("lost")
        columns.append(track.lost.astype(float))
    if crs is not None:
        lon, lat = _lonlat(track, crs, origin)
        names[1:1] = ["lat", "lon"]
        columns[1:1] = [lat, lon]
    reference = _reference(track, reference)
    if reference is not None:
        names += ["ref_north", "ref_east"]
        columns += [reference[:, 0], reference[:, 1]]
    return names, np.column_stack(columns)


# Formats by column: times to the microsecond, lat/lon to 1e-9 deg (0.1 mm), the rest 10 digits.
_CSV_FORMAT = {"time": "%.6f", "lat": "%.9f", "lon": "%.9f"}


def write_track_csv(
    track: Track,
    path: str | os.PathLike,
    *,
    crs: str | None = None,
    origin: Any = (0.0, 0.0),
    reference: np.ndarray | None = None,
    start_time: str | None = None,
    overwrite: bool = False,
) -> Path:
    """CSV with time, latitude/longitude (when ``crs`` is given: the map's), north, east, heading
    (degrees clockwise from grid north), the covariance terms, ``lost`` (1 where the estimator
    flagged the pose as lost: ``Track.lost``; when it records them) and, given the survey's ``reference``
    track (K, 2 or 3: GPS or the truth, in the frame of ``north``, ``east``), ``ref_north`` and
    ``ref_east``.

    ``time`` (seconds from the survey start) is written to the microsecond; given the survey's
    ``start_time`` (ISO 8601, ``meta["start_time"]``) a ``utc`` column follows it with each pose's
    absolute UTC time (ISO 8601, microseconds, ``Z``).
    """
    from tangraph.outputs import write_atomically

    names, data = _columns(track, crs, origin, reference)
    text = [[_CSV_FORMAT.get(name, "%.10g") % v for v in data[:, j]] for j, name in enumerate(names)]
    if start_time is not None:
        names.insert(1, "utc")
        text.insert(1, utc_times(track.time, start_time))
    lines = [",".join(names)] + [",".join(row) for row in zip(*text, strict=True)]
    p = Path(path)
    write_atomically(p, overwrite, lambda tmp: tmp.write_text("\n".join(lines) + "\n"))
    return p


# -- GIS: GeoJSON and GeoPackage ---------------------------------------------------------------
_CHI2_2DOF_95 = -2.0 * np.log(0.05)  # 95 % quantile of chi-square with 2 degrees of freedom


def error_ellipse(covariance: np.ndarray, *, chi2: float = _CHI2_2DOF_95) -> tuple[np.ndarray, ...]:
    """Semi-axes (m) and orientation of the confidence ellipses of (north, east) covariances.

    Parameters
    ----------
    covariance : ndarray (..., 2, 2) or (..., 3, 3)
        Covariances whose top-left 2 x 2 block is (north, east).
    chi2 : float
        Squared Mahalanobis radius; default the 95 % quantile of chi-square(2), 5.991.

    Returns
    -------
    major, minor, azimuth_deg : ndarray (...)
        Semi-major and semi-minor axes, and the major axis' direction in degrees clockwise from
        grid north in [0, 180). NaN where the covariance is unknown.

    Examples
    --------
    >>> major, minor, azimuth = error_ellipse(np.diag([4.0, 1.0]), chi2=1.0)
    >>> float(major), float(minor), float(azimuth)
    (2.0, 1.0, 0.0)
    """
    c = np.asarray(covariance, float)
    a, b, d = c[..., 0, 0], c[..., 0, 1], c[..., 1, 1]
    mean, radius = 0.5 * (a + d), np.hypot(0.5 * (a - d), b)
    major = np.sqrt(chi2 * (mean + radius))
    minor = np.sqrt(chi2 * np.maximum(mean - radius, 0.0))
    azimuth = np.mod(np.degrees(0.5 * np.arctan2(2 * b, a - d)), 180.0)
    return major, minor, azimuth


def _pose_properties(track: Track, reference: Any, start_time: str | None) -> dict[str, np.ndarray]:
    """Per-pose attribute columns of the GIS files (float64, NaN where unknown; ``utc`` strings)."""
    c = track.covariance
    assert c is not None  # __post_init__ fills it
    major, minor, azimuth = error_ellipse(c)
    numbers = {
        "time": track.time,
        "north": track.pose[:, 0],
        "east": track.pose[:, 1],
        "heading_deg": np.degrees(np.mod(track.pose[:, 2], 2 * np.pi)),
        "var_north": c[:, 0, 0],
        "cov_north_east": c[:, 0, 1],
        "var_east": c[:, 1, 1],
        "var_heading": c[:, 2, 2],
        "ellipse95_major": major,
        "ellipse95_minor": minor,
        "ellipse95_azimuth_deg": azimuth,
    }
    if "lost_steps" in track.meta:
        numbers["lost"] = track.lost.astype(float)
    reference = _reference(track, reference)
    if reference is not None:
        numbers["ref_north"], numbers["ref_east"] = reference[:, 0], reference[:, 1]
    if start_time is None:
        return numbers
    utc = np.array(utc_times(track.time, start_time), dtype=object)
    return {"time": numbers.pop("time"), "utc": utc, **numbers}


def _placed(track: Track, crs: str | None, origin: Any, what: str) -> tuple[np.ndarray, np.ndarray]:
    if crs is None:
        raise TangraphError(
            f"track {track.method!r}: {what} needs the map's CRS to place the track on the Earth; "
            "a track in a local frame (no CRS) cannot be written as latitude/longitude"
        )
    return _lonlat(track, crs, origin)


def _track_properties(track: Track, crs: str | None, start_time: str | None) -> dict[str, Any]:
    props: dict[str, Any] = {"method": track.method, "n_poses": track.n_poses, "map_crs": str(crs),
                             "duration": float(track.time[-1] - track.time[0])}
    if start_time is not None:
        first, last = utc_times(track.time[[0, -1]], start_time)
        props.update(start_utc=first, end_utc=last)
    return props


def write_track_geojson(
    track: Track,
    path: str | os.PathLike,
    *,
    crs: str | None,
    origin: Any = (0.0, 0.0),
    reference: np.ndarray | None = None,
    start_time: str | None = None,
    overwrite: bool = False,
) -> Path:
    """GeoJSON (RFC 7946: WGS84 ``[longitude, latitude]``) of the track, for GIS tools.

    A FeatureCollection: first the track as one LineString (properties ``method``, ``n_poses``,
    ``map_crs``, ``duration`` s and, given ``start_time``, ``start_utc``/``end_utc``; left out for
    a single pose), then one Point per pose with the properties ``time`` (s from the survey
    start), ``utc`` (ISO 8601, given the survey's ``start_time``), ``north``, ``east`` (m, map
    frame), ``heading_deg`` (clockwise from grid north), ``var_north``, ``cov_north_east``,
    ``var_east`` (m²), ``var_heading`` (rad²), the 95 % error ellipse ``ellipse95_major``,
    ``ellipse95_minor`` (m) and ``ellipse95_azimuth_deg`` (major axis, clockwise from grid
    north) and, given ``reference``, ``ref_north``, ``ref_east``. Unknown values are ``null``.

    ``crs`` and ``origin`` are the map's; a track without a CRS cannot be placed and is refused.
    """
    import json

    from tangraph.outputs import write_atomically

    lon, lat = _placed(track, crs, origin, "GeoJSON")
    props = {
        name: [v if isinstance(v, str) else float(v) if np.isfinite(v) else None for v in values]
        for name, values in _pose_properties(track, reference, start_time).items()
    }
    names = list(props)
    features = []
    if track.n_poses >= 2:
        features.append({
            "type": "Feature",
            "geometry": {"type": "LineString", "coordinates": np.column_stack([lon, lat]).tolist()},
            "properties": _track_properties(track, crs, start_time),
        })
    for k in range(track.n_poses):
        features.append({
            "type": "Feature",
            "geometry": {"type": "Point", "coordinates": [float(lon[k]), float(lat[k])]},
            "properties": {name: props[name][k] for name in names},
        })
    collection = {
        "type": "FeatureCollection",
        "bbox": [float(lon.min()), float(lat.min()), float(lon.max()), float(lat.max())],
        "features": features,
    }
    text = json.dumps(collection, allow_nan=False)
    p = Path(path)
    write_atomically(p, overwrite, lambda tmp: tmp.write_text(text + "\n", encoding="utf-8"))
    return p


def _wkb_point(x: float, y: float) -> bytes:
    return struct.pack("<BIdd", 1, 1, x, y)


def _wkb_linestring(x: np.ndarray, y: np.ndarray) -> bytes:
    return struct.pack("<BII", 1, 2, x.size) + np.column_stack([x, y]).astype("<f8").tobytes()


def write_track_gpkg(
    track: Track,
    path: str | os.PathLike,
    *,
    crs: str | None,
    origin: Any = (0.0, 0.0),
    reference: np.ndarray | None = None,
    start_time: str | None = None,
    overwrite: bool = False,
) -> Path:
    """GeoPackage (EPSG:4326) of the track: layer ``track`` (one LineString, left out for a single
    pose) and layer ``poses`` (a Point per pose), with the attributes of
    :func:`write_track_geojson`. Needs ``pyogrio`` (GDAL); unknown values are NULL."""
    try:
        import pyogrio.raw
    except ImportError:
        raise TangraphError("writing GeoPackage needs pyogrio (pip install pyogrio)") from None
    from tangraph.outputs import write_atomically

    lon, lat = _placed(track, crs, origin, "GeoPackage")
    props = _pose_properties(track, reference, start_time)
    points = np.array([_wkb_point(x, y) for x, y in zip(lon, lat, strict=True)], dtype=object)
    line = _track_properties(track, crs, start_time)

    def write(tmp: Path) -> None:
        tmp.unlink()  # GDAL creates the file; it cannot open an empty one
        common = {"driver": "GPKG", "crs": "EPSG:4326"}
        if track.n_poses >= 2:
            pyogrio.raw.write(
                tmp, np.array([_wkb_linestring(lon, lat)], dtype=object),
                [np.array([v], dtype=object if isinstance(v, str) else None) for v in line.values()],
                list(line), layer="track", geometry_type="LineString", **common,
            )
        pyogrio.raw.write(
            tmp, points, list(props.values()), list(props), layer="poses", geometry_type="Point",
            **common,
        )

    p = Path(path)
    write_atomically(p, overwrite, write)
    return p


TumFrame = Literal["ned", "enu"]


def write_track_tum(
    track: Track, path: str | os.PathLike, *, frame: TumFrame = "ned", overwrite: bool = False
) -> Path:
    """TUM trajectory format (``time x y z qx qy qz qw``), readable by evo and other tools.

    The quaternion is Hamilton, scalar last (TUM's order), and rotates body vectors into the
    written frame; depth is not estimated here, so z = 0 and the rotation is the heading alone.

    ``frame="ned"`` (default): x = north, y = east, z = down; body axes forward, starboard, down;
    the heading ``psi`` (clockwise from north) is a rotation about z (down):
    ``q = (0, 0, sin(psi/2), cos(psi/2))``.

    ``frame="enu"``: x = east, y = north, z = up (ROS REP 103); body axes forward, left, up; the
    yaw ``pi/2 - psi`` (counter-clockwise from east) is a rotation about z (up):
    ``q = (0, 0, sin(yaw/2), cos(yaw/2))``. evo's top views then show north up, east right.
    """
    from tangraph.outputs import write_atomically

    if frame not in ("ned", "enu"):
        raise TangraphError(f"TUM frame must be 'ned' or 'enu', got {frame!r}")
    north, east, psi = track.pose.T
    x, y, angle = (north, east, psi) if frame == "ned" else (east, north, np.pi / 2 - psi)
    half = angle / 2
    zeros = np.zeros(track.n_poses)
    data = np.column_stack([track.time, x, y, zeros, zeros, zeros, np.sin(half), np.cos(half)])
    p = Path(path)
    write_atomically(p, overwrite, lambda tmp: np.savetxt(tmp, data, fmt="%.9f"))
    return p
