"""eXtended Triton Format (``.xtf``) multibeam files as surveys.

An XTF file is a 1024-byte file header and a sequence of packets, each starting with the
magic number ``0xFACE``, its type and its length. The packets are read with ``pyxtf``
(:func:`pyxtf.xtf_read`); this module uses:

- type 65 (``XTF_HEADER_QINSY_R2SONIC_BATHY``, what QINSy writes for R2Sonic sonars): an XTF
  ping header (little endian: ship position, heading, pitch, roll, heave) followed by the
  sonar's own ``BTH0`` packet (big endian, which pyxtf does not decode; it is decoded here):
  section ``H0`` (ping time, sound speed at the transducer, number of points), ``R0`` (two-way
  travel times), ``A0`` or ``A2`` (beam angles across the array, port first, relative to the
  array's centreline, i.e. *not* roll stabilised) and ``Q0`` (4-bit quality flags per point);
- type 107 (``XTF_HEADER_POS_RAW_NAVIGATION``): the positioning system's raw latitude and
  longitude with a microsecond time, interpolated to the ping times.

Soundings are straight rays at the transducer's sound speed (no sound-velocity profile):
range ``c t / 2`` along the beam, turned by the ping's roll (positive starboard down) and pitch
(positive bow up) into the level frame. Other XTF bathymetry packets (types 2, 28, 68, ...) are
refused with a message naming them.
"""

from __future__ import annotations

import dataclasses
import logging
import os
import struct
import warnings
from pathlib import Path

import numpy as np

from tangraph.formats._checks import projected_crs
from tangraph.maps.projection import north_in_grid
from tangraph.survey import Survey, SurveyError

__all__ = ["import_xtf"]

log = logging.getLogger(__name__)

_FILE_HEADER = 1024
_CHANINFO = 128
_PACKET_MAGIC = 0xFACE
_R2SONIC_BATHY = 65
_RAW_NAVIGATION = 107
_PING_HEADER = 256
#: R2Sonic Q0 flag bits: brightness and colinearity filters passed, magnitude or phase detect
_Q_FILTERS, _Q_DETECT = 0x3, 0xC


@dataclasses.dataclass(frozen=True)
class _Ping:
    time: float  # Unix seconds (the sonar's H0 time)
    lat: float
    lon: float
    heading: float  # degrees
    pitch: float
    roll: float
    heave: float
    sound_speed: float
    two_way_time: np.ndarray  # (B,) s, NaN = no range
    angle: np.ndarray  # (B,) rad across the array, starboard positive
    quality: np.ndarray  # (B,) 4-bit flags


def _check_packets(p: Path, data: bytes) -> None:
    """Walk the packet chain; a cut-off or corrupt packet is refused with its byte offset."""
    if len(data) < _FILE_HEADER or data[0] != 0x7B:
        raise SurveyError(f"{p}: not an XTF file (no 1024-byte file header starting with 0x7B)")
    # sonar, bathymetry, snippet, (forward-look), echo-strength, interferometry channels
    counts = struct.unpack_from("<6H", data, 166)
    channels = sum(counts[i] for i in (0, 1, 2, 4, 5))
    offset = _FILE_HEADER + (max(channels - 6, 0) + 7) // 8 * 8 * _CHANINFO
    while offset < len(data):
        if offset + 14 > len(data):
            raise SurveyError(f"{p}, byte {offset}: a packet header is cut off by the end of the file "
                              "(truncated file)")
        magic, kind = struct.unpack_from("<HB", data, offset)
        size = struct.unpack_from("<I", data, offset + 10)[0]
        if magic != _PACKET_MAGIC or size < 14:
            raise SurveyError(f"{p}, byte {offset}: no XTF packet here (magic 0x{magic:04X}, "
                              f"expected 0xFACE; a corrupt file)")
        if offset + size > len(data):
            raise SurveyError(f"{p}, byte {offset}: packet type {kind} of {size} bytes is cut off by "
                              f"the end of the file after {len(data) - offset} bytes (truncated file)")
        offset += size


