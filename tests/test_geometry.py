"""tangraph.geometry against simple references: known rotations, SE(2) round trips, the DR
calibration's similarity and its inverse, the Mahalanobis distance against a linear solve, and
angle wrapping at its boundaries."""

import numpy as np
import pytest

from tangraph.geometry import (
    between,
    body_to_world,
    compose,
    from_dr_frame,
    mahalanobis2,
    rotate,
    rotation_matrix,
    to_dr_frame,
    world_to_body,
    wrap_angle,
    wrap_near,
)

RNG = np.random.default_rng(20231)


def random_poses(shape):
    return np.concatenate([RNG.normal(0.0, 100.0, (*shape, 2)), RNG.uniform(-4.0, 4.0, (*shape, 1))], axis=-1)


@pytest.mark.parametrize(("psi", "expected"), [
    (0.0, [10.0, 2.0]),  # north: forward is north, starboard east
    (np.pi / 2, [-2.0, 10.0]),  # east: forward is east, starboard south
    (np.pi, [-10.0, -2.0]),
    (-np.pi / 2, [2.0, -10.0]),  # west: starboard is north
])
def test_rotation_turns_known_vectors_clockwise_from_north(psi, expected):
    np.testing.assert_allclose(rotate(psi, [10.0, 2.0]), expected, atol=1e-12)
    np.testing.assert_allclose(rotation_matrix(psi) @ [10.0, 2.0], expected, atol=1e-12)


