"""Planning on any dual-arm set-up: the robot carries its rig, and ``plan`` plans the
paper's 4 x 4 x 4 poses on every bundled robot.

The poses are checked here independently of the planner (Pinocchio's forward kinematics and Coal's
distances, not MuJoCo's): the needle tip on its grid point and at its pixel within what the IK's
own stopping tolerances allow, inside the joint limits, the links apart.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hostile import Case, check_refusal

from brachycal.errors import InputError
from brachycal.model import names
from brachycal.model.collision import ClearanceChecker, collision_link_pairs, srdf_disabled_pairs
from brachycal.model.description import BUNDLED_ROBOTS, load_description
from brachycal.model.robot import Robot
from brachycal.planning import IKSettings, PlanSpec, Thresholds, plan_poses
from brachycal.se3 import inverse, transform_points

IK = IKSettings()
CHECK = Thresholds()
#: ``arccos`` of a cosine within 1 ulp of 1 is up to ~1.5e-8 rad: the direction bound's rounding room.
ARCCOS_ROUNDING_RAD = 2e-8


@pytest.fixture(scope="module", params=BUNDLED_ROBOTS)
def planned(request):
    robot = load_description(request.param).robot
    spec = PlanSpec.for_robot(robot)
    return robot, spec, plan_poses(robot, spec)


def test_every_bundled_robot_plans_all_64_poses(planned):
    robot, _, plan = planned
    assert plan.infeasible == []
    assert len(plan.poses) == 64
    assert sorted(p.point.name for p in plan.poses) == sorted({p.point.name for p in plan.poses})  # each once
    assert np.array_equal(plan.start_q, robot.rig.ready)  # it starts from the rig's ready stance


def test_the_needle_tip_is_on_its_grid_point_and_at_its_pixel(planned):
    """The IK stops once both tips are within ``position_tol_m`` of their targets and both tools'
    orientations within ``angle_tol_rad``. So the needle tip is at most ``position_tol_m`` off its
    point, and off the image's prediction (pixel and plane) by at most the two tips' errors plus the
    probe's angle error times its lever to the needle tip."""
    robot, spec, plan = planned
    Q = np.array([p.q for p in plan.poses])
    T_needle, T_image, T_probe = robot.fk_frames(["needle_tip", "us_image", "probe_tip"], Q)
    p_target = np.array([p.point.p_base for p in plan.poses])
    assert np.linalg.norm(T_needle[:, :3, 3] - p_target, axis=1).max() <= IK.position_tol_m
    lever_m = np.linalg.norm(T_needle[:, :3, 3] - T_probe[:, :3, 3], axis=1)
    image_bound_m = 2 * IK.position_tol_m + IK.angle_tol_rad * lever_m
    p_image = np.array([transform_points(inverse(T), t[:3, 3]) for T, t in zip(T_image, T_needle, strict=True)])
    uv_px = np.array([p.point.uv_px for p in plan.poses])
    in_plane_m = np.linalg.norm((p_image[:, :2] / spec.spacing_m - uv_px) * spec.spacing_m, axis=1)
    assert np.all(in_plane_m <= image_bound_m)
    assert np.all(np.abs(p_image[:, 2]) <= image_bound_m)
    # the needle along the insertion direction (the roll about it is free)
    insertion = spec.insertion_dir / np.linalg.norm(spec.insertion_dir)
    angle = np.arccos(np.clip(T_needle[:, :3, 2] @ insertion, -1.0, 1.0))
    assert angle.max() <= IK.angle_tol_rad + ARCCOS_ROUNDING_RAD


def test_the_poses_are_inside_the_limits_and_the_links_apart(planned):
    robot, _, plan = planned
    checker = ClearanceChecker(robot, collision_link_pairs(robot))  # the rig's pairs, by Coal
    for pose in plan.poses:
        assert robot.within_limits(pose.q, margin=CHECK.joint_margin_rad)
        assert np.min(checker.distances(pose.q)) >= CHECK.collision_margin_m


