"""Forward kinematics back ends: every URDF joint type loads, the batch path is an optional fast path.

The batch path (NumPy, :mod:`brachycal.model.batch_fk`) compiles revolute, continuous and
prismatic joints; a model with any other joint (mimic, planar, floating) falls back to Pinocchio's
own per-configuration evaluation, chosen once when the robot is built. Either way the poses must
be Pinocchio's: 1e-12 m (and 1e-12 on rotation entries) is a few hundred float64 roundings on
metre-sized chains, far below anything physical, and far above the last bits that differ between
two correct evaluation orders.
"""

from __future__ import annotations

import importlib.metadata
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from conftest import random_configurations

from brachycal import InputError
from brachycal.model import Robot
from brachycal.se3 import make_transform

ROBOTS = Path(
    str(
        importlib.metadata.distribution("example-robot-data").locate_file(
            "cmeel.prefix/share/example-robot-data/robots"
        )
    )
)
#: Agreement of two evaluations of the same pose (see the module docstring).
TOL = 1e-12


def _draw(robot: Robot, n: int, seed: int) -> np.ndarray:
    """``(n, nq)`` configurations inside finite limits, in ±4 rad (more than half a turn) where unbounded."""
    rng = np.random.default_rng(seed)
    lower = np.where(np.isfinite(robot.lower), robot.lower, -4.0)
    upper = np.where(np.isfinite(robot.upper), robot.upper, 4.0)
    return rng.uniform(lower, upper, size=(n, robot.nq))


def _pinocchio_reference(path: Path, frames: list[str], V: np.ndarray) -> np.ndarray:
    """``(F, N, 4, 4)`` frame poses from a model Pinocchio builds from the file itself.

    A model of revolute, prismatic and mimic joints takes the coordinates as they are; one with
    continuous joints gets them through Pinocchio's own ``integrate`` from its neutral
    configuration (the tangent coordinate of a continuous joint is exactly its angle). Either way
    this is independent of brachycal's coordinate mapping.
    """
    model = pin.buildModelFromUrdf(str(path), mimic=True)
    data = model.createData()
    ids = [model.getFrameId(f) for f in frames]
    out = np.empty((len(frames), len(V), 4, 4))
    for i, v in enumerate(V):
        q = v if model.nq == model.nv else pin.integrate(model, pin.neutral(model), v)
        pin.framesForwardKinematics(model, data, q)
        for k, fid in enumerate(ids):
            out[k, i] = data.oMf[fid].homogeneous
    return out


def test_the_sda10f_keeps_the_batch_path(robot):
    assert robot.fk_backend == "batch"
    assert robot.nq == robot.model.nq == 15  # its coordinates are Pinocchio's configuration as they are


@pytest.mark.parametrize(
    ("relative", "backend", "kinds"),
    [
        ("ur_description/urdf/ur5_robot.urdf", "batch", {"revolute"}),
        ("kinova_description/robots/kinova.urdf", "batch", {"revolute", "continuous"}),
        ("double_pendulum_description/urdf/double_pendulum_continuous.urdf", "batch", {"continuous"}),
        ("panda_description/urdf/panda.urdf", "pinocchio", {"revolute", "prismatic", "mimic"}),
    ],
)
def test_published_robots_load_and_match_pinocchio(relative, backend, kinds):
    path = ROBOTS / relative
    other = Robot.load(path)
    assert other.fk_backend == backend
    assert set(other.joint_kinds.values()) == kinds  # the joint types the case is about
    V = _draw(other, 300, seed=12)
    frames = list(other.frame_names[1:])
    assert np.abs(other.fk_frames(frames, V) - _pinocchio_reference(path, frames, V)).max() < TOL
    # One configuration goes through the same back end and gives the same pose.
    assert np.abs(other.fk(frames[-1], V[7]) - _pinocchio_reference(path, frames[-1:], V[7:8])[0, 0]).max() < TOL


def _urdf(first: str, extra: str = "") -> str:
    """Joint ``j1`` of URDF type ``first`` (origin and axis off the coordinate axes), then a revolute ``j2``."""
    return f"""<robot name="r">
  <link name="a"/><link name="b"/><link name="c"/><link name="tip"/>
  <joint name="j1" type="{first}"><parent link="a"/><child link="b"/>
    <origin xyz="0.1 0.2 0.3" rpy="0.1 0.2 0.3"/><axis xyz="0 0.6 0.8"/>
    <limit lower="-1" upper="1" effort="1" velocity="2"/></joint>
  <joint name="j2" type="revolute"><parent link="b"/><child link="c"/><origin xyz="0.1 0 0"/><axis xyz="1 0 0"/>
    {extra}<limit lower="-1" upper="1" effort="1" velocity="2"/></joint>
  <joint name="tip_joint" type="fixed"><parent link="c"/><child link="tip"/><origin xyz="0 0.2 0"/></joint>
</robot>"""


