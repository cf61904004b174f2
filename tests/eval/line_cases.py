"""Survey lines over a known seafloor for the check-line tests: a ping a metre along east, beams
across, soundings with white noise, the reference track the truth; a map of it by an earlier
survey and the seafloor as a later survey finds it."""

import numpy as np

from tangraph.maps import BathymetryMap
from tangraph.sensors.matern import matern_field
from tangraph.survey import Survey

AXIS_N = np.arange(0.0, 400.0, 2.0)
AXIS_E = np.arange(0.0, 2000.0, 2.0)
SOUNDING_STD = 0.1


def seafloor(north, east):
    return 30.0 + 0.02 * north + 1.5 * np.sin(east / 60.0) * np.cos(north / 45.0)


def line_survey(truth, rng, *, lines, offsets=(-3.0, 0.0, 3.0), name="s"):
    """Lines along east at the given norths, a ping per metre, beams across, soundings of the
    seafloor ``truth(north, east)`` with white noise; the reference track is the truth."""
    east = np.arange(20.0, 1980.0, 1.0)
    poses = np.concatenate([np.column_stack([np.full(east.size, n), east if i % 2 == 0 else east[::-1],
                                             np.full(east.size, 0.0 if i % 2 == 0 else np.pi / 2 * 2)])
                            for i, n in enumerate(lines)])
    k, b = poses.shape[0], len(offsets)
    fwd, stb = np.zeros((k, b)), np.tile(np.asarray(offsets, float), (k, 1))
    survey = Survey(time=np.arange(k, dtype=float), dr_pose=poses, true_pose=poses, vehicle_depth=np.zeros(k),
                    beam_forward=fwd, beam_starboard=stb, beam_depth=np.zeros((k, b)), meta={"name": name})
    north, east_ = survey.footprints(poses)
    depth = truth(north, east_) + SOUNDING_STD * rng.standard_normal((k, b))
    return survey.replace(beam_depth=depth)


MAP_STD, MAP_LENGTH = 0.1, 8.0  # the map's own statement: its error as it was gridded
AXIS_MAP_N, AXIS_MAP_E = np.arange(0.0, 400.0, 4.0), np.arange(0.0, 2000.0, 4.0)


def earlier_map() -> BathymetryMap:
    """The seafloor as an earlier survey mapped it, stating its error: 0.1 m over 8 m."""
    nn, ee = np.meshgrid(AXIS_MAP_N, AXIS_MAP_E, indexing="ij")
    return BathymetryMap(AXIS_MAP_N, AXIS_MAP_E, seafloor(nn, ee), depth_std=np.full(nn.shape, MAP_STD),
                         correlation_length=MAP_LENGTH, name="earlier")


def field_on_lines(std: float, length: float, rng) -> BathymetryMap:
    """A Matérn field of ``std`` and range ``length`` over the lines' area."""
    return BathymetryMap(AXIS_N, AXIS_E, matern_field(AXIS_N, AXIS_E, std, length, rng=rng))


def later_survey(seed: int, change_std: float, change_length: float = 40.0):
    """Lines over the seafloor as it is now: the map, its own error as stated, and a change of
    ``change_std`` and range ``change_length`` since."""
    rng = np.random.default_rng(seed)
    error = field_on_lines(MAP_STD, MAP_LENGTH, rng)
    change = field_on_lines(change_std, change_length, rng) if change_std > 0 else None

    def now(north, east):
        depth = seafloor(north, east) + error.depth_at(north, east)
        return depth if change is None else depth + change.depth_at(north, east)

    return line_survey(now, rng, lines=np.arange(30.0, 380.0, 45.0), name=f"later {seed}")
