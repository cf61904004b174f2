"""A survey from a CSV navigation log and an XYZ soundings file (:func:`import_csv_xyz`).

The log's columns by name or position, with or without a header, any of ``;``, ``,``, tab or
whitespace between fields; times as seconds, epoch seconds or ISO 8601; positions as projected
metres (or the unit of the CRS given: feet are converted to metres) or latitude/longitude
(projected into the CRS given, headings turned to its grid north). Every error names the file,
the line and the column.
"""

from __future__ import annotations

import dataclasses
import os
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Literal, cast

import numpy as np

from tangraph.formats._checks import check_reach, projected_crs, time_zone
from tangraph.survey import Survey, SurveyError, to_body

__all__ = ["import_csv_xyz"]


#: the navigation log's columns, by the keys of ``columns=``
_NAV_KEYS = ("time", "north", "east", "lat", "lon", "heading", "depth")
TimeFormat = Literal["auto", "seconds", "epoch", "iso"]
#: with ``time_format="auto"``, numbers from this on (1973-03-03) are epoch seconds
_EPOCH_FROM = 1e8
_ISO = re.compile(
    r"\d{4}-\d{2}-\d{2}[Tt ]\d{2}:\d{2}(?::\d{2}(?:\.\d+)?)?(?:(Z|z|[+-]\d{2}(?::?\d{2})?))?"
)


@dataclasses.dataclass(frozen=True)
class _Table:
    """The fields of a delimited text file, with the line number of every row."""

    path: Path
    header: list[str] | None
    rows: list[list[str]]
    lines: list[int]
    min_fields: int

    def column(self, index: int, label: str) -> list[str]:
        if index >= self.min_fields:
            i = next(i for i, row in enumerate(self.rows) if len(row) <= index)
            raise SurveyError(
                f"{self.path}, line {self.lines[i]}: column {label} is field {index + 1} "
                f"(0-based {index}) but the line has {len(self.rows[i])} fields"
            )
        return [row[index] for row in self.rows]

    def numbers(self, index: int, label: str, *, finite: bool = True) -> np.ndarray:
        """The column as floats; the first text (or non-finite value) is named by line."""
        text = self.column(index, label)
        try:
            values = np.array(text, dtype=np.float64)
        except ValueError:
            values = None
        bad = [i for i, t in enumerate(text) if not _is_number(t)] if values is None else \
            (np.flatnonzero(~np.isfinite(values)) if finite else [])
        if len(bad):
            i = int(bad[0])
            raise SurveyError(
                f"{self.path}, line {self.lines[i]}, column {label}: {text[i]!r} is not a "
                f"{'number' if values is None else 'finite number'}"
            )
        return cast(np.ndarray, values)  # None only after the raise above


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _read_rows(path: Path, what: str, header: bool | None) -> _Table:
    """Rows of a text table: ``#`` comments and blank lines skipped, fields separated by the
    first line's ``;``, ``,``, tab or (otherwise) whitespace; ``header=None`` detects a header
    (the first line holds text where ``time x y z`` has numbers)."""
    if not path.is_file():
        raise FileNotFoundError(f"{what} {path} does not exist")
    with open(path, encoding="utf-8-sig", errors="replace") as f:
        content = [(n, line.strip()) for n, line in enumerate(f, start=1)]
    content = [(n, line) for n, line in content if line and not line.startswith("#")]
    if not content:
        raise SurveyError(f"{path}: {what} holds no rows")
    first = content[0][1]
    sep = next((s for s in (";", ",", "\t") if s in first), None)
    lines = [n for n, _ in content]
    if sep is None:
        rows = [line.split() for _, line in content]
    else:
        rows = [[v.strip() for v in line.split(sep)] for _, line in content]
    if any('"' in line for _, line in content):
        rows = [[v.strip('"').strip() for v in row] for row in rows]
    if header is None:
        header = not all(_is_number(v) for v in rows[0][1:4])
    names = [v.lower() for v in rows[0]] if header else None
    if header:
        rows, lines = rows[1:], lines[1:]
        if not rows:
            raise SurveyError(f"{path}: {what} has a header row but no data rows")
    return _Table(path, names, rows, lines, min(map(len, rows)))


