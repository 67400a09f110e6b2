"""A calibrated URDF of any robot: joint-origin corrections (``corrected_robot``) written by
``Robot.write_urdf`` land in the right ``<joint>`` (a direct child of ``<robot>``, never a
``<transmission>``'s), and the written file, loaded back by Pinocchio and by yourdfpy (an
independent URDF reader), has the corrected robot's forward kinematics to 1e-9 m.

A property over random corrections (1 mm / 0.5° scale on every joint, several seeds) and random
configurations, on a Panda (example-robot-data, through the bundled description) and on FIGAROH's
UR10 URDF (its ``<transmission>`` elements come first).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from conftest import random_configurations, reference

from brachycal.calibration.robot.identification import corrected_robot
from brachycal.model import Robot
from brachycal.model.description import load_description

SEEDS = range(4)


def panda() -> tuple[Robot, str, str]:
    robot = load_description("panda").robot
    arm = robot.arm()
    return robot, arm.base, str(arm.tool)


def ur10() -> tuple[Robot, str, str]:
    return Robot.load(reference("figaroh_mocap", "ur10", "urdf", "ur10_robot.urdf")), "base_link", "tool0"


ROBOTS = {"panda": panda, "ur10": ur10}


def random_corrections(robot: Robot, seed: int) -> np.ndarray:
    """``(nq, 6)`` per joint ``(v, ω)``: translations of ~1 mm, rotations of ~0.5° (a real arm's scale, ×10)."""
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.normal(0.0, 1e-3, (robot.nq, 3)), rng.normal(0.0, np.radians(0.5), (robot.nq, 3))])


def yourdfpy_poses(path: Path, joint_names: tuple[str, ...], Q: np.ndarray, base: str, frame: str) -> np.ndarray:
    """``(N, 4, 4)`` ``T_base_frame`` by yourdfpy's own forward kinematics of the file at ``path``."""
    import yourdfpy

    urdf = yourdfpy.URDF.load(
        str(path), load_meshes=False, build_collision_scene_graph=False, load_collision_meshes=False
    )
    poses = []
    for q in Q:
        urdf.update_cfg(dict(zip(joint_names, q, strict=True)))
        poses.append(urdf.get_transform(frame_to=frame, frame_from=base))
    return np.array(poses)


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("name", sorted(ROBOTS))
def test_a_written_calibrated_urdf_has_the_corrected_robots_kinematics(name, seed, tmp_path):
    nominal, base, tip = ROBOTS[name]()
    corrections = random_corrections(nominal, seed)
    corrected = corrected_robot(nominal, corrections)
    path = corrected.write_urdf(tmp_path / f"{name}_calibrated.urdf")
    Q = random_configurations(nominal, 20, seed=100 + seed)

    # The corrections moved the tool (by millimetres), so the comparison below can fail.
    moved = np.linalg.norm(corrected.fk(tip, Q)[:, :3, 3] - nominal.fk(tip, Q)[:, :3, 3], axis=1)
    assert moved.min() > 1e-4

    # Each correction is in the joint of that name, a direct child of <robot>; nothing else changed.
    root = ET.parse(path).getroot()
    kinematic = {j.get("name"): j for j in root.findall("joint")}
    for joint in root.iter("joint"):
        if joint.get("name") in nominal.joint_names and joint not in kinematic.values():
            assert joint.find("origin") is None  # a <transmission>'s <joint> carries no origin
    reloaded = Robot.load(path)
    assert reloaded.joint_names == nominal.joint_names
    for k, joint in enumerate(nominal.joint_names):
        assert joint in kinematic
        assert np.abs(reloaded.joint_origin(joint) - corrected.joint_origin(joint)).max() < 1e-12
        assert not np.allclose(reloaded.joint_origin(joint), nominal.joint_origin(joint), atol=1e-6), k

    # Loaded back by Pinocchio and by yourdfpy: the corrected robot's poses, every link, to 1e-9 m.
    links = [f for f in ("world", base, tip) if reloaded.model.existFrame(f)]
    for frame in links:
        assert np.abs(reloaded.fk(frame, Q) - corrected.fk(frame, Q)).max() < 1e-9
    T_base_tip = corrected.transform(base, tip, Q)
    mine = yourdfpy_poses(path, nominal.joint_names, Q, base, tip)
    assert np.abs(mine[:, :3, 3] - T_base_tip[:, :3, 3]).max() < 1e-9
    assert np.abs(mine[:, :3, :3] - T_base_tip[:, :3, :3]).max() < 1e-9
