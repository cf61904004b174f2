"""Faults a real survey has, laid on a clean one: blocks of bad pings and a wrong start.

The robustness study (``experiments/robustness``) and the tests navigate surveys spoiled in the
ways real ones are, and compare against the same survey clean:

- **footprint shift** (:func:`outlier_blocks`, ``kind="footprint_shift"``): in each block of
  consecutive pings every footprint is displaced by ``shift`` metres in one direction (drawn per
  block), as a wrong lever arm, a time-tag error or a sound-velocity error laying the swath in
  the wrong place would do: the depths are measured in one place and recorded in another;
- **depth bias** (``kind="depth_bias"``): every depth of a block is off by one value of
  ``bias`` metres (its size uniform in the range given, its sign drawn), as a wrong draft, a
  tide step or a heave error would do;
- **wrong start** (:func:`offset_start`): the whole dead-reckoned track is moved by an offset
  that the navigation model's start uncertainty does not admit (the vehicle started elsewhere
  than its log says).

Each returns a new :class:`~tangraph.survey.Survey` whose ``meta["faults"]`` lists what was
done (kind, pings, size), so a run can be scored against it.
"""

from __future__ import annotations

from typing import Any, Literal

import numpy as np

from tangraph.errors import TangraphError
from tangraph.geometry import rotate
from tangraph.survey import Survey

__all__ = ["faulty_pings", "offset_start", "outlier_blocks"]

FaultKind = Literal["footprint_shift", "depth_bias"]


def _check_fraction(fraction: float, block: int, n_pings: int) -> int:
    """The number of blocks of ``block`` pings that make ``fraction`` of the survey."""
    if not 0.0 <= float(fraction) < 1.0:
        raise TangraphError(f"outlier_blocks: fraction must lie in [0, 1), got {fraction!r}")
    if isinstance(block, bool) or not isinstance(block, int | np.integer) or block < 1:
        raise TangraphError(f"outlier_blocks: block must be an integer >= 1, got {block!r}")
    slots = n_pings // block
    count = round(float(fraction) * n_pings / block)
    if count > max(slots - 1, 0):
        raise TangraphError(
            f"outlier_blocks: {count} blocks of {block} pings do not fit in a survey of {n_pings} pings"
        )
    return count


def _block_sizes(shift, bias) -> tuple[float, float, float]:
    """:func:`outlier_blocks`' ``shift`` and ``bias`` range ``(low, high)`` checked, as floats."""
    try:
        shift = float(shift)
        low, high = (float(v) for v in bias)
    except (TypeError, ValueError):
        raise TangraphError(f"outlier_blocks: shift must be a number and bias a range (low, high), "
                            f"got shift={shift!r}, bias={bias!r}") from None
    if not (np.isfinite(shift) and shift >= 0):
        raise TangraphError(f"outlier_blocks: shift must be a finite number >= 0, got {shift!r}")
    if not (np.isfinite(low) and np.isfinite(high) and 0 <= low <= high):
        raise TangraphError(
            f"outlier_blocks: bias must be a range (low, high) with 0 <= low <= high, got {bias!r}")
    return shift, low, high


def outlier_blocks(
    survey: Survey,
    kind: FaultKind,
    fraction: float,
    *,
    rng: np.random.Generator,
    block: int = 20,
    shift: float = 30.0,
    bias: tuple[float, float] = (3.0, 10.0),
) -> Survey:
    """The survey with ``fraction`` of its pings spoiled in blocks of ``block`` consecutive pings.

    The blocks do not overlap: the survey is cut into slots of ``block`` pings from a random
    phase, and ``round(fraction * n_pings / block)`` slots are drawn.

    Parameters
    ----------
    survey : Survey
    kind : {"footprint_shift", "depth_bias"}
        See the module docstring.
    fraction : float
        Share of the pings spoiled, in [0, 1).
    rng : numpy.random.Generator
        Draws the blocks, the shift directions and the biases.
    block : int
        Pings per block.
    shift : float
        Metres every footprint of a block is moved (``footprint_shift``).
    bias : (float, float)
        Range of the size of a block's depth bias in metres (``depth_bias``).

    Returns
    -------
    Survey
        ``meta["faults"]`` gains one record per block: ``kind``, ``first`` and ``last`` ping,
        and ``shift_north``/``shift_east`` (m, in the world frame of the footprints as the
        dead reckoning lays them) or ``bias`` (m, added to the depths).

    Examples
    --------
    >>> spoiled = outlier_blocks(survey, "depth_bias", 0.2, rng=np.random.default_rng(0))  # doctest: +SKIP
    >>> faulty_pings(spoiled).mean()                                                      # doctest: +SKIP
    0.2
    """
    if kind not in ("footprint_shift", "depth_bias"):
        raise TangraphError(f"outlier_blocks: kind must be footprint_shift or depth_bias, got {kind!r}")
    n = survey.n_pings
    count = _check_fraction(fraction, block, n)
    shift, low, high = _block_sizes(shift, bias)
    phase = int(rng.integers(block))
    slots = (n - phase) // block
    firsts: Any = phase + block * np.sort(rng.choice(slots, size=count, replace=False)) if count else []
    forward, starboard = survey.beam_forward.copy(), survey.beam_starboard.copy()
    depth = survey.beam_depth.copy()
    records = []
    for first in (int(f) for f in firsts):
        pings = slice(first, first + block)
        record: dict[str, Any] = {"kind": kind, "first": first, "last": first + block - 1}
        if kind == "footprint_shift":
            direction = rng.uniform(0.0, 2.0 * np.pi)  # world frame, clockwise from north
            north, east = shift * np.cos(direction), shift * np.sin(direction)
            # into each ping's body frame by the DR heading: the shift is (north, east) in the
            # footprints a navigator lays with the dead reckoning (the recorded values)
            body = rotate(-survey.dr_pose[pings, 2][:, None], [north, east])  # R(psi)^T (north, east)
            forward[pings] += body[..., 0]
            starboard[pings] += body[..., 1]
            record.update(shift_north=float(north), shift_east=float(east))
        else:
            value = float(rng.choice([-1.0, 1.0]) * rng.uniform(low, high))
            depth[pings] += value
            record["bias"] = value
        records.append(record)
    meta = {**survey.meta, "faults": [*survey.meta.get("faults", []), *records]}
    return survey.replace(beam_forward=forward, beam_starboard=starboard, beam_depth=depth, meta=meta)


def offset_start(survey: Survey, offset) -> Survey:
    """The survey with its whole dead-reckoned track moved by ``offset (north, east)`` metres: it
    starts that far from where the vehicle was (``meta["faults"]`` records it)."""
    offset = np.asarray(offset, float)
    if offset.shape != (2,) or not np.all(np.isfinite(offset)):
        raise TangraphError(
            f"offset_start: offset must be a finite (north, east) pair, got {offset.tolist()!r}")
    record = {"kind": "start_offset", "first": 0, "last": survey.n_pings - 1,
              "shift_north": float(offset[0]), "shift_east": float(offset[1])}
    meta = {**survey.meta, "faults": [*survey.meta.get("faults", []), record]}
    return survey.replace(dr_pose=survey.dr_pose + np.array([*offset, 0.0]), meta=meta)


def faulty_pings(survey: Survey, kinds=("footprint_shift", "depth_bias")) -> np.ndarray:
    """``(K,)`` bool: the pings inside a block of ``meta["faults"]`` of one of ``kinds``."""
    mask = np.zeros(survey.n_pings, bool)
    for fault in survey.meta.get("faults", []):
        if fault["kind"] in kinds:
            mask[fault["first"] : fault["last"] + 1] = True
    return mask
