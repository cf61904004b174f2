"""Matplotlib figures shared by the CLI, the experiments and the docs."""

from __future__ import annotations

import matplotlib
import numpy as np
from matplotlib import cm, colors
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from tangraph.maps.grid import BathymetryMap

__all__ = [
    "covariance_ellipse",
    "hillshade_rgb",
    "plot_errors",
    "plot_fix",
    "plot_map",
    "plot_survey",
    "plot_tracks",
]


def hillshade_rgb(
    bathymetry: BathymetryMap,
    *,
    cmap: str = "viridis_r",
    exaggeration: float | None = None,
    vmin: float | None = None,
    vmax: float | None = None,
) -> np.ndarray:
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
        -filled[::-1],
        cmap=matplotlib.colormaps[cmap].reversed(),
        blend_mode="soft",
        dx=de,
        dy=dn,
        vert_exag=exaggeration,
        vmin=-vmax,
        vmax=-vmin,
    )[::-1]
    rgb[..., 3] = valid
    return rgb


def plot_map(
    bathymetry: BathymetryMap,
    ax: Axes | None = None,
    *,
    title: str | None = None,
    cmap: str = "viridis_r",
    colorbar: bool = True,
) -> Axes:
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
        hillshade_rgb(bathymetry, cmap=cmap, vmin=vmin, vmax=vmax),
        origin="lower",
        extent=(e_lo - de / 2, e_hi + de / 2, n_lo - dn / 2, n_hi + dn / 2),
        interpolation="nearest",
    )
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_aspect("equal")
    ax.set_title(title if title is not None else bathymetry.name)
    if colorbar:
        mappable = cm.ScalarMappable(norm=colors.Normalize(vmin, vmax), cmap=cmap)
        ax.figure.colorbar(mappable, ax=ax, label="depth (m, positive down)", shrink=0.85)
    return ax


def plot_survey(
    survey,
    bathymetry: BathymetryMap | None = None,
    ax: Axes | None = None,
    *,
    title: str | None = None,
    swath_every: int | None = None,
) -> Axes:
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
    ax.scatter(
        east[mask], north[mask], s=2, c="tab:cyan", edgecolors="none", alpha=0.6, label="swath footprints"
    )
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


def covariance_ellipse(covariance: np.ndarray, probability: float = 0.95, n: int = 100) -> np.ndarray:
    """Points ``(n, 2)`` (north, east offsets) of the ``probability`` ellipse of a 2-D Gaussian."""
    from scipy import stats

    values, vectors = np.linalg.eigh(np.asarray(covariance, float))
    radius = np.sqrt(stats.chi2.ppf(probability, 2) * np.clip(values, 0, None))
    angle = np.linspace(0, 2 * np.pi, n)
    return (vectors @ (radius[:, None] * np.vstack([np.cos(angle), np.sin(angle)]))).T


def plot_fix(fix, ax: Axes | None = None, *, truth=None, title: str | None = None) -> Axes:
    """A TAP fix like Wang et al.'s figures: the criterion surface, the fix (and truth), each
    confidence region's outline and the 95 % ellipse of the fix's covariance."""
    from matplotlib.lines import Line2D

    if ax is None:
        fig = Figure(figsize=(7, 6), layout="constrained")
        ax = fig.add_subplot()
    grid = fix.grid
    q = fix.surface
    step_n = grid.north[1] - grid.north[0] if grid.north.size > 1 else 1.0
    step_e = grid.east[1] - grid.east[0] if grid.east.size > 1 else 1.0
    extent = (
        grid.east[0] - step_e / 2,
        grid.east[-1] + step_e / 2,
        grid.north[0] - step_n / 2,
        grid.north[-1] + step_n / 2,
    )
    image = ax.imshow(
        np.log10(q - np.nanmin(q) + 1e-3 * np.nanmin(q) + 1e-12),
        origin="lower",
        extent=extent,
        cmap="Greys_r",
        interpolation="nearest",
    )
    ax.figure.colorbar(image, ax=ax, label="log10(Q - Q_min + eps), Q = (n-1) sigma^2", shrink=0.85)
    handles = []
    for (method, region), colour in zip(
        fix.regions.items(), ("tab:orange", "tab:blue", "tab:green"), strict=False
    ):
        if region.mask.any():
            ax.contour(grid.east, grid.north, region.mask.astype(float), levels=[0.5], colors=colour)
        handles.append(
            Line2D(
                [], [], color=colour, label=f"{method.value} {1 - region.alpha:.0%} ({region.area:.0f} m²)"
            )
        )
    ellipse = fix.position + covariance_ellipse(fix.covariance)
    ax.plot(ellipse[:, 1], ellipse[:, 0], "m--", lw=1.2)
    handles.append(Line2D([], [], color="m", ls="--", label="95% covariance ellipse"))
    ax.plot(fix.position[1], fix.position[0], "r+", ms=12, mew=2)
    handles.append(Line2D([], [], color="r", marker="+", ls="", ms=10, label="fix"))
    if truth is not None:
        ax.plot(truth[1], truth[0], "cx", ms=10, mew=2)
        handles.append(Line2D([], [], color="c", marker="x", ls="", ms=10, label="truth"))
    ax.legend(handles=handles, fontsize="small", loc="upper right", framealpha=0.85)
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_aspect("equal")
    ax.set_title(
        title
        if title is not None
        else f"TAP fix of pings {fix.first}..{fix.index}: sigma {fix.sigma:.3f} m, tide {fix.tide:.2f} m"
    )
    return ax


