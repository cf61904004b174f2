"""Errors of a track against the truth, shared by the tests of the online navigator and of the
smoother."""

from __future__ import annotations

import numpy as np

from tangraph.track import position_errors


def rmse(track, truth) -> float:
    return float(np.sqrt(np.mean(position_errors(track, truth) ** 2)))


def mean_nees(track, truth) -> float:
    err = track.pose[:, :2] - truth[:, :2]
    cov = track.covariance[:, :2, :2]
    return float(np.mean([e @ np.linalg.solve(c, e) for e, c in zip(err, cov, strict=True)]))
