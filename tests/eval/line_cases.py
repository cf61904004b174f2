"""Survey lines over a known seafloor for the check-line tests: a ping a metre along east, beams
across, soundings with white noise, the reference track the truth."""

import numpy as np

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
