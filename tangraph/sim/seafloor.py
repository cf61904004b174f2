"""A world whose seafloor is not the map: a true seafloor and a prior map gridded from a survey of it.

A scenario may declare its true seafloor and its prior map (``[seafloor]`` and ``[prior_map]``
in its TOML, :mod:`tangraph.sim.scenario`). Then:

- the **true seafloor** is the scenario's map resampled (bicubic) to ``seafloor.cell`` over the
  area the survey needs, plus a seeded Gaussian random field of std ``seafloor.std`` and range
  ``seafloor.correlation_length`` (the Matérn field of :func:`tangraph.sensors.matern_field`):
  relief the map never had;
- the **prior map** the estimators navigate on is gridded (:func:`tangraph.maps.grid_surveys`)
  from a simulated earlier survey of that seafloor: a lawnmower of parallel lines
  ``prior_map.line_spacing`` apart, ray cast with the scenario's sonar (or
  ``[prior_map.sonar]``), placed at a GPS track with a slowly varying error of std
  ``prior_map.position_std`` forgetting over ``prior_map.position_time`` (60 s; the gridding
  counts it in the map's error through its slope, :func:`tangraph.maps.gridded_error`),
  binned at ``prior_map.cell``, with gaps of up to ``prior_map.fill`` cells filled. Its error
  is spatially correlated, larger between lines and in filled gaps, and its data stop at
  edges, as a real map's do, while the truth stays known. The map keeps a horizontal offset of
  that GPS error, patch by patch (:func:`_offset`), which the survey's metadata states.

The survey itself is ray cast on the true seafloor. With ``seafloor.change_std > 0`` the seafloor
has **changed since the earlier survey**: the survey sees it plus a Matérn field of std
``change_std`` and range ``correlation_length``, which the prior map cannot know of. With
``seafloor.patch_scale_std > 0`` that change varies in patches: it is multiplied by
``exp(patch_scale_std * g - patch_scale_std^2)``, ``g`` a unit Matérn field of range
``seafloor.patch_length``, so its mean square stays ``change_std^2`` while a few patches change
several times more than the rest (a Gaussian scale mixture: the heavy-tailed, patchy error
that check lines find between the days of a real survey, which the gridding of one day's
soundings does not see). Everything is drawn from the generator the
caller passes, so a run's seed fixes its seafloor and prior map too.
"""

from __future__ import annotations

import dataclasses
import logging
from typing import Any

import numpy as np

from tangraph.errors import TangraphError
from tangraph.geometry import rotation_matrix
from tangraph.maps.grid import BathymetryMap
from tangraph.validation import number

__all__ = ["PriorMapSettings", "ScenarioWorld", "SeafloorSettings", "changed_seafloor", "simulate_world"]

log = logging.getLogger(__name__)


def _known_keys(cls, table: dict, where: str) -> None:
    allowed = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise TangraphError(f"{where}: unknown keys {unknown}; allowed: {sorted(allowed)}")


def _positive(table: dict, key: str, where: str, *, zero: bool = False) -> float:
    return number(table[key], f"{where}: {key}", open_low=not zero)


@dataclasses.dataclass(frozen=True)
class SeafloorSettings:
    """The true seafloor: the map at ``cell`` (m) plus a Matérn field of ``std`` (m) and range
    ``correlation_length`` (m); ``margin`` (m) of seafloor around the survey's track. Its change
    since the earlier survey: a field of std ``change_std`` (m; 0: none) whose std varies in
    patches of range ``patch_length`` (m) by a log-normal factor of log-std ``patch_scale_std``
    (0: the same std everywhere; only with a change). See the module docstring."""

    std: float = 0.3
    correlation_length: float = 30.0
    cell: float | None = None
    margin: float = 300.0
    change_std: float = 0.0
    patch_scale_std: float = 0.0
    patch_length: float = 300.0

    @classmethod
    def from_table(cls, table: dict, where: str) -> SeafloorSettings:
        _known_keys(cls, table, where)
        values: dict[str, Any] = {}
        for key in table:
            values[key] = _positive(table, key, where, zero=key in ("std", "change_std", "patch_scale_std"))
        if values.get("patch_scale_std", 0.0) > 0 and values.get("change_std", 0.0) == 0:
            raise TangraphError(f"{where}: patch_scale_std varies the seafloor's change since the earlier "
                                "survey in patches: give change_std > 0 too")
        return cls(**values)