def _nav_columns(
    table: _Table, columns: Mapping[str, int | str] | None
) -> tuple[dict[str, tuple[int, str]], bool]:
    """Index and label of each column the log needs, and whether it holds lat/lon."""
    given = dict(columns or {})
    unknown = sorted(set(given) - set(_NAV_KEYS))
    if unknown:
        raise SurveyError(f"columns: unknown keys {unknown}; known: {', '.join(_NAV_KEYS)}")
    for key, spec in given.items():
        name = isinstance(spec, str) and bool(spec.strip())
        position = isinstance(spec, int | np.integer) and not isinstance(spec, bool) and spec >= 0
        if not (name or position):
            raise SurveyError(f"columns: {key} must be a column name or a 0-based position, got {spec!r}")
    if {"lat", "lon"} & set(given) and {"north", "east"} & set(given):
        raise SurveyError("columns: give lat/lon or north/east, not both")
    if {"lat", "lon"} & set(given):
        geographic = True
    elif {"north", "east"} & set(given):
        geographic = False
    else:
        geographic = table.header is not None and {"lat", "lon"} <= set(table.header)
    need = ["time", *(("lat", "lon") if geographic else ("north", "east")), "heading", "depth"]
    chosen = {key: given.get(key, key) for key in need}
    if table.header is None:
        named = [key for key in need if isinstance(chosen[key], str)]
        if named:
            raise SurveyError(
                f"{table.path}: without a header row, give the 0-based position of every column "
                f"(columns=, CLI: --columns time=0,...); no position for {named}"
            )
    else:
        missing = [s.strip().lower() for s in chosen.values()
                   if isinstance(s, str) and s.strip().lower() not in table.header]
        if missing:
            raise SurveyError(f"{table.path}: missing columns {missing}; it has {table.header}")
    found = {}
    for key, s in chosen.items():
        if isinstance(s, str):
            assert table.header is not None  # refused above without a header
            found[key] = (table.header.index(s.strip().lower()), s.strip().lower())
        else:
            found[key] = (int(s), f"{int(s)} ({key})")
    return found, geographic


def _times(
    table: _Table, index: int, label: str, time_format: TimeFormat, zone
) -> tuple[np.ndarray, bool, bool]:
    """Seconds of a time column, whether they are absolute (epoch, UTC), and whether naive ISO
    times were localised with ``zone``."""
    text = table.column(index, label)
    try:
        np.array(text, dtype=np.float64)
        numeric = True
    except ValueError:
        numeric = False
    if time_format == "iso" or (time_format == "auto" and not numeric):
        seconds, naive = _iso_times(table, text, label, zone)
        return seconds, True, naive
    if not numeric:
        i = next(i for i, t in enumerate(text) if not _is_number(t))
        raise SurveyError(
            f"{table.path}, line {table.lines[i]}, column {label}: {text[i]!r} is not a number of "
            f"seconds (time_format={time_format!r})"
        )
    seconds = table.numbers(index, label)
    absolute = time_format == "epoch" or (time_format == "auto" and seconds.min() >= _EPOCH_FROM)
    return seconds, absolute, False


def _iso_times(table: _Table, text: list[str], label: str, zone) -> tuple[np.ndarray, bool]:
    """Epoch seconds (UTC) of ISO 8601 times; those without a zone are in ``zone``."""
    import pandas as pd

    def refuse(i: int, why: str):
        raise SurveyError(f"{table.path}, line {table.lines[i]}, column {label}: {text[i]!r} {why}")

    matches = [_ISO.fullmatch(t) for t in text]
    for i, m in enumerate(matches):
        if m is None:
            refuse(i, "is not a time (seconds, epoch seconds or ISO 8601 such as 2024-05-01T12:00:00Z)")
    naive = np.array([cast(re.Match[str], m).group(1) is None for m in matches])
    if naive.any() and zone is None:
        refuse(int(np.argmax(naive)), "has no time zone; give the zone of the clock "
               "(timezone=, CLI: --timezone), e.g. UTC or Europe/Berlin")
    epoch = pd.Timestamp(0, tz="UTC")
    seconds = np.empty(len(text))
    for local in (True, False):
        rows = np.flatnonzero(naive == local)
        if not rows.size:
            continue
        part = pd.Series([text[i].replace(" ", "T") for i in rows])
        try:
            if local:
                stamps = pd.to_datetime(part, format="ISO8601").dt.tz_localize(
                    zone, ambiguous="raise", nonexistent="raise")
            else:
                stamps = pd.to_datetime(part, format="ISO8601", utc=True)
        except Exception:  # pandas raises several types (parse, ambiguous, non-existent)
            for row in rows:
                try:
                    stamp = pd.Timestamp(text[row].replace(" ", "T"))
                    if local:
                        stamp.tz_localize(zone, ambiguous="raise", nonexistent="raise")
                except Exception:
                    refuse(int(row), f"is not a valid time in {zone} (or is ambiguous or skipped "
                           "there: a daylight-saving change)" if local else "is not a valid time")
            raise SurveyError(f"{table.path}, column {label}: times not readable as ISO 8601") from None
        seconds[rows] = ((stamps - epoch) / pd.Timedelta(seconds=1)).to_numpy(np.float64)
    return seconds, bool(naive.any())