def _r2sonic_ping(raw: bytes, where: str) -> _Ping:
    """One type-65 packet (its bytes from the packet start) as a ping."""
    from pyxtf import xtf_ctypes

    head = xtf_ctypes.XTFPingHeader.from_buffer_copy(raw[:_PING_HEADER])
    bth = raw[_PING_HEADER:]
    if bth[:4] != b"BTH0":
        raise SurveyError(f"{where}: no R2Sonic BTH0 packet after the ping header (got {bth[:4]!r})")
    size = struct.unpack_from(">I", bth, 4)[0]
    sections: dict[str, bytes] = {}
    i = 12
    while i + 4 <= min(size, len(bth)):
        name, length = struct.unpack_from(">2sH", bth, i)
        if length < 4:
            raise SurveyError(f"{where}: BTH0 section {name!r} has length {length}")
        sections[name.decode("latin-1")] = bth[i:i + length]
        i += length
    missing = [s for s in ("H0", "R0") if s not in sections] + (
        [] if "A0" in sections or "A2" in sections else ["A0/A2"])
    if missing:
        raise SurveyError(f"{where}: BTH0 packet without section(s) {missing}")
    h0 = sections["H0"]
    seconds, nanoseconds = struct.unpack_from(">II", h0, 28)
    sound_speed = struct.unpack_from(">f", h0, 44)[0]
    n = struct.unpack_from(">H", h0, 114)[0]
    r0 = sections["R0"]
    scale = struct.unpack_from(">f", r0, 4)[0]
    counts = np.frombuffer(r0, ">u2", count=n, offset=8).astype(float)
    two_way = np.where(counts > 0, counts * scale, np.nan)
    if "A2" in sections:
        a2 = sections["A2"]
        first, step = struct.unpack_from(">ff", a2, 4)
        steps = np.frombuffer(a2, ">u2", count=n, offset=36).astype(np.int64)
        angle = first + np.cumsum(steps) * float(step)
    else:
        first, last = struct.unpack_from(">ff", sections["A0"], 4)
        angle = np.linspace(first, last, n)
    if "Q0" in sections:
        words = np.frombuffer(sections["Q0"], ">u4", count=(n + 7) // 8, offset=4)
        quality = ((words[:, None] >> (28 - 4 * np.arange(8))) & 0xF).ravel()[:n]
    else:
        quality = np.full(n, _Q_FILTERS | _Q_DETECT)
    return _Ping(
        time=seconds + nanoseconds * 1e-9, lat=head.SensorYcoordinate, lon=head.SensorXcoordinate,
        heading=head.SensorHeading, pitch=head.SensorPitch, roll=head.SensorRoll, heave=head.Heave,
        sound_speed=sound_speed, two_way_time=two_way, angle=angle, quality=quality,
    )


def _nav_time(packet) -> float:
    import calendar

    day = calendar.timegm((packet.Year, packet.Month, packet.Day, packet.Hour, packet.Minute,
                           packet.Second, 0, 0, 0))
    return day + packet.Microsecond * 1e-6


def _read_xtf(path: str | os.PathLike) -> tuple[list[_Ping], np.ndarray, dict]:
    """The R2Sonic pings, the raw navigation (N, 3: Unix time, lat, lon) and header facts."""
    try:
        import pyxtf
    except ImportError as exc:
        raise SurveyError(f"reading XTF needs pyxtf (pip install pyxtf): {exc}") from None

    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"XTF file {p} does not exist")
    _check_packets(p, p.read_bytes())
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # pyxtf warns of every packet type it does not decode
            header, packets = pyxtf.xtf_read(str(p))
    except Exception as exc:  # pyxtf raises several types on a corrupt file
        raise SurveyError(f"{p}: pyxtf cannot read the file ({type(exc).__name__}: {exc})") from None
    kinds = {int(k): len(v) for k, v in packets.items()}
    bathy = packets.get(pyxtf.XTFHeaderType.qinsy_r2sonic_bathy, [])
    if not bathy:
        raise SurveyError(
            f"{p}: no QINSy R2Sonic bathymetry packets (type 65); packet types in the file: "
            f"{sorted(kinds)} (only type 65 is read)"
        )
    if header.NavUnits != 3:
        raise SurveyError(f"{p}: NavUnits is {header.NavUnits}; only latitude/longitude (3) is read")
    pings = []
    for i, packet in enumerate(bathy):
        raw = bytes(bytearray(packet)[:14]) + packet.data
        try:
            pings.append(_r2sonic_ping(raw, f"{p}, bathymetry packet {i}"))
        except struct.error as exc:
            raise SurveyError(f"{p}, bathymetry packet {i}: shorter than its sections say ({exc})") from None
    nav = np.array([(_nav_time(n), n.RawYcoordinate, n.RawXcoordinate)
                    for n in packets.get(pyxtf.XTFHeaderType.pos_raw_navigation, [])]).reshape(-1, 3)
    facts = {
        "recording_program": header.RecordingProgramName.decode("latin-1").strip("\x00"),
        "packet_counts": {str(k): v for k, v in sorted(kinds.items())},
    }
    return pings, nav, facts