_STYLE = {
    "truth": ("k", "-", 1.6),
    "dr": ("tab:red", "--", 1.4),
    "smoother": ("tab:blue", "-", 1.4),
    "isam2": ("tab:cyan", "-", 1.1),
    "pf": ("tab:orange", "-", 0.9),
    "ipf": ("tab:green", "-", 0.9),
    "sjcpf": ("tab:purple", "-", 0.9),
    "jbpf": ("tab:brown", "-", 0.9),
    "tercom-pf": ("tab:olive", "-", 0.9),
    "mle": ("tab:pink", "-", 0.9),
}


def _style(name: str) -> dict:
    colour, ls, lw = _STYLE.get(name, ("tab:gray", "-", 1.0))
    return {"color": colour, "ls": ls, "lw": lw}


def plot_tracks(
    tracks: dict,
    bathymetry: BathymetryMap | None = None,
    ax: Axes | None = None,
    *,
    truth: np.ndarray | None = None,
    ellipses: str | None = None,
    n_ellipses: int = 12,
    title: str | None = None,
    zoom: bool = True,
) -> Axes:
    """Estimated tracks (``{label: Track}``) over the hill-shaded map, with the truth and the
    95 % ellipses of the track named by ``ellipses`` at ``n_ellipses`` poses."""
    if ax is None:
        fig = Figure(figsize=(8, 7), layout="constrained")
        ax = fig.add_subplot()
    if bathymetry is not None:
        plot_map(bathymetry, ax, title="", colorbar=False)
    if truth is not None:
        ax.plot(truth[:, 1], truth[:, 0], label="truth", **_style("truth"))
    for label, track in tracks.items():
        ax.plot(track.pose[:, 1], track.pose[:, 0], label=label, **_style(track.method))
    if ellipses is not None:
        track = tracks[ellipses]
        known = np.flatnonzero(np.all(np.isfinite(track.covariance[:, :2, :2]), axis=(1, 2)))
        for k in known[:: max(1, known.size // n_ellipses)] if known.size else []:
            e = track.pose[k, :2] + covariance_ellipse(track.covariance[k, :2, :2])
            ax.plot(e[:, 1], e[:, 0], color=_style(track.method)["color"], lw=0.8, alpha=0.9)
        ax.plot([], [], color=_style(track.method)["color"], lw=0.8, label=f"{ellipses}: 95% ellipses")
    if zoom:
        everything = [t.pose[:, :2] for t in tracks.values()] + ([truth[:, :2]] if truth is not None else [])
        points = np.vstack(everything)
        lo, hi = points.min(axis=0), points.max(axis=0)
        pad = 0.08 * np.max(hi - lo) + 20.0
        ax.set_xlim(lo[1] - pad, hi[1] + pad)
        ax.set_ylim(lo[0] - pad, hi[0] + pad)
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_aspect("equal")
    ax.legend(loc="best", fontsize="small", framealpha=0.85)
    if title is not None:
        ax.set_title(title)
    return ax


def plot_errors(
    tracks: dict,
    truth: np.ndarray,
    ax: Axes | None = None,
    *,
    bound: str | None = None,
    title: str | None = None,
) -> Axes:
    """Horizontal position error against time of each track (``{label: Track}``), with the
    2-sigma bound of the track named by ``bound`` (twice the standard deviation along the worst
    axis of its position covariance)."""
    from tangraph.track import position_errors

    if ax is None:
        fig = Figure(figsize=(9, 4.5), layout="constrained")
        ax = fig.add_subplot()
    for label, track in tracks.items():
        ax.plot(track.time, position_errors(track, truth), label=label, **_style(track.method))
    if bound is not None:
        track = tracks[bound]
        cov = track.covariance[:, :2, :2]
        known = np.all(np.isfinite(cov), axis=(1, 2))
        radius = np.full(track.n_poses, np.nan)
        if known.any():
            radius[known] = 2.0 * np.sqrt(np.linalg.eigvalsh(cov[known])[:, -1])
        ax.fill_between(
            track.time, 0, radius, color=_style(track.method)["color"], alpha=0.15, label=f"{bound}: 2-sigma"
        )
    ax.set_xlabel("time (s)")
    ax.set_ylabel("horizontal error (m)")
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.3)
    ax.legend(loc="upper left", fontsize="small", ncols=2, framealpha=0.85)
    if title is not None:
        ax.set_title(title)
    return ax
