"""The bundled URDF: the vendor's kinematics, 15 axes, tool frames, and the same file in three libraries."""

from __future__ import annotations

import subprocess
import sys

import mujoco
import numpy as np
import pinocchio as pin
import pytest
import yourdfpy
from conftest import ROOT, random_configurations, reference

from brachycal.model import JOINT_NAMES, TOOL_FRAME_PARENTS, bundled_urdf_path

TOOL_FRAMES = list(TOOL_FRAME_PARENTS)
FLANGES = ["arm_left_link_tool0", "arm_right_link_tool0"]


def vendor_configuration(vendor_model: pin.Model, named: dict[str, float]) -> np.ndarray:
    """The vendor model has ``torso_joint_b2`` as a 16th axis; the controller keeps it equal to b1."""
    q = np.zeros(vendor_model.nq)
    for name, value in {**named, "torso_joint_b2": named["torso_joint_b1"]}.items():
        q[vendor_model.joints[vendor_model.getJointId(name)].idx_q] = value
    return q


def test_fifteen_controlled_axes_in_documented_order(robot):
    assert robot.joint_names == JOINT_NAMES
    assert robot.nq == 15


def test_vendor_links_and_flanges_sit_where_the_vendor_puts_them(robot, vendor_model):
    vendor_data = vendor_model.createData()
    links = [f.name for f in vendor_model.frames if f.type == pin.FrameType.BODY and f.name != "universe"]
    assert set(FLANGES) <= set(links) and "torso_link_b2" in links
    worst = 0.0
    for q in random_configurations(robot, 200, seed=1):
        pin.framesForwardKinematics(vendor_model, vendor_data, vendor_configuration(vendor_model, robot.named(q)))
        ours = robot.fk_frames(links, q[None])[:, 0]
        for k, link in enumerate(links):
            theirs = vendor_data.oMf[vendor_model.getFrameId(link)].homogeneous
            worst = max(worst, float(np.abs(ours[k] - theirs).max()))
    assert worst < 1e-9


def test_joint_limits_are_the_vendors(robot, vendor_model):
    for k, name in enumerate(robot.joint_names):
        j = vendor_model.joints[vendor_model.getJointId(name)].idx_q
        assert robot.lower[k] == vendor_model.lowerPositionLimit[j]
        assert robot.upper[k] == vendor_model.upperPositionLimit[j]
        assert robot.velocity_limit[k] == vendor_model.velocityLimit[j]


def test_tool_frames_are_fixed_links_on_the_conventions_parents(robot):
    for frame, parent in TOOL_FRAME_PARENTS.items():
        got_parent, T = robot.tool_transform(frame)
        assert got_parent == parent
        q = random_configurations(robot, 1, seed=3)[0]
        assert np.allclose(robot.fk(frame, q), robot.fk(parent, q) @ T, atol=1e-12)


def test_urdf_is_regenerated_exactly_from_the_vendor_file(tmp_path):
    vendor = reference("motoman_sda10f", "sda10f_expanded.urdf")
    out = tmp_path / "sda10f.urdf"
    subprocess.run([sys.executable, str(ROOT / "urdf" / "make_sda10f_urdf.py"), str(vendor), str(out)], check=True)
    # Text equality is safe here: the script copies the vendor's numbers as text and writes its
    # own constants with repr (pi/2 is an exact halving); it computes no number.
    assert out.read_text() == bundled_urdf_path().read_text()


def _mujoco_poses(model: mujoco.MjModel, named: dict[str, float], frames: list[str]) -> np.ndarray:
    data = mujoco.MjData(model)
    for name, value in named.items():
        data.qpos[model.jnt_qposadr[model.joint(name).id]] = value
    mujoco.mj_kinematics(model, data)
    out = np.zeros((len(frames), 4, 4))
    for k, frame in enumerate(frames):
        body = data.body(frame)
        out[k, :3, :3] = body.xmat.reshape(3, 3)
        out[k, :3, 3] = body.xpos
        out[k, 3, 3] = 1.0
    return out


def test_pinocchio_mujoco_and_yourdfpy_agree_on_every_tool_frame(robot):
    mj_model = mujoco.MjModel.from_xml_path(str(bundled_urdf_path()))
    assert mj_model.nq == 15
    urdf = yourdfpy.URDF.load(str(bundled_urdf_path()))
    assert urdf.num_actuated_joints == 15
    frames = [*TOOL_FRAMES, *FLANGES]
    worst_mj = worst_ydf = 0.0
    for q in random_configurations(robot, 100, seed=2):
        named = robot.named(q)
        ours = robot.fk_frames(frames, q[None])[:, 0]
        worst_mj = max(worst_mj, float(np.abs(ours - _mujoco_poses(mj_model, named, frames)).max()))
        urdf.update_cfg(named)
        theirs = np.array([urdf.get_transform(frame_to=f, frame_from="base_link") for f in frames])
        worst_ydf = max(worst_ydf, float(np.abs(ours - theirs).max()))
    assert worst_mj < 1e-9
    assert worst_ydf < 1e-9


def test_mujoco_keeps_tool_frames_as_bodies_and_resolves_meshes(robot):
    model = robot.mujoco_model()
    bodies = {model.body(i).name for i in range(model.nbody)}
    assert set(TOOL_FRAMES) <= bodies
    assert model.nmesh == 9  # the nine light collision meshes of the vendor
    assert model.ngeom == 16  # one per link with geometry


def test_collision_meshes_load_in_pinocchio_and_yourdfpy(robot):
    geometry = robot.collision_model()
    assert geometry.ngeoms == 16
    assert all(obj.geometry.num_vertices > 0 for obj in geometry.geometryObjects)
    urdf = yourdfpy.URDF.load(str(bundled_urdf_path()), build_collision_scene_graph=True, load_collision_meshes=True)
    meshes = urdf.collision_scene.geometry.values()
    assert len(meshes) == 16 and all(len(mesh.vertices) > 0 for mesh in meshes)


@pytest.mark.parametrize("tool", TOOL_FRAMES)
def test_tool_values_are_documented_as_placeholders(tool):
    text = bundled_urdf_path().read_text()
    assert "NOMINAL PLACEHOLDERS" in text
    assert f'<link name="{tool}" />' in text
