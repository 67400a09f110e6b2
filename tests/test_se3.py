"""Rigid-transform helpers, checked as properties over random poses (hypothesis)."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays
from scipy.spatial.transform import Rotation

from brachycal import se3

finite = st.floats(-10.0, 10.0, allow_nan=False)
vectors = arrays(np.float64, 3, elements=finite)
quaternions = arrays(np.float64, 4, elements=st.floats(-1.0, 1.0)).filter(lambda q: np.linalg.norm(q) > 0.1)


def pose(q: np.ndarray, p: np.ndarray) -> np.ndarray:
    return se3.make_transform(Rotation.from_quat(q).as_matrix(), p)


@given(quaternions, vectors)
def test_inverse_undoes_the_transform(q, p):
    T_a_b = pose(q, p)
    assert np.allclose(se3.inverse(T_a_b) @ T_a_b, np.eye(4), atol=1e-12)
    assert se3.is_rigid(se3.inverse(T_a_b))


@given(quaternions, vectors, quaternions, vectors, vectors)
def test_composition_reads_left_to_right(q1, p1, q2, p2, p_c):
    T_a_b, T_b_c = pose(q1, p1), pose(q2, p2)
    p_a = se3.transform_points(T_a_b @ T_b_c, p_c)
    assert np.allclose(p_a, se3.transform_points(T_a_b, se3.transform_points(T_b_c, p_c)), atol=1e-12)


@given(quaternions, vectors)
def test_quaternion_is_ros_order_with_nonnegative_w(q, p):
    position, quat = se3.to_position_quaternion(pose(q, p))
    assert quat[3] >= 0.0
    assert np.isclose(np.linalg.norm(quat), 1.0)
    assert np.allclose(Rotation.from_quat(quat).as_matrix(), pose(q, p)[:3, :3], atol=1e-12)
    assert np.allclose(position, p)


@settings(max_examples=300)
@given(quaternions, vectors)
def test_urdf_xyz_rpy_round_trip(q, p):
    T = pose(q, p)
    xyz, rpy = se3.to_xyz_rpy(T)
    assert np.abs(se3.from_xyz_rpy(xyz, rpy) - T).max() < 1e-14


@pytest.mark.parametrize("pitch", [np.pi / 2, -np.pi / 2, np.pi / 2 - 1e-11, np.pi / 2 - 3e-8, -np.pi / 2 + 1e-9])
def test_urdf_xyz_rpy_round_trip_at_gimbal_lock(pitch):
    T = se3.from_xyz_rpy([0.1, 0.2, 0.3], [0.4, pitch, -1.2])
    assert np.abs(se3.from_xyz_rpy(*se3.to_xyz_rpy(T)) - T).max() < 1e-14


def test_urdf_rpy_is_fixed_axis_roll_pitch_yaw():
    # URDF: R = Rz(yaw) @ Ry(pitch) @ Rx(roll)
    roll, pitch, yaw = 0.3, -0.2, 1.1
    Rx = Rotation.from_rotvec([roll, 0, 0]).as_matrix()
    Ry = Rotation.from_rotvec([0, pitch, 0]).as_matrix()
    Rz = Rotation.from_rotvec([0, 0, yaw]).as_matrix()
    assert np.allclose(se3.from_xyz_rpy([0, 0, 0], [roll, pitch, yaw])[:3, :3], Rz @ Ry @ Rx)


def test_batched_shapes():
    T = np.broadcast_to(np.eye(4), (5, 2, 4, 4))
    assert se3.inverse(T).shape == (5, 2, 4, 4)
    assert se3.transform_points(T, np.ones((5, 2, 3))).shape == (5, 2, 3)
    assert se3.to_position_quaternion(T)[1].shape == (5, 2, 4)


def test_reflection_is_not_rigid():
    assert not se3.is_rigid(np.diag([1.0, 1.0, -1.0, 1.0]))


@given(quaternions, arrays(np.float64, 3, elements=st.floats(0.05, 5.0)))
def test_nearest_rotation_of_scaled_columns_is_their_rotation(q, scales):
    """A rotation with its columns scaled (an Image→Probe matrix and its spacings) gives back that rotation."""
    R = Rotation.from_quat(q).as_matrix()
    np.testing.assert_allclose(se3.nearest_rotation(R * scales), R, atol=1e-9)  # well-conditioned SVD


def test_nearest_rotation_agrees_with_scipy_on_a_noisy_matrix():
    """An independent second computation: SciPy's Kabsch alignment of the identity basis with M's columns."""
    rng = np.random.default_rng(3)
    M = Rotation.random(random_state=4).as_matrix() + 0.05 * rng.normal(size=(3, 3))
    R, _ = Rotation.align_vectors(M.T, np.eye(3))
    np.testing.assert_allclose(se3.nearest_rotation(M), R.as_matrix(), atol=1e-9)
    assert np.linalg.det(se3.nearest_rotation(np.diag([1.0, 1.0, -1.0]))) > 0  # a reflection gives a rotation
