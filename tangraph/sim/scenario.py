"""Scenarios: a map, a trajectory, a dead-reckoning model and a sonar, as a TOML file.

``experiments/scenarios/NAME.toml`` (packed into the wheel under ``tangraph/_experiments``)::

    name = "wang2019"
    description = "..."
    map = "merimbula"            # catalogue name or file; `tangraph simulate --map` overrides
    seed = 2019                  # default seed; `--seed` overrides
    vehicle_depth = 0.5          # metres, depth of the sonar
    [trajectory]                 # positions in metres from the map's south-west cell centre
    kind = "waypoints"           # "line" | "waypoints" | "lawnmower"
    ...
    [dead_reckoning]             # DeadReckoningModel fields, or preset = "..." plus overrides;
                                 # an angle field may be given in degrees as NAME_deg
    [sonar]                      # kind = "multibeam" | "singlebeam", preset, and config fields
    [study]                      # free-form settings for the studies (e.g. window lengths)
    [seafloor]                   # optional: the true seafloor is the map plus a random field
    [prior_map]                  # (with [seafloor]) the estimators' map, gridded from an
                                 # earlier survey of it (tangraph.sim.seafloor)

Unknown keys anywhere are refused, naming the key and the keys allowed there.
"""

from __future__ import annotations

import dataclasses
import os
import tomllib
from pathlib import Path
from typing import Any

import numpy as np

from tangraph.errors import TangraphError
from tangraph.maps.grid import BathymetryMap
from tangraph.sensors import (
    DeadReckoningModel,
    MultibeamConfig,
    SingleBeamConfig,
    simulate_dead_reckoning,
    simulate_pings,
)
from tangraph.sim import trajectories
from tangraph.sim.seafloor import PriorMapSettings, ScenarioWorld, SeafloorSettings, simulate_world
from tangraph.survey import Survey

__all__ = [
    "Scenario",
    "Simulation",
    "list_scenarios",
    "load_dr_model",
    "load_scenario",
    "scenario_path",
    "simulate",
    "simulate_run",
]

_TOP = {
    "name",
    "description",
    "map",
    "seed",
    "vehicle_depth",
    "trajectory",
    "dead_reckoning",
    "sonar",
    "study",
    "seafloor",
    "prior_map",
}
_TRAJECTORY = {
    "line": {"start", "heading_deg", "speed", "duration"},
    "waypoints": {"points", "speed", "turn_radius"},
    "lawnmower": {"origin", "heading_deg", "line_length", "line_spacing", "n_lines", "speed", "turn_radius"},
}
_SONARS = {"multibeam": MultibeamConfig, "singlebeam": SingleBeamConfig}


class ScenarioError(TangraphError):
    """A scenario file is not valid."""


@dataclasses.dataclass(frozen=True)
class Scenario:
    """A simulation setting; see the module docstring for the TOML form."""

    name: str
    map: str
    seed: int
    vehicle_depth: float
    trajectory: dict[str, Any]
    dead_reckoning: DeadReckoningModel
    sonar: MultibeamConfig | SingleBeamConfig
    description: str = ""
    study: dict[str, Any] = dataclasses.field(default_factory=dict)
    source: str = ""
    seafloor: SeafloorSettings | None = None
    prior_map: PriorMapSettings | None = None

    @property
    def map_error(self) -> bool:
        """The soundings see a true seafloor that is not the estimators' map."""
        return self.seafloor is not None

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready form, stored in a simulated survey's metadata."""
        world = {}
        if self.seafloor is not None and self.prior_map is not None:
            world = {"seafloor": dataclasses.asdict(self.seafloor),
                     "prior_map": dataclasses.asdict(self.prior_map)}
        return world | {
            "name": self.name,
            "map": self.map,
            "seed": self.seed,
            "vehicle_depth": self.vehicle_depth,
            "trajectory": self.trajectory,
            "dead_reckoning": dataclasses.asdict(self.dead_reckoning),
            "sonar": {"kind": _sonar_kind(self.sonar), **dataclasses.asdict(self.sonar)},
            "study": self.study,
            "source": self.source,
        }


def _sonar_kind(sonar) -> str:
    return next(k for k, cls in _SONARS.items() if isinstance(sonar, cls))


