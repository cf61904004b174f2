"""Checks every importer makes of its options and what it read: the target CRS, the clock's time
zone, and soundings within an echo sounder's reach of the vehicle."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from tangraph.survey import SurveyError

#: A sounding lies at most this many times its depth below the vehicle from it (a beam 85 deg off
#: the vertical), and never farther than ``MIN_REACH`` m beyond that
REACH_PER_DEPTH = 11.5
MIN_REACH = 100.0


def check_reach(forward, starboard, depth, vehicle_depth, where: str) -> None:
    """Refuse soundings farther from the vehicle than an echo sounder reaches: ``sqrt(forward^2 +
    starboard^2) > max(MIN_REACH, REACH_PER_DEPTH * |depth - vehicle_depth|)`` (m; ``(K, B)``,
    ``vehicle_depth (K,)``), which columns in the wrong order (x and y, latitude and longitude),
    another CRS or a clock offset between the files make. The first such sounding is named."""
    reach = np.hypot(forward, starboard)
    limit = np.maximum(MIN_REACH, REACH_PER_DEPTH * np.abs(depth - np.asarray(vehicle_depth)[:, None]))
    far = np.isfinite(reach) & np.isfinite(limit) & (reach > limit)
    if far.any():
        k, b = (int(v) for v in np.argwhere(far)[0])
        raise SurveyError(
            f"{where}: {int(far.sum())} soundings lie farther from the vehicle than an echo sounder reaches "
            f"(ping {k}: {reach[k, b]:,.0f} m away, {abs(depth[k, b] - vehicle_depth[k]):.1f} m below it): "
            "the x and y (or latitude and longitude) columns swapped, another CRS, or the clocks apart?")


@dataclasses.dataclass(frozen=True)
class SurveyCRS:
    """The projected CRS a survey is imported in, with its axes in metres.

    A survey's frame is metres (``docs/conventions.rst``). A CRS whose axes are in another unit
    (US survey feet, feet) becomes the same projection with metre axes, by the rule the maps
    follow (:func:`tangraph.maps.io.metric_crs`): latitude/longitude projected into it come out
    in metres, and coordinates read in the given CRS are multiplied by ``metres_per_unit``.

    Attributes
    ----------
    given : str
        The CRS as the user gave it.
    crs : pyproj.CRS
        The same projection with metre axes (the given one when it is in metres already).
    unit : str
        The unit of the given CRS's axes (``"metre"``, ``"US survey foot"``, ...).
    metres_per_unit : float
        Metres per unit of the given CRS's axes (1 for a CRS in metres).
    """

    given: str
    crs: Any
    unit: str
    metres_per_unit: float

    @property
    def converted(self) -> bool:
        """Whether the given CRS is not in metres (its coordinates are converted)."""
        return self.metres_per_unit != 1.0

    def meta(self) -> dict:
        """What a survey records of its CRS: ``crs`` (in metres: the given one, else the WKT of
        the metric projection, which writers use to go back to latitude/longitude) and, for a
        converted one, ``crs_given`` (the CRS given, its unit and the metres per unit)."""
        if not self.converted:
            return {"crs": self.crs.to_string()}
        return {"crs": self.crs.to_wkt(),
                "crs_given": {"crs": self.given, "unit": self.unit, "metres_per_unit": self.metres_per_unit}}


def projected_crs(crs: str) -> SurveyCRS:
    """``crs`` as a :class:`SurveyCRS`, in metres.

    Raises
    ------
    SurveyError
        pyproj does not read ``crs``, or it is not projected (geographic: degrees).
    """
    import pyproj

    from tangraph.maps.io import metric_crs

    try:
        parsed = pyproj.CRS.from_user_input(crs)
    except pyproj.exceptions.CRSError:
        raise SurveyError(f"crs={crs!r} is not understood by pyproj (e.g. EPSG:32633)") from None
    if not parsed.is_projected:
        raise SurveyError(
            f"crs={crs!r} is not a projected CRS: give one in metres or feet (crs=, CLI: --crs), "
            "e.g. the UTM zone EPSG:32633"
        )
    metric, factor = metric_crs(str(crs), f"crs={crs!r}")
    unit = parsed.axis_info[0].unit_name if parsed.axis_info else "metre"
    return SurveyCRS(given=str(crs), crs=pyproj.CRS.from_user_input(metric), unit=unit,
                     metres_per_unit=float(factor))


def time_zone(timezone: str | None):
    """``timezone`` as a ``zoneinfo.ZoneInfo`` (None stays None); an unknown name is refused."""
    if timezone is None:
        return None
    import zoneinfo

    try:
        return zoneinfo.ZoneInfo(timezone)
    except (zoneinfo.ZoneInfoNotFoundError, ValueError):
        raise SurveyError(
            f"timezone={timezone!r} is not a known time zone (e.g. UTC, Europe/Berlin)"
        ) from None