def _utc_iso(seconds: float) -> str:
    """ISO 8601 UTC of epoch seconds, to the microsecond where they have a fraction."""
    us = round(seconds * 1e6)
    unit: Literal["s", "ms", "us"] = "s" if us % 1_000_000 == 0 else "ms" if us % 1000 == 0 else "us"
    return np.datetime_as_string(np.datetime64(us, "us"), unit=unit) + "Z"


def import_csv_xyz(navigation: str | os.PathLike, soundings: str | os.PathLike, *,
                   sign: Literal["depth", "elevation"] = "depth", crs: str | None = None,
                   columns: Mapping[str, int | str] | None = None, header: bool = True,
                   time_format: TimeFormat = "auto", timezone: str | None = None,
                   time_tolerance: float = 1e-3, units: str | None = None) -> Survey:
    """A survey from a CSV navigation log and an XYZ soundings file.

    Parameters
    ----------
    navigation : path
        A text table (comma, semicolon, tab or whitespace separated; ``#`` comments) with the
        columns ``time``, ``north`` and ``east`` in the unit of ``crs``'s axes (metres, or feet:
        converted to metres) or ``lat`` and ``lon`` in decimal degrees (WGS84), ``heading`` in
        degrees clockwise from north (from true north for a lat/lon log, from the grid north of
        ``crs`` otherwise), ``depth`` (the vehicle's, in ``units``).
    soundings : path
        Rows ``time x y z`` (a header row is detected; further columns ignored): the ping time on
        the log's clock, the footprint's east and north (or longitude and latitude when the log
        has lat/lon, in the same unit as the log's) and its depth (in ``units``; NaN: no return).
    sign : {"depth", "elevation"}
        Whether ``z`` is a depth (positive down) or an elevation (positive up).
    crs : str, optional
        The projected CRS of the survey. With north/east, theirs; with lat/lon, the one they are
        projected into. Without it a lat/lon log goes into a transverse Mercator centred on the
        log (:func:`~tangraph.maps.local_crs`). A geographic CRS is refused. A CRS whose axes are
        not in metres (``EPSG:2278``, US survey feet) is recorded as the same projection in
        metres (the survey's frame is metres; ``meta["crs_given"]`` keeps the CRS given, its
        unit and the metres per unit) and north/east read in it are converted.
    columns : mapping, optional
        Column name (case-insensitive) or 0-based position per key ``time``, ``north``,
        ``east``, ``lat``, ``lon``, ``heading``, ``depth``; by default the key is the name.
        Giving ``lat``/``lon`` (or ``north``/``east``) chooses the coordinates.
    header : bool
        Whether the log's first row holds the column names; without one, ``columns`` gives
        every column's position.
    time_format : {"auto", "seconds", "epoch", "iso"}
        How both files' times read: seconds on any clock, Unix epoch seconds, or ISO 8601
        strings (``2024-05-01T12:00:00Z``, ``...+02:00``). ``"auto"``: text is ISO 8601,
        numbers from 1e8 on (1973) are epoch seconds, smaller ones seconds.
    timezone : str, optional
        Zone (IANA name) of ISO 8601 times written without one; such times are refused without it.
    time_tolerance : float
        Soundings whose times differ by less than this (s) belong to one ping.
    units : str, optional
        The unit of the depths ``z`` and of the log's ``depth`` (``"m"``, ``"ft"``, ``"US survey
        foot"``, ``"fathom"``: :func:`tangraph.maps.io.unit_factor`); metres by default. Required
        when north/east are given in a CRS that is not in metres: their depths may be in its
        unit or in metres, and the files do not say.

    Returns
    -------
    Survey
        One ping per distinct sounding time inside the navigation's time span; its pose is
        the log interpolated at that time (heading on the circle, turned from true to grid north
        for a lat/lon log); footprints become body coordinates relative to it. Soundings outside
        the log's time span are dropped and counted in ``meta["n_dropped_outside_navigation"]``.
        ``meta["crs"]`` and ``meta["origin"]`` (northing, easting of local (0, 0): the whole
        metres below the log's smallest, or (0, 0) without ``crs``) place it. With absolute
        times (epoch, ISO), ``time`` counts from the first ping, whose UTC time is
        ``meta["start_time"]`` (ISO 8601).

    Raises
    ------
    SurveyError
        A missing column, text in a number column or an unreadable time (each naming the file,
        line and column), a time without zone and no ``timezone``, the two files on different
        clocks, a CRS that is not projected, north/east in a CRS not in metres without
        ``units``, repeated log times, no sounding within the log.
    MapFormatError
        An unknown unit.

    Examples
    --------
    >>> import_csv_xyz("nav.txt", "soundings.xyz", header=False, timezone="Europe/Berlin",
    ...                columns={"time": 0, "lat": 1, "lon": 2, "heading": 3, "depth": 4},
    ...                crs="EPSG:25833")  # doctest: +SKIP
    """
    return _survey_from_files(navigation, soundings, sign, crs, columns, header, time_format, timezone,
                              time_tolerance, units)


