"""One entry point over every estimator: the particle filters and the factor graph.

:func:`navigate` runs the method named (``pf``, ``ipf``, ``sjcpf``, ``jbpf``, ``tercom-pf``,
``mle``, ``isam2`` or ``smoother``) on a survey and a map and returns its
:class:`~tangraph.track.Track`, in the map's frame; :func:`survey_on_map` is what it does to
the survey first (the map it was simulated on, the map's frame, the overlap with the map's
data), in one place for the library and the CLI; :func:`dead_reckoning_track` is the baseline
every estimator must beat; :func:`track_summary` is the text the CLI and the demo print.
"""

from __future__ import annotations

import enum

import numpy as np

from tangraph.errors import TangraphError
from tangraph.maps.grid import BathymetryMap
from tangraph.survey import Survey
from tangraph.track import Track

__all__ = [
    "MIN_MAP_OVERLAP",
    "Method",
    "check_map",
    "check_overlap",
    "dead_reckoning_track",
    "in_map_frame",
    "map_identity",
    "navigate",
    "survey_on_map",
    "track_report",
    "track_summary",
]

#: A survey is navigated on a map only when at least this share of its pings with soundings has
#: a sounding on the map's data (footprints laid with the dead reckoning in the map's frame). A
#: survey that leaves the map, or starts off it, is navigated; one that (nearly) never meets it
#: is refused: its map is another place's, or its CRS or origin is wrong.
MIN_MAP_OVERLAP = 0.05
#: beams per ping looked at by the overlap test (evenly spread over the swath)
_OVERLAP_BEAMS = 16


class Method(enum.StrEnum):
    """Every estimator of tangraph, by the name the CLI uses."""

    PF = "pf"
    IPF = "ipf"
    SJCPF = "sjcpf"
    JBPF = "jbpf"
    TERCOM_PF = "tercom-pf"
    MLE = "mle"
    PMF = "pmf"
    ISAM2 = "isam2"
    SMOOTHER = "smoother"

    @property
    def is_graph(self) -> bool:
        return self in (Method.ISAM2, Method.SMOOTHER)

    @property
    def is_random(self) -> bool:
        """Whether the method draws random numbers (needs ``rng``)."""
        return self not in (Method.ISAM2, Method.SMOOTHER, Method.MLE, Method.PMF)


def _method(method: Method | str) -> Method:
    try:
        return Method(method)
    except ValueError:
        known = ", ".join(m.value for m in Method)
        raise TangraphError(f"unknown navigation method {method!r}; known: {known}") from None


def navigate(
    survey: Survey,
    bathymetry: BathymetryMap,
    method: Method | str,
    config=None,
    *,
    rng: np.random.Generator | None = None,
    model=None,
    progress: bool = False,
    other_map: bool = False,
) -> Track:
    """Run one estimator on a survey.

    The survey is first made ready for the map by :func:`survey_on_map` (checked against the
    map it was simulated on, put into the map's frame: a recorded survey in its own CRS and
    origin is shifted or reprojected; refused when it does not overlap the map's data), so a
    survey read from a file can be passed as it is.

    Parameters
    ----------
    survey, bathymetry
        The run and the prior map.
    method : Method or str
        ``"pf"``, ``"ipf"``, ``"sjcpf"``, ``"jbpf"``, ``"tercom-pf"``, ``"mle"``, ``"pmf"`` (the filter
        family, :mod:`tangraph.filters`) or ``"isam2"``, ``"smoother"`` (the factor graph,
        :mod:`tangraph.graph`).
    config
        The method's own configuration (``tangraph.filters.*Config`` or
        ``tangraph.graph.GraphConfig``); ``None`` for its defaults.
    rng : numpy.random.Generator
        Required by the particle filters; unused by the graph, the MLE and the point-mass
        filter, which are deterministic.
    model : NavigationModel, optional
        What every estimator believes about the DR and the sonar (the constant DR errors it
        estimates, the start uncertainty, the terrain measurement); by default the one of a
        simulated survey (:meth:`~tangraph.sensors.NavigationModel.from_survey`). A recorded
        survey needs one (``load_navigation_model``).
    progress : bool
        Show a progress bar over the pings.
    other_map : bool
        Navigate a survey on a map that is not its own: one simulated on another map
        (:func:`check_map` refuses it otherwise), or one that does not overlap the map's data
        (:func:`check_overlap` refuses it otherwise; the estimators then keep the dead
        reckoning).

    Returns
    -------
    Track
        Poses in the map's frame (``bathymetry.crs``, ``bathymetry.origin``: write it with
        those to get latitude and longitude).

    Raises
    ------
    TangraphError
        An unknown method, a random method without ``rng``, and whatever
        :func:`survey_on_map` refuses.

    Examples
    --------
    >>> from tangraph.survey import read_survey
    >>> from tangraph.maps import read_map
    >>> track = navigate(read_survey("run.nc"), read_map("grid.nc"), "smoother",
    ...                  model=load_navigation_model("dr.toml"))  # doctest: +SKIP
    """
    from tangraph.sensors import survey_navigation_model

    method = _method(method)
    survey = survey_on_map(survey, bathymetry, other_map=other_map)
    model = survey_navigation_model(survey, model)
    return _estimate(method, survey, bathymetry, config, model, rng, progress)


