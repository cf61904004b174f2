"""True trajectories: straight lines, waypoint routes and lawnmower surveys.

Each returns ``(time (K,), pose (K, 3))`` sampled at a fixed rate, pose ``(north, east, psi)``
with psi clockwise from north; the vehicle moves at constant speed along straight legs and turns
at a bounded rate where legs meet (a coordinated turn, so headings are smooth).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from tangraph.errors import TangraphError
from tangraph.geometry import rotation_matrix
from tangraph.validation import number

__all__ = ["lawnmower", "straight_line", "waypoint_route"]


def _positive(value: float, name: str) -> float:
    return number(value, f"trajectory: {name}", open_low=True)


def straight_line(
    start: Sequence[float], heading: float, speed: float, duration: float, rate: float
) -> tuple[np.ndarray, np.ndarray]:
    """A straight run from ``start = (north, east)`` on ``heading`` (rad) for ``duration`` s.

    Examples
    --------
    >>> t, pose = straight_line((0.0, 0.0), np.pi / 2, 2.0, 10.0, 1.0)
    >>> pose[-1].round(6).tolist()
    [0.0, 20.0, 1.570796]
    """
    speed, duration, rate = (
        _positive(v, n) for v, n in ((speed, "speed"), (duration, "duration"), (rate, "rate"))
    )
    time = np.arange(int(np.floor(duration * rate + 1e-9)) + 1) / rate
    s = speed * time
    pose = np.column_stack(
        [
            start[0] + s * np.cos(heading),
            start[1] + s * np.sin(heading),
            np.full(time.size, np.mod(heading, 2 * np.pi)),
        ]
    )
    return time, pose


def waypoint_route(
    points: Sequence[Sequence[float]], speed: float, rate: float, *, turn_radius: float = 0.0
) -> tuple[np.ndarray, np.ndarray]:
    """Through ``points`` ((north, east), at least 2) at constant ``speed``, sampled at ``rate``.

    With ``turn_radius > 0`` each corner is rounded by a circular arc of that radius (the
    arc is tangent to both legs), so the heading changes continuously.
    """
    pts = np.asarray(points, dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 2 or not np.all(np.isfinite(pts)):
        raise TangraphError(
            f"trajectory: waypoints must be (N >= 2, 2) finite (north, east), got {pts.shape}"
        )
    speed, rate = _positive(speed, "speed"), _positive(rate, "rate")
    legs = np.diff(pts, axis=0)
    lengths = np.hypot(legs[:, 0], legs[:, 1])
    if np.any(lengths == 0):
        raise TangraphError(f"trajectory: repeated waypoint at index {int(np.argmax(lengths == 0)) + 1}")
    headings = np.arctan2(legs[:, 1], legs[:, 0])
    # the path as a sequence of (straight or arc) pieces, each with its length
    pieces: list[tuple] = []
    cut_prev = 0.0
    for k in range(len(legs)):
        cut_next = 0.0
        if k + 1 < len(legs) and turn_radius > 0:
            turn = np.angle(np.exp(1j * (headings[k + 1] - headings[k])))
            cut_next = min(turn_radius * abs(np.tan(turn / 2)), 0.5 * lengths[k], 0.5 * lengths[k + 1])
        direction = legs[k] / lengths[k]
        a = pts[k] + direction * cut_prev
        straight = lengths[k] - cut_prev - cut_next
        pieces.append(("line", a, headings[k], straight))
        if cut_next > 0:
            turn = np.angle(np.exp(1j * (headings[k + 1] - headings[k])))
            radius = cut_next / abs(np.tan(turn / 2)) if abs(turn) > 1e-12 else 0.0
            pieces.append(("arc", a + direction * straight, headings[k], radius, turn))
        cut_prev = cut_next
    piece_len = np.array([p[3] if p[0] == "line" else p[3] * abs(p[4]) for p in pieces])
    total = float(piece_len.sum())
    time = np.arange(int(np.floor(total / speed * rate + 1e-9)) + 1) / rate
    s = speed * time
    edges = np.concatenate([[0.0], np.cumsum(piece_len)])
    which = np.clip(np.searchsorted(edges, s, side="right") - 1, 0, len(pieces) - 1)
    pose = np.empty((time.size, 3))
    for k, piece in enumerate(pieces):  # a loop over the few pieces, vectorised over samples
        sel = which == k
        u = s[sel] - edges[k]
        if piece[0] == "line":
            _, a, h, _ = piece
            pose[sel] = np.column_stack([a[0] + u * np.cos(h), a[1] + u * np.sin(h), np.full(u.size, h)])
        else:
            _, a, h, radius, turn = piece
            sign = np.sign(turn)
            h_u = h + sign * u / radius
            # centre of the arc is to starboard (turn > 0, clockwise) or port of the start
            cn, ce = a[0] - sign * radius * np.sin(h), a[1] + sign * radius * np.cos(h)
            pose[sel] = np.column_stack(
                [cn + sign * radius * np.sin(h_u), ce - sign * radius * np.cos(h_u), h_u]
            )
    pose[:, 2] = np.mod(pose[:, 2], 2 * np.pi)
    return time, pose


def lawnmower(
    origin: Sequence[float],
    heading: float,
    line_length: float,
    line_spacing: float,
    n_lines: int,
    speed: float,
    rate: float,
    *,
    turn_radius: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """A lawnmower survey: ``n_lines`` parallel lines of ``line_length`` on ``heading``, stepping
    ``line_spacing`` to starboard, joined by turns (radius default ``line_spacing / 2``)."""
    line_length, line_spacing = _positive(line_length, "line_length"), _positive(line_spacing, "line_spacing")
    if int(n_lines) < 1:
        raise TangraphError(f"trajectory: n_lines must be at least 1, got {n_lines!r}")
    along, across = rotation_matrix(heading).T  # the heading's unit vector and its starboard
    points = []
    for k in range(int(n_lines)):
        start = np.asarray(origin, float) + k * line_spacing * across
        ends = [start, start + line_length * along]
        points.extend(ends if k % 2 == 0 else ends[::-1])
    radius = 0.5 * line_spacing if turn_radius is None else turn_radius
    return waypoint_route(points, speed, rate, turn_radius=radius)