CONTINUOUS = """<robot name="wheel">
  <link name="base"/><link name="wheel"/><link name="tip"/>
  <joint name="spin" type="continuous"><parent link="base"/><child link="wheel"/><axis xyz="0 1 0"/></joint>
  <joint name="tip_joint" type="fixed"><parent link="wheel"/><child link="tip"/><origin xyz="0.1 0 0"/></joint>
</robot>"""


def test_a_continuous_joint_is_one_unbounded_angle_on_the_batch_path():
    wheel = Robot(CONTINUOUS, base_dir=".")
    assert wheel.fk_backend == "batch"
    assert wheel.joint_names == ("spin",) and wheel.model.nq == 2  # Pinocchio's (cos, sin), one angle for us
    assert (wheel.lower, wheel.upper) == (-np.inf, np.inf)
    theta = np.array([[-7.0], [-0.3], [0.0], [2.0], [9.5]])  # past a full turn both ways
    p_base_tip = wheel.fk("tip", theta)[:, :3, 3]
    # A turn by θ about y carries (0.1, 0, 0) to (0.1 cos θ, 0, −0.1 sin θ).
    expected = 0.1 * np.column_stack([np.cos(theta[:, 0]), np.zeros(5), -np.sin(theta[:, 0])])
    assert np.abs(p_base_tip - expected).max() < TOL
    assert np.allclose(wheel.joint_axis("spin"), [0.0, 1.0, 0.0], atol=0)


def test_a_mimic_joint_follows_its_leader_on_the_pinocchio_path():
    follower = Robot(_urdf("revolute", '<mimic joint="j1" multiplier="2" offset="0.1"/>'), base_dir=".")
    free = Robot(_urdf("revolute"), base_dir=".")  # the same geometry with j2 an axis of its own
    assert (follower.fk_backend, free.fk_backend) == ("pinocchio", "batch")
    assert follower.joint_names == ("j1",)  # no column for the mimic joint
    q1 = _draw(follower, 200, seed=1)[:, 0]
    expected = free.fk_frames(["c", "tip"], np.column_stack([q1, 2 * q1 + 0.1]))
    assert np.abs(follower.fk_frames(["c", "tip"], q1[:, None]) - expected).max() < TOL


def test_a_floating_joint_takes_xyz_and_urdf_rpy_on_the_pinocchio_path():
    robot = Robot(_urdf("floating"), base_dir=".")
    assert robot.fk_backend == "pinocchio"
    assert robot.joint_names == ("j1.x", "j1.y", "j1.z", "j1.roll", "j1.pitch", "j1.yaw", "j2")
    assert robot.in_metres.tolist() == [True, True, True, False, False, False, False]
    Q = _draw(robot, 100, seed=2)
    T_a_j1 = make_transform(pin.rpy.rpyToMatrix(0.1, 0.2, 0.3), [0.1, 0.2, 0.3])  # the joint's <origin>
    for q, T in zip(Q, robot.fk("b", Q), strict=True):
        # Pinocchio's rpyToMatrix is URDF's convention: R = Rz(yaw) Ry(pitch) Rx(roll).
        assert np.abs(T - T_a_j1 @ make_transform(pin.rpy.rpyToMatrix(*q[3:6]), q[:3])).max() < TOL


def test_a_planar_joint_takes_x_y_theta_on_the_pinocchio_path():
    robot = Robot(_urdf("planar"), base_dir=".")
    assert robot.fk_backend == "pinocchio"
    assert robot.joint_names == ("j1.x", "j1.y", "j1.theta", "j2")
    Q = _draw(robot, 100, seed=3)
    T_a_j1 = make_transform(pin.rpy.rpyToMatrix(0.1, 0.2, 0.3), [0.1, 0.2, 0.3])
    for (x, y, theta, _), T in zip(Q, robot.fk("b", Q), strict=True):
        motion = make_transform(pin.rpy.rpyToMatrix(0.0, 0.0, theta), [x, y, 0.0])  # in the joint's xy plane
        assert np.abs(T - T_a_j1 @ motion).max() < TOL
    with pytest.raises(InputError, match="'j1' is planar: it has no single axis"):
        robot.joint_axis("j1")
    with pytest.raises(InputError, match="unknown joint 'j9'"):
        robot.joint_axis("j9")


def test_the_back_end_is_chosen_by_the_model_not_by_the_array_shape(robot, monkeypatch):
    def no_loop(*args, **kwargs):
        raise AssertionError("the batch robot must not evaluate through Pinocchio's loop")

    monkeypatch.setattr(robot, "_pinocchio_frame_poses", no_loop)
    q = random_configurations(robot, 1, seed=5)[0]
    # The same path on the same numbers: bit for bit.
    assert np.array_equal(robot.fk("needle_tip", q), robot.fk("needle_tip", q[None])[0])
    assert robot.transform("probe_tip", "needle_tip", q).shape == (4, 4)
