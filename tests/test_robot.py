"""Kinematics API: batch FK against Pinocchio, frame transforms, limits, tool frames, URDF out."""

from __future__ import annotations

import mujoco
import numpy as np
import pinocchio as pin
import pytest
import yourdfpy
from conftest import random_configurations
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from brachycal import InputError
from brachycal.errors import OutputError
from brachycal.model import Robot
from brachycal.se3 import inverse, make_transform


def test_batch_fk_matches_pinocchio_loop_on_every_frame(robot):
    Q = random_configurations(robot, 3000, seed=4)
    frames = list(robot.frame_names[1:])
    assert np.abs(robot.fk_frames(frames, Q) - robot.fk_frames_loop(frames, Q)).max() < 1e-12


def test_single_and_batch_paths_agree(robot):
    Q = random_configurations(robot, 5, seed=5)
    batch = robot.fk("needle_tip", Q)
    assert batch.shape == (5, 4, 4)
    for q, T in zip(Q, batch, strict=True):
        assert np.allclose(robot.fk("needle_tip", q), T, atol=1e-13)


@settings(max_examples=50, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_frame_to_frame_transform_reads_left_to_right(robot, seed):
    q = random_configurations(robot, 1, seed=seed)[0]
    T_R_EL = robot.fk("arm_left_link_tool0", q)
    T_R_I = robot.fk("us_image", q)
    T_EL_I = robot.transform("arm_left_link_tool0", "us_image", q)
    assert np.allclose(T_R_EL @ T_EL_I, T_R_I, atol=1e-12)
    T_Ntip_I = robot.transform("needle_tip", "us_image", q)
    assert np.allclose(T_Ntip_I, inverse(robot.fk("needle_tip", q)) @ T_R_I, atol=1e-12)


def test_batch_of_frame_transforms(robot):
    Q = random_configurations(robot, 7, seed=6)
    T = robot.transform("probe_tip", "needle_tip", Q)
    assert T.shape == (7, 4, 4)
    assert np.allclose(T[3], robot.transform("probe_tip", "needle_tip", Q[3]), atol=1e-12)


def test_named_configuration_round_trip(robot):
    q = random_configurations(robot, 1, seed=7)[0]
    named = robot.named(q)
    assert list(named) == list(robot.joint_names)
    assert np.array_equal(robot.configuration(dict(reversed(list(named.items())))), q)
    with pytest.raises(InputError, match=r"missing joint.*arm_left_joint_4_u"):
        robot.configuration({k: v for k, v in named.items() if k != "arm_left_joint_4_u"})


def test_joint_limit_checks(robot):
    q = robot.neutral()
    assert robot.within_limits(q)
    q_out = q.copy()
    q_out[3] = robot.upper[3] + 1e-3
    assert not robot.within_limits(q_out)
    assert robot.within_limits(np.stack([q, q_out])).tolist() == [True, False]
    q_edge = q.copy()
    q_edge[3] = robot.upper[3] - 0.01
    assert robot.within_limits(q_edge) and not robot.within_limits(q_edge, margin=0.02)


def test_unknown_frame_is_refused(robot):
    with pytest.raises(InputError, match="unknown frame 'needle_tipp'"):
        robot.fk("needle_tipp", robot.neutral())


def _random_pose(seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return make_transform(Rotation.random(random_state=seed).as_matrix(), rng.normal(scale=0.1, size=3))


def test_replacing_a_tool_frame_moves_it_and_its_children(robot):
    T_EL_Ptip = _random_pose(8)
    calibrated = robot.with_tool_transform("probe_tip", T_EL_Ptip)
    parent, T = calibrated.tool_transform("probe_tip")
    assert parent == "arm_left_link_tool0"
    assert np.allclose(T, T_EL_Ptip, atol=1e-14)
    q = random_configurations(robot, 1, seed=9)[0]
    T_Ptip_I = robot.tool_transform("us_image")[1]
    assert np.allclose(
        calibrated.fk("us_image", q), robot.fk("arm_left_link_tool0", q) @ T_EL_Ptip @ T_Ptip_I, atol=1e-12
    )
    assert np.allclose(calibrated.fk("needle_tip", q), robot.fk("needle_tip", q), atol=0)
    assert not np.allclose(robot.fk("probe_tip", q), calibrated.fk("probe_tip", q))  # the original is untouched


def test_calibrated_urdf_written_elsewhere_loads_in_three_libraries(robot, tmp_path):
    T_ER_Ntip = _random_pose(10)
    calibrated = robot.with_tool_transform("needle_tip", T_ER_Ntip)
    out_dir = tmp_path / "ros_ws" / "urdf"
    out_dir.mkdir(parents=True)
    path = calibrated.write_urdf(out_dir / "sda10f_calibrated.urdf")
    reloaded = Robot.load(path)
    assert np.allclose(reloaded.tool_transform("needle_tip")[1], T_ER_Ntip, atol=1e-14)
    assert reloaded.collision_model().ngeoms == 16  # mesh paths were rebased
    mj = mujoco.MjModel.from_xml_path(str(path))
    assert mj.body("needle_tip").id > 0
    urdf = yourdfpy.URDF.load(str(path), build_collision_scene_graph=True, load_collision_meshes=True)
    q = random_configurations(robot, 1, seed=11)[0]
    urdf.update_cfg(robot.named(q))
    assert np.allclose(urdf.get_transform("needle_tip", "base_link"), calibrated.fk("needle_tip", q), atol=1e-9)
    assert "NOMINAL PLACEHOLDERS" in path.read_text()  # provenance comments survive


def test_write_urdf_never_overwrites_without_force(robot, tmp_path):
    path = robot.write_urdf(tmp_path / "a.urdf")
    with pytest.raises(OutputError, match="already exists"):
        robot.write_urdf(path)
    robot.write_urdf(path, force=True)
    assert list(tmp_path.iterdir()) == [path]  # no temporary file left behind


def test_replacing_a_moving_joint_is_refused(robot):
    with pytest.raises(InputError, match="moving joint"):
        robot.with_tool_transform("arm_left_link_1_s", np.eye(4))


def test_malformed_urdf_is_refused(tmp_path):
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot><link name='a'>")
    with pytest.raises(InputError, match=r"bad\.urdf: not valid XML"):
        Robot.load(bad)
    with pytest.raises(InputError, match=r"missing\.urdf: no such file"):
        Robot.load(tmp_path / "missing.urdf")


def test_pinocchio_model_matches_its_own_frames(robot):
    # The batch path reads joint placements from the model; a frame placed by Pinocchio itself
    # must therefore come out identical.
    q = random_configurations(robot, 1, seed=13)[0]
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    fid = robot.frame_id("us_image")
    assert np.allclose(robot.fk_frames(["us_image"], q[None])[0, 0], data.oMf[fid].homogeneous, atol=1e-13)


def test_written_files_get_the_usual_permissions(robot, tmp_path):
    import os

    mask = os.umask(0o022)
    try:
        path = robot.write_urdf(tmp_path / "p.urdf")
    finally:
        os.umask(mask)
    assert path.stat().st_mode & 0o777 == 0o644


def test_moved_joint_origins_are_the_reread_urdf(robot):
    """Moving joint origins moves the Pinocchio model directly (no URDF re-read): on both back ends
    every frame's pose is the one of the robot read back from its text to 1e-12 m, that text is
    the one rewriting the origins gives, a second move composes on the first, and the robot still
    carries its rig."""
    from brachycal.model import urdf_text

    rng = np.random.default_rng(5)

    def moves(names: tuple[str, ...]) -> dict[str, np.ndarray]:
        return {
            n: robot.joint_origin(n)
            @ make_transform(Rotation.from_rotvec(rng.normal(0, 1e-2, 3)).as_matrix(), rng.normal(0, 1e-2, 3))
            for n in names
        }

    first, second = moves(robot.joint_names[::3]), moves(robot.joint_names[1::4])
    moved = robot.with_joint_origins(first).with_joint_origins(second)
    root = urdf_text.parse(robot.urdf_xml, "test")
    for name, T in {**first, **second}.items():
        urdf_text.set_joint_origin(root, name, T, "test")
    assert moved.urdf_xml == urdf_text.to_text(root)
    reread = Robot(moved.urdf_xml, base_dir=robot.base_dir)
    Q = random_configurations(robot, 20, seed=6)
    frames = robot.frame_names
    assert np.abs(moved.fk_frames(frames, Q) - reread.fk_frames(frames, Q)).max() < 1e-12
    assert np.abs(moved.fk_frames_loop(frames, Q) - reread.fk_frames_loop(frames, Q)).max() < 1e-12
    assert np.abs(moved.fk_frames(frames, Q) - robot.fk_frames(frames, Q)).max() > 1e-3
    for name, T in {**first, **second}.items():
        assert np.abs(moved.joint_origin(name) - T).max() < 1e-12
    assert moved.rig is robot.rig


def test_joint_origin_corrections_move_the_tool_on_a_urdf_with_transmissions_first(tmp_path):
    """The UR10 description of FIGAROH's data lists its <transmission> elements (each holding a
    <joint name=...>) before the kinematic joints: a correction must land on the real joint."""
    from conftest import reference

    path = reference("figaroh_mocap", "ur10", "urdf", "ur10_robot.urdf")
    robot = Robot.load(path)
    name = "shoulder_lift_joint"
    T = robot.joint_origin(name)
    assert not np.allclose(T, np.eye(4))  # the real joint's origin, not the transmission's (none: identity)
    moved = T.copy()
    moved[:3, 3] += [0.0, 0.0, 0.010]
    corrected = robot.with_joint_origins({name: moved})
    q = robot.neutral()
    shift = corrected.fk("tool0", q)[:3, 3] - robot.fk("tool0", q)[:3, 3]
    R_base_joint_parent = robot.fk("shoulder_link", q)[:3, :3]
    assert np.allclose(shift, R_base_joint_parent @ [0.0, 0.0, 0.010], atol=1e-12)
    assert np.allclose(corrected.joint_origin(name), moved, atol=1e-12)
    # Written and loaded back (Pinocchio), the corrected robot has the same FK.
    reloaded = Robot.load(corrected.write_urdf(tmp_path / "ur10_corrected.urdf"))
    assert np.allclose(reloaded.fk("tool0", q), corrected.fk("tool0", q), atol=1e-9)