def _survey_from_files(navigation, soundings, sign, crs, columns, header, time_format, timezone,
                       time_tolerance, units) -> Survey:
    """The survey of :func:`import_csv_xyz` (its options checked here): both files read, their clocks
    checked, positions put in the survey's frame, soundings grouped into posed pings."""
    if sign not in ("depth", "elevation"):
        raise SurveyError(f"sign must be 'depth' or 'elevation', got {sign!r}")
    if time_format not in ("auto", "seconds", "epoch", "iso"):
        raise SurveyError(f"time_format must be auto, seconds, epoch or iso, got {time_format!r}")
    zone = time_zone(timezone)
    target = None if crs is None else projected_crs(crs)
    nav_path, xyz_path = Path(navigation), Path(soundings)
    nav = _read_rows(nav_path, "navigation log", bool(header))
    cols, geographic = _nav_columns(nav, columns)
    feet = None if geographic or target is None or not target.converted else target  # north/east to metres
    depth_unit = _depth_unit(units, feet, nav_path, xyz_path)
    xyz = _read_rows(xyz_path, "soundings file", None)
    if xyz.min_fields < 4:
        i = next(i for i, r in enumerate(xyz.rows) if len(r) < 4)
        raise SurveyError(
            f"{xyz_path}, line {xyz.lines[i]}: expected columns time x y z, got {len(xyz.rows[i])} columns"
        )
    t_nav, t_s, absolute, order = _clocks(nav, xyz, cols, time_format, zone, timezone)
    z_scale = depth_unit if sign == "depth" else -depth_unit
    recorded, origin, (n_nav, e_nav, heading), (y_s, x_s, z_s) = _positions(
        nav, xyz, cols, geographic, feet, z_scale, crs, target)
    ping_time, north, east, depth, n_dropped = _pings(t_nav, t_s, x_s, y_s, z_s, time_tolerance, nav_path,
                                                      xyz_path)
    heading = np.unwrap(heading[order])
    pose = np.column_stack(
        [
            np.interp(ping_time, t_nav, n_nav[order]),
            np.interp(ping_time, t_nav, e_nav[order]),
            np.mod(np.interp(ping_time, t_nav, heading), 2 * np.pi),
        ]
    )
    forward, starboard = to_body(pose, north, east)
    meta = {
        "source": {"navigation": str(nav_path), "soundings": str(xyz_path)},
        **recorded,
        "origin": list(origin),
        "n_dropped_outside_navigation": n_dropped,
    }
    vehicle_depth = np.interp(ping_time, t_nav, nav.numbers(*cols["depth"])[order]) * depth_unit
    check_reach(forward, starboard, depth, vehicle_depth, str(xyz_path))
    if absolute:
        meta["start_time"] = _utc_iso(float(ping_time[0]))
        ping_time = ping_time - ping_time[0]
    return Survey(
        time=ping_time,
        dr_pose=pose,
        vehicle_depth=vehicle_depth,
        beam_forward=forward,
        beam_starboard=starboard,
        beam_depth=depth,
        meta=meta,
    )


