"""A track's outputs as one set: the track file in the format its suffix names, its TUM copy,
the refined map and a figure, all written or none (:class:`tangraph.outputs.OutputSet`).

Above the track, the maps, the navigation and the plots, which it uses; the CLI's ``navigate``
and ``smooth`` write through it.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Literal, cast

from tangraph.outputs import OutputSet, sigterm_exits

__all__ = ["write_track_outputs"]


def write_track_outputs(
    track,
    survey,
    bathymetry,
    output: str | os.PathLike,
    *,
    tum: str | os.PathLike | None = None,
    frame: str = "ned",
    plot: str | os.PathLike | None = None,
    refined_map: str | os.PathLike | None = None,
    overwrite: bool = False,
) -> list[Path]:
    """Write a track (a :class:`~tangraph.track.Track` of ``survey`` on ``bathymetry``) as one
    :class:`~tangraph.outputs.OutputSet`: all of the files, or (after an error, Ctrl-C or
    SIGTERM) none, and no existing file touched. Returns the files written.

    ``output``'s suffix picks the format: ``.tum`` (:func:`~tangraph.track.write_track_tum`, in
    ``frame``), ``.geojson`` or ``.gpkg`` (WGS84; the map needs a CRS) or else CSV
    (:func:`~tangraph.track.write_track_csv`), placed through the map's CRS and origin with the
    survey's reference track and start time. ``tum``: also a TUM copy; ``refined_map``: the
    map the smoother refined (``track.meta["refined_map"]``), in any map format by suffix;
    ``plot``: a figure of the track vs the dead reckoning (and the truth) over the map.
    """
    import tangraph.track as tracks

    output = Path(output)
    placed = {
        "crs": bathymetry.crs, "origin": bathymetry.origin, "reference": survey.true_pose,
        "start_time": survey.meta.get("start_time"), "overwrite": True,  # onto the set's temporary file
    }
    writer = {".tum": None, ".geojson": tracks.write_track_geojson, ".gpkg": tracks.write_track_gpkg}.get(
        output.suffix.lower(), tracks.write_track_csv
    )
    written = [Path(p) for p in (output, tum, plot, refined_map) if p is not None]
    tum_frame = cast(Literal["ned", "enu"], frame)  # write_track_tum checks it
    with sigterm_exits(), OutputSet(overwrite=overwrite) as outputs:
        if writer is None:
            tracks.write_track_tum(track, outputs.path(output), frame=tum_frame, overwrite=True)
        else:
            writer(track, outputs.path(output), **placed)
        if tum is not None:
            tracks.write_track_tum(track, outputs.path(tum), frame=tum_frame, overwrite=True)
        if refined_map is not None:
            from tangraph.maps.io import write_map

            write_map(track.meta["refined_map"], outputs.path(refined_map), overwrite=True)
        if plot is not None:
            _track_figure(track, survey, bathymetry).savefig(
                outputs.path(plot), dpi=130, format=Path(plot).suffix[1:]
            )
    return written


def _track_figure(track, survey, bathymetry):
    """The track, the dead reckoning and (where the survey has one) the truth over the map."""
    from matplotlib.figure import Figure

    from tangraph.plot import plot_tracks
    from tangraph.track_reports import dead_reckoning_track

    fig = Figure(figsize=(8, 7.5), layout="constrained")
    tracks = {"dead reckoning": dead_reckoning_track(survey), track.method: track}
    plot_tracks(
        tracks,
        bathymetry,
        fig.add_subplot(),
        truth=survey.true_pose,
        ellipses=track.method,
        title=f"{track.method} on {bathymetry.name}",
    )
    return fig