def import_xtf(path: str | os.PathLike, *, crs: str | None, draft: float = 0.0) -> Survey:
    """A survey from an XTF multibeam file (QINSy R2Sonic bathymetry, packet type 65).

    Parameters
    ----------
    path : path
        The ``.xtf`` file.
    crs : str
        Projected CRS of the survey's frame (e.g. ``EPSG:32610``); the file's latitude and
        longitude are projected into it, the heading turned from true to grid north. One in
        feet is recorded as the same projection in metres (``meta["crs_given"]`` keeps the one
        given).
    draft : float
        Depth of the transducer below the water surface, m (the file has none: QINSy leaves the
        ping header's sensor depth at 0). Depths are then ``draft - heave + range * cos``.

    Returns
    -------
    Survey
        One ping per type-65 packet, time from the sonar's clock. ``true_pose`` is the raw
        navigation (type 107, ``meta["reference"] = "GNSS"``) interpolated to the ping times
        (the ping header's own position where the file has no such packets), heading the ping
        header's; ``dr_pose`` is the same track (the file has no separate dead reckoning).
        Footprints: across the array -> starboard, along -> forward (from the pitch), depth
        positive down; NaN where the range is 0 or the Q0 flags say the point failed the
        sonar's brightness or colinearity filter or has no detection.
    """
    if crs is None:
        raise SurveyError(f"{path}: give the projected CRS of the survey (crs=, CLI: --crs), e.g. EPSG:32610")
    draft = float(draft)
    if not (np.isfinite(draft) and 0.0 <= draft < 1000.0):
        raise SurveyError(f"draft must be between 0 and 1000 m, got {draft!r}")
    target = projected_crs(crs)
    p = Path(path)
    pings, nav, facts = _read_xtf(p)
    unix = _ping_times(p, pings)
    pose, origin, convergence, position_source = _pose(p, pings, nav, unix, crs, target)
    attitude = np.radians([(q.pitch, q.roll) for q in pings])
    two_way, sound_speed, valid, (forward, starboard, down) = _soundings(pings, attitude)
    vehicle_depth = draft - np.array([q.heave for q in pings])
    start = np.datetime64(round(float(unix[0]) * 1e6), "us")
    meta = {
        "format": "xtf",
        "source": str(p),
        "sonar": "R2Sonic (XTF packet type 65, BTH0)",
        **facts,
        "reference": "GNSS",
        "reference_note": f"vessel position from the {position_source}; dr_pose is the same track "
                          "(the file has no separate dead reckoning)",
        **target.meta(),
        "origin": list(origin),
        "start_time": np.datetime_as_string(start, unit="ms") + "Z",
        "vertical_datum": "water surface (draft - heave), no tide",
        "draft": draft,
        "sound_speed_m_s": [float(sound_speed.min()), float(sound_speed.max())],
        "ray_model": "straight rays at the transducer sound speed",
        "grid_convergence_deg": float(np.degrees(np.median(convergence))),
        "n_pings": len(pings),
        "n_beams": int(valid.shape[1]),
        "n_navigation": int(nav.shape[0]),
        "n_beams_without_return": int((~valid).sum()),
        "n_no_range": int((~np.isfinite(two_way)).sum()),
        "n_quality_rejected": int((np.isfinite(two_way) & ~valid).sum()),
        "n_no_depth": int((~valid.any(axis=1)).sum()),
    }
    return Survey(
        time=unix - unix[0],
        dr_pose=pose,
        vehicle_depth=vehicle_depth,
        beam_forward=forward,
        beam_starboard=starboard,
        beam_depth=vehicle_depth[:, None] + down,
        true_pose=pose.copy(),
        attitude=attitude,
        meta=meta,
    )


