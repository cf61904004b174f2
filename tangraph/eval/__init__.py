"""Evaluation: metrics of estimated tracks against the truth and the posterior Cramér-Rao bound.

:mod:`tangraph.eval.metrics` compares a :class:`~tangraph.track.Track` with the true poses (RMSE,
NEES and its chi-square band); :mod:`tangraph.eval.crb` computes the physical limit of a survey,
the posterior Cramér-Rao bound (PCRB) of its linearised error-state model, to report next to an
estimator's RMSE; where the map has an error, the bound carries it as a Gaussian-Markov random
field (:mod:`tangraph.eval.map_field`) solved sparsely with the track (:mod:`tangraph.eval.field_bound`,
:mod:`tangraph.eval.selected_inverse`);
:mod:`tangraph.eval.map_check` tests a gridded map's stated error against held-out surveys (check
lines). Nothing here touches files.
"""

from tangraph.eval.crb import CramerRaoBound, posterior_crb
from tangraph.eval.map_check import MapCheck, calibrate_error, check_map_error
from tangraph.eval.metrics import (
    anees_band,
    bound_rmse,
    format_figure,
    metrics_with_bound,
    position_nees,
    track_metrics,
)

__all__ = [
    "CramerRaoBound",
    "MapCheck",
    "anees_band",
    "bound_rmse",
    "calibrate_error",
    "check_map_error",
    "format_figure",
    "metrics_with_bound",
    "position_nees",
    "posterior_crb",
    "track_metrics",
]
