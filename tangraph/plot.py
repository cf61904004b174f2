"""Matplotlib figures shared by the CLI, the experiments and the docs."""

from __future__ import annotations

import matplotlib
import numpy as np
from matplotlib import cm, colors
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from tangraph.maps.grid import BathymetryMap

__all__ = ["hillshade_rgb", "plot_map", "plot_survey"]


def hillshade_rgb(bathymetry: BathymetryMap, *, cmap: str = "viridis_r",
                  exaggeration: float | None = None, vmin: float | None = None,
                  vmax: float | None = None) -> np.ndarray:
    """RGBA image (ny, nx, 4) of the depth, coloured and lit from the north-west; NaN clear.

    ``exaggeration`` is the vertical exaggeration of the shading; by default it is chosen so
    that the relief is 5 % of the map's width (shallow lakes and deep charts both show).
    """
    dn, de = bathymetry.cell_size
    valid = np.isfinite(bathymetry.depth)
    filled = np.where(valid, bathymetry.depth, np.nanmean(bathymetry.depth))
    vmin = float(np.nanmin(bathymetry.depth)) if vmin is None else vmin
    vmax = float(np.nanmax(bathymetry.depth)) if vmax is None else vmax
    if exaggeration is None:
        n_lo, n_hi, e_lo, e_hi = bathymetry.extent
        relief = max(vmax - vmin, 1e-6)
        exaggeration = 0.05 * max(n_hi - n_lo, e_hi - e_lo) / relief
    light = colors.LightSource(azdeg=315, altdeg=45)
    # shade the elevation (-depth): rows run south to north, hence the flip for LightSource
    rgb = light.shade(
        -filled[::-1], cmap=matplotlib.colormaps[cmap].reversed(), blend_mode="soft", dx=de, dy=dn,
        vert_exag=exaggeration, vmin=-vmax, vmax=-vmin,
    )[::-1]
    rgb[..., 3] = valid
    return rgb


def plot_map(bathymetry: BathymetryMap, ax: Axes | None = None, *, title: str | None = None,
             cmap: str = "viridis_r", colorbar: bool = True) -> Axes:
    """Hill-shaded depth with a colour bar, local north/east in metres on the axes.

    Examples
    --------
    >>> import matplotlib
    >>> matplotlib.use("Agg")
    >>> from tangraph.maps import load
    >>> from tangraph.plot import plot_map
    >>> ax = plot_map(load("lidar-dem"))
    """
    if ax is None:
        fig = Figure(figsize=(7, 6), layout="constrained")
        ax = fig.add_subplot()
    dn, de = bathymetry.cell_size
    n_lo, n_hi, e_lo, e_hi = bathymetry.extent
    vmin, vmax = float(np.nanmin(bathymetry.depth)), float(np.nanmax(bathymetry.depth))
    ax.set_facecolor("0.85")
    ax.imshow(
        hillshade_rgb(bathymetry, cmap=cmap, vmin=vmin, vmax=vmax), origin="lower",
        extent=(e_lo - de / 2, e_hi + de / 2, n_lo - dn / 2, n_hi + dn / 2), interpolation="nearest",
    )
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_aspect("equal")
    ax.set_title(title if title is not None else bathymetry.name)
    if colorbar:
        mappable = cm.ScalarMappable(norm=colors.Normalize(vmin, vmax), cmap=cmap)
        ax.figure.colorbar(mappable, ax=ax, label="depth (m, positive down)", shrink=0.85)
    return ax


def plot_survey(survey, bathymetry: BathymetryMap | None = None, ax: Axes | None = None, *,
                title: str | None = None, swath_every: int | None = None) -> Axes:
    """Truth and dead reckoning over the hill-shaded map, with swath footprints.

    ``swath_every`` draws the footprints (as seen from the true pose, else DR) of every n-th ping;
    by default about 40 pings across the survey.
    """
    if ax is None:
        fig = Figure(figsize=(8, 7), layout="constrained")
        ax = fig.add_subplot()
    if bathymetry is not None:
        plot_map(bathymetry, ax, title="")
    pose = survey.true_pose if survey.true_pose is not None else survey.dr_pose
    step = swath_every or max(1, survey.n_pings // 40)
    north, east = survey.footprints(pose)
    valid = np.isfinite(survey.beam_depth)
    sel = np.zeros(survey.n_pings, bool)
    sel[::step] = True
    mask = valid & sel[:, None]
    ax.scatter(east[mask], north[mask], s=2, c="white", edgecolors="none", alpha=0.7,
               label="swath footprints")
    if survey.true_pose is not None:
        ax.plot(survey.true_pose[:, 1], survey.true_pose[:, 0], "k-", lw=1.5, label="truth")
    ax.plot(survey.dr_pose[:, 1], survey.dr_pose[:, 0], "r--", lw=1.5, label="dead reckoning")
    ax.plot(pose[0, 1], pose[0, 0], "ko", ms=5, label="start")
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_aspect("equal")
    ax.legend(loc="best", fontsize="small", framealpha=0.8)
    ax.set_title(title if title is not None else f"survey on {survey.meta.get('map', 'unknown map')}")
    return ax