def scenario_path() -> Path:
    """The folder of the shipped scenarios."""
    here = Path(__file__).resolve().parent
    for folder in (here.parent / "_experiments" / "scenarios", here.parents[1] / "experiments" / "scenarios"):
        if folder.is_dir():
            return folder
    raise TangraphError("the scenario folder is missing (experiments/scenarios)")


def list_scenarios() -> list[str]:
    """Names of the shipped scenarios."""
    return sorted(p.stem for p in scenario_path().glob("*.toml"))


def _check_keys(table: dict, allowed: set[str], where: str) -> None:
    unknown = sorted(set(table) - allowed)
    if unknown:
        raise ScenarioError(f"{where}: unknown keys {unknown}; allowed: {sorted(allowed)}")


def _config(cls, table: dict, presets: dict, where: str):
    table = dict(table)
    preset = table.pop("preset", None)
    fields = {f.name for f in dataclasses.fields(cls)}
    for key in [k for k in table if k.endswith("_deg") and k[:-4] in fields]:  # angles in degrees
        value = table.pop(key)
        if not isinstance(value, (int, float)):
            raise ScenarioError(f"{where}: {key} must be a number, got {value!r}")
        table[key[:-4]] = float(np.radians(value))
    _check_keys(table, fields, where)
    if preset is not None:
        if preset not in presets:
            raise ScenarioError(f"{where}: unknown preset {preset!r}; known: {sorted(presets)}")
        base = presets[preset]()
    else:
        base = cls()
    try:
        return dataclasses.replace(base, **table)
    except (TangraphError, TypeError) as exc:
        raise ScenarioError(f"{where}: {exc}") from None


def _presets(cls) -> dict:
    return {
        name: getattr(cls, name)
        for name in dir(cls)
        if not name.startswith("_") and isinstance(cls.__dict__.get(name), classmethod)
    }


