"""Robot descriptions: the bundled SDA10F, Baxter and a cell of two UR5 arms, and the
refusals of a bad description file.

Pose agreements use 1e-12 (metres, and rotation entries): two evaluations of the same kinematic
chain differ by a few hundred float64 roundings on metre-sized chains, far below anything physical
and far above the last bits.
"""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest
from conftest import random_configurations

from brachycal.errors import InputError
from brachycal.model import names
from brachycal.model.collision import ClearanceChecker, collision_link_pairs, srdf_disabled_pairs
from brachycal.model.description import BUNDLED_ROBOTS, load_description
from brachycal.model.description_file import bundled_description_path, example_robot_data_share
from brachycal.model.ik import solve_ik
from brachycal.model.rig import TOOL_FRAMES
from brachycal.model.robot import Robot
from brachycal.planning.spec import PlanSpec
from brachycal.se3 import from_xyz_rpy, inverse

#: Two evaluations of the same chain (see the module docstring).
TOL = 1e-12
#: Half the 0.01 rad to which the bundled ready stances are rounded.
READY_ROUNDING_RAD = 0.005
ERD = "example-robot-data:robots"


@pytest.fixture(scope="module", params=BUNDLED_ROBOTS)
def description(request):
    return load_description(request.param)


# --- every bundled description ---------------------------------------------------------------
def test_a_bundled_description_loads_with_its_tool_frames(description):
    robot = description.robot
    Q = np.vstack([description.ready, random_configurations(robot, 20, seed=1)])
    poses = robot.fk_frames(list(TOOL_FRAMES), Q)
    assert np.all(np.isfinite(poses))
    for frame, parent in description.tool_frame_parents.items():
        assert robot.tool_transform(frame)[0] == parent
    # every coordinate in exactly one group; the ready stance inside the limits
    groups = description.needle_arm_indices + description.probe_arm_indices + description.shared_indices
    assert sorted(groups) == list(range(description.nq))
    assert robot.within_limits(description.ready)
    assert description.base == robot.model.frames[1].name  # the root link: poses are in it
    assert robot.rig is description.rig  # the model carries its rig


def test_the_sda10f_description_is_todays_constants(robot):
    d = load_description()  # the default
    assert d.name == "sda10f"
    assert d.joint_names == names.JOINT_NAMES
    assert d.needle_arm_indices == names.RIGHT_ARM and d.probe_arm_indices == names.LEFT_ARM
    assert d.shared_joints == ("torso_joint_b1",)
    assert np.array_equal(d.ready, names.READY)  # same decimal literals: exactly equal
    assert dict(d.mimic_joints) == names.MIMIC_JOINTS
    assert d.controller_joint_names == names.CONTROLLER_JOINT_NAMES
    assert d.tool_frame_parents == names.TOOL_FRAME_PARENTS
    assert d.base == names.BASE
    assert d.disabled_pairs == srdf_disabled_pairs()
    frames = [names.RIGHT_FLANGE, names.LEFT_FLANGE, *TOOL_FRAMES]
    Q = random_configurations(robot, 50, seed=2)
    assert np.max(np.abs(d.robot.fk_frames(frames, Q) - robot.fk_frames(frames, Q))) <= TOL
    spec = PlanSpec()  # the planner's defaults are the SDA10F's workspace
    ws = d.workspace
    for mine, theirs in (
        (ws.cube_centre_m, spec.cube_centre_m),
        (ws.insertion_dir, spec.insertion_dir),
        (ws.image_depth_dir, spec.image_depth_dir),
        (ws.image_lateral_dir, spec.image_lateral_dir),
    ):
        assert np.max(np.abs(np.asarray(mine) - theirs)) <= TOL


# --- Baxter ------------------------------------------------------------------------------------
def _erd_robot(relative: str) -> Robot:
    return Robot.load(example_robot_data_share() / "robots" / relative)


