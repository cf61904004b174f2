"""Generic Sensor Format (``.gsf``) multibeam files as surveys.

GSF files are read through ``gsfpy`` (the UK Hydrographic Office's ctypes binding of the
Leidos GSF library, version 3.08 by default). Of its records this module uses the swath
bathymetry ping (``GSF_RECORD_SWATH_BATHYMETRY_PING``): ping time, latitude, longitude,
heading (true), pitch, roll, heave, and per beam ``depth``, ``across_track``, ``along_track``
and ``beam_flags``. GSF stores the soundings already georeferenced to the vessel: depth
positive down from the water line (with the file's depth and tide correctors applied),
across-track positive to starboard, along-track positive forward, both in metres from the
vessel's reference point in the level frame (attitude already applied). A beam whose flags have
``GSF_IGNORE_BEAM`` (bit 0) set, or a depth of 0 (GSF's null), is no return; a ping whose
``ping_flags`` have ``GSF_IGNORE_PING`` (bit 0) set has no soundings.

gsfpy 2.0.0 names the two fields after ``ping_time`` of its ``c_gsfSwathBathyPing``
``longitude, latitude``, while the C library's ``gsf.h`` declares ``latitude, longitude``:
the values are read by their position in the C structure, not by gsfpy's names.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np

from tangraph.formats._checks import projected_crs
from tangraph.maps.projection import north_in_grid
from tangraph.survey import Survey, SurveyError

__all__ = ["import_gsf"]

log = logging.getLogger(__name__)

_IGNORE_BEAM = 0x01
_IGNORE_PING = 0x0001
_EOF = -23  # GSF_READ_TO_END_OF_FILE


def _lat_lon_fields() -> tuple[str, str]:
    """gsfpy's names of the C structure's first and second double (latitude, longitude)."""
    try:
        from gsfpy.gsfSwathBathyPing import c_gsfSwathBathyPing
    except (ImportError, OSError) as exc:  # OSError: its GSF library does not load here
        raise SurveyError(f"reading GSF needs gsfpy (pip install gsfpy; Linux x86-64): {exc}") from None

    names = [f[0] for f in c_gsfSwathBathyPing._fields_[1:3]]
    if sorted(names) != ["latitude", "longitude"]:
        raise SurveyError(f"gsfpy's swath ping structure has unexpected fields {names}")
    return names[0], names[1]


def _read_pings(p: Path) -> tuple[dict[str, np.ndarray], dict]:
    lat_field, lon_field = _lat_lon_fields()
    from gsfpy import GsfException, open_gsf
    from gsfpy.enums import RecordType

    rows: dict[str, list] = {k: [] for k in (
        "time", "lat", "lon", "heading", "pitch", "roll", "heave", "flags",
        "depth", "across", "along", "beam_flags")}
    counts: dict[str, int] = {}
    record = 0
    try:
        gsf = open_gsf(p)
    except GsfException as exc:
        raise SurveyError(f"{p}: gsfpy cannot open the file ({exc})") from None
    with gsf:
        while True:
            try:
                data_id, records = gsf.read()
            except GsfException as exc:
                if exc.error_code == _EOF:
                    break
                raise SurveyError(
                    f"{p}, record {record}: the GSF library cannot read it ({exc}); a truncated or "
                    "corrupt file") from None
            record += 1
            kind = RecordType(data_id.recordID).name if data_id.recordID in iter(RecordType) else str(
                data_id.recordID)
            counts[kind] = counts.get(kind, 0) + 1
            if data_id.recordID != RecordType.GSF_RECORD_SWATH_BATHYMETRY_PING:
                continue
            ping = records.mb_ping
            n = int(ping.number_beams)

            def beams(name, dtype=float, ping=ping, n=n, record=record):
                pointer = getattr(ping, name)
                if not pointer:
                    raise SurveyError(f"{p}, record {record}: swath ping without a {name} array")
                return np.ctypeslib.as_array(pointer, (n,)).astype(dtype)

            rows["time"].append(ping.ping_time.tv_sec + ping.ping_time.tv_nsec * 1e-9)
            rows["lat"].append(getattr(ping, lat_field))
            rows["lon"].append(getattr(ping, lon_field))
            for key in ("heading", "pitch", "roll", "heave"):
                rows[key].append(getattr(ping, key))
            rows["flags"].append(ping.ping_flags)
            rows["depth"].append(beams("depth"))
            rows["across"].append(beams("across_track"))
            rows["along"].append(beams("along_track"))
            rows["beam_flags"].append(
                beams("beam_flags", np.uint8) if ping.beam_flags else np.zeros(n, np.uint8))
    if not rows["time"]:
        raise SurveyError(f"{p}: no swath bathymetry ping records (records in the file: {counts})")
    sizes = sorted({a.size for a in rows["depth"]})
    if len(sizes) != 1:
        raise SurveyError(f"{p}: pings have different numbers of beams {sizes}")
    arrays = {k: (np.vstack(v) if k in ("depth", "across", "along", "beam_flags") else np.asarray(v))
              for k, v in rows.items()}
    return arrays, counts


def _grid_pose(p: Path, r, target, crs: str) -> tuple[np.ndarray, tuple[float, float], np.ndarray]:
    """The pings' poses ``(K, 3)`` in ``target``'s grid from the survey's origin (the floored
    least north and east), that origin, and the grid convergence at each ping (rad)."""
    import pyproj

    transform = pyproj.Transformer.from_crs("EPSG:4326", target.crs, always_xy=True).transform
    north, east, convergence = north_in_grid(transform, r["lon"], r["lat"], 1e-5)
    if not (np.all(np.isfinite(north)) and np.all(np.isfinite(east))):
        raise SurveyError(f"{p}: positions do not project into {crs}; give the CRS of the survey's region")
    origin = (float(np.floor(north.min())), float(np.floor(east.min())))
    heading = np.mod(np.radians(r["heading"]) + convergence, 2 * np.pi)
    return np.column_stack([north - origin[0], east - origin[1], heading]), origin, convergence


def import_gsf(path: str | os.PathLike, *, crs: str | None) -> Survey:
    """A survey from a GSF file's swath bathymetry pings.

    Parameters
    ----------
    path : path
        The ``.gsf`` file.
    crs : str
        Projected CRS of the survey's frame (e.g. ``EPSG:32658``); the pings' latitude and
        longitude are projected into it, the heading turned from true to grid north. One in
        feet is recorded as the same projection in metres (``meta["crs_given"]`` keeps the one
        given).

    Returns
    -------
    Survey
        One ping per swath record: ``true_pose`` the pings' positions (``meta["reference"] =
        "GSF ping position"``: whatever navigation the file was made with), ``dr_pose`` the
        same track (GSF has no separate dead reckoning); across-track -> starboard,
        along-track -> forward, depth positive down from the water line; ``vehicle_depth`` 0
        (the ping holds no transducer depth; ``depth`` already includes the draft). NaN where
        a beam is flagged ``GSF_IGNORE_BEAM``, has depth 0, or its ping is ``GSF_IGNORE_PING``.
    """
    if crs is None:
        raise SurveyError(f"{path}: give the projected CRS of the survey (crs=, CLI: --crs), e.g. EPSG:32658")
    target = projected_crs(crs)
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"GSF file {p} does not exist")
    r, counts = _read_pings(p)
    steps = np.diff(r["time"])
    if np.any(steps <= 0):
        i = int(np.argmax(steps <= 0))
        raise SurveyError(f"{p}: ping time does not increase at swath ping {i + 1}")
    pose, origin, convergence = _grid_pose(p, r, target, crs)
    ignored_ping = (r["flags"] & _IGNORE_PING) != 0
    flagged = (r["beam_flags"] & _IGNORE_BEAM) != 0
    null = ~np.isfinite(r["depth"]) | (r["depth"] == 0.0)
    valid = ~flagged & ~null & ~ignored_ping[:, None]
    depth = np.where(valid, r["depth"], np.nan)
    forward = np.where(valid, r["along"], np.nan)
    starboard = np.where(valid, r["across"], np.nan)
    start = np.datetime64(round(float(r["time"][0]) * 1e6), "us")
    meta = {
        "format": "gsf",
        "source": str(p),
        "record_counts": counts,
        "reference": "GSF ping position",
        "reference_note": "the swath pings' latitude/longitude; dr_pose is the same track "
                          "(the file has no separate dead reckoning)",
        **target.meta(),
        "origin": list(origin),
        "start_time": np.datetime_as_string(start, unit="ms") + "Z",
        "vertical_datum": "GSF depth (water line, the file's depth and tide correctors applied)",
        "grid_convergence_deg": float(np.degrees(np.median(convergence))),
        "n_pings": int(depth.shape[0]),
        "n_beams": int(depth.shape[1]),
        "n_beams_without_return": int((~valid).sum()),
        "n_beams_flagged": int((flagged & ~ignored_ping[:, None]).sum()),
        "n_beams_null": int((null & ~flagged & ~ignored_ping[:, None]).sum()),
        "n_pings_ignored": int(ignored_ping.sum()),
        "n_no_depth": int((~valid.any(axis=1)).sum()),
    }
    return Survey(
        time=r["time"] - r["time"][0],
        dr_pose=pose,
        vehicle_depth=np.zeros(depth.shape[0]),
        beam_forward=forward,
        beam_starboard=starboard,
        beam_depth=depth,
        true_pose=pose.copy(),
        attitude=np.radians(np.column_stack([r["pitch"], r["roll"]])),
        meta=meta,
    )