def _clocks(nav: _Table, xyz: _Table, cols: dict[str, tuple[int, str]], time_format: TimeFormat, zone,
            timezone: str | None):
    """The log's times in order, the soundings' times, whether both are absolute, and the order
    of the log's rows; refused: the files on different clocks, a ``timezone`` that no time
    needs, repeated log times."""
    t_nav, absolute, naive_nav = _times(nav, *cols["time"], time_format, zone)
    t_s, absolute_s, naive_s = _times(xyz, 0, "0 (time)", time_format, zone)
    if absolute != absolute_s:
        kinds = {True: "absolute (epoch or ISO 8601)", False: "seconds on their own clock"}
        raise SurveyError(f"{nav.path}: times are {kinds[absolute]} but {xyz.path}: times are "
                          f"{kinds[absolute_s]}; both files must use one clock")
    if zone is not None and not (naive_nav or naive_s):
        raise SurveyError(f"timezone={timezone!r} applies to ISO 8601 times without a zone, and "
                          f"neither {nav.path} nor {xyz.path} has any")
    order = np.argsort(t_nav, kind="stable")
    if np.any(np.diff(t_nav[order]) <= 0):
        raise SurveyError(f"{nav.path}: repeated times in column {cols['time'][1]}")
    return t_nav[order], t_s, absolute, order


def _positions(nav: _Table, xyz: _Table, cols, geographic: bool, feet, z_scale: float, crs, target):
    """The survey's CRS as recorded in its meta, its origin, and in the local frame the log's (north,
    east, heading) and the soundings' (north, east, depth times ``z_scale``): lat/lon projected,
    north/east in feet turned to metres."""
    a, b = ("lat", "lon") if geographic else ("north", "east")
    n_nav, e_nav = nav.numbers(*cols[a]), nav.numbers(*cols[b])
    heading = np.radians(nav.numbers(*cols["heading"]))
    y_s, x_s = xyz.numbers(2, "2 (y)"), xyz.numbers(1, "1 (x)")
    z_s = xyz.numbers(3, "3 (z)", finite=False) * z_scale
    if feet is not None:
        n_nav, e_nav, y_s, x_s = (v * feet.metres_per_unit for v in (n_nav, e_nav, y_s, x_s))
    local = geographic and crs is None  # a transverse Mercator centred on the log: origin (0, 0)
    recorded = {"crs": crs} if target is None else target.meta()
    if geographic:
        crs, (n_nav, e_nav, heading, y_s, x_s) = _project_log(nav, cols, n_nav, e_nav, heading,
                                                             y_s, x_s, crs, target)
        if local:
            recorded = {"crs": crs}
    if crs is None or local:
        origin = (0.0, 0.0)
    else:
        origin = (float(np.floor(n_nav.min())), float(np.floor(e_nav.min())))
    return (recorded, origin, (n_nav - origin[0], e_nav - origin[1], heading),
            (y_s - origin[0], x_s - origin[1], z_s))


def _pings(t_nav, t_s, x_s, y_s, z_s, time_tolerance: float, nav_path, xyz_path):
    """The soundings within the log's time span (``t_nav``, in order) grouped into pings, those
    closer in time than ``time_tolerance``: the ping times, the (pings, beams) north, east and
    depth of their soundings (NaN past a ping's last), and the number of soundings dropped."""
    inside = (t_s >= t_nav[0]) & (t_s <= t_nav[-1])
    n_dropped = int((~inside).sum())
    _check_clocks(t_nav, t_s, inside, nav_path, xyz_path)
    t_s, x_s, y_s, z_s = t_s[inside], x_s[inside], y_s[inside], z_s[inside]
    if t_s.size == 0:
        raise SurveyError(
            f"{xyz_path}: no sounding lies within the navigation log's time span [{t_nav[0]}, {t_nav[-1]}] s"
        )
    s_order = np.argsort(t_s, kind="stable")
    t_s, x_s, y_s, z_s = t_s[s_order], x_s[s_order], y_s[s_order], z_s[s_order]
    new_ping = np.concatenate([[True], np.diff(t_s) > time_tolerance])
    ping = np.cumsum(new_ping) - 1
    ping_time = t_s[new_ping]
    slot = np.arange(t_s.size) - np.flatnonzero(new_ping)[ping]
    n_beams = int(slot.max()) + 1
    north = np.full((ping_time.size, n_beams), np.nan)
    east = north.copy()
    depth = north.copy()
    north[ping, slot], east[ping, slot], depth[ping, slot] = y_s, x_s, z_s
    return ping_time, north, east, depth, n_dropped


