"""A survey meets its map (:func:`tangraph.navigation.survey_on_map`): the survey put into the map's
frame (:func:`in_map_frame`: shifted between origins, or reprojected between CRSs), refused on a
map it was not simulated on (:func:`check_map`, by :func:`map_identity`) or when it does not
overlap the map's data (:func:`check_overlap`). Re-exported by :mod:`tangraph.navigation`."""

from __future__ import annotations

import numpy as np

from tangraph.errors import TangraphError
from tangraph.maps.grid import BathymetryMap
from tangraph.maps.projection import same_crs
from tangraph.survey import Survey

__all__ = ["MIN_MAP_OVERLAP", "check_map", "check_overlap", "in_map_frame", "map_identity"]


#: A survey is navigated on a map only when at least this share of its pings with soundings has
#: a sounding on the map's data (footprints laid with the dead reckoning in the map's frame). A
#: survey that leaves the map, or starts off it, is navigated; one that (nearly) never meets it
#: is refused: its map is another place's, or its CRS or origin is wrong.
MIN_MAP_OVERLAP = 0.05
#: beams per ping looked at by the overlap test (evenly spread over the swath)
_OVERLAP_BEAMS = 16


_NAVIGATE_ANYWAY = ("pass the map of the survey's area (or other_map=True, CLI: --other-map, to run it on "
                    "this one anyway)")


def check_overlap(survey: Survey, bathymetry: BathymetryMap, *, where: str = "",
                  remedy: str = _NAVIGATE_ANYWAY) -> None:
    """Refuse a survey that (nearly) never meets the map's data.

    The survey is put into the map's frame (:func:`in_map_frame`) and its soundings laid with
    the dead reckoning (up to 16 beams per ping, spread over the swath). It is refused when
    fewer than :data:`MIN_MAP_OVERLAP` (5 %) of its pings with soundings have one on the map's
    data (a cell that is not NaN). A survey that partly leaves the map, or starts off it,
    passes: off the map the estimators keep the dead reckoning.

    Parameters
    ----------
    survey : Survey
        In the map's frame or in the CRS and origin it records.
    bathymetry : BathymetryMap
        The map.

    Raises
    ------
    TangraphError
        One line (after ``where``) naming how many pings meet the map, the survey's extent and
        the map's (in latitude/longitude where both have a CRS, else in the map's local metres),
        the two CRSs where they differ, and ``remedy`` (by default the option that navigates it
        anyway: ``other_map=True``, CLI: ``--other-map``).
    """
    problem = _overlap_problem(in_map_frame(survey, bathymetry), bathymetry, survey, remedy)
    if problem:
        raise TangraphError(where + problem)


def _overlap_problem(framed: Survey, bathymetry: BathymetryMap, original: Survey,
                     remedy: str = _NAVIGATE_ANYWAY) -> str | None:
    """Why ``framed`` (in the map's frame) is not to be navigated on the map, or None;
    ``original`` is the survey as given (its own CRS), for its extent in latitude/longitude."""
    n_beams = framed.beam_depth.shape[1]
    beams = np.unique(np.linspace(0, n_beams - 1, min(n_beams, _OVERLAP_BEAMS)).astype(int))
    north, east = framed.footprints()
    has = np.isfinite(framed.beam_depth[:, beams])
    rows = has.any(axis=1)  # pings with a sounding among the beams looked at
    on_data = np.isfinite(bathymetry.depth_at(np.where(has, north[:, beams], np.nan)[rows],
                                              np.where(has, east[:, beams], np.nan)[rows])).any(axis=1)
    total, met = int(rows.sum()), int(on_data.sum())
    if total == 0 or met >= MIN_MAP_OVERLAP * total:
        return None
    pose = original.dr_pose
    survey_box = _lonlat_box(original.meta.get("crs"), original.meta.get("origin"),
                             (pose[:, 0].min(), pose[:, 0].max()), (pose[:, 1].min(), pose[:, 1].max()))
    finite = np.isfinite(bathymetry.depth)
    data_box = None
    if finite.any():
        rows_, cols = np.flatnonzero(finite.any(axis=1)), np.flatnonzero(finite.any(axis=0))
        n_span = (bathymetry.north[rows_[0]], bathymetry.north[rows_[-1]])
        e_span = (bathymetry.east[cols[0]], bathymetry.east[cols[-1]])
        data_box = _lonlat_box(bathymetry.crs, bathymetry.origin, n_span, e_span)
        data_text = _box_text(data_box) if data_box is not None else _local_text(n_span, e_span)
    else:
        data_text = "(none: every cell is NaN)"
    if survey_box is not None and data_box is not None:
        survey_text = _box_text(survey_box)
    else:
        n, e = framed.dr_pose[:, 0], framed.dr_pose[:, 1]
        survey_text = _local_text((n.min(), n.max()), (e.min(), e.max()))
    apart = ""
    if survey_box is not None and data_box is not None:
        km = _distance_km(survey_box, data_box)
        crs, map_crs = original.meta.get("crs"), bathymetry.crs
        if km > 100.0:
            apart = f"; it lies {km:,.0f} km from them"
            if not same_crs(crs, map_crs):
                apart += f" (its CRS {_crs_name(crs)}, the map's {_crs_name(map_crs)}: another region?)"
    return (
        f"the survey does not overlap map {bathymetry.name!r}: {met} of its {total} pings with soundings "
        f"({met / total:.1%}; at least {MIN_MAP_OVERLAP:.0%} needed) have a sounding on the map's data; "
        f"the survey spans {survey_text}, the map's data {data_text}{apart}; {remedy}"
    )