@dataclasses.dataclass(frozen=True)
class PriorMapSettings:
    """The earlier survey the prior map is gridded from, and the gridding."""

    line_spacing: float = 70.0
    line_heading_deg: float | None = None  # default: along the longer side of the area
    speed: float = 2.0
    ping_rate: float = 1.0
    position_std: float = 1.0
    position_time: float = 60.0
    cell: float = 10.0
    fill: int = 3
    statistic: str = "median"
    vehicle_depth: float = 0.5
    sonar: dict[str, Any] = dataclasses.field(default_factory=dict)

    @classmethod
    def from_table(cls, table: dict, where: str) -> PriorMapSettings:
        _known_keys(cls, table, where)
        values: dict[str, Any] = {}
        for key, value in table.items():
            if key in ("line_spacing", "speed", "ping_rate", "cell", "position_time"):
                values[key] = _positive(table, key, where)
            elif key in ("position_std", "vehicle_depth"):
                values[key] = _positive(table, key, where, zero=True)
            elif key == "line_heading_deg":
                values[key] = float(_finite(value, key, where))
            elif key == "fill":
                if isinstance(value, bool) or not isinstance(value, int) or value < 0:
                    raise TangraphError(f"{where}: fill must be an integer >= 0, got {value!r}")
                values[key] = value
            elif key == "statistic":
                if value not in ("mean", "median"):
                    raise TangraphError(f"{where}: statistic must be 'mean' or 'median', got {value!r}")
                values[key] = value
            elif key == "sonar":
                if not isinstance(value, dict):
                    raise TangraphError(f"{where}: sonar must be a table, got {value!r}")
                values[key] = dict(value)
        return cls(**values)