# --- the rig -----------------------------------------------------------------------------------
def test_the_bundled_urdf_carries_the_sda10f_rig_of_the_names_module():
    rig = Robot.load().rig
    assert rig == load_description("sda10f").rig
    assert rig.joint_names == names.JOINT_NAMES
    assert rig.needle_arm_indices == names.RIGHT_ARM and rig.probe_arm_indices == names.LEFT_ARM
    assert (rig.needle_flange, rig.probe_flange) == (names.RIGHT_FLANGE, names.LEFT_FLANGE)
    assert np.array_equal(rig.ready, names.READY)  # same decimal literals: exactly equal
    assert dict(rig.mimic_joints) == names.MIMIC_JOINTS
    assert rig.controller_joint_names == names.CONTROLLER_JOINT_NAMES
    assert rig.tool_frame_parents == names.TOOL_FRAME_PARENTS
    assert rig.disabled_pairs == srdf_disabled_pairs()
    # the planner's defaults are the SDA10F's workspace (its directions normalised when read: 1e-15)
    spec, default = PlanSpec.for_robot(Robot.load()), PlanSpec()
    for field in ("cube_centre_m", "insertion_dir", "image_depth_dir", "image_lateral_dir"):
        assert np.max(np.abs(getattr(spec, field) - getattr(default, field))) <= 1e-15, field


@pytest.mark.parametrize("name", ["sda10f", "baxter"])
def test_a_changed_robot_keeps_its_rig(name):
    robot = Robot.load() if name == "sda10f" else load_description(name).robot
    rig = robot.rig
    joint = rig.needle_arm.joints[1]
    changed = [
        robot.with_tool_transform("needle_tip", np.eye(4)),
        robot.with_joint_origins({joint: robot.joint_origin(joint)}),
        robot.with_joint_offsets({joint: 1e-3}),
    ]
    for other in changed:
        assert other.rig is rig


ONE_JOINT_URDF = (
    '<robot name="one"><link name="a"/><link name="b"/>'
    '<joint name="j" type="revolute"><parent link="a"/><child link="b"/><axis xyz="0 0 1"/>'
    '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>'
)


def test_a_robot_travels_to_a_worker_process_with_its_rig():
    """Pickled (as a parallel study sends it), a robot keeps its rig, read-only mappings included."""
    import pickle

    for robot in (Robot.load(), load_description("ur5_pair").robot):
        rig = robot.rig
        copy = pickle.loads(pickle.dumps(robot))
        assert copy.rig == rig
        assert all(np.array_equal(copy.rig.mounts[k], rig.mounts[k]) for k in rig.mounts)
        with pytest.raises(TypeError):
            copy.rig.mimic_joints["x"] = "y"  # type: ignore[index]


def test_a_robot_without_a_description_is_refused_when_asked_for_its_rig(tmp_path):
    urdf = tmp_path / "one.urdf"
    urdf.write_text(ONE_JOINT_URDF)
    robot = Robot.load(urdf)  # loads: only its rig is missing
    with pytest.raises(InputError, match=r"one\.urdf: this URDF is not the SDA10F's .*--robot FILE") as caught:
        _ = robot.rig
    assert "\n" not in str(caught.value)
    with pytest.raises(InputError, match="no description of its arms"):
        _ = Robot(urdf.read_text(), base_dir=tmp_path).rig
    with pytest.raises(InputError, match="no description of its arms"):
        plan_poses(Robot(urdf.read_text(), base_dir=tmp_path), PlanSpec(points_per_axis=2))


