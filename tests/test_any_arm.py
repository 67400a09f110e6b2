"""Any arm: robot descriptions naming one arm or several (``[[arm]]``: a base link, a flange link, an
optional tool frame), plain URDF files and example-robot-data's robots, wherever a robot is taken.

The commands about any robot (``model``, ``fk``) take them; the commands about the dual-arm rig
(calibrate, plan, demo, ...) refuse a robot without a needle arm and a probe arm in one line.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from conftest import random_configurations, reference
from hostile import Case, check_refusal, run_cli

from brachycal.errors import InputError
from brachycal.model import Robot
from brachycal.model.description import SINGLE_ARM_ROBOTS, load_description, load_robot
from brachycal.model.description_file import example_robot_data_share

#: A three-link arm with a revolute shoulder, a prismatic slide and a revolute wrist; no meshes.
SLIDE_URDF = """<robot name="slide">
  <link name="base"/><link name="l1"/><link name="l2"/><link name="flange"/><link name="marker"/>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0.3"/><axis xyz="0 0 1"/><limit lower="-2" upper="2" effort="1" velocity="1.5"/></joint>
  <joint name="slide" type="prismatic"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.1 0 0"/><axis xyz="1 0 0"/><limit lower="-0.05" upper="0.25" effort="1" velocity="0.2"/></joint>
  <joint name="wrist" type="revolute"><parent link="l2"/><child link="flange"/>
    <origin xyz="0.2 0 0"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="1" velocity="2"/></joint>
  <joint name="marker_joint" type="fixed"><parent link="flange"/><child link="marker"/>
    <origin xyz="0 0 0.05"/></joint>