def _ping_times(p: Path, pings: list[_Ping]) -> np.ndarray:
    """The pings' Unix times; refused: pings with different numbers of beams, a time that does not
    increase."""
    sizes = sorted({q.angle.size for q in pings})
    if len(sizes) != 1:
        raise SurveyError(f"{p}: pings have different numbers of beams {sizes}")
    unix = np.array([q.time for q in pings])
    steps = np.diff(unix)
    if np.any(steps <= 0):
        i = int(np.argmax(steps <= 0))
        raise SurveyError(f"{p}: ping time does not increase at bathymetry packet {i + 1}")
    return unix


def _pose(p: Path, pings: list[_Ping], nav: np.ndarray, unix: np.ndarray, crs: str, target):
    """The pings' (north, east, heading from grid north) in the local frame, its origin, the grid
    convergence and where the positions come from: the raw navigation interpolated to the ping
    times where it has two or more fixes in increasing time, else the ping headers."""
    import pyproj

    if nav.shape[0] >= 2 and np.all(np.diff(nav[:, 0]) > 0):
        lat, lon = np.interp(unix, nav[:, 0], nav[:, 1]), np.interp(unix, nav[:, 0], nav[:, 2])
        position_source = "raw navigation packets (type 107), interpolated to the ping times"
    else:
        lat, lon = np.array([q.lat for q in pings]), np.array([q.lon for q in pings])
        position_source = "ping headers (type 65)"
    transform = pyproj.Transformer.from_crs("EPSG:4326", target.crs, always_xy=True).transform
    north, east, convergence = north_in_grid(transform, lon, lat, 1e-5)
    if not (np.all(np.isfinite(north)) and np.all(np.isfinite(east))):
        raise SurveyError(f"{p}: positions do not project into {crs}; give the CRS of the survey's region")
    origin = (float(np.floor(north.min())), float(np.floor(east.min())))
    heading = np.mod(np.radians([q.heading for q in pings]) + convergence, 2 * np.pi)
    pose = np.column_stack([north - origin[0], east - origin[1], heading])
    return pose, origin, convergence, position_source


def _soundings(pings: list[_Ping], attitude: np.ndarray):
    """The pings' two-way travel times, sound speeds, which points are valid (a range and Q0 flags
    passed) and the level-frame (forward, starboard, down) of the valid ones (NaN elsewhere)."""
    two_way = np.vstack([q.two_way_time for q in pings])
    angle = np.vstack([q.angle for q in pings])
    quality = np.vstack([q.quality for q in pings])
    sound_speed = np.array([q.sound_speed for q in pings])
    valid = np.isfinite(two_way) & ((quality & _Q_FILTERS) == _Q_FILTERS) & ((quality & _Q_DETECT) != 0)
    rng = np.where(valid, 0.5 * sound_speed[:, None] * two_way, np.nan)
    return two_way, sound_speed, valid, _level(rng, angle, attitude)


def _level(rng: np.ndarray, angle: np.ndarray, attitude: np.ndarray):
    """Level-frame (forward, starboard, down) of beams at ``angle`` across the array (starboard
    positive, in the plane of the array's athwartships axis and its normal), range ``rng``,
    turned by roll (positive starboard down) then pitch (positive bow up)."""
    pitch, roll = attitude[:, 0:1], attitude[:, 1:2]
    x, y, z = np.zeros_like(angle), np.sin(angle), np.cos(angle)
    y, z = y * np.cos(roll) - z * np.sin(roll), y * np.sin(roll) + z * np.cos(roll)
    x, z = x * np.cos(pitch) + z * np.sin(pitch), -x * np.sin(pitch) + z * np.cos(pitch)
    return rng * x, rng * y, rng * z