# --- the command line --------------------------------------------------------------------------
def test_plan_robot_writes_the_rigs_controller_order_from_its_ready_stance(tmp_path, capsys):
    """``brachycal plan --robot`` plans in that robot's workspace and writes its joints in its
    controller's order; each row's joints put the needle tip on the row's target within the IK's
    tolerance plus 1e-8 m for the written text (9 decimals: 5e-10 rad per joint over arms ~1 m long)."""
    from brachycal.cli.main import main

    d = load_description("ur5_pair")
    out = tmp_path / "plan.csv"
    assert main(["plan", "--robot", "ur5_pair", "--points", "2", "--out", str(out), "--quiet"]) == 0
    assert "planned 8 of 8 poses" in capsys.readouterr().out
    header = out.read_text().splitlines()[0].split(",")
    controller = list(d.rig.controller_joint_names)
    assert header[12 : 12 + len(controller)] == controller
    rows = np.loadtxt(out, delimiter=",", skiprows=1, usecols=range(5, 12 + len(controller)))
    q = np.zeros((len(rows), d.nq))
    q[:, [d.joint_names.index(n) for n in controller]] = rows[:, 7:]
    assert np.linalg.norm(d.robot.fk("needle_tip", q)[:, :3, 3] - rows[:, :3], axis=1).max() <= IK.position_tol_m + 1e-8
    centre = np.array(d.workspace.cube_centre_m)
    assert np.abs(rows[:, :3].mean(axis=0) - centre).max() < 1e-8  # the 2x2x2 grid is centred on it


CASES = [
    Case("plan-robot-unknown", ["plan", "--robot", "kuka", "--out", "{tmp}/p.csv"], ("kuka", "bundled robots")),
    Case(
        "plan-robot-and-urdf",
        ["plan", "--robot", "baxter", "--urdf", "{tmp}/x.urdf", "--out", "{tmp}/p.csv"],
        ("--robot and --urdf",),
    ),
    Case(
        "plan-urdf-of-another-robot",
        ["plan", "--urdf", "{tmp}/one.urdf", "--out", "{tmp}/p.csv", "--quiet"],
        ("one.urdf", "not the SDA10F's", "--robot FILE"),
        setup=lambda tmp: (tmp / "one.urdf").write_text(ONE_JOINT_URDF),
    ),
    Case(
        "plan-robot-file-missing",
        ["plan", "--robot", "{tmp}/none.toml", "--out", "{tmp}/p.csv"],
        ("none.toml", "cannot read robot description"),
    ),
]


@pytest.mark.parametrize("case", CASES, ids=lambda c: c.id)
def test_plan_refuses_a_robot_it_cannot_plan_on(case, tmp_path):
    check_refusal(case, tmp_path)


def test_a_collision_mesh_mujoco_cannot_read_is_converted_and_a_broken_one_refused(tmp_path):
    """Baxter's torso is COLLADA: MuJoCo gets it as STL with the same extent as Coal's mesh (1e-6 m:
    STL stores float32 vertices, ~6e-8 relative, on a ~1 m mesh); a file that is no mesh is one line."""
    import trimesh

    from brachycal.model.robot import _stl_bytes

    robot = load_description("baxter").robot
    torso = next(g for g in robot.collision_model().geometryObjects if g.meshPath.endswith(".DAE"))
    mesh = trimesh.load(trimesh.util.wrap_as_stream(_stl_bytes(Path(torso.meshPath), 0)), file_type="stl")
    vertices = np.asarray(torso.geometry.vertices())  # the mesh Coal read (through assimp)
    assert np.abs(mesh.bounds - np.array([vertices.min(axis=0), vertices.max(axis=0)])).max() < 1e-6
    assert robot.mujoco_model().nq == robot.nq

    (tmp_path / "bad.dae").write_text("not a mesh")
    urdf = ONE_JOINT_URDF.replace(
        '<link name="b"/>',
        '<link name="b"><collision><geometry><mesh filename="bad.dae"/></geometry></collision></link>',
    )
    with pytest.raises(InputError, match=r"cannot convert collision mesh .*bad\.dae to STL") as caught:
        Robot(urdf, base_dir=tmp_path).mujoco_model()
    assert "\n" not in str(caught.value)
