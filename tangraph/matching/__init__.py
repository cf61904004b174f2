"""Batch terrain matching: TAP fixes with confidence regions and covariances (no gtsam here)."""

from tangraph.matching.patch import MatchingError, Patch, calibrated_window, shape_covariance, window_patch
from tangraph.matching.search import CandidateGrid, CriterionSums, criterion_sums
from tangraph.matching.tap import (
    Criterion,
    FixQuality,
    Region,
    RegionMethod,
    TapConfig,
    TapFix,
    criterion_at,
    nees,
    region_thresholds,
    tap_fix,
    tap_fix_patch,
)
from tangraph.matching.tap_types import TerrainFix

__all__ = [
    "CandidateGrid",
    "Criterion",
    "CriterionSums",
    "FixQuality",
    "MatchingError",
    "Patch",
    "Region",
    "RegionMethod",
    "TapConfig",
    "TapFix",
    "TerrainFix",
    "calibrated_window",
    "criterion_at",
    "criterion_sums",
    "nees",
    "region_thresholds",
    "shape_covariance",
    "tap_fix",
    "tap_fix_patch",
    "window_patch",
]
