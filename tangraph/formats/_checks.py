"""Checks every importer makes of its options: the target CRS and the clock's time zone."""

from __future__ import annotations

from tangraph.survey import SurveyError


def projected_crs(crs: str):
    """``crs`` as a ``pyproj.CRS``; refused unless pyproj reads it and it is projected."""
    import pyproj

    try:
        parsed = pyproj.CRS.from_user_input(crs)
    except pyproj.exceptions.CRSError:
        raise SurveyError(f"crs={crs!r} is not understood by pyproj (e.g. EPSG:32633)") from None
    if not parsed.is_projected:
        raise SurveyError(
            f"crs={crs!r} is not a projected CRS: give one in metres (crs=, CLI: --crs), "
            "e.g. the UTM zone EPSG:32633"
        )
    return parsed


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