def _depth_unit(units: str | None, feet, nav_path, xyz_path) -> float:
    """Metres per unit of the depths: ``units``, else metres; refused without ``units`` when
    north/east are in a CRS not in metres (``feet``), where the depths may be in either."""
    if units is not None:
        from tangraph.maps.io import unit_factor

        return unit_factor(units, f"{nav_path}, {xyz_path}", "units=")
    if feet is not None:
        raise SurveyError(
            f"crs={feet.given!r} has axes in {feet.unit}: give the unit of the depths in {nav_path} "
            f"and {xyz_path} (units='m' or units='ft', 'US survey foot'; CLI: --units)"
        )
    return 1.0


def _check_clocks(t_nav: np.ndarray, t_s: np.ndarray, inside: np.ndarray, nav_path, xyz_path) -> None:
    """Refuse two files whose clocks do not agree: most soundings outside the log's span, or
    spans whose lengths differ by more than 10 times (milliseconds beside seconds, say)."""
    span_nav = float(t_nav[-1] - t_nav[0])
    span_s = float(np.nanmax(t_s) - np.nanmin(t_s)) if t_s.size else 0.0
    outside = 1.0 - float(np.mean(inside)) if t_s.size else 0.0
    unlike = span_nav > 0 and span_s > 0 and max(span_nav / span_s, span_s / span_nav) > 10.0
    if outside > 0.5 or unlike:
        raise SurveyError(
            f"{xyz_path}: the soundings' times ({np.nanmin(t_s):.6g} .. {np.nanmax(t_s):.6g}, a span of "
            f"{span_s:.6g}) do not fit the log's in {nav_path} ({t_nav[0]:.6g} .. {t_nav[-1]:.6g}, "
            f"{span_nav:.6g}; {outside:.0%} of the soundings outside it): are both in seconds on one "
            "clock? (time_format=, CLI: --time-format)"
        )


def _project_log(nav: _Table, cols, lat, lon, heading, lat_s, lon_s, crs, target):
    """Lat/lon of the log and the soundings into ``crs`` (or a local transverse Mercator):
    the CRS, and (north, east, heading from grid north) of the log, (north, east) of the
    soundings. The heading turns by the angle of true north in the grid (numerically: the
    projected step to a point 1 m north)."""
    import pyproj

    from tangraph.maps.projection import local_crs, north_in_grid

    for values, key, limit in ((lat, "lat", 90.0), (lon, "lon", 360.0)):
        bad = np.flatnonzero((np.abs(values) > limit) | ((values < -180) if key == "lon" else False))
        if bad.size:
            i = int(bad[0])
            raise SurveyError(f"{nav.path}, line {nav.lines[i]}, column {cols[key][1]}: {float(values[i])!r} "
                              f"is not a {'latitude' if key == 'lat' else 'longitude'} in degrees")
    if crs is None:
        crs = local_crs(float(np.mean(lat)), float(np.mean(lon)))
        into = crs
    else:
        into = target.crs  # in metres
    t = pyproj.Transformer.from_crs("EPSG:4326", into, always_xy=True)
    n, e, turn = north_in_grid(t.transform, lon, lat, 1.0 / 111_320.0)
    e_s, n_s = (np.asarray(v) for v in t.transform(lon_s, lat_s))
    if not (np.all(np.isfinite([e, n, turn])) and np.all(np.isfinite([e_s, n_s]))):
        raise SurveyError(f"{nav.path}: positions lie outside where {crs} projects (crs=, CLI: --crs)")
    return crs, (n, e, heading + turn, n_s, e_s)