def test_rotation_matrices_are_orthonormal_and_vectorised():
    psi = RNG.uniform(-10.0, 10.0, (4, 5))
    r = rotation_matrix(psi)
    assert r.shape == (4, 5, 2, 2)
    np.testing.assert_allclose(r @ np.swapaxes(r, -1, -2), np.broadcast_to(np.eye(2), r.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(r), 1.0)
    vec = RNG.normal(size=(4, 5, 2))
    np.testing.assert_array_equal(rotate(psi, vec), np.einsum("...ij,...j->...i", r, vec))
    np.testing.assert_allclose(rotate(-psi, rotate(psi, vec)), vec, atol=1e-12)


def test_rotate_broadcasts_headings_against_vectors():
    psi, vec = RNG.uniform(-3.0, 3.0, (3, 1)), RNG.normal(size=(7, 2))
    out = rotate(psi, vec)
    assert out.shape == (3, 7, 2)
    for h in range(3):
        np.testing.assert_allclose(out[h], vec @ rotation_matrix(psi[h, 0]).T, atol=1e-12)


def test_body_and_world_points_round_trip():
    pose, points = random_poses((6, 1)), RNG.normal(0.0, 30.0, (6, 9, 2))
    world = body_to_world(pose, points)
    assert world.shape == (6, 9, 2)
    turned = np.einsum("...ij,...j->...i", rotation_matrix(pose[..., 2]), points)
    np.testing.assert_allclose(world, pose[..., :2] + turned, atol=1e-9)
    np.testing.assert_allclose(world_to_body(pose, world), points, atol=1e-9)


def test_compose_then_between_is_the_identity():
    pose, increment = random_poses((50,)), random_poses((50,))
    increment[:, 2] = RNG.uniform(-np.pi, np.pi, 50)
    np.testing.assert_allclose(between(pose, compose(pose, increment)), increment, atol=1e-9)
    np.testing.assert_allclose(between(pose, pose), 0.0, atol=1e-12)


def test_between_then_compose_gives_the_pose_up_to_whole_turns():
    a, b = random_poses((3, 4)), random_poses((3, 4))
    back = compose(a, between(a, b))
    np.testing.assert_allclose(back[..., :2], b[..., :2], atol=1e-9)
    np.testing.assert_allclose(wrap_angle(back[..., 2] - b[..., 2]), 0.0, atol=1e-12)


def test_compose_matches_gtsam_pose2():
    gtsam = pytest.importorskip("gtsam")
    pose, increment = random_poses((20,)), random_poses((20,))
    for p, d, got in zip(pose, increment, compose(pose, increment), strict=True):
        want = gtsam.Pose2(*p).compose(gtsam.Pose2(*d))
        np.testing.assert_allclose(got[:2], [want.x(), want.y()], atol=1e-9)
        assert wrap_angle(got[2] - want.theta()) == pytest.approx(0.0, abs=1e-12)
    for p, q, got in zip(pose, increment, between(pose, increment), strict=True):
        want = gtsam.Pose2(*p).between(gtsam.Pose2(*q))
        np.testing.assert_allclose(got, [want.x(), want.y(), want.theta()], atol=1e-9)


def test_dr_frame_similarity_and_its_inverse_round_trip():
    calibration, origin = (0.03, np.deg2rad(-4.0)), np.array([120.0, -40.0])
    poses = random_poses((5, 8))
    dr = to_dr_frame(poses, calibration, origin)
    assert dr.shape == poses.shape
    np.testing.assert_allclose(from_dr_frame(dr, calibration, origin), poses, atol=1e-9)
    np.testing.assert_allclose(to_dr_frame(from_dr_frame(poses, calibration, origin), calibration, origin),
                               poses, atol=1e-9)
    # positions alone: the same map without a heading
    np.testing.assert_array_equal(to_dr_frame(poses[..., :2], calibration, origin), dr[..., :2])
    np.testing.assert_allclose(dr[..., 2], poses[..., 2] + calibration[1])


def test_dr_frame_is_the_dead_reckoning_of_a_biased_scaled_track():
    # a DVL reading 1 + k times the speed and a heading b off turn every step by b and stretch it
    k, b = 0.05, np.deg2rad(10.0)
    truth = np.cumsum(RNG.normal(0.0, 5.0, (30, 2)), axis=0)
    steps = np.diff(truth, axis=0)
    dr = np.concatenate([truth[:1], truth[:1] + np.cumsum((1 + k) * rotate(b, steps), axis=0)])
    np.testing.assert_allclose(to_dr_frame(truth, (k, b), truth[0]), dr, atol=1e-9)
    np.testing.assert_allclose(to_dr_frame(truth[0], (k, b), truth[0]), truth[0])  # the start stays


def test_mahalanobis_matches_a_linear_solve():
    error = RNG.normal(0.0, 3.0, (40, 2))
    root = RNG.normal(size=(40, 2, 2))
    cov = root @ np.swapaxes(root, -1, -2) + 0.1 * np.eye(2)
    want = np.array([e @ np.linalg.solve(c, e) for e, c in zip(error, cov, strict=True)])
    np.testing.assert_allclose(mahalanobis2(error, cov), want, rtol=1e-12)
    # one covariance for many errors, factorised once
    np.testing.assert_allclose(mahalanobis2(error, cov[0]), [e @ np.linalg.solve(cov[0], e) for e in error],
                               rtol=1e-12)
    assert mahalanobis2(error[0], cov[0]) == pytest.approx(want[0], rel=1e-12)
    assert mahalanobis2(error.reshape(4, 10, 2), cov.reshape(4, 10, 2, 2)).shape == (4, 10)
    assert mahalanobis2(np.zeros((0, 2)), cov[0]).shape == (0,)


def test_mahalanobis_of_more_dimensions_and_known_values():
    assert mahalanobis2([3.0, 4.0], np.eye(2)) == pytest.approx(25.0)
    assert mahalanobis2([2.0, 0.0, 3.0], np.diag([4.0, 1.0, 9.0])) == pytest.approx(2.0)


@pytest.mark.parametrize(("angle", "expected"), [
    (0.0, 0.0),
    (np.pi, -np.pi),  # the interval is [-pi, pi): pi itself is -pi
    (-np.pi, -np.pi),
    (3 * np.pi, -np.pi),
    (np.pi - 1e-9, np.pi - 1e-9),  # just inside stays
    (1.5 * np.pi, -0.5 * np.pi),
    (-1.5 * np.pi, 0.5 * np.pi),
    (2 * np.pi + 0.25, 0.25),
])
def test_wrap_at_the_boundaries(angle, expected):
    assert wrap_angle(angle) == pytest.approx(expected, abs=1e-12)


def test_wrap_lands_in_the_interval_and_keeps_the_angle():
    angle = RNG.uniform(-50.0, 50.0, 1000)
    wrapped = wrap_angle(angle)
    assert np.all((wrapped >= -np.pi) & (wrapped < np.pi))
    np.testing.assert_allclose(np.cos(wrapped), np.cos(angle), atol=1e-12)
    np.testing.assert_allclose(np.sin(wrapped), np.sin(angle), atol=1e-12)
    near = wrap_near(angle, 10.0)
    assert np.all(np.abs(near - 10.0) <= np.pi)
    np.testing.assert_allclose(np.sin(near), np.sin(angle), atol=1e-12)
