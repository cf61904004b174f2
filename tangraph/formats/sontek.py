"""SonTek RiverSurveyor summary exports (``.sum``) as surveys.

A ``.sum`` file is what RiverSurveyor Live exports for one run: a header row and one row per
sample (one second), comma separated, CR line ends, Latin-1 text. Columns read here (by name):
``Sample #``, ``Date/Time`` (local time of the computer, ``month/day/year h:m:s AM``),
``Latitude``/``Longitude`` (degree-minute-second strings of the GPS), ``Heading`` (compass),
``Pitch``, ``Roll``, ``VB Depth`` (vertical beam), ``BT Beam1..4 Depth`` (the four slant beams,
their vertical depths), ``Boat Speed`` and ``Boat Direction`` (the boat's velocity over ground
in the software's track reference: bottom track or GPS). A depth of 0 is no return; a boat
speed of exactly 0 is no velocity (the software writes ``0.000`` with direction ``90.0``).

:func:`read_sontek_sum` reads the columns; :func:`import_sontek_sum` builds the `Survey`: the
GPS track projected into a CRS as the reference, the dead reckoning integrated from the boat
velocity (or the speed along the compass heading), five soundings per sample with their
body-frame footprints, and the depths referred to a water-level datum.
"""

from __future__ import annotations

import csv
import dataclasses
import datetime as dt
import logging
import os
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Literal

import numpy as np

from tangraph.formats._checks import projected_crs, time_zone
from tangraph.maps.projection import north_in_grid
from tangraph.survey import Survey, SurveyError

__all__ = ["SontekRecord", "import_sontek_sum", "read_sontek_sum"]

log = logging.getLogger(__name__)

#: the columns read, by the start of their header (units in brackets follow)
_COLUMNS = {
    "sample": "Sample #",
    "time": "Date/Time",
    "lat": "Latitude",
    "lon": "Longitude",
    "heading": "Heading",
    "pitch": "Pitch",
    "roll": "Roll",
    "vb_depth": "VB Depth",
    "beam1": "BT Beam1 Depth",
    "beam2": "BT Beam2 Depth",
    "beam3": "BT Beam3 Depth",
    "beam4": "BT Beam4 Depth",
    "boat_speed": "Boat Speed",
    "boat_direction": "Boat Direction",
}
_TIME_FORMAT = "%m/%d/%Y %I:%M:%S %p"
_DMS = re.compile(r"^\s*(-?)\s*(\d+)\s*°\s*(\d+)\s*'\s*(\d+(?:\.\d*)?)\s*\"\s*([NSEW]?)\s*$")
#: the M9's slant beams: 25 deg from vertical; azimuths (clockwise from the bow) of beams 1-4
SLANT_ANGLE_DEG = 25.0
BEAM_AZIMUTHS_DEG = (315.0, 225.0, 135.0, 45.0)
#: largest gap (s) between the end of one file and the start of the next in one survey
MAX_FILE_GAP = 10.0


@dataclasses.dataclass(frozen=True, eq=False)
class SontekRecord:
    """The columns of one ``.sum`` file, one value per sample (angles in degrees, lengths in m).

    ``local_time`` holds naive ``datetime64[s]`` of the file's local clock; ``beam_depth`` is
    (K, 5): the vertical beam, then slant beams 1-4, NaN where the file has 0 (no return).
    """

    path: str
    sample: np.ndarray
    local_time: np.ndarray
    lat: np.ndarray
    lon: np.ndarray
    heading: np.ndarray
    pitch: np.ndarray
    roll: np.ndarray
    beam_depth: np.ndarray
    boat_speed: np.ndarray
    boat_direction: np.ndarray

    @property
    def n_samples(self) -> int:
        return int(self.sample.size)

    @property
    def has_velocity(self) -> np.ndarray:
        """Samples with a boat velocity (speed not exactly 0)."""
        return self.boat_speed != 0.0