def load_dr_model(path: str | os.PathLike) -> DeadReckoningModel:
    """A dead-reckoning error model from a TOML file: the ``[dead_reckoning]`` table of a scenario,
    or the same keys at the top level (``DeadReckoningModel`` fields, ``preset``, ``NAME_deg``).

    Examples
    --------
    The file of a recorded survey's INS/DVL might read::

        heading_bias_deg = 0.5
        heading_walk_deg = 0.01     # deg / sqrt(s)
        speed_scale = 0.005
        speed_noise = 0.05
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"dead-reckoning model file {path} does not exist")
    try:
        with open(path, "rb") as f:
            table = tomllib.load(f)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path}: not valid TOML ({exc})") from None
    table = table.get("dead_reckoning", table)
    return _config(DeadReckoningModel, table, _presets(DeadReckoningModel), f"{path}")


def load_scenario(name_or_path: str | os.PathLike) -> Scenario:
    """A scenario from a TOML file, or a shipped one by name (``list_scenarios()``)."""
    path = Path(name_or_path)
    if not path.suffix and not path.is_file():  # a name (a folder of that name here is not a scenario)
        path = scenario_path() / f"{name_or_path}.toml"
        if not path.is_file():
            raise ScenarioError(
                f"no scenario named {str(name_or_path)!r}; known: {', '.join(list_scenarios())}"
            )
    if not path.is_file():
        raise FileNotFoundError(f"scenario file {path} does not exist")
    try:
        with open(path, "rb") as f:
            table = tomllib.load(f)
    except tomllib.TOMLDecodeError as exc:
        raise ScenarioError(f"{path}: not valid TOML ({exc})") from None
    where = str(path)
    _check_keys(table, _TOP, where)
    missing = sorted({"map", "vehicle_depth", "trajectory", "sonar"} - set(table))
    if missing:
        raise ScenarioError(f"{where}: missing keys {missing}")
    traj = dict(table["trajectory"])
    kind = traj.pop("kind", None)
    if kind not in _TRAJECTORY:
        raise ScenarioError(f"{where} [trajectory]: kind must be one of {sorted(_TRAJECTORY)}, got {kind!r}")
    _check_keys(traj, _TRAJECTORY[kind], f"{where} [trajectory]")
    sonar = dict(table["sonar"])
    sonar_kind = sonar.pop("kind", "multibeam")
    if sonar_kind not in _SONARS:
        raise ScenarioError(f"{where} [sonar]: kind must be one of {sorted(_SONARS)}, got {sonar_kind!r}")
    depth = table["vehicle_depth"]
    if not isinstance(depth, (int, float)) or not np.isfinite(depth) or depth < 0:
        raise ScenarioError(f"{where}: vehicle_depth must be a number >= 0, got {depth!r}")
    seed = table.get("seed", 0)
    if not isinstance(seed, int) or seed < 0:
        raise ScenarioError(f"{where}: seed must be a non-negative integer, got {seed!r}")
    return Scenario(
        name=str(table.get("name", path.stem)),
        map=str(table["map"]),
        seed=seed,
        vehicle_depth=float(depth),
        trajectory={"kind": kind, **traj},
        dead_reckoning=_config(
            DeadReckoningModel,
            table.get("dead_reckoning", {}),
            _presets(DeadReckoningModel),
            f"{where} [dead_reckoning]",
        ),
        sonar=_config(_SONARS[sonar_kind], sonar, _presets(_SONARS[sonar_kind]), f"{where} [sonar]"),
        description=str(table.get("description", "")),
        study=dict(table.get("study", {})),
        source=str(path),
        **_world(table, where),
    )


def _world(table: dict, where: str) -> dict[str, Any]:
    """The ``[seafloor]`` and ``[prior_map]`` tables: both or neither."""
    if ("seafloor" in table) != ("prior_map" in table):
        raise ScenarioError(f"{where}: [seafloor] and [prior_map] go together (a seafloor that is not the "
                            "map needs the map the estimators use, and the other way round)")
    if "seafloor" not in table:
        return {}
    try:
        return {"seafloor": SeafloorSettings.from_table(dict(table["seafloor"]), f"{where} [seafloor]"),
                "prior_map": PriorMapSettings.from_table(dict(table["prior_map"]), f"{where} [prior_map]")}
    except TangraphError as exc:
        raise ScenarioError(str(exc)) from None


def true_trajectory(scenario: Scenario, bathymetry: BathymetryMap) -> tuple[np.ndarray, np.ndarray]:
    """``(time, pose)`` of the scenario on a map, sampled at the sonar's ping rate."""
    t = dict(scenario.trajectory)
    kind = t.pop("kind")
    corner = np.array([bathymetry.north[0], bathymetry.east[0]])
    rate = scenario.sonar.ping_rate
    try:
        if kind == "line":
            return trajectories.straight_line(
                corner + np.asarray(t["start"], float),
                np.radians(t["heading_deg"]),
                t["speed"],
                t["duration"],
                rate,
            )
        if kind == "waypoints":
            return trajectories.waypoint_route(
                corner + np.asarray(t["points"], float),
                t["speed"],
                rate,
                turn_radius=t.get("turn_radius", 0.0),
            )
        return trajectories.lawnmower(
            corner + np.asarray(t["origin"], float),
            np.radians(t["heading_deg"]),
            t["line_length"],
            t["line_spacing"],
            t["n_lines"],
            t["speed"],
            rate,
            turn_radius=t.get("turn_radius"),
        )
    except KeyError as exc:
        raise ScenarioError(
            f"{scenario.source} [trajectory]: missing key {exc.args[0]!r} for kind {kind!r}"
        ) from None


@dataclasses.dataclass(frozen=True, eq=False)
class Simulation:
    """A simulated run: the ``survey``, the ``bathymetry`` its estimators navigate on, and the
    ``world`` (true seafloor and prior map) when the seafloor is not that map (None otherwise:
    the soundings were ray cast on ``bathymetry`` itself)."""

    survey: Survey
    bathymetry: BathymetryMap
    world: ScenarioWorld | None = None


def simulate(
    scenario: Scenario,
    *,
    rng: np.random.Generator,
    bathymetry: BathymetryMap | None = None,
    seed: int | None = None,
) -> Survey:
    """Simulate a survey: truth, dead reckoning and ray-cast soundings on the scenario's map.

    The survey of :func:`simulate_run`; use that one for a scenario whose seafloor is not its map
    (``[seafloor]``), whose estimators navigate on the prior map it returns.
    """
    return simulate_run(scenario, rng=rng, bathymetry=bathymetry, seed=seed).survey


