"""What became of each terrain fix a method attempted: one record type for the graph and the
fix-based filters (TERCOM-PF, MLE), kept in ``Track.fixes``."""

from __future__ import annotations

import dataclasses
import enum

import numpy as np

__all__ = ["FixRecord", "FixStatus"]


class FixStatus(enum.StrEnum):
    """What became of a window's fix: used by the estimator, or why not (one meaning per value;
    what the online navigator's fix policy does with a fix is :mod:`tangraph.graph.policy`, a
    filter's :func:`tangraph.filters.fixes.decide_fix`)."""

    ACCEPTED = "accepted"  #: used: its factor is in the graph, or the filter took it
    GATE = "gate"  #: its NIS against the prediction is above the gate
    MULTIMODAL = "multimodal"  #: the calibrated region has several parts: two places fit
    UNINFORMATIVE = "uninformative"  #: the region reaches the search's edge or is too large
    MATCH_FAILED = "match failed"  #: no fix could be made (``detail`` says why)
    INVALID_COVARIANCE = "invalid covariance"  #: not finite, symmetric, positive definite
    MISFIT = "misfit"  #: the soundings fit the map nowhere in the search: bad data, not a position
    OUTSIDE_SEARCH = "outside search"  #: the best match lies on the search's edge: the truth may lie beyond
    HELD = "held"  #: within the gate but surprising: waiting for a later fix to agree (still so at the end)
    CONFIRMED = "confirmed"  #: held, then a later fix agreed with it: that fix was taken (``detail``: which)
    UNCONFIRMED = "unconfirmed"  #: held, then dropped: no later fix agreed with it (``detail`` says why)
    VAGUE = "vague"  #: as surprising as a held fix it agrees with, but too vague to confirm it: not used
    CANDIDATE = "candidate"  #: a lost navigator's relocalisation candidate that no relocalisation used
    GIVEN_UP = "given up"  #: used, then removed: the navigator found the belief it was searched around wrong
    LEFT_WINDOW = "left window"  #: to be used late, but its key pose had left iSAM2's window: not added
    OUTLIER = "outlier"  #: the batch smoother's robust solve found it inconsistent with the rest
    CHECKED = "checked"  #: made as a check while the online graph tracked on soundings: not used

    @property
    def says_lost(self) -> bool:
        """Whether a window with this outcome says the prediction it was searched around is
        wrong (the evidence that makes a navigator lost)."""
        return self in (FixStatus.GATE, FixStatus.OUTSIDE_SEARCH)


@dataclasses.dataclass(frozen=True)
class FixRecord:
    """One window's outcome, as kept in ``Track.fixes``: the ping ``index`` it refers to,
    the fix's position and the covariance the estimator gave it (NaN without a fix), its
    ``status``, its ``nis`` against the prediction (NaN if not judged), the search ``half_width``
    (m) and a ``detail`` for people (never parsed).

    Examples
    --------
    >>> record = FixRecord.of(9, None, FixStatus.MATCH_FAILED, float("nan"), 30.0, "no soundings")
    >>> record.accepted, record.reason
    (False, 'match failed: no soundings')
    """

    index: int
    north: float
    east: float
    cov_nn: float
    cov_ne: float
    cov_ee: float
    status: FixStatus
    nis: float
    half_width: float
    detail: str = ""

    @classmethod
    def of(cls, index: int, fix, status: FixStatus, nis: float, half_width: float,
           detail: str = "") -> FixRecord:
        """The record of ``fix`` (anything with ``position (2,)`` and ``covariance (2, 2)``; None:
        no fix was made) for the window ending at ping ``index``."""
        pos = np.full(2, np.nan) if fix is None else np.asarray(fix.position, float)
        cov = np.full((2, 2), np.nan) if fix is None else np.asarray(fix.covariance, float)
        return cls(int(index), float(pos[0]), float(pos[1]), float(cov[0, 0]), float(cov[0, 1]),
                   float(cov[1, 1]), status, float(nis), float(half_width), detail)

    @property
    def accepted(self) -> bool:
        """Whether the estimator used the fix."""
        return self.status is FixStatus.ACCEPTED

    @property
    def position(self) -> np.ndarray:
        return np.array([self.north, self.east])

    @property
    def covariance(self) -> np.ndarray:
        return np.array([[self.cov_nn, self.cov_ne], [self.cov_ne, self.cov_ee]])

    @property
    def reason(self) -> str:
        """The status and its detail, for people."""
        return f"{self.status.value}: {self.detail}" if self.detail else self.status.value

    def as_dict(self) -> dict:
        """JSON-ready form."""
        return {**dataclasses.asdict(self), "status": self.status.value}