def read_sontek_sum(path: str | os.PathLike) -> SontekRecord:
    """Read a RiverSurveyor ``.sum`` export.

    Raises
    ------
    SurveyError
        A missing column, a row with a different number of fields than the header (a
        truncated line), text where a number or a DMS angle belongs, a date that is not
        ``month/day/year h:m:s AM``: each names the file, the line and the column.
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"SonTek file {p} does not exist")
    raw = p.read_bytes()
    lines = raw.decode("latin-1").replace("\r\n", "\n").replace("\r", "\n").split("\n")
    numbered = [(i + 1, line) for i, line in enumerate(lines) if line.strip()]
    if len(numbered) < 2:
        raise SurveyError(f"{p}: no samples (a .sum file has a header row and one row per sample)")
    header = [h.strip() for h in next(csv.reader([numbered[0][1]]))]
    index = {}
    for key, start in _COLUMNS.items():
        found = [i for i, h in enumerate(header) if h == start or h.startswith(start + " (")]
        if not found:
            raise SurveyError(f"{p}, line {numbered[0][0]}: no column {start!r} in the header")
        index[key] = found[0]
    rows = list(csv.reader([line for _, line in numbered[1:]]))
    columns: dict[str, list] = {key: [] for key in _COLUMNS}
    for (number, _), fields in zip(numbered[1:], rows, strict=True):
        if len(fields) != len(header):
            raise SurveyError(
                f"{p}, line {number}: {len(fields)} fields, the header has {len(header)} "
                "(a truncated or joined line)"
            )
        for key, i in index.items():
            columns[key].append(_value(key, fields[i], p, number, header[i]))
    local = np.array(columns.pop("time"), dtype="datetime64[s]")
    depth = np.column_stack([columns.pop(k) for k in ("vb_depth", "beam1", "beam2", "beam3", "beam4")])
    depth[depth == 0.0] = np.nan
    arrays = {k: np.asarray(v, dtype=np.int64 if k == "sample" else float) for k, v in columns.items()}
    return SontekRecord(path=str(p), local_time=local, beam_depth=depth, **arrays)


def _value(key: str, text: str, path: Path, line: int, column: str):
    where = f"{path}, line {line}, column {column!r}"
    if key == "time":
        try:
            return dt.datetime.strptime(text.strip(), _TIME_FORMAT)
        except ValueError:
            raise SurveyError(f"{where}: {text!r} is not a time (month/day/year h:m:s AM)") from None
    if key in ("lat", "lon"):
        return _dms(text, where)
    try:
        value = int(text) if key == "sample" else float(text)
    except ValueError:
        raise SurveyError(f"{where}: {text!r} is not a number") from None
    if key != "sample" and not np.isfinite(value):
        raise SurveyError(f"{where}: {text!r} is not finite")
    return value


def _dms(text: str, where: str) -> float:
    """Degrees of a ``D° M' S.ss"`` string (a leading ``-`` or a trailing S/W is negative).

    >>> _dms(' 52° 20\\' 35.27"', "x")
    52.34313055555556
    """
    m = _DMS.match(text)
    if m is None:
        raise SurveyError(f"{where}: {text!r} is not a degree-minute-second angle (D° M' S.ss\")")
    minus, degrees, minutes, seconds, hemisphere = m.groups()
    # the exporter rounds 59.996" up to 60.00" without carrying: accept exactly 60.00
    if int(minutes) >= 60 or float(seconds) > 60.0:
        raise SurveyError(f"{where}: {text!r} has minutes of 60 or more, or seconds over 60")
    value = int(degrees) + int(minutes) / 60.0 + float(seconds) / 3600.0
    return -value if (minus or hemisphere in ("S", "W")) else value


def _to_utc(local: np.ndarray, timezone: str, path: str) -> np.ndarray:
    """UTC ``datetime64[s]`` of naive local times; ambiguous or skipped clock times refused."""
    zone = time_zone(timezone)
    # the offset changes at most at a few instants: convert each distinct hour once
    hours, inverse = np.unique(local.astype("datetime64[h]"), return_inverse=True)
    offsets = np.empty(hours.size, dtype="timedelta64[s]")
    for i, hour in enumerate(hours.astype(dt.datetime)):
        early, late = (hour.replace(tzinfo=zone, fold=f).utcoffset() for f in (0, 1))
        there = hour.replace(tzinfo=zone).astimezone(dt.UTC).astimezone(zone).replace(tzinfo=None)
        if early != late or there != hour:
            raise SurveyError(
                f"{path}: local time {hour:%Y-%m-%d %H}h is {'skipped' if there != hour else 'ambiguous'} "
                f"in {timezone} (a daylight-saving change); give the zone of the clock without "
                "daylight saving (e.g. Etc/GMT-1 for CET)"
            )
        offsets[i] = np.timedelta64(int(early.total_seconds()), "s")
    return local - offsets[inverse.ravel()]


def import_sontek_sum(
    paths: str | os.PathLike | Sequence[str | os.PathLike],
    *,
    crs: str | None,
    timezone: str | None,
    water_level: str | os.PathLike | None = None,
    water_level_interpolate: bool = False,
    draft: float = 0.0,
    dr_heading: Literal["boat", "compass"] = "boat",
    declination_deg: float = 0.0,
    beam_azimuths_deg: Sequence[float] = BEAM_AZIMUTHS_DEG,
) -> Survey:
    """A survey from one RiverSurveyor run (one ``.sum`` file, or consecutive files of one run).

    Parameters
    ----------
    paths : path or sequence of paths
        The ``.sum`` files; several must follow each other within 10 s.
    crs : str
        Projected CRS of the survey's frame (e.g. ``EPSG:25833``); required, and checked
        against the positions (they must lie in its area of use). One in feet is recorded as
        the same projection in metres (``meta["crs_given"]`` keeps the one given).
    timezone : str
        Zone of the file's local clock (e.g. ``Europe/Berlin``, ``UTC``); required, since the
        file does not say.
    water_level : path, optional
        A water-level table (:func:`~tangraph.formats.waterlevel.read_water_level`): depths are
        then below the table's zero (``depth - level of the day``), so that runs of different
        days share one datum. Without it they are below the water surface of the day.
    water_level_interpolate : bool
        Interpolate the level between the table's neighbouring dates when the day is missing.
    draft : float
        Depth of the transducer below the surface, m (the exported depths are measured from the
        surface); used for the slant beams' footprints.
    dr_heading : {"boat", "compass"}
        The dead reckoning's velocity: the exported boat velocity (``"boat"``: speed along
        ``Boat Direction``), or the boat speed along the compass heading (``"compass"``: the
        heading's real errors and the boat's sideslip enter the DR; both change with the
        heading, so navigate it with a model whose ``heading_turn_std`` says by how much, as
        the caputh_replay study's ``[navigation.compass]`` does).
    declination_deg : float
        Magnetic declination, added to the compass heading to make it true; the heading is then
        turned to the grid north of ``crs`` (at Lake Caputh, true north lies 1.6 deg clockwise
        of the grid north of EPSG:25833). The boat direction is taken as it is: on the files
        tested it is a grid direction (its integral follows the GPS projected into EPSG:25833
        within 0.13 m per 300 s).
    beam_azimuths_deg : four floats
        Azimuths of slant beams 1-4, clockwise from the bow.

    Returns
    -------
    Survey
        One ping per sample: ``true_pose`` is the GPS track (linearly interpolated over the
        samples that repeat the previous position: the GPS had no new fix), ``dr_pose`` the
        dead reckoning started at the first GPS position, heading the compass (+ declination,
        + convergence);
        five beams (vertical, slant 1-4) with footprints from the depth, the 25 deg slant and the
        pitch and roll. Samples without a boat velocity keep the last velocity (none before the
        first); samples without any depth stay as pings without soundings. ``meta`` counts both,
        and records the median drift of the DR from the GPS over 300 s windows: near the GPS's own
        resolution means the velocity is GPS-referenced, not an independent bottom track.
    """
    files = [paths] if isinstance(paths, str | os.PathLike) else list(paths)
    azimuths, draft = _checked_options(files, timezone, crs, dr_heading, beam_azimuths_deg, draft)
    declination_deg = _checked_declination(declination_deg)
    if water_level_interpolate and water_level is None:
        raise SurveyError("water_level_interpolate (--water-level-interpolate) interpolates a water-level "
                          "table: give it (water_level=, CLI: --water-level)")
    records, rec, t_utc, steps = _read_run(files, timezone)
    return _survey_of_run(records, rec, t_utc, steps, crs=crs, timezone=timezone, water_level=water_level,
                          water_level_interpolate=water_level_interpolate, draft=draft, dr_heading=dr_heading,
                          declination_deg=declination_deg, azimuths=azimuths)


def _checked_options(files, timezone, crs, dr_heading, beam_azimuths_deg, draft) -> tuple[np.ndarray, float]:
    """Refuse no file, a missing time zone or CRS and an unknown or impossible option; the slant
    beams' azimuths (radians) and the draft (a float)."""
    if not files:
        raise SurveyError("import_sontek_sum: no .sum file given")
    if timezone is None:
        raise SurveyError(
            f"{files[0]}: .sum times are the computer's local time; give its zone "
            "(timezone=, CLI: --timezone), e.g. Europe/Berlin or UTC"
        )
    if crs is None:
        raise SurveyError(
            f"{files[0]}: give the projected CRS of the survey (crs=, CLI: --crs), e.g. EPSG:25833"
        )
    if dr_heading not in ("boat", "compass"):
        raise SurveyError(f"dr_heading must be 'boat' or 'compass', got {dr_heading!r}")
    azimuths = np.radians(np.asarray(beam_azimuths_deg, float))
    if azimuths.shape != (4,) or not np.all(np.isfinite(azimuths)):
        raise SurveyError(f"beam_azimuths_deg must be four angles, got {beam_azimuths_deg!r}")
    draft = float(draft)
    if not (np.isfinite(draft) and 0.0 <= draft < 5.0):
        raise SurveyError(f"draft must be between 0 and 5 m, got {draft!r}")
    return azimuths, draft


def _checked_declination(declination_deg) -> float:
    """The magnetic declination (deg, east positive) as a float in [-180, 180]."""
    try:
        value = float(declination_deg)
    except (TypeError, ValueError):
        value = float("nan")
    if not (np.isfinite(value) and -180.0 <= value <= 180.0):
        raise SurveyError(f"declination_deg (--declination) must be between -180 and 180 deg, "
                          f"got {declination_deg!r}")
    return value


def _read_run(files: list, timezone):
    """The files' records in the order of their start, joined into one record, its UTC times and
    the steps (s) between its samples; refused: files not following each other within
    ``MAX_FILE_GAP``, a time that does not increase."""
    records = sorted((read_sontek_sum(f) for f in files), key=lambda r: r.local_time[0])
    utc = [_to_utc(r.local_time, timezone, r.path) for r in records]
    for (a, ta), (b, tb) in zip(zip(records, utc, strict=True), zip(records[1:], utc[1:], strict=True),
                                strict=False):
        gap = (tb[0] - ta[-1]) / np.timedelta64(1, "s")
        if not 0.0 < gap <= MAX_FILE_GAP:
            raise SurveyError(
                f"{b.path} starts {gap:g} s after {a.path} ends: a survey is one continuous run; "
                "import the files one by one"
            )
    rec = _concatenate(records)
    t_utc = np.concatenate(utc)
    steps = np.diff(t_utc) / np.timedelta64(1, "s")
    if np.any(steps <= 0):
        i = int(np.argmax(steps <= 0))
        raise SurveyError(f"{rec.path}: time does not increase at sample {int(rec.sample[i + 1])}")
    return records, rec, t_utc, steps


def _survey_of_run(records, rec: SontekRecord, t_utc, steps, *, crs, timezone, water_level,
                   water_level_interpolate, draft, dr_heading, declination_deg, azimuths) -> Survey:
    """The survey of :func:`import_sontek_sum` from the run read (``rec``: ``records`` joined), its
    options checked: GPS reference, dead reckoning, soundings, meta."""
    time = np.concatenate([[0.0], np.cumsum(steps)])
    target, origin, reference, convergence, n_repeated = _gps_reference(rec, time, crs)

    # the compass reads from magnetic north: + declination -> true north, + convergence -> grid
    psi = np.radians(rec.heading + float(declination_deg)) + convergence
    direction = np.radians(rec.boat_direction) if dr_heading == "boat" else psi
    velocity, n_no_velocity, longest = _held_velocity(rec, direction)
    dr = np.zeros((time.size, 2))
    dr[1:] = np.cumsum(velocity[1:] * steps[:, None], axis=0)
    dr += reference[0]
    heading = np.mod(psi, 2 * np.pi)

    levels, datum = _datum(water_level, water_level_interpolate, rec.local_time)
    attitude = np.radians(np.column_stack([rec.pitch, rec.roll]))
    forward, starboard = _footprints(rec.beam_depth - draft, attitude, azimuths)
    depth = rec.beam_depth - levels[:, None]
    has_depth = np.isfinite(depth).any(axis=1)
    drift = _drift(dr, reference, rec.has_velocity)
    meta = {
        "format": "sontek-sum",
        "source": [r.path for r in records],
        "reference": "GPS",
        "reference_note": "the RiverSurveyor's internal receiver: DGPS, a few metres",
        **target.meta(),
        "origin": list(origin),
        "start_time": np.datetime_as_string(t_utc[0], unit="s") + "Z",
        "timezone": timezone,
        "vertical_datum": datum,
        "draft": draft,
        "dr_heading": dr_heading,
        "declination_deg": float(declination_deg),
        "grid_convergence_deg": float(np.degrees(np.median(convergence))),
        "beams": "vertical beam, slant beams 1-4",
        "slant_angle_deg": SLANT_ANGLE_DEG,
        "beam_azimuths_deg": [float(a) for a in np.degrees(azimuths)],
        "n_samples": int(time.size),
        "n_no_boat_velocity": n_no_velocity,
        "longest_no_velocity_s": longest,
        "n_no_depth": int((~has_depth).sum()),
        "n_beams_without_return": int(np.isnan(depth).sum()),
        "n_gps_repeated": n_repeated,
        "dr_drift_300s_m": drift,
    }
    if water_level is not None:
        days, first = np.unique(rec.local_time.astype("datetime64[D]"), return_index=True)
        meta["water_level"] = {str(d): float(levels[i]) for d, i in zip(days, first, strict=True)}
    if np.isfinite(drift) and drift < 0.5 and dr_heading == "boat":
        log.warning(
            "%s: the boat velocity follows the GPS track within %.2f m per 300 s: the file's track "
            "reference is GPS, not bottom track, so its DR is not independent of the reference "
            "(dr_heading='compass' integrates the speed along the compass heading instead)",
            rec.path, drift,
        )
    return Survey(
        time=time,
        dr_pose=np.column_stack([dr, heading]),
        vehicle_depth=draft - levels,
        beam_forward=forward,
        beam_starboard=starboard,
        beam_depth=depth,
        true_pose=np.column_stack([reference, heading]),
        attitude=attitude,
        meta=meta,
    )


def _concatenate(records: list[SontekRecord]) -> SontekRecord:
    if len(records) == 1:
        return records[0]
    fields = {f.name: np.concatenate([getattr(r, f.name) for r in records])
              for f in dataclasses.fields(SontekRecord) if f.name != "path"}
    return SontekRecord(path=", ".join(r.path for r in records), **fields)


def _check_area(target, crs: str, rec: SontekRecord) -> None:
    """Refuse a CRS whose area of use does not hold the positions (a wrong zone or a typo)."""
    area = target.crs.area_of_use
    if area is None:
        return
    margin = 1.0  # degrees: UTM zones are used a little beyond their edges
    lat, lon = rec.lat, rec.lon
    inside = ((lat >= area.south - margin) & (lat <= area.north + margin)
              & (lon >= area.west - margin) & (lon <= area.east + margin))
    if not inside.all():
        i = int(np.argmin(inside))
        raise SurveyError(
            f"{rec.path}: sample {int(rec.sample[i])} at {lat[i]:.5f} N, {lon[i]:.5f} E lies outside "
            f"the area of use of {crs} ({area.name}: {area.south:g}..{area.north:g} N, "
            f"{area.west:g}..{area.east:g} E); give the CRS of the survey's region"
        )


def _gps_reference(rec: SontekRecord, time, crs):
    """The CRS of the survey (the positions checked against its area of use), the origin of its
    local frame, the GPS track in that frame, the grid convergence and the number of samples
    that repeat the previous position."""
    import pyproj

    target = projected_crs(crs)
    _check_area(target, crs, rec)
    transform = pyproj.Transformer.from_crs("EPSG:4326", target.crs, always_xy=True).transform
    n, e, convergence = north_in_grid(transform, rec.lon, rec.lat, 1e-5)
    reference, n_repeated = _gps_track(time, n, e, rec)
    origin = (float(np.floor(reference[:, 0].min())), float(np.floor(reference[:, 1].min())))
    reference -= origin
    return target, origin, reference, convergence, n_repeated


def _gps_track(time, north, east, rec: SontekRecord) -> tuple[np.ndarray, int]:
    """The GPS track, linear in time between the samples where the position changed."""
    repeated = np.concatenate([[False], (np.diff(rec.lat) == 0) & (np.diff(rec.lon) == 0)])
    fresh = ~repeated
    track = np.column_stack([np.interp(time, time[fresh], north[fresh]),
                             np.interp(time, time[fresh], east[fresh])])
    return track, int(repeated.sum())


def _held_velocity(rec: SontekRecord, direction: np.ndarray) -> tuple[np.ndarray, int, float]:
    """(north, east) velocity per sample, the last valid one held where the file has none."""
    valid = rec.has_velocity
    v = rec.boat_speed[:, None] * np.column_stack([np.cos(direction), np.sin(direction)])
    last = np.maximum.accumulate(np.where(valid, np.arange(valid.size), -1))
    held = np.where((last >= 0)[:, None], v[np.maximum(last, 0)], 0.0)
    runs = np.diff(np.concatenate([[0], (~valid).astype(int), [0]]))
    lengths = np.flatnonzero(runs == -1) - np.flatnonzero(runs == 1)
    return held, int((~valid).sum()), float(lengths.max()) if lengths.size else 0.0


def _drift(dr: np.ndarray, reference: np.ndarray, valid: np.ndarray, window: int = 300) -> float:
    """Median horizontal drift (m) of the DR from the reference over windows of ``window``
    samples that hold a velocity throughout (NaN when there is no such window)."""
    if dr.shape[0] <= window:
        return float("nan")
    change = (dr[window:] - dr[:-window]) - (reference[window:] - reference[:-window])
    bad = np.concatenate([[0], np.cumsum(~valid)])
    ok = bad[window + 1:] - bad[1:-window] == 0  # no invalid sample in (start, end]
    return float(np.median(np.hypot(change[ok, 0], change[ok, 1]))) if ok.any() else float("nan")


def _datum(water_level, interpolate: bool, local: np.ndarray) -> tuple[np.ndarray, str]:
    """The water level (m above the table's zero) of each sample's local day, and the datum."""
    if water_level is None:
        return np.zeros(local.size), "water surface"
    from tangraph.formats.waterlevel import read_water_level

    table = read_water_level(water_level)
    days, inverse = np.unique(local.astype("datetime64[D]"), return_inverse=True)
    level = np.array([table.on(d, interpolate=interpolate) for d in days.astype(dt.date)])
    return level[inverse.ravel()], f"zero of the water-level table {Path(water_level).name}"


def _footprints(height: np.ndarray, attitude: np.ndarray, azimuths: np.ndarray):
    """Body-frame horizontal (forward, starboard) of the five beams' footprints, (K, 5) each.

    ``height`` (K, 5) is the vertical distance from the transducer to the seafloor at each
    footprint; beams point down (vertical) and 25 deg off vertical at ``azimuths``, then are
    turned by roll (positive starboard down) and pitch (positive bow up) into the level frame.
    """
    tilt = np.radians(SLANT_ANGLE_DEG)
    u = np.zeros((5, 3))
    u[0] = (0.0, 0.0, 1.0)
    u[1:, 0] = np.sin(tilt) * np.cos(azimuths)
    u[1:, 1] = np.sin(tilt) * np.sin(azimuths)
    u[1:, 2] = np.cos(tilt)
    pitch, roll = attitude[:, 0:1], attitude[:, 1:2]
    x, y, z = u[None, :, 0], u[None, :, 1], u[None, :, 2]
    # roll about the bow axis, then pitch about the starboard axis (body -> level, z down)
    y, z = y * np.cos(roll) - z * np.sin(roll), y * np.sin(roll) + z * np.cos(roll)
    x, z = x * np.cos(pitch) + z * np.sin(pitch), -x * np.sin(pitch) + z * np.cos(pitch)
    return height * x / z, height * y / z
