"""One entry point over every estimator: the particle filters and the factor graph.

:func:`navigate` runs the method named (``pf``, ``ipf``, ``sjcpf``, ``jbpf``, ``tercom-pf``,
``mle``, ``isam2`` or ``smoother``) on a survey and a map and returns its
:class:`~tangraph.track.Track`; :func:`dead_reckoning_track` is the baseline every estimator
must beat; :func:`track_summary` is the text the CLI and the demo print.
"""

from __future__ import annotations

import enum

import numpy as np

from tangraph.errors import TangraphError
from tangraph.maps.grid import BathymetryMap
from tangraph.survey import Survey
from tangraph.track import Track

__all__ = [
    "Method",
    "check_map",
    "dead_reckoning_track",
    "in_map_frame",
    "map_identity",
    "navigate",
    "track_report",
    "track_summary",
]


class Method(enum.StrEnum):
    """Every estimator of tangraph, by the name the CLI uses."""

    PF = "pf"
    IPF = "ipf"
    SJCPF = "sjcpf"
    JBPF = "jbpf"
    TERCOM_PF = "tercom-pf"
    MLE = "mle"
    ISAM2 = "isam2"
    SMOOTHER = "smoother"

    @property
    def is_graph(self) -> bool:
        return self in (Method.ISAM2, Method.SMOOTHER)


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

    Parameters
    ----------
    survey, bathymetry
        The run and the prior map.
    method : Method or str
        ``"pf"``, ``"ipf"``, ``"sjcpf"``, ``"jbpf"``, ``"tercom-pf"``, ``"mle"`` (the particle
        family, :mod:`tangraph.filters`) or ``"isam2"``, ``"smoother"`` (the factor graph,
        :mod:`tangraph.graph`).
    config
        The method's own configuration (``tangraph.filters.*Config`` or
        ``tangraph.graph.GraphConfig``); ``None`` for its defaults.
    rng : numpy.random.Generator
        Required by the particle filters; unused by the graph, which is deterministic.
    model : NavigationModel, optional
        What every estimator believes about the DR and the sonar (the constant DR errors it
        estimates, the start uncertainty, the terrain measurement); by default the one of a
        simulated survey (:meth:`~tangraph.sensors.NavigationModel.from_survey`). A recorded
        survey needs one (``load_navigation_model``).
    progress : bool
        Show a progress bar over the pings.
    other_map : bool
        Navigate a survey simulated on one map on another (:func:`check_map` refuses it
        otherwise).
    """
    from tangraph.sensors import survey_navigation_model

    method = _method(method)
    if not other_map:
        check_map(survey, bathymetry)
    model = survey_navigation_model(survey, model)
    if method is Method.ISAM2 or method is Method.SMOOTHER:
        from tangraph import graph

        run = graph.navigate_online if method is Method.ISAM2 else graph.smooth_survey
        return run(survey, bathymetry, config, model=model, progress=progress)
    if rng is None:
        raise TangraphError(
            f"navigation method {method.value!r} is random: pass rng=np.random.default_rng(seed)"
        )
    from tangraph import filters

    return filters.run_filter(method.value, survey, bathymetry, config, model=model, rng=rng,
                              progress=progress)


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
        from tangraph.eval import track_metrics

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
