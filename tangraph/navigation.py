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
from typing import TYPE_CHECKING, Any

import numpy as np

from tangraph.errors import TangraphError
from tangraph.map_frame import (
    MIN_MAP_OVERLAP,
    _overlap_problem,
    check_map,
    check_overlap,
    in_map_frame,
    map_identity,
)
from tangraph.maps.grid import BathymetryMap
from tangraph.survey import Survey
from tangraph.track import Track
from tangraph.track_reports import dead_reckoning_track, track_report, track_summary

if TYPE_CHECKING:
    from tangraph.sensors import NavigationModel

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
    config: Any = None,
    *,
    rng: np.random.Generator | None = None,
    model: NavigationModel | None = None,
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
    model = survey_navigation_model(survey, model, bathymetry=bathymetry)
    return _estimate(method, survey, bathymetry, config, model, rng, progress)


def _estimate(method: Method, survey: Survey, bathymetry: BathymetryMap, config: Any, model: Any,
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
