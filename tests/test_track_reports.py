"""A track's reports against its survey (tangraph.track_reports): the summary the CLI and the demo
print, with the poses flagged lost."""

from __future__ import annotations

import numpy as np

from tangraph.track import Track


def test_the_summary_says_which_poses_are_lost():
    from tangraph.navigation import track_summary
    from tangraph.survey import Survey

    survey = Survey(time=np.arange(5.0), dr_pose=np.zeros((5, 3)), vehicle_depth=np.zeros(5),
                    beam_forward=np.zeros((5, 1)), beam_starboard=np.zeros((5, 1)),
                    beam_depth=np.full((5, 1), 10.0))
    track = Track(time=np.arange(5.0), pose=np.zeros((5, 3)),
                  meta={"lost_steps": [1, 2], "lost_episodes": [{"start": 1}], "n_off_map": 3,
                        "start_prior": "outlier"})
    text = track_summary(track, survey)
    assert "2 pings flagged lost in 1 episodes" in text and "3 pings: dead reckoning only" in text
    assert "start position prior disagreed" in text