</robot>
"""

ARM_TOML = """format = "brachycal-robot/1"
name = "slide_arm"
urdf = "slide.urdf"
base = "base"
[[arm]]
name = "arm"
flange = "flange"
{tool}
"""


def slide_description(tmp: Path, tool: str = 'tool = "marker"', extra: str = "") -> Path:
    (tmp / "slide.urdf").write_text(SLIDE_URDF)
    path = tmp / "slide.toml"
    path.write_text(ARM_TOML.format(tool=tool) + extra)
    return path


# --- descriptions of any arm -------------------------------------------------------------------------
@pytest.mark.parametrize("name", SINGLE_ARM_ROBOTS)
def test_a_bundled_single_arm_loads_with_its_arm_and_no_rig(name):
    description = load_description(name)
    (arm,) = description.arms
    robot = description.robot
    assert robot.arms == description.arms and robot.arm() == arm
    assert arm.joints == robot.joint_names  # every coordinate moves the flange: fingers are frozen
    assert len(arm.joints) == {"panda": 7, "ur5": 6, "ur10": 6}[name]
    assert not description.dual_arm and not robot.has_rig
    with pytest.raises(InputError, match="needle arm and probe arm") as caught:
        _ = description.rig
    assert "\n" not in str(caught.value)
    q = random_configurations(robot, 3, seed=1)
    T_base_flange = robot.transform(arm.base, arm.flange, q)
    assert np.allclose(T_base_flange[:, 3, 3], 1.0)  # the chain is there: Pinocchio evaluates it


def test_the_help_names_the_bundled_single_arms_without_reading_them():
    from brachycal.cli.common import SINGLE_ARM_ROBOT_NAMES

    assert SINGLE_ARM_ROBOT_NAMES == SINGLE_ARM_ROBOTS


def test_a_single_arm_description_adds_its_tool_on_the_flange(tmp_path):
    tool = '[arm.tool]\nframe = "ball"\nxyz_m = [0.0, 0.0, 0.1]\nwhat = "touch probe ball"'
    robot = load_description(slide_description(tmp_path, tool)).robot
    arm = robot.arm("arm")
    assert (arm.base, arm.flange, arm.tool, arm.joints) == ("base", "flange", "ball", ("shoulder", "slide", "wrist"))
    q = random_configurations(robot, 4, seed=2)
    T_flange_ball = robot.transform("flange", "ball", q)
    assert np.allclose(T_flange_ball[:, :3, 3], [0.0, 0.0, 0.1], atol=1e-12)
    assert np.allclose(T_flange_ball[:, :3, :3], np.eye(3), atol=1e-12)


def test_a_description_may_name_several_arms(tmp_path):
    """Two arms on one tree (here the flange and, from the slide's link, the same flange): each arm's
    joints are those between its own base and its flange."""
    extra = '[[arm]]\nname = "wrist_only"\nbase = "l2"\nflange = "flange"\n'
    robot = load_description(slide_description(tmp_path, extra=extra)).robot
    assert [a.name for a in robot.arms] == ["arm", "wrist_only"]
    assert robot.arm("wrist_only").joints == ("wrist",)
    with pytest.raises(InputError, match="2 arms"):
        robot.arm()
    with pytest.raises(InputError, match="no arm 'elbow'"):
        robot.arm("elbow")


@pytest.mark.parametrize(
    ("tool", "extra", "words"),
    [
        ('tool = "l1"', "", ("arm[0].tool", "not below the flange")),
        ('tool = "nowhere"', "", ("arm[0].tool", "no link 'nowhere'")),
        ("", '[[arm]]\nname = "up"\nbase = "flange"\nflange = "l1"\n', ("arm[1].base", "not above")),
        ("", '[[arm]]\nname = "arm"\nflange = "l2"\n', ("arm[1].name", "named twice")),
        ("", '[needle_arm]\nflange = "flange"\njoints = []\nready_rad = []\n', ("'arm'", "not both")),
        ("", "[workspace]\ncube_centre_m = [0.5, 0.0, 0.0]\n", ("'workspace'", "dual-arm")),
        ("", '[[arm]]\nname = "still"\nflange = "base"\n', ("arm[1].flange", "no joint moves")),
    ],
)
def test_a_bad_arm_is_refused_in_one_line_naming_the_key(tmp_path, tool, extra, words):
    with pytest.raises(InputError) as caught:
        load_description(slide_description(tmp_path, tool, extra))
    message = str(caught.value)
    assert "\n" not in message and "slide.toml" in message
    for word in words:
        assert word in message


def test_a_description_without_arms_says_what_it_needs(tmp_path):
    (tmp_path / "slide.urdf").write_text(SLIDE_URDF)
    path = tmp_path / "bare.toml"
    path.write_text('format = "brachycal-robot/1"\nname = "bare"\nurdf = "slide.urdf"\nbase = "base"\n')
    with pytest.raises(InputError, match=r"key 'arm': missing.*\[\[arm\]\].*\[needle_arm\] and \[probe_arm\]"):
        load_description(path)


def test_a_dual_arm_rig_has_its_needle_and_probe_arms():
    robot = load_description("ur5_pair").robot
    needle, probe = robot.arms
    assert (needle.name, needle.flange, needle.tool) == ("needle_arm", "right_tool0", "needle_tip")
    assert (probe.name, probe.flange, probe.tool) == ("probe_arm", "left_tool0", "probe_tip")
    assert needle.joints == robot.rig.needle_arm.joints and probe.joints == robot.rig.probe_arm.joints
    sda10f = Robot.load()
    assert sda10f.arms[0].joints[0] == "torso_joint_b1"  # the shared torso, then the arm's own


# --- plain URDFs and example-robot-data ---------------------------------------------------------
def test_a_plain_urdf_loads_as_a_robot_with_no_arms_named(tmp_path):
    (tmp_path / "slide.urdf").write_text(SLIDE_URDF)
    robot = load_robot(tmp_path / "slide.urdf")
    assert robot.joint_names == ("shoulder", "slide", "wrist") and robot.arms == ()
    with pytest.raises(InputError, match="needle arm and a probe arm"):
        _ = robot.rig


def test_an_example_robot_data_urdf_is_taken_by_its_reference():
    robot = load_robot("example-robot-data:robots/ur_description/urdf/ur10_robot.urdf")
    ur10 = load_description("ur10").robot
    q = random_configurations(ur10, 5, seed=3)
    assert np.array_equal(robot.fk("tool0", q), ur10.fk("tool0", q))
    assert (example_robot_data_share() / "robots/ur_description/urdf/ur10_robot.urdf").is_file()
    with pytest.raises(InputError, match=r"no file robots/none\.urdf in example-robot-data"):
        load_robot("example-robot-data:robots/none.urdf")


# --- brachycal model -----------------------------------------------------------------------------
def prismatic_lines(text: str, name: str) -> str:
    (line,) = [line for line in text.splitlines() if line.strip().startswith(name + " ")]
    return line


def test_model_prints_a_prismatic_joints_limits_in_metres_and_millimetres(tmp_path):
    (tmp_path / "slide.urdf").write_text(SLIDE_URDF)
    for argv in (["--urdf", str(tmp_path / "slide.urdf")], ["--robot", str(slide_description(tmp_path))]):
        outcome = run_cli(["model", *argv])
        assert outcome.code == 0, outcome.err
        slide = prismatic_lines(outcome.out, "slide")
        assert "[-0.0500, +0.2500] m" in slide and "-50.0..+250.0 mm" in slide and "max 0.200 m/s" in slide
        assert "rad" not in slide and "deg" not in slide
        shoulder = prismatic_lines(outcome.out, "shoulder")
        assert "[-2.0000, +2.0000] rad" in shoulder and "-114.6..+114.6 deg" in shoulder


def test_model_prints_the_tiago_torso_lift_in_metres():
    urdf = reference("figaroh_mocap", "tiago", "urdf", "tiago_48_schunk.urdf")
    outcome = run_cli(["model", "--robot", str(urdf)])
    assert outcome.code == 0, outcome.err
    torso = prismatic_lines(outcome.out, "torso_lift_joint")
    assert "[+0.0000, +0.3500] m" in torso and "+0.0..+350.0 mm" in torso and "max 0.070 m/s" in torso
    assert "arms: none named" in outcome.out


def test_model_lists_a_described_arm():
    outcome = run_cli(["model", "--robot", "panda"])
    assert outcome.code == 0, outcome.err
    assert "7 controlled axes" in outcome.out
    assert "arm: panda_link0 -> panda_link8 -> panda_hand_tcp: panda_joint1, " in outcome.out
    assert "tool frames" not in outcome.out  # the dual-arm rig's needle and probe tips: none here


def test_fk_urdf_help_does_not_restrict_it_to_the_sda10f():
    import argparse

    from brachycal.cli import fk

    parser = argparse.ArgumentParser()
    fk.add_parser(parser.add_subparsers())
    sub = parser._subparsers._group_actions[0].choices["fk"]  # type: ignore[union-attr]
    (urdf,) = [a for a in sub._actions if "--urdf" in a.option_strings]
    (robot,) = [a for a in sub._actions if "--robot" in a.option_strings]
    assert "any robot" in urdf.help and "SDA10F URDF" not in urdf.help
    assert "panda" in robot.help and "URDF" in robot.help


# --- the dual-arm commands refuse a single arm ------------------------------------------------------
NEEDS = ("needle arm", "probe arm")
SESSION = str(Path(__file__).resolve().parents[1] / "examples" / "session_exact")
DUAL_ARM = [
    Case("calibrate-panda", ["calibrate", SESSION, "--robot", "panda", "--out", "{tmp}/r.json", "--quiet"], NEEDS),
    Case("plan-ur10", ["plan", "--robot", "ur10", "--out", "{tmp}/p.csv", "--quiet"], NEEDS),
    Case("demo-ur5", ["demo", "--robot", "ur5", "--out", "{tmp}/d"], NEEDS),
    Case("study-panda", ["study", "--robot", "panda", "--out", "{tmp}/s", "--quiet"], NEEDS),
    Case(
        "calibrate-plain-urdf",
        ["calibrate", SESSION, "--robot", "{tmp}/slide.urdf", "--out", "{tmp}/r.json", "--quiet"],
        NEEDS,
        setup=lambda tmp: (tmp / "slide.urdf").write_text(SLIDE_URDF),
    ),
    Case(
        "plan-arm-description",
        ["plan", "--robot", "{tmp}/slide.toml", "--out", "{tmp}/p.csv", "--quiet"],
        (*NEEDS, "slide_arm", "its arms: arm"),
        setup=slide_description,
    ),
]


@pytest.mark.parametrize("case", DUAL_ARM, ids=lambda c: c.id)
def test_a_dual_arm_command_refuses_a_robot_without_needle_and_probe_arms(case, tmp_path):
    check_refusal(case, tmp_path)


def test_tiago_described_as_one_arm_has_its_torso_lift_in_metres(tmp_path):
    """FIGAROH's TIAGo: the base, wheels, casters, head and gripper frozen, the arm from the base to
    the wrist is the torso lift (prismatic) and the 7 arm joints; sliding the lift by d metres moves
    the wrist by d along the lift's axis."""
    urdf = reference("figaroh_mocap", "tiago", "urdf", "tiago_48_schunk.urdf")
    still = [f"caster_{s}_{k}_joint" for s in ("back_left", "back_right", "front_left", "front_right") for k in (1, 2)]
    still += ["suspension_left_joint", "suspension_right_joint", "wheel_left_joint", "wheel_right_joint"]
    still += ["head_1_joint", "head_2_joint"]
    frozen = ", ".join(f"{name} = 0.0" for name in still) + ", gripper_finger_joint = 0.01"
    path = tmp_path / "tiago.toml"
    path.write_text(
        f'format = "brachycal-robot/1"\nname = "tiago"\nurdf = "{urdf}"\nbase = "base_footprint"\n'
        f'frozen = {{ {frozen} }}\n[[arm]]\nname = "arm"\nflange = "arm_7_link"\n'
    )
    robot = load_description(path).robot
    arm = robot.arm()
    assert arm.joints == ("torso_lift_joint", *(f"arm_{k}_joint" for k in range(1, 8))) == robot.joint_names
    assert robot.in_metres.tolist() == [True] + [False] * 7
    q = random_configurations(robot, 3, seed=8)
    lifted = q.copy()
    lifted[:, 0] = np.clip(q[:, 0] + 0.1, robot.lower[0], robot.upper[0])
    d = lifted[:, 0] - q[:, 0]
    axis = robot.fk("torso_lift_link", q)[:, :3, :3] @ robot.joint_axis("torso_lift_joint")
    shift = robot.fk("arm_7_link", lifted)[:, :3, 3] - robot.fk("arm_7_link", q)[:, :3, 3]
    assert np.abs(shift - d[:, None] * axis).max() < 1e-12 and d.max() > 0.05


@pytest.mark.parametrize("option", ["--robot", "--urdf"])
def test_fk_takes_a_plain_urdf(option, tmp_path):
    from brachycal.data.pose_table import read_pose_table

    (tmp_path / "slide.urdf").write_text(SLIDE_URDF)
    robot = load_robot(tmp_path / "slide.urdf")
    Q = random_configurations(robot, 4, seed=9)
    table = tmp_path / "q.csv"
    table.write_text("".join(",".join(f"{v:.17g}" for v in row) + "\n" for row in Q))
    out = tmp_path / "poses.csv"
    argv = ["fk", str(table), option, str(tmp_path / "slide.urdf"), "--frames", "marker", "--out", str(out)]
    outcome = run_cli(argv)
    assert outcome.code == 0, outcome.err
    samples, frames, T = read_pose_table(out)
    assert samples.tolist() == [1, 2, 3, 4] and frames == ["marker"] * 4
    assert np.abs(T[:, :3, 3] - robot.fk("marker", Q)[:, :3, 3]).max() < 1e-9