def _estimate(method: Method, survey: Survey, bathymetry: BathymetryMap, config, model,
              rng: np.random.Generator | None, progress: bool) -> Track:
    """Run ``method`` (the graph's or a filter) on a survey already on the map, with its model."""
    if method is Method.ISAM2 or method is Method.SMOOTHER:
        from tangraph import graph

        run = graph.navigate_online if method is Method.ISAM2 else graph.smooth_survey
        return run(survey, bathymetry, config, model=model, progress=progress)
    if rng is None and method.is_random:
        raise TangraphError(
            f"navigation method {method.value!r} is random: pass rng=np.random.default_rng(seed)"
        )
    from tangraph import filters

    return filters.run_filter(method.value, survey, bathymetry, config, model=model, rng=rng,
                              progress=progress)


def survey_on_map(survey: Survey, bathymetry: BathymetryMap, *, other_map: bool = False) -> Survey:
    """The survey as every estimator takes it: in the map's frame, on the map.

    The one place where a survey meets its map, used by :func:`navigate` and the CLI: refused
    on a map it was not simulated on (:func:`check_map`), put into the map's frame
    (:func:`in_map_frame`), refused when it does not overlap the map's data
    (:func:`check_overlap`). A survey already in the map's frame is returned as it is, so
    calling it twice is harmless.

    Parameters
    ----------
    survey : Survey
        A simulated survey, or a recorded one in the CRS and origin it was imported in
        (``meta["crs"]``, ``meta["origin"]``).
    bathymetry : BathymetryMap
        The prior map.
    other_map : bool
        Skip :func:`check_map` and :func:`check_overlap`: navigate the survey on this map
        whatever it was made on and wherever it lies.

    Returns
    -------
    Survey
        Its poses (DR and reference) in the map's frame.

    Raises
    ------
    TangraphError
        What :func:`check_map`, :func:`in_map_frame` and :func:`check_overlap` refuse.
    """
    if not other_map:
        check_map(survey, bathymetry)
    framed = in_map_frame(survey, bathymetry)
    if not other_map:
        problem = _overlap_problem(framed, bathymetry, survey)
        if problem:
            raise TangraphError(problem)
    return framed


