"""`Survey`: one recorded or simulated run as arrays, and its files.

The NetCDF schema (version 2: CF-1.8 trajectories, written and read through xarray; version 1
is still read) is documented in ``docs/survey_schema.rst``; :func:`read_survey` validates
everything and names what is wrong.
Surveys recorded by other systems come in through :mod:`tangraph.formats` (a CSV navigation log
plus XYZ soundings, SonTek RiverSurveyor exports).
"""

from __future__ import annotations

import dataclasses
import datetime
import json
import logging
import os
from pathlib import Path
from typing import Any

import numpy as np

from tangraph.errors import TangraphError
from tangraph.geometry import body_to_world, world_to_body

_log = logging.getLogger(__name__)

__all__ = [
    "SCHEMA_VERSION",
    "Survey",
    "SurveyError",
    "footprints",
    "read_survey",
    "to_body",
    "write_survey",
]

SCHEMA_VERSION = 2


class SurveyError(TangraphError):
    """A survey (in memory or in a file) is not valid."""


def footprints(pose: np.ndarray, forward: np.ndarray, starboard: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World ``(north, east)`` of body-frame points ``(forward, starboard)`` seen from ``pose``.

    ``pose`` is (K, 3) ``(north, east, psi)``; ``forward``, ``starboard`` are (K, B).
    """
    pose = np.asarray(pose, float)
    body = np.stack(np.broadcast_arrays(np.asarray(forward, float), np.asarray(starboard, float)), axis=-1)
    world = body_to_world(pose[:, None, :], body)
    return world[..., 0].copy(), world[..., 1].copy()


def to_body(pose: np.ndarray, north: np.ndarray, east: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse of :func:`footprints`: body ``(forward, starboard)`` of world points."""
    world = np.stack(np.broadcast_arrays(np.asarray(north, float), np.asarray(east, float)), axis=-1)
    body = world_to_body(np.asarray(pose, float)[:, None, :], world)
    return body[..., 0].copy(), body[..., 1].copy()


@dataclasses.dataclass(frozen=True, eq=False)
class Survey:
    """One run of an AUV: poses, vehicle depth and the soundings of every ping.

    Parameters
    ----------
    time : ndarray (K,)
        Seconds from the survey start, strictly increasing.
    dr_pose : ndarray (K, 3)
        Dead-reckoned ``(north, east, psi)``, metres and radians (psi clockwise from north).
    vehicle_depth : ndarray (K,)
        Depth of the sonar below the surface, metres.
    beam_forward, beam_starboard : ndarray (K, B)
        Footprint of each beam in the vehicle's body frame, metres.
    beam_depth : ndarray (K, B)
        Measured depth of the seafloor at the footprint, metres positive down; NaN where the
        beam has no return.
    true_pose : ndarray (K, 3), optional
        The reference track: the truth of a simulated run, or the GPS track of a recorded one
        (``meta["reference"]`` says which). Estimators never see it; it scores them.
    attitude : ndarray (K, 2), optional
        Pitch and roll of the sonar, radians (pitch positive bow up, roll positive starboard
        down), where the recording has them; the footprints already account for them.
    meta : dict
        JSON-serialisable metadata: map name, sensor settings, seed, counts of what was
        dropped or missing, start time (ISO 8601) and the like.
    """

    time: np.ndarray
    dr_pose: np.ndarray
    vehicle_depth: np.ndarray
    beam_forward: np.ndarray
    beam_starboard: np.ndarray
    beam_depth: np.ndarray
    true_pose: np.ndarray | None = None
    attitude: np.ndarray | None = None
    meta: dict[str, Any] = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        def arr(name: str, ndim: int) -> np.ndarray:
            a = np.array(getattr(self, name), dtype=np.float64)
            if a.ndim != ndim:
                raise SurveyError(f"survey: {name} must be {ndim}-D, got shape {a.shape}")
            a.setflags(write=False)
            object.__setattr__(self, name, a)
            return a

        time = arr("time", 1)
        k = time.size
        if k < 1:
            raise SurveyError("survey: no pings (time is empty)")
        if not np.all(np.isfinite(time)):
            raise SurveyError(f"survey: time holds non-finite values at pings {_first(~np.isfinite(time))}")
        steps = np.diff(time)
        if np.any(steps <= 0):
            i = int(np.argmax(steps <= 0))
            raise SurveyError(
                f"survey: time is not increasing at ping {i + 1} "
                f"(time[{i}] = {time[i]!r}, time[{i + 1}] = {time[i + 1]!r})"
            )
        names = ["dr_pose", "vehicle_depth"] + [
            n for n in ("true_pose", "attitude") if getattr(self, n) is not None
        ]
        for name in names:
            a = arr(name, 1 if name == "vehicle_depth" else 2)
            expected = {"vehicle_depth": (k,), "attitude": (k, 2)}.get(name, (k, 3))
            if a.shape != expected:
                raise SurveyError(f"survey: {name} has shape {a.shape}, expected {expected} (K = {k} pings)")
            if not np.all(np.isfinite(a)):
                raise SurveyError(
                    f"survey: {name} holds non-finite values at pings "
                    f"{_first((~np.isfinite(a.reshape(k, -1))).any(axis=1))}"
                )
        beams = [arr(n, 2) for n in ("beam_forward", "beam_starboard", "beam_depth")]
        if any(b.shape != beams[2].shape or b.shape[0] != k for b in beams):
            raise SurveyError(
                "survey: beam_forward, beam_starboard, beam_depth must all be (K, B) with K = "
                f"{k}; got {[b.shape for b in beams]}"
            )
        has = np.isfinite(beams[2])
        if np.isinf(beams[2]).any():  # NaN is no return; an infinite depth is a broken value
            raise SurveyError(f"survey: beam_depth is infinite at pings {_first(np.isinf(beams[2]).any(1))}")
        if not np.all(np.isfinite(beams[0])[has] & np.isfinite(beams[1])[has]):
            raise SurveyError("survey: a beam with a depth has no finite footprint (forward/starboard NaN)")
        if not has.any():
            raise SurveyError("survey: no ping has any sounding (beam_depth is all NaN)")
        try:
            meta = json.loads(json.dumps(dict(self.meta)))
        except (TypeError, ValueError) as exc:
            raise SurveyError(f"survey: meta must be JSON-serialisable ({exc})") from None
        object.__setattr__(self, "meta", meta)

    @property
    def n_pings(self) -> int:
        return int(self.time.size)

    @property
    def n_beams(self) -> int:
        return int(self.beam_depth.shape[1])

    @property
    def n_soundings(self) -> int:
        """Beams with a return."""
        return int(np.isfinite(self.beam_depth).sum())

    @property
    def n_empty_pings(self) -> int:
        """Pings without any return (kept, so the timeline stays whole)."""
        return int((~np.isfinite(self.beam_depth).any(axis=1)).sum())

    def footprints(self, pose: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """World ``(north, east)`` (K, B) of every beam seen from ``pose`` (default: DR)."""
        return footprints(self.dr_pose if pose is None else pose, self.beam_forward, self.beam_starboard)

    def replace(self, **changes: Any) -> Survey:
        return dataclasses.replace(self, **changes)

    def pings(self, start: int, stop: int) -> Survey:
        """The pings ``start`` to ``stop - 1`` as a survey of their own (``meta`` says which).

        Raises
        ------
        SurveyError
            An empty range, or pings without any sounding.
        """
        start, stop = int(start), int(stop)
        if not 0 <= start < stop <= self.n_pings:
            raise SurveyError(f"survey: pings {start}..{stop - 1} are not inside 0..{self.n_pings - 1}")
        w = slice(start, stop)
        return Survey(
            time=self.time[w],
            dr_pose=self.dr_pose[w],
            vehicle_depth=self.vehicle_depth[w],
            beam_forward=self.beam_forward[w],
            beam_starboard=self.beam_starboard[w],
            beam_depth=self.beam_depth[w],
            true_pose=None if self.true_pose is None else self.true_pose[w],
            attitude=None if self.attitude is None else self.attitude[w],
            meta={**self.meta, "pings": [start, stop]},
        )

    def report(self) -> dict[str, Any]:
        """The survey's figures, as data (``tangraph survey info --json``)."""
        span = float(self.time[-1] - self.time[0])
        r: dict[str, Any] = {
            "pings": self.n_pings, "duration_s": span, "rate_hz": self.n_pings / max(span, 1e-9),
            "beams": self.n_beams, "soundings": self.n_soundings,
            "returned_fraction": self.n_soundings / self.beam_depth.size,
            "empty_pings": self.n_empty_pings,
            "dr_track_m": float(np.sum(np.hypot(*np.diff(self.dr_pose[:, :2], axis=0).T))),
            "vehicle_depth_m": [float(self.vehicle_depth.min()), float(self.vehicle_depth.max())],
            "seafloor_depth_m": [float(np.nanmin(self.beam_depth)), float(np.nanmax(self.beam_depth))],
        }
        if self.true_pose is not None:
            err = np.hypot(*(self.dr_pose[:, :2] - self.true_pose[:, :2]).T)
            r["reference"] = self.meta.get("reference", "truth")
            r["dr_error_m"] = {"final": float(err[-1]), "max": float(err.max()),
                               "median": float(np.median(err))}
        for key in ("map", "scenario", "seed", "crs", "origin", "start_time", "vertical_datum", "format"):
            if key in self.meta:
                r[key] = self.meta[key]
        r["counts"] = {k: v for k, v in self.meta.items() if k.startswith("n_")}
        return r

    def summary(self) -> str:
        """A few lines for a person: :meth:`report` as text."""
        r = self.report()
        lines = [
            f"pings        {r['pings']} over {r['duration_s']:.1f} s ({r['rate_hz']:.3g} Hz)",
            f"beams        {r['beams']} per ping; {r['soundings']} soundings "
            f"({r['returned_fraction']:.1%} of beams returned); {r['empty_pings']} empty pings",
            f"track        {r['dr_track_m']:.1f} m (DR)",
            f"depth        vehicle {r['vehicle_depth_m'][0]:.1f}..{r['vehicle_depth_m'][1]:.1f} m, "
            f"seafloor {r['seafloor_depth_m'][0]:.1f}..{r['seafloor_depth_m'][1]:.1f} m",
        ]
        if "dr_error_m" in r:
            e = r["dr_error_m"]
            lines.append(f"DR error     final {e['final']:.1f} m, max {e['max']:.1f} m "
                         f"(against the {r['reference']})")
        for key in ("map", "scenario", "seed"):
            if key in r:
                lines.append(f"{key:<13}{r[key]}")
        return "\n".join(lines)


def _first(mask: np.ndarray, n: int = 5) -> list[int]:
    return [int(i) for i in np.flatnonzero(mask)[:n]]


# -- NetCDF ------------------------------------------------------------------------------------
_POSE = ("north", "east", "heading")
_UNITS = {"north": "m", "east": "m", "heading": "rad"}
_READABLE_VERSIONS = (1, 2)
_SECONDS_PER = {"s": 1.0, "sec": 1.0, "secs": 1.0, "second": 1.0, "seconds": 1.0,
                "ms": 1e-3, "millisecond": 1e-3, "milliseconds": 1e-3, "microsecond": 1e-6,
                "microseconds": 1e-6, "min": 60.0, "minute": 60.0, "minutes": 60.0, "h": 3600.0,
                "hr": 3600.0, "hour": 3600.0, "hours": 3600.0, "d": 86400.0, "day": 86400.0,
                "days": 86400.0}


def _utc(text: Any) -> datetime.datetime | None:
    """An ISO 8601 time as a naive UTC datetime (a time without zone is taken as UTC)."""
    try:
        t = datetime.datetime.fromisoformat(str(text))
    except (TypeError, ValueError):
        return None
    return t if t.tzinfo is None else t.astimezone(datetime.UTC).replace(tzinfo=None)


def _time_units(start: datetime.datetime) -> str:
    stamp = start.strftime("%Y-%m-%d %H:%M:%S") + (f".{start.microsecond:06d}" if start.microsecond else "")
    return f"seconds since {stamp}"


def _reference_lonlat(survey: Survey) -> tuple[np.ndarray, np.ndarray, str] | None:
    """Longitude and latitude (WGS84) of the reference track (true_pose, else DR), where
    ``meta`` places the local frame (``crs`` and ``origin``)."""
    import pyproj

    crs, origin = survey.meta.get("crs"), survey.meta.get("origin")
    if not crs or origin is None:
        return None
    which, pose = ("dr_pose", survey.dr_pose) if survey.true_pose is None else ("true_pose", survey.true_pose)
    try:
        to_wgs84 = pyproj.Transformer.from_crs(crs, "EPSG:4326", always_xy=True)
        lon, lat = to_wgs84.transform(pose[:, 1] + float(origin[1]), pose[:, 0] + float(origin[0]))
    except (pyproj.exceptions.CRSError, pyproj.exceptions.ProjError, TypeError, ValueError,
            IndexError) as exc:
        _log.warning("survey: no latitude/longitude written (meta crs %r, origin %r: %s)", crs, origin, exc)
        return None
    lon, lat = np.asarray(lon, float), np.asarray(lat, float)
    if not (np.all(np.isfinite(lon)) and np.all(np.isfinite(lat))):
        _log.warning("survey: no latitude/longitude written (the track does not project from %r)", crs)
        return None
    return lon, lat, which


def _coordinates(survey: Survey, p: Path, below_surface: bool) -> dict[str, Any]:
    """The survey file's coordinates: ``time``, ``vehicle_depth``, the reference track's
    ``lat``/``lon`` where the survey is placed on Earth, and the ``trajectory`` id."""
    start = _utc(survey.meta["start_time"]) if "start_time" in survey.meta else None
    if start is not None:
        time_attrs = {"standard_name": "time", "long_name": "time of the ping", "axis": "T",
                      "units": _time_units(start), "calendar": "standard"}
    else:  # no epoch: not a CF time coordinate, only seconds
        time_attrs = {"units": "s", "long_name": "time from the survey start"}
    coords: dict[str, Any] = {
        "time": (("ping",), survey.time, time_attrs),
        "vehicle_depth": (
            ("ping",),
            survey.vehicle_depth,
            {**({"standard_name": "depth"} if below_surface else {}), "units": "m", "positive": "down",
             "axis": "Z", "long_name": "depth of the sonar"},
        ),
    }
    lonlat = _reference_lonlat(survey)
    if lonlat is not None:
        lon, lat, which = lonlat
        coords["lat"] = (("ping",), lat, {"standard_name": "latitude", "units": "degrees_north",
                                           "long_name": f"latitude of the reference track ({which})"})
        coords["lon"] = (("ping",), lon, {"standard_name": "longitude", "units": "degrees_east",
                                           "long_name": f"longitude of the reference track ({which})"})
    coords["trajectory"] = ((), str(survey.meta.get("name", p.stem)),
                            {"cf_role": "trajectory_id", "long_name": "survey"})
    return coords


def _variables(survey: Survey, below_surface: bool) -> dict[str, Any]:
    """The survey file's data variables: the poses, the attitude and the beams."""
    data: dict[str, Any] = {}
    for prefix, pose in (("dr", survey.dr_pose), ("true", survey.true_pose)):
        if pose is None:
            continue
        for k, comp in enumerate(_POSE):
            data[f"{prefix}_{comp}"] = (
                ("ping",),
                pose[:, k],
                {
                    "units": _UNITS[comp],
                    "long_name": f"{'dead-reckoned' if prefix == 'dr' else 'true'} {comp}"
                    + (" (clockwise from grid north)" if comp == "heading" else " (local frame)"),
                },
            )
    if survey.attitude is not None:
        senses = (("pitch", "bow up", "platform_pitch_fore_up"),
                  ("roll", "starboard down", "platform_roll_starboard_down"))
        for k, (comp, sense, standard) in enumerate(senses):
            data[comp] = (("ping",), survey.attitude[:, k],
                          {"units": "rad", "standard_name": standard,
                           "long_name": f"{comp} of the sonar, positive {sense}"})
    for name, long_name in (
        ("beam_forward", "footprint, body x (forward)"),
        ("beam_starboard", "footprint, body y (starboard)"),
        ("beam_depth", "measured seafloor depth, NaN = no return"),
    ):
        attrs = {"units": "m", "long_name": long_name}
        if name == "beam_depth":
            attrs["positive"] = "down"
            if below_surface:
                attrs["standard_name"] = "sea_floor_depth_below_sea_surface"
        data[name] = (("ping", "beam"), getattr(survey, name), attrs)
    return data


def write_survey(survey: Survey, path: str | os.PathLike, *, overwrite: bool = False) -> Path:
    """Write a survey as CF-1.8 NetCDF (schema version 2); atomic, never over an existing file
    unless ``overwrite``.

    The file is a CF trajectory (``featureType = "trajectory"``, a ``trajectory`` id variable:
    ``meta["name"]``, else the file's stem); where ``meta`` places it on Earth (``crs`` and
    ``origin``), ``lat``/``lon`` of the reference track (``true_pose``, else the dead
    reckoning) are its auxiliary coordinates. ``time`` is in
    ``seconds since meta["start_time"]`` (UTC) where the start time is known, else in seconds
    from the start.
    """
    import xarray as xr

    import tangraph
    from tangraph.outputs import write_atomically

    p = Path(path)
    # CF names depths below the sea surface; a survey on another datum (a gauge's zero, chart
    # datum) has none
    below_surface = survey.meta.get("vertical_datum", "water surface") == "water surface"
    coords = _coordinates(survey, p, below_surface)
    data = _variables(survey, below_surface)
    attrs = {
        "Conventions": "CF-1.8",
        "title": "tangraph survey",
        "featureType": "trajectory",
        "tangraph_survey_version": SCHEMA_VERSION,
        "source": f"tangraph {tangraph.__version__}",
        "tangraph_meta": json.dumps(survey.meta, sort_keys=True),
    }
    ds = xr.Dataset(data, coords=coords, attrs=attrs)
    # xarray lists the coordinates (time, lat, lon, vehicle_depth, trajectory) in each variable's
    # ``coordinates`` attribute
    encoding: dict[str, dict] = {k: {"zlib": True, "complevel": 4} for k in data}
    encoding.update({k: {"zlib": True, "complevel": 4, "_FillValue": None}
                     for k in coords if k != "trajectory"})
    encoding["trajectory"] = {"dtype": "S1"}  # a char array: CF-1.8 checkers refuse vlen strings
    write_atomically(p, overwrite, lambda tmp: ds.to_netcdf(tmp, encoding=encoding))
    return p


def _seconds_from_start(p: Path, time: Any, meta: dict) -> np.ndarray:
    """``Survey.time`` from the ``time`` variable: plain seconds (version 1, or no start time),
    or ``<unit> since <epoch>`` taken relative to ``meta["start_time"]`` (set to the first ping
    when missing)."""
    values = np.asarray(time.values, dtype=np.float64)
    units = str(time.attrs.get("units", "s")).strip()
    if " since " not in units:
        return values
    unit = units.split(" since ")[0].strip().lower()
    if unit not in _SECONDS_PER:
        raise SurveyError(f"{p}: time has units {units!r}; expected seconds (or minutes ...) since an epoch")
    import cftime

    try:
        epoch = cftime.num2date(0.0, "seconds since " + units.split(" since ", 1)[1],
                                calendar=str(time.attrs.get("calendar", "standard")),
                                only_use_cftime_datetimes=False, only_use_python_datetimes=True)
    except (ValueError, TypeError) as exc:
        raise SurveyError(f"{p}: time units {units!r} are not understood ({exc})") from None
    seconds = values * _SECONDS_PER[unit]
    start = _utc(meta.get("start_time"))
    if start is None:  # the first ping (to the microsecond in meta)
        meta["start_time"] = (epoch + datetime.timedelta(seconds=float(seconds[0]))).isoformat() + "Z"
        return seconds - seconds[0]
    return seconds + (epoch - start).total_seconds()


def read_survey(path: str | os.PathLike) -> Survey:
    """Read and validate a survey NetCDF file (schema version 1 or 2); every error names the
    file and the variable."""
    import xarray as xr

    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"survey file {p} does not exist")
    try:
        ds = xr.open_dataset(p, decode_times=False)
    except Exception as exc:  # netCDF4 raises several types for a bad file
        raise SurveyError(f"{p}: not a readable NetCDF file ({exc})") from None
    with ds:
        version = ds.attrs.get("tangraph_survey_version")
        if version not in _READABLE_VERSIONS:
            shown = version.item() if isinstance(version, np.generic) else version
            raise SurveyError(
                f"{p}: tangraph_survey_version is {shown!r}, this tangraph reads "
                f"{' and '.join(map(str, _READABLE_VERSIONS))}"
            )
        required = [
            "time",
            "vehicle_depth",
            "beam_forward",
            "beam_starboard",
            "beam_depth",
            *(f"dr_{c}" for c in _POSE),
        ]
        missing = [v for v in required if v not in ds.variables]
        if missing:
            raise SurveyError(f"{p}: missing variables {missing}")
        for name in required:
            dims = ("ping", "beam") if name.startswith("beam_") else ("ping",)
            if ds[name].dims != dims:
                raise SurveyError(f"{p}: variable {name} has dims {ds[name].dims}, expected {dims}")
        pose: dict[str, Any] = {
            prefix: (
                np.column_stack([ds[f"{prefix}_{c}"].values for c in _POSE])
                if all(f"{prefix}_{c}" in ds for c in _POSE)
                else None
            )
            for prefix in ("dr", "true")
        }
        try:
            meta = json.loads(ds.attrs.get("tangraph_meta", "{}"))
        except json.JSONDecodeError as exc:
            raise SurveyError(f"{p}: attribute tangraph_meta is not JSON ({exc})") from None
        time = _seconds_from_start(p, ds["time"], meta)
        try:
            return Survey(
                time=time,
                dr_pose=pose["dr"],
                vehicle_depth=ds["vehicle_depth"].values,
                beam_forward=ds["beam_forward"].values,
                beam_starboard=ds["beam_starboard"].values,
                beam_depth=ds["beam_depth"].values,
                true_pose=pose["true"],
                attitude=(np.column_stack([ds["pitch"].values, ds["roll"].values])
                          if "pitch" in ds and "roll" in ds else None),
                meta=meta,
            )
        except SurveyError as exc:
            raise SurveyError(f"{p}: {exc}") from None