def _lonlat_box(crs, origin, north_span, east_span) -> np.ndarray | None:
    """(lat min, lat max, lon min, lon max) of a local box in ``crs`` with ``origin``, or None
    where there is no CRS or it does not go to latitude/longitude."""
    import pyproj

    if crs is None or origin is None:
        return None
    north, east = np.meshgrid(np.asarray(north_span, float), np.asarray(east_span, float))
    try:
        to_wgs84 = pyproj.Transformer.from_crs(crs, "EPSG:4326", always_xy=True)
        lon, lat = to_wgs84.transform(east.ravel() + float(origin[1]), north.ravel() + float(origin[0]))
    except (pyproj.exceptions.CRSError, pyproj.exceptions.ProjError):
        return None
    lon, lat = np.asarray(lon, float), np.asarray(lat, float)
    if not (np.all(np.isfinite(lon)) and np.all(np.isfinite(lat))):
        return None
    return np.array([lat.min(), lat.max(), lon.min(), lon.max()])


def _box_text(box: np.ndarray) -> str:
    return f"lat {box[0]:.4f}..{box[1]:.4f}, lon {box[2]:.4f}..{box[3]:.4f}"


def _local_text(north_span, east_span) -> str:
    (n0, n1), (e0, e1) = north_span, east_span
    return f"north {n0:.0f}..{n1:.0f} m, east {e0:.0f}..{e1:.0f} m (the map's frame)"


def _distance_km(a: np.ndarray, b: np.ndarray) -> float:
    """Distance (km, WGS84 ellipsoid) between the centres of two latitude/longitude boxes."""
    import pyproj

    _, _, metres = pyproj.Geod(ellps="WGS84").inv(
        (a[2] + a[3]) / 2, (a[0] + a[1]) / 2, (b[2] + b[3]) / 2, (b[0] + b[1]) / 2)
    return float(metres) / 1000.0


def _crs_name(crs) -> str:
    import pyproj

    try:
        parsed = pyproj.CRS.from_user_input(crs)
    except pyproj.exceptions.CRSError:
        return repr(crs)
    code = parsed.to_authority()
    if code:
        return f"{code[0]}:{code[1]} ({parsed.name})"
    return repr(parsed.name) if parsed.name != "unknown" else repr(str(crs))


def map_identity(bathymetry: BathymetryMap) -> dict:
    """What identifies a map: its name, CRS, shape, cell, the projected extent of its cell
    centres and a content hash (SHA-256 of its depths, NaN included), as recorded in a survey
    simulated on it (``meta["map_identity"]``)."""
    import hashlib

    depth = np.ascontiguousarray(bathymetry.depth, dtype=np.float64)
    n_lo, n_hi, e_lo, e_hi = bathymetry.extent
    north0, east0 = bathymetry.origin
    return {
        "name": bathymetry.name, "crs": bathymetry.crs, "shape": [int(v) for v in depth.shape],
        "cell": [float(v) for v in bathymetry.cell_size],
        "extent": [float(n_lo + north0), float(n_hi + north0), float(e_lo + east0), float(e_hi + east0)],
        "sha256": hashlib.sha256(depth.tobytes()).hexdigest()[:32],
    }