def check_overlap(survey: Survey, bathymetry: BathymetryMap) -> None:
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
        One line naming how many pings meet the map, the survey's extent and the map's (in
        latitude/longitude where both have a CRS, else in the map's local metres), the two CRSs
        where they differ, and the option that navigates it anyway (``other_map=True``, CLI:
        ``--other-map``).
    """
    problem = _overlap_problem(in_map_frame(survey, bathymetry), bathymetry, survey)
    if problem:
        raise TangraphError(problem)


def _overlap_problem(framed: Survey, bathymetry: BathymetryMap, original: Survey) -> str | None:
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
            if not _same_crs(crs, map_crs):
                apart += f" (its CRS {_crs_name(crs)}, the map's {_crs_name(map_crs)}: another region?)"
    return (
        f"the survey does not overlap map {bathymetry.name!r}: {met} of its {total} pings with soundings "
        f"({met / total:.1%}; at least {MIN_MAP_OVERLAP:.0%} needed) have a sounding on the map's data; "
        f"the survey spans {survey_text}, the map's data {data_text}{apart}; pass the map of the "
        "survey's area (or other_map=True, CLI: --other-map, to run it on this one anyway)"
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


def _same_crs(a, b) -> bool:
    import pyproj

    try:
        return pyproj.CRS.from_user_input(a).equals(pyproj.CRS.from_user_input(b))
    except pyproj.exceptions.CRSError:
        return a == b


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


def dead_reckoning_track(survey: Survey) -> Track:
    """The dead-reckoned poses as a track (no covariance): the baseline."""
    return Track(time=survey.time, pose=survey.dr_pose, method="dr")


def track_report(track: Track, survey: Survey) -> dict:
    """The figures of a track, as data (``tangraph navigate/smooth --json``): poses, fixes by
    outcome (graph and fix-based filters), divergences, run time, and the errors against the
    survey's reference track (with the dead reckoning's) where it has one."""
    report: dict = {"method": track.method, "poses": track.n_poses,
                    "duration_s": float(track.time[-1] - track.time[0])}
    meta = track.meta
    if "fixes" in meta:
        outcomes: dict[str, int] = {}
        for fix in meta["fixes"]:  # the graph's FixRecords; the fix-based filters keep dicts
            status = fix.status.value if hasattr(fix, "status") else \
                ("accepted" if fix.get("accepted") else "refused")
            outcomes[status] = outcomes.get(status, 0) + 1
        report["fixes"] = {"accepted": int(meta.get("n_fixes_accepted", 0)),
                           "rejected": int(meta.get("n_fixes_rejected", 0)),
                           "by_outcome": dict(sorted(outcomes.items(), key=lambda kv: -kv[1]))}
    if "soundings" in meta:  # the smoother on every sounding
        counts = ("soundings", "soundings_used", "field_nodes")
        report["soundings"] = {k: int(v) if k in counts else float(v) for k, v in meta["soundings"].items()}
    if "n_divergences" in meta:
        report["divergences"] = int(meta["n_divergences"])
    if "lost_steps" in meta:
        report["lost"] = {"pings": int(track.lost.sum()), "episodes": len(meta.get("lost_episodes", [])),
                          "off_map_pings": int(meta.get("n_off_map", 0))}
    if "start_prior" in meta:
        report["start_prior"] = meta["start_prior"]
    if track.timings:
        report["run_time_s"] = float(track.timings.get("total", float("nan")))
        report["per_step_s"] = float(track.timings.get("per_step", float("nan")))
    if "calibration" in meta:
        report["calibration"] = {k: float(v) for k, v in meta["calibration"].items()}
    if survey.true_pose is not None:
        from tangraph.eval.metrics import track_metrics

        keys = ("rmse", "median_error", "final_error", "max_error", "anees", "final_nees")
        m = track_metrics(track, survey.true_pose)
        d = track_metrics(dead_reckoning_track(survey), survey.true_pose)
        report["reference"] = survey.meta.get("reference", "truth")
        report["error"] = {k: m[k] for k in keys}
        report["dead_reckoning_error"] = {k: d[k] for k in keys[:4]}
    return report


def track_summary(track: Track, survey: Survey) -> str:
    """A few lines on a track for a person: :func:`track_report` as text."""
    r = track_report(track, survey)
    lines = [f"method       {r['method']}: {r['poses']} poses over {r['duration_s']:.1f} s"]
    if "fixes" in r:
        detail = ", ".join(f"{n} {k}" for k, n in r["fixes"]["by_outcome"].items())
        lines.append(f"fixes        {r['fixes']['accepted']} accepted, {r['fixes']['rejected']} "
                     f"rejected ({detail})")
    if "soundings" in r:
        snd = r["soundings"]
        lines.append(f"soundings    {snd['soundings_used']} of {snd['soundings']} weighed (the others left "
                     f"out by the gate), tide {snd['tide']:+.2f} m, variances x "
                     f"{snd['variance_factor']:.2f}^2")
        if "field_factor" in snd:
            lines.append(f"map error    estimated with the track on {snd['field_nodes']} nodes "
                         f"{snd['field_spacing']:.0f} m apart, its stated std x {snd['field_factor']:.2f}, "
                         f"correction RMS {snd['field_rms']:.2f} m")
    if "divergences" in r:
        lines.append(f"divergences  {r['divergences']} (re-initialised from dead reckoning)")
    if r.get("lost", {}).get("pings"):
        lost = r["lost"]
        episodes = f" in {lost['episodes']} episodes" if lost["episodes"] else ""
        lines.append(f"lost         {lost['pings']} pings flagged lost{episodes} (column 'lost' of the "
                     "track: their poses are not to be trusted)")
    if r.get("lost", {}).get("off_map_pings"):
        lines.append(f"off the map  {r['lost']['off_map_pings']} pings: dead reckoning only there")
    if r.get("start_prior") == "outlier":
        lines.append("start        the start position prior disagreed with the fixes and was dropped")
    if "run_time_s" in r:
        lines.append(f"run time     {r['run_time_s']:.2f} s in all, {1e3 * r['per_step_s']:.2f} ms per step")
    if "error" in r:
        m, d = r["error"], r["dead_reckoning_error"]
        lines.append(
            f"error        RMSE {m['rmse']:.2f} m, median {m['median_error']:.2f} m, "
            f"final {m['final_error']:.2f} m, max {m['max_error']:.2f} m against the {r['reference']} "
            f"(dead reckoning: RMSE {d['rmse']:.2f} m, median {d['median_error']:.2f} m, "
            f"final {d['final_error']:.2f} m)"
        )
        if np.isfinite(m["anees"]):
            lines.append(f"consistency  ANEES {m['anees']:.2f} (2 for an honest covariance)")
    return "\n".join(lines)