def _finite(value, key: str, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not np.isfinite(value):
        raise TangraphError(f"{where}: {key} must be a finite number, got {value!r}")
    return float(value)


@dataclasses.dataclass(frozen=True, eq=False)
class ScenarioWorld:
    """The true ``seafloor`` the soundings see and the ``prior_map`` the estimators use, with the
    ``prior_survey`` it was gridded from (its ``true_pose`` is the GPS track it was placed at),
    and the std (m per axis) and range (m) of the horizontal offset the gridding kept of that
    track's error (:func:`_offset`)."""

    seafloor: BathymetryMap
    prior_map: BathymetryMap
    prior_survey: Any = None
    offset: tuple[float, float] = (0.0, 0.0)

    def map_error(self) -> np.ndarray:
        """The prior map's true error on its own grid, ``seafloor - prior map`` (m; NaN where
        either has no data)."""
        nn, ee = np.meshgrid(self.prior_map.north, self.prior_map.east, indexing="ij")
        return self.seafloor.depth_at(nn, ee) - self.prior_map.depth


def _area(track: np.ndarray, source: BathymetryMap, margin: float) -> tuple[float, float, float, float]:
    n_lo, n_hi, e_lo, e_hi = source.extent
    lo = np.maximum(track.min(axis=0) - margin, [n_lo, e_lo])
    hi = np.minimum(track.max(axis=0) + margin, [n_hi, e_hi])
    if np.any(hi - lo <= 0):
        raise TangraphError(f"the scenario's track lies off its map {source.name!r}: no seafloor to draw")
    return float(lo[0]), float(hi[0]), float(lo[1]), float(hi[1])


def true_seafloor(source: BathymetryMap, track: np.ndarray, settings: SeafloorSettings, *,
                  rng: np.random.Generator) -> BathymetryMap:
    """The source map around ``track (K, 2)`` at the seafloor's cell plus its random field."""
    from tangraph.sensors.matern import matern_field

    n_lo, n_hi, e_lo, e_hi = _area(track, source, settings.margin)
    crop = source.crop(north=(n_lo, n_hi), east=(e_lo, e_hi))
    cell = settings.cell or min(source.cell_size)
    fine = crop.resample(cell, order=3) if cell != min(crop.cell_size) else crop
    field = matern_field(fine.north, fine.east, settings.std, settings.correlation_length, rng=rng)
    return BathymetryMap(fine.north, fine.east, fine.depth + field, crs=source.crs, origin=source.origin,
                         name=f"{source.name} seafloor")


def changed_seafloor(seafloor: BathymetryMap, settings: SeafloorSettings, *,
                     rng: np.random.Generator) -> BathymetryMap:
    """``seafloor`` after its change since the earlier survey (the module docstring); the same
    map when ``settings.change_std`` is 0."""
    from tangraph.sensors.matern import matern_field

    if settings.change_std == 0:
        return seafloor
    north, east = seafloor.north, seafloor.east
    change = matern_field(north, east, settings.change_std, settings.correlation_length, rng=rng)
    if settings.patch_scale_std > 0:
        s = settings.patch_scale_std
        change *= np.exp(s * matern_field(north, east, 1.0, settings.patch_length, rng=rng) - s * s)
    return seafloor.replace(depth=seafloor.depth + change, name=f"{seafloor.name}, changed")


def _line_axes(seafloor: BathymetryMap, settings: PriorMapSettings) -> tuple[float, np.ndarray, np.ndarray]:
    """The earlier survey's line heading and its unit vector along and across (to starboard)."""
    n_lo, n_hi, e_lo, e_hi = seafloor.extent
    if settings.line_heading_deg is None:
        heading = 0.0 if n_hi - n_lo >= e_hi - e_lo else np.pi / 2
    else:
        heading = np.radians(settings.line_heading_deg)
    along, across = rotation_matrix(heading).T
    return heading, along, across


def _prior_trajectory(seafloor: BathymetryMap, settings: PriorMapSettings) -> tuple[np.ndarray, np.ndarray]:
    from tangraph.sim import trajectories

    n_lo, n_hi, e_lo, e_hi = seafloor.extent
    heading, along, across = _line_axes(seafloor, settings)
    corners = np.array([[n_lo, e_lo], [n_lo, e_hi], [n_hi, e_lo], [n_hi, e_hi]])
    a, c = corners @ along, corners @ across
    length = float(a.max() - a.min())
    n_lines = int(np.floor((c.max() - c.min()) / settings.line_spacing)) + 1
    # lines centred across the area, from its lowest along-coordinate
    first = c.min() + 0.5 * ((c.max() - c.min()) - (n_lines - 1) * settings.line_spacing)
    origin = along * a.min() + across * first
    return trajectories.lawnmower(origin, heading, length, settings.line_spacing, n_lines, settings.speed,
                                  settings.ping_rate)


def _gps_error(time: np.ndarray, std: float, rng: np.random.Generator, memory: float) -> np.ndarray:
    """A first-order Gauss-Markov error (K, 2) of stationary std ``std`` per axis, forgetting
    over ``memory`` seconds."""
    out = np.zeros((time.size, 2))
    if std == 0 or time.size == 0:
        return out
    phi = np.exp(-np.diff(time, prepend=time[0]) / memory)
    draws = rng.standard_normal((time.size, 2))
    out[0] = std * draws[0]
    for k in range(1, time.size):
        out[k] = phi[k] * out[k - 1] + std * np.sqrt(1 - phi[k] ** 2) * draws[k]
    return out


def prior_map(seafloor: BathymetryMap, settings: PriorMapSettings, sonar, *, rng: np.random.Generator,
              name: str) -> tuple[BathymetryMap, Any, tuple[float, float]]:
    """The map gridded from a simulated earlier survey of ``seafloor``, that survey, and the
    std and range of the map's horizontal offset its gridding keeps (:func:`_offset`)."""
    from tangraph.gridding_surveys import grid_surveys
    from tangraph.maps.mesh import raycasting_scene
    from tangraph.sensors import simulate_pings
    from tangraph.survey import Survey

    time, truth = _prior_trajectory(seafloor, settings)
    # an earlier survey's soundings are reduced to the map's datum (no tide) unless stated
    sonar = dataclasses.replace(sonar, **({"ping_rate": settings.ping_rate, "tide": 0.0} | settings.sonar))
    depth = np.full(time.size, settings.vehicle_depth)
    pings = simulate_pings(raycasting_scene(seafloor), truth, depth, sonar, rng=rng)
    gps = truth.copy()
    gps[:, :2] += _gps_error(time, settings.position_std, rng, settings.position_time)
    survey = Survey(time=time, dr_pose=gps, vehicle_depth=depth, beam_forward=pings.beam_forward,
                    beam_starboard=pings.beam_starboard, beam_depth=pings.beam_depth, true_pose=gps,
                    meta={"crs": seafloor.crs, "origin": list(seafloor.origin), "name": f"{name} survey"})
    grid = grid_surveys([survey], cell=settings.cell, statistic=settings.statistic,  # type: ignore[arg-type]
                        fill=settings.fill, name=name, position_std=settings.position_std)
    log.info("prior map %r: %d pings, %.0f %% of cells measured", name, time.size,
             100 * float(np.mean(grid.count > 0)))
    across = truth[:, :2] @ _line_axes(seafloor, settings)[2]
    lines = np.rint((across - across[0]) / settings.line_spacing)
    return grid.depth.replace(name=name), survey, _offset(survey, lines, grid.depth, settings)


def _offset(survey, lines: np.ndarray, gridded: BathymetryMap,
            settings: PriorMapSettings) -> tuple[float, float]:
    """The horizontal offset a gridded map keeps of its soundings' positioning error: its std (m
    per axis) and its range (m). A cell's depth is placed where the soundings of the lines over
    it were placed, and the lines' errors are independent (a line takes many of the error's
    memories), so a cell of ``n`` lines is off by ``position_std / sqrt(n)``: the std is the
    root mean square of that over the measured cells. The offset is shared along a line over
    twice the distance the survey runs while its error forgets (an exponential correlation has
    fallen to 0.14 there, as a Matérn field's at its range) and across it by the lines' width
    of cover (the spacing times the lines over a cell); the range is the geometric mean of the
    two, the isotropic field of the same correlation area. ``lines (K,)`` is each ping's line."""
    north, east = survey.footprints(survey.dr_pose)
    i = np.rint((north - gridded.north[0]) / gridded.cell_size[0])
    j = np.rint((east - gridded.east[0]) / gridded.cell_size[1])
    has = (np.isfinite(survey.beam_depth) & (i >= 0) & (i < gridded.shape[0])
           & (j >= 0) & (j < gridded.shape[1]))
    if settings.position_std == 0 or not has.any():
        return 0.0, 0.0
    cell = (i * gridded.shape[1] + j)[has].astype(np.int64)
    line = np.broadcast_to(lines[:, None], has.shape)[has].astype(np.int64)
    n = np.bincount(np.unique(np.column_stack([cell, line]), axis=0)[:, 0])
    n = n[n > 0]
    along = 2.0 * settings.speed * settings.position_time
    return (float(settings.position_std * np.sqrt(np.mean(1.0 / n))),
            float(np.sqrt(along * settings.line_spacing * np.mean(n))))


def simulate_world(source: BathymetryMap, track: np.ndarray, seafloor: SeafloorSettings,
                   prior: PriorMapSettings, sonar, *, rng: np.random.Generator, name: str) -> ScenarioWorld:
    """The true seafloor around ``track (K, 2)`` and the prior map gridded from an earlier survey
    of it (module docstring)."""
    truth = true_seafloor(source, track, seafloor, rng=rng)
    gridded, survey, offset = prior_map(truth, prior, sonar, rng=rng, name=name)
    # drawn after the prior map: a world whose seafloor did not change is drawn as before
    return ScenarioWorld(changed_seafloor(truth, seafloor, rng=rng), gridded, survey, offset)