def simulate_run(
    scenario: Scenario,
    *,
    rng: np.random.Generator,
    bathymetry: BathymetryMap | None = None,
    seed: int | None = None,
) -> Simulation:
    """Simulate a survey and the map its estimators use.

    Truth, dead reckoning and soundings ray cast on the seafloor: the scenario's map
    (``bathymetry`` overrides it), or, for a scenario with ``[seafloor]`` and ``[prior_map]``,
    a true seafloor that is the map plus a random field, with a prior map gridded from an
    earlier survey of it (:mod:`tangraph.sim.seafloor`), all drawn from ``rng``. ``seed`` is
    only recorded (pass the generator built from it as ``rng``). The trajectory leaving the map
    is allowed: its pings have no returns, counted in ``meta["sonar_counts"]``.
    """
    from tangraph.maps import load_any
    from tangraph.maps.mesh import raycasting_scene

    source = bathymetry if bathymetry is not None else load_any(scenario.map)
    time, true_pose = true_trajectory(scenario, source)
    world = None
    seafloor, estimators_map = source, source
    if scenario.seafloor is not None and scenario.prior_map is not None:
        world = simulate_world(source, true_pose[:, :2], scenario.seafloor, scenario.prior_map,
                               scenario.sonar, rng=rng, name=f"{scenario.name} prior map")
        seafloor, estimators_map = world.seafloor, world.prior_map
    dr = simulate_dead_reckoning(time, true_pose, scenario.dead_reckoning, rng=rng)
    vehicle_depth = np.full(time.size, scenario.vehicle_depth)
    pings = simulate_pings(raycasting_scene(seafloor), true_pose, vehicle_depth, scenario.sonar, rng=rng)
    depth = pings.beam_depth
    sonar = scenario.sonar
    if sonar.tide_drift_std > 0:  # drawn last: a survey without a drift draws what it always did
        depth = depth + _tide_drift(time, sonar.tide_drift_std, sonar.tide_drift_time, rng)[:, None]
    import tangraph
    from tangraph.map_frame import map_identity

    meta = {
        "map": estimators_map.name,
        "map_identity": map_identity(estimators_map),
        "scenario": scenario.name,
        "seed": seed,
        "software": f"tangraph {tangraph.__version__}",
        "crs": estimators_map.crs,
        "origin": list(estimators_map.origin),
        "settings": scenario.as_dict(),
        "sonar_counts": {
            "missing": int(pings.n_missing),
            "outliers": int(pings.n_outliers),
            "off_map": int(pings.n_off_map),
        },
        "dvl_dropouts": int(dr.n_dropouts),
    }
    if world is not None:
        drawn = scenario.seafloor  # the change since the earlier survey: its RMS and range
        change = (drawn.change_std, drawn.correlation_length) if drawn and drawn.change_std else (0.0, 0.0)
        meta["seafloor"] = {"source_map": source.name, "map_error_rms": _rms(world.map_error()),
                            "map_offset_std": world.offset[0], "map_offset_length": world.offset[1],
                            "map_change_std": change[0], "map_change_length": change[1]}
    survey = Survey(
        time=time,
        dr_pose=dr.pose,
        vehicle_depth=vehicle_depth,
        beam_forward=pings.beam_forward,
        beam_starboard=pings.beam_starboard,
        beam_depth=depth,
        true_pose=true_pose,
        meta=meta,
    )
    return Simulation(survey, estimators_map, world)


def _tide_drift(time: np.ndarray, std: float, forget: float, rng: np.random.Generator) -> np.ndarray:
    """A Gauss-Markov offset of ``std`` m forgetting over ``forget`` s at ``time (K,)``, started
    from its stationary law: the tide's drift on top of the sonar's ``tide``."""
    keep = np.exp(-np.diff(time) / forget)
    draws = rng.standard_normal(time.size)
    drift = np.empty(time.size)
    drift[0] = std * draws[0]
    for k in range(1, time.size):
        drift[k] = keep[k - 1] * drift[k - 1] + std * np.sqrt(1.0 - keep[k - 1] ** 2) * draws[k]
    return drift


def _rms(error: np.ndarray) -> float:
    finite = error[np.isfinite(error)]
    return float(np.sqrt(np.mean(finite**2))) if finite.size else float("nan")