def test_baxter_is_its_two_arms_with_the_grippers_off_and_the_head_held():
    d = load_description("baxter")
    assert d.nq == 14 and d.shared_joints == ()
    assert dict(d.frozen_joints) == {"head_pan": 0.0}
    assert not {"l_gripper_l_finger", "left_gripper_base_link"} & set(d.robot.frame_names)
    # The published URDF itself, with its prismatic fingers and mimic joints, loads as it is.
    original = _erd_robot("baxter_description/urdf/baxter.urdf")
    assert {"revolute", "prismatic", "mimic"} == set(original.joint_kinds.values())
    # Same arm kinematics as the published model (head at 0, fingers anywhere: they move no flange).
    Q = random_configurations(d.robot, 20, seed=3)
    Q_original = np.zeros((len(Q), original.nq))
    for k, joint in enumerate(d.joint_names):
        Q_original[:, original.joint_names.index(joint)] = Q[:, k]
    for flange in ("left_hand_link", "right_hand_link"):
        assert np.max(np.abs(d.robot.fk_frames([flange], Q) - original.fk_frames([flange], Q_original))) <= TOL


def _write(tmp_path: Path, text: str, name: str = "robot.toml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_a_frozen_joint_holds_its_value_and_its_mimic_follows(tmp_path):
    """Freezing turns (or slides) the joint's origin by the value; a mimic follower freezes with it."""
    text = bundled_description_path("baxter").read_text()
    text = text.replace('remove_links = ["left_gripper_base_link", "right_gripper_base_link"]\n', "")
    text = text.replace(
        "frozen = { head_pan = 0.0 }",
        "frozen = { head_pan = 0.5, l_gripper_l_finger_joint = 0.01, r_gripper_l_finger_joint = 0.0 }",
    )
    d = load_description(_write(tmp_path, text))
    assert d.frozen_joints["l_gripper_r_finger_joint"] == pytest.approx(-0.01)  # multiplier -1 in the URDF
    original = _erd_robot("baxter_description/urdf/baxter.urdf")
    q_original = np.zeros(original.nq)
    q_original[original.joint_names.index("head_pan")] = 0.5
    q_original[original.joint_names.index("l_gripper_l_finger_joint")] = 0.01
    for frame in ("head", "l_gripper_l_finger", "l_gripper_r_finger"):
        assert np.max(np.abs(d.robot.fk(frame, np.zeros(d.nq)) - original.fk(frame, q_original))) <= TOL


# --- the two-arm cell ----------------------------------------------------------------------------
def test_the_ur5_cell_places_each_arm_where_it_says():
    d = load_description("ur5_pair")
    assert d.nq == 12 and len(d.needle_arm.joints) == len(d.probe_arm.joints) == 6
    single = _erd_robot("ur_description/urdf/ur5_robot.urdf")
    Q = random_configurations(d.robot, 20, seed=4)
    for prefix, y in (("left_", 0.4), ("right_", -0.4)):
        stated = from_xyz_rpy([0.0, y, 0.0], [0.0, 0.0, 0.0])
        assert np.max(np.abs(d.mounts[prefix] - stated)) <= TOL
        assert np.max(np.abs(d.robot.transform("base_link", f"{prefix}world", Q[0]) - stated)) <= TOL
        # each arm is the published UR5, seen from its own root
        columns = [d.joint_names.index(prefix + j) for j in single.joint_names]
        T_root_tool0 = inverse(stated) @ d.robot.fk_frames([f"{prefix}tool0"], Q)[0]
        assert np.max(np.abs(T_root_tool0 - single.fk_frames(["tool0"], Q[:, columns])[0])) <= TOL
    # the UR5's own SRDF pairs, once per arm under its prefix
    assert frozenset(("left_shoulder_link", "left_upper_arm_link")) in d.disabled_pairs
    assert frozenset(("right_shoulder_link", "right_upper_arm_link")) in d.disabled_pairs


def test_cell_meshes_resolve_from_the_installed_package():
    d = load_description("ur5_pair")
    geometry = d.robot.collision_model()  # loads every collision mesh through the rewritten paths
    single = (example_robot_data_share() / "robots/ur_description/urdf/ur5_robot.urdf").read_text()
    # each arm's, once, less the ee_link placeholder box the description removes
    assert geometry.ngeoms == 2 * (single.count("<collision") - 1)
    meshes = [g.meshPath for g in geometry.geometryObjects]
    assert all(m.endswith(".stl") and Path(m).is_file() for m in meshes)
    assert "example-robot-data" in d.robot.urdf_xml and "package://" not in d.robot.urdf_xml


# --- the workspace: both arms reach the paper's poses ---------------------------------------------
def _workspace_targets(d) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """Needle poses at the cube centre and its 8 corners, probe poses of the 3 layers (centre, ±edge/2)."""
    ws = d.workspace
    spec = PlanSpec(
        cube_centre_m=np.array(ws.cube_centre_m),
        insertion_dir=np.array(ws.insertion_dir),
        image_depth_dir=np.array(ws.image_depth_dir),
        image_lateral_dir=np.array(ws.image_lateral_dir),
    )
    half, R = spec.edge_m / 2, spec.image_axes()
    centre = np.array(ws.cube_centre_m)
    points = [centre] + [centre + R @ (np.array(s) * half) for s in itertools.product((-1, 1), repeat=3)]
    T_Ptip_I = d.robot.transform("probe_tip", "us_image", d.ready)
    return [spec.needle_pose(p) for p in points], [spec.probe_pose(o, T_Ptip_I) for o in (-half, 0.0, half)]


def _clearance(d):
    """``distances(q)``: metres between the convex hulls of the link pairs the planner keeps apart
    (the description's SRDF pairs off), by :class:`~brachycal.model.collision.ClearanceChecker`
    (Baxter's head is two spheres: convex primitives, one link with several shapes)."""
    return ClearanceChecker(d.robot, collision_link_pairs(d.robot, disabled=set(d.disabled_pairs))).distances


def test_the_ready_stance_is_collision_free(description):
    assert np.min(_clearance(description)(description.ready)) > 0.0


@pytest.mark.parametrize("name", ["baxter", "ur5_pair"])
def test_both_arms_reach_the_cube_with_the_tools_on(name):
    """From the ready stance, IK places the needle tip at the cube centre and its 8 corners and the
    probe at the 3 layers, inside the limits, with the other arm at its ready stance and no two
    link hulls touching. (The planner, not this test, chooses among the solutions.)"""
    d = load_description(name)
    clearance = _clearance(d)
    needles, probes = _workspace_targets(d)
    for frame, targets, joints in (
        ("needle_tip", needles, d.needle_arm_indices),
        ("probe_tip", probes, d.probe_arm_indices),
    ):
        for T in targets:
            q = solve_ik(d.robot, frame, T, d.ready, joints, restarts=30, margin=0.05)  # SolverError fails the test
            assert d.robot.within_limits(q, margin=0.05)
            assert np.min(clearance(q)) > 0.0


@pytest.mark.parametrize("name", ["baxter", "ur5_pair"])
def test_the_ready_stance_holds_the_tools_back_from_the_cube_centre(name):
    """The ready stance is each tool 5 cm back along its axis from its pose at the cube centre, with
    the joints rounded to 0.01 rad: the tool may be off by at most what that rounding moves it,
    0.005 rad times the sum of the Jacobian's column norms (position) or times the joint count (angle)."""
    d = load_description(name)
    needles, probes = _workspace_targets(d)
    q = d.ready
    q_pin = d.robot.to_pinocchio(q[None])[0]
    data = d.robot.model.createData()
    for frame, T, joints in (
        ("needle_tip", needles[0], d.needle_arm_indices),
        ("probe_tip", probes[1], d.probe_arm_indices),
    ):
        target = T[:3, 3] - 0.05 * T[:3, 2]
        pose = d.robot.fk(frame, q)
        fid = d.robot.frame_id(frame)
        J = pin.computeFrameJacobian(d.robot.model, data, q_pin, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
        names_ = [d.joint_names[j] for j in joints]
        cols = [d.robot.model.joints[d.robot.model.getJointId(n)].idx_v for n in names_]
        bound_m = READY_ROUNDING_RAD * np.linalg.norm(J[:3, cols], axis=0).sum()
        assert np.linalg.norm(pose[:3, 3] - target) <= bound_m
        angle = np.arccos(np.clip(pose[:3, 2] @ T[:3, 2], -1.0, 1.0))
        assert angle <= READY_ROUNDING_RAD * len(joints)


# --- refusals -------------------------------------------------------------------------------------
def _edited(source: str, old: str, new: str):
    def make(tmp_path: Path) -> Path:
        text = bundled_description_path(source).read_text()
        assert old in text, old
        return _write(tmp_path, text.replace(old, new, 1))

    return make


REFUSALS = [
    # (id, make the file, words the one line must hold besides the file name)
    (
        "unknown-joint",
        _edited("ur5_pair", '"right_wrist_3_joint"]', '"right_wrist_9_joint"]'),
        ["needle_arm.joints", "right_wrist_9_joint"],
    ),
    ("missing-key", _edited("ur5_pair", "[probe_arm]", "[probe_arm_typo]"), ["probe_arm"]),
    ("missing-workspace-key", _edited("sda10f", "cube_centre_m = [0.80, 0.10, 1.05]\n", ""), ["cube_centre_m"]),
    (
        "ready-wrong-length",
        _edited("ur5_pair", "ready_rad = [0.15, -1.22, 2.14, 2.22, -1.11, -1.57]", "ready_rad = [0.15, -1.22]"),
        ["needle_arm.ready_rad", "6 values"],
    ),
    (
        "ready-outside-limits",
        _edited("baxter", "ready_rad = [0.45, -0.42,", "ready_rad = [2.5, 0.05,"),
        ["needle_arm.ready_rad", "right_s0", "limits"],
    ),
    (
        "ready-nan",
        _edited("baxter", "ready_rad = [0.45, -0.42,", "ready_rad = [nan, 0.05,"),
        ["needle_arm.ready_rad", "non-finite"],
    ),
    (
        "urdf-not-found",
        _edited("baxter", "baxter_description/urdf/baxter.urdf", "baxter_description/urdf/nothing.urdf"),
        ["urdf", "not found", "nothing.urdf"],
    ),
    (
        "relative-urdf-not-found",
        _edited("baxter", f'"{ERD}/baxter_description/urdf/baxter.urdf"', '"r.urdf"'),
        ["urdf", "r.urdf"],
    ),
    (
        "flange-unknown",
        _edited("baxter", 'flange = "left_hand_link"', 'flange = "left_paw"'),
        ["probe_arm.flange", "left_paw"],
    ),
    (
        "joint-in-the-wrong-arm",
        _edited("sda10f", '"arm_right_joint_7_t"]', '"arm_right_joint_7_t", "arm_left_joint_7_t"]'),
        ["needle_arm.joints", "arm_left_joint_7_t"],
    ),
    (
        "joint-in-no-arm",
        _edited("baxter", "frozen = { head_pan = 0.0 }", "frozen = {}"),
        ["head_pan", "frozen"],
    ),
    ("unknown-key", _edited("baxter", 'base = "base"', 'base = "base"\nbsae = 1'), ["bsae", "unknown key"]),
    ("base-not-root", _edited("baxter", 'base = "base"', 'base = "torso"'), ["base", "root link"]),
    (
        "tool-mount-not-rigid",
        _edited(
            "ur5_pair",
            "xyz_m = [0.030, 0.0, 0.280]",
            "matrix = [[2.0, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0.28], [0, 0, 0, 1]]",
        ),
        ["tools.needle_tip.matrix", "rigid"],
    ),
    (
        "tool-mount-in-millimetres",
        _edited("ur5_pair", "xyz_m = [0.030, 0.0, 0.280]", "xyz_m = [30.0, 0.0, 280.0]"),
        ["tools.needle_tip", "10 m"],
    ),
    (
        "tool-twice",
        _edited("sda10f", "[tools]  # in the URDF (see above)", "[tools.probe_tip]\nxyz_m = [0, 0, 0.3]"),
        ["tools.probe_tip", "already"],
    ),
    ("tool-missing", _edited("ur5_pair", "[tools.top_model_tip]", "[tools.top_model_typo]"), ["top_model_typo"]),
    ("not-toml", _edited("ur5_pair", "[needle_arm]", "[needle_arm"), ["TOML"]),
    ("name-is-a-path", _edited("ur5_pair", 'name = "ur5_pair"', 'name = "../ur5"'), ["name", "../ur5"]),
    ("wrong-format", _edited("ur5_pair", 'format = "brachycal-robot/1"', 'format = "brachycal-robot/9"'), ["format"]),
    (
        "mount-prefix-twice",
        _edited("ur5_pair", 'prefix = "right_"', 'prefix = "left_"'),
        ["mount[1].prefix", "twice"],
    ),
]


@pytest.mark.parametrize(("make", "words"), [r[1:] for r in REFUSALS], ids=[r[0] for r in REFUSALS])
def test_a_bad_description_is_refused_in_one_line_naming_file_and_key(tmp_path, make, words):
    path = make(tmp_path)
    with pytest.raises(InputError) as caught:
        load_description(path)
    message = str(caught.value)
    assert "\n" not in message
    assert str(path) in message
    for word in words:
        assert word.lower() in message.lower(), (word, message)


def test_a_urdf_that_is_not_xml_is_refused_naming_the_key(tmp_path):
    (tmp_path / "arm.urdf").write_text("<robot name='x'><link name='a'></robot>")
    text = bundled_description_path("ur5_pair").read_text()
    path = _write(tmp_path, text.replace(f"{ERD}/ur_description/urdf/ur5_robot.urdf", "arm.urdf", 1))
    with pytest.raises(InputError, match=r"robot\.toml: key 'mount\[0\]\.urdf': .*arm\.urdf: not valid XML"):
        load_description(path)


def test_an_unknown_robot_name_lists_the_bundled_ones():
    with pytest.raises(InputError, match="bundled robots are sda10f, baxter, ur5_pair"):
        load_description("kuka")


def test_a_missing_description_file_is_named(tmp_path):
    with pytest.raises(InputError, match=r"none\.toml"):
        load_description(tmp_path / "none.toml")


# --- the command line: --robot for the kinematics-first commands --------------------------------------


def test_the_command_line_names_the_bundled_robots():
    from brachycal.cli.common import BUNDLED_ROBOT_NAMES

    assert BUNDLED_ROBOT_NAMES == tuple(BUNDLED_ROBOTS)  # --help lists them without reading the files


@pytest.mark.parametrize("name", ["baxter", "ur5_pair"])
def test_fk_and_model_run_on_another_robot(tmp_path, capsys, name):
    """``brachycal fk --robot`` reads a log in that robot's joint names and writes the tool poses its
    model gives (1e-9 m: the table's text precision is 1e-9 m); ``model --robot`` lists its axes."""
    from brachycal.cli.main import main
    from brachycal.data import read_pose_table

    robot = load_description(name).robot
    q = random_configurations(robot, 5, seed=2)
    log = tmp_path / "log.csv"
    rows = [",".join(["time", *robot.joint_names])] + [
        ",".join([f"{0.1 * k:.1f}", *(f"{v:.17g}" for v in row)]) for k, row in enumerate(q)
    ]
    log.write_text("\n".join(rows) + "\n")
    out = tmp_path / "poses.csv"
    argv = ["fk", str(log), "--robot", name, "--frames", "needle_tip,probe_tip", "--out", str(out), "--quiet"]
    assert main(argv) == 0
    _, frames, T = read_pose_table(out)
    needle = T[np.array(frames) == "needle_tip"]
    assert np.abs(needle[:, :3, 3] - robot.fk("needle_tip", q)[:, :3, 3]).max() < 1e-9
    assert main(["model", "--robot", name]) == 0
    text = capsys.readouterr().out
    assert f"{robot.nq} controlled axes" in text and "needle_tip" in text and "us_image" in text


def test_robot_and_urdf_together_are_refused(capsys):
    from brachycal.cli.main import main

    assert main(["model", "--robot", "baxter", "--urdf", "x.urdf"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--robot and --urdf" in err