def check_map(survey: Survey, bathymetry: BathymetryMap) -> None:
    """Refuse to navigate a survey simulated on one map with another: the fixes would be made
    against a seafloor the soundings never saw. A survey without ``meta["map_identity"]`` (a
    recorded one) is not checked.

    Raises
    ------
    TangraphError
        The map's content, extent or CRS differs from the one the survey records; names both and
        the option that navigates anyway (``other_map=True``, CLI: ``--other-map``).
    """
    recorded = survey.meta.get("map_identity")
    if not recorded:
        return
    here = map_identity(bathymetry)
    if recorded.get("sha256") == here["sha256"]:
        return
    what = [k for k in ("crs", "shape", "cell", "extent") if recorded.get(k) != here[k]] or ["depths"]
    raise TangraphError(
        f"the survey was simulated on map {recorded.get('name')!r}, not on {bathymetry.name!r} "
        f"(they differ in {', '.join(what)}); pass the map it was made on, or other_map=True "
        "(CLI: --other-map) to navigate it on this one anyway"
    )


def in_map_frame(survey: Survey, bathymetry: BathymetryMap) -> Survey:
    """The survey with its poses in the map's local frame.

    A recorded survey keeps the projected CRS and the local origin it was imported in
    (``meta["crs"]``, ``meta["origin"]``). When the CRS is the map's, its poses are shifted by the
    difference of the origins. When it is another (projected) CRS, the poses are reprojected
    (pyproj: survey frame + survey origin -> survey CRS -> map CRS -> minus the map's origin) and
    their headings turned by the difference of grid convergence between the two CRSs at each
    pose (the angle, in the map's grid, of a 1 m step to grid north of the survey's CRS);
    ``meta["reprojected_from"]`` then holds the survey's former CRS and origin. Body-frame beam
    footprints stay as they are (both projections are conformal). A survey that records no CRS
    or origin, or a map without a CRS, is returned as it is.

    Raises
    ------
    TangraphError
        A CRS pyproj does not understand or that is not projected, or poses the map's CRS
        cannot hold.
    """
    crs, origin = survey.meta.get("crs"), survey.meta.get("origin")
    if crs is None or origin is None or bathymetry.crs is None:
        return survey
    source, target = _projected(crs, "the survey's"), _projected(bathymetry.crs, f"map {bathymetry.name!r}'s")
    if not source.equals(target):
        return _reprojected(survey, bathymetry, source, target)
    shift = np.array([*(np.asarray(origin, float) - np.asarray(bathymetry.origin, float)), 0.0])
    if not np.any(shift):
        return survey
    truth = None if survey.true_pose is None else survey.true_pose + shift
    meta = {**survey.meta, "origin": [float(v) for v in bathymetry.origin]}
    return survey.replace(dr_pose=survey.dr_pose + shift, true_pose=truth, meta=meta)


def _projected(crs, whose: str):
    import pyproj

    try:
        parsed = pyproj.CRS.from_user_input(crs)
    except pyproj.exceptions.CRSError:
        raise TangraphError(f"{whose} CRS {crs!r} is not understood by pyproj") from None
    if not parsed.is_projected:
        raise TangraphError(f"{whose} CRS {crs!r} is not projected (metres): cannot reproject the survey")
    unit = parsed.axis_info[0] if parsed.axis_info else None
    if unit is not None and abs(unit.unit_conversion_factor - 1.0) > 1e-12:
        # tangraph's importers record a CRS in feet as the same projection in metres
        # (tangraph.maps.io.metric_crs); one in feet comes from a file written before they did
        raise TangraphError(
            f"{whose} CRS {crs!r} has axes in {unit.unit_name}, but a survey's frame is metres and "
            "its positions may have been taken as metres: import the survey again (tangraph survey "
            "import converts a CRS in feet to metres)"
        )
    return parsed


def _reprojected(survey: Survey, bathymetry: BathymetryMap, source, target) -> Survey:
    """The survey's poses from its CRS and origin into the map's."""
    import pyproj

    from tangraph.maps.projection import north_in_grid

    transform = pyproj.Transformer.from_crs(source, target, always_xy=True).transform
    origin = np.asarray(survey.meta["origin"], float)
    map_origin = np.asarray(bathymetry.origin, float)

    def move(pose: np.ndarray) -> np.ndarray:
        n, e, turn = north_in_grid(transform, pose[:, 1] + origin[1], pose[:, 0] + origin[0], 1.0)
        if not np.all(np.isfinite([e, n, turn])):
            raise TangraphError(
                f"the survey's poses in {survey.meta['crs']} do not project into {bathymetry.crs} "
                f"(map {bathymetry.name!r})"
            )
        return np.column_stack([n - map_origin[0], e - map_origin[1], pose[:, 2] + turn])

    meta = {
        **survey.meta,
        "crs": bathymetry.crs,
        "origin": [float(v) for v in map_origin],
        "reprojected_from": {"crs": survey.meta["crs"], "origin": [float(v) for v in origin]},
    }
    truth = None if survey.true_pose is None else move(survey.true_pose)
    return survey.replace(dr_pose=move(survey.dr_pose), true_pose=truth, meta=meta)
