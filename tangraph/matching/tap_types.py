"""The settings and results of a terrain-aided position fix (:func:`tangraph.matching.tap_fix`): the
criterion, the confidence regions' methods, :class:`TapConfig`, :class:`Region`,
:class:`FixQuality` and :class:`TapFix`."""

from __future__ import annotations

import dataclasses
import enum
from typing import Literal, Protocol

import numpy as np

from tangraph.errors import TangraphError
from tangraph.matching.search import CandidateGrid

__all__ = ["Criterion", "FixQuality", "Region", "RegionMethod", "TapConfig", "TapFix", "TerrainFix"]


class Criterion(enum.StrEnum):
    """What the fix minimises (or, for correlation, maximises)."""

    MLE = "mle"  # sigma^2 with the tide removed (Wang et al. eqs. 3-6)
    MSD = "msd"
    MAD = "mad"
    CORRELATION = "correlation"


class RegionMethod(enum.StrEnum):
    XIE = "xie"
    WANG = "wang"
    CALIBRATED = "calibrated"


@dataclasses.dataclass(frozen=True)
class TapConfig:
    """Settings of a fix. ``step`` defaults to the map's cell size; angles in radians."""

    half_width: float = 50.0
    step: float | None = None
    headings: tuple[float, ...] = (0.0,)
    criterion: Criterion = Criterion.MLE
    alpha: float = 0.05
    covariance: Literal["region", "curvature", "crlb"] = "region"
    calibrate: bool = True
    jackknife: bool = True
    min_soundings: int = 10
    search_method: Literal["auto", "direct", "fft"] = "auto"
    max_area_fraction: float = 0.5

    def __post_init__(self) -> None:
        if not 0.0 < self.alpha < 1.0:
            raise TangraphError(f"TapConfig.alpha must lie in (0, 1), got {self.alpha!r}")
        if not (np.isfinite(self.half_width) and self.half_width > 0):
            raise TangraphError(f"TapConfig.half_width must be positive, got {self.half_width!r}")
        if self.step is not None and not (np.isfinite(self.step) and self.step > 0):
            raise TangraphError(f"TapConfig.step must be positive, got {self.step!r}")
        if self.covariance not in ("region", "curvature", "crlb"):
            raise TangraphError(
                f"TapConfig.covariance must be region, curvature or crlb, got {self.covariance!r}"
            )
        if self.search_method not in ("auto", "direct", "fft"):
            raise TangraphError(
                f"TapConfig.search_method must be auto, direct or fft, got {self.search_method!r}"
            )
        object.__setattr__(self, "criterion", Criterion(self.criterion))
        object.__setattr__(self, "headings", tuple(float(h) for h in self.headings))


@dataclasses.dataclass(frozen=True, eq=False)
class Region:
    """A confidence region as a mask over the candidate grid (at the fix's heading)."""

    method: RegionMethod
    alpha: float
    mask: np.ndarray  # (nn, ne) bool
    threshold: float  # on Q (Xie, calibrated) or on S (Wang)
    area: float  # m^2


@dataclasses.dataclass(frozen=True)
class FixQuality:
    """Figures that say whether the graph may trust a fix."""

    peak_ratio: float  # criterion of the best separate basin / criterion at the fix (inf if none)
    n_basins: int  # connected parts of the calibrated region
    area_fraction: float  # calibrated region area / search area
    touches_edge: bool  # the calibrated region reaches the edge of the search grid
    reasons: tuple[str, ...]  # why the fix is flagged; empty if it is not
    best_on_edge: bool = False  # the best candidate lies on the outer ring of the search grid
    holds_centre: bool = False  # the calibrated region holds the search's centre (the prediction)

    @property
    def outside(self) -> bool:
        """The best match lies on the edge of the search: the best fit is likely outside it
        (the prediction the search was centred on is wrong by more than its half-width)."""
        return self.best_on_edge

    @property
    def informative(self) -> bool:
        return not any(r.startswith("uninformative") for r in self.reasons)

    @property
    def multimodal(self) -> bool:
        return any(r.startswith("multimodal") for r in self.reasons)

    @property
    def depth_fault(self) -> bool:
        """The window's depths are off the tide the graph holds by more than a position could
        explain (the point-mass front end's test): a depth error of its pings, not a place."""
        return any(r.startswith("depth fault") for r in self.reasons)


class TerrainFix(Protocol):
    """What a window's terrain fix gives the graph, whichever front end made it (a TAP search,
    :class:`TapFix`, or the point-mass front end's :class:`tangraph.graph.posterior_fix.WindowFix`):
    the window of pings ``first`` to ``index``, the ``position (2,)`` and ``covariance (2, 2)``
    (world, north/east), the ``tide`` and the soundings' residual std ``sigma`` at it, their
    number, the ``quality`` flags and whether it is ``accepted``."""

    @property
    def index(self) -> int: ...
    @property
    def first(self) -> int: ...
    @property
    def position(self) -> np.ndarray: ...
    @property
    def covariance(self) -> np.ndarray: ...
    @property
    def tide(self) -> float: ...
    @property
    def sigma(self) -> float: ...
    @property
    def n_soundings(self) -> int: ...
    @property
    def quality(self) -> FixQuality: ...
    @property
    def accepted(self) -> bool: ...


@dataclasses.dataclass(frozen=True, eq=False)
class TapFix:
    """A terrain-aided position fix of the window of pings from ``first`` to ``index``."""

    index: int
    first: int
    position: np.ndarray  # (2,) north, east
    covariance: np.ndarray  # (2, 2), the one chosen by TapConfig.covariance
    tide: float  # mean of measured - map at the fix: the tide, measured = map + tide
    sigma: float  # std of the sounding error, sqrt of Wang's eq. 4 at the fix
    n_soundings: int
    method: Criterion
    heading_offset: float
    covariances: dict[str, np.ndarray]
    regions: dict[RegionMethod, Region]
    quality: FixQuality
    grid: CandidateGrid
    surface: np.ndarray  # Q over the grid at the fix's heading, NaN where invalid
    variance_inflation: float
    prior: np.ndarray

    @property
    def accepted(self) -> bool:
        """Informative and unimodal: fit to become a prior factor."""
        return self.quality.informative and not self.quality.multimodal

    @property
    def region(self) -> Region:
        return self.regions[RegionMethod.CALIBRATED]
