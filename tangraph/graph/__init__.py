"""Factor-graph terrain-aided navigation: key poses, DR odometry and TAP fixes solved by GTSAM.

The only package of tangraph that imports gtsam. Online: :class:`GraphNavigator` and
:func:`navigate_online` (iSAM2), whose fix policy (:class:`FixPolicy`, :mod:`tangraph.graph.policy`)
is pure; recorded surveys: :func:`smooth_survey` (batch smoother).
"""

from tangraph.fix_records import FixRecord, FixStatus
from tangraph.graph.config import BatchConfig, FixConfig, GraphConfig, OnlineConfig, load_graph_config
from tangraph.graph.factors import (
    between_noise,
    check_fix_covariance,
    compose,
    propagate,
    tangent_to_world,
    world_to_tangent,
)
from tangraph.graph.fixes import LostEpisode, search_half_width
from tangraph.graph.keyposes import PoseGraph, fix_windows, increments, key_indices, window_ends
from tangraph.graph.online import GraphNavigator, navigate_online
from tangraph.graph.policy import FixPolicy, PolicyState
from tangraph.graph.smoother import SmootherSolution, dense_track, smooth_pose_graph, smooth_survey

__all__ = [
    "BatchConfig",
    "FixConfig",
    "FixPolicy",
    "FixRecord",
    "FixStatus",
    "GraphConfig",
    "GraphNavigator",
    "LostEpisode",
    "OnlineConfig",
    "PolicyState",
    "PoseGraph",
    "SmootherSolution",
    "between_noise",
    "check_fix_covariance",
    "compose",
    "dense_track",
    "fix_windows",
    "increments",
    "key_indices",
    "load_graph_config",
    "navigate_online",
    "propagate",
    "search_half_width",
    "smooth_pose_graph",
    "smooth_survey",
    "tangent_to_world",
    "window_ends",
    "world_to_tangent",
]
